/// Lattices of quadruplex cells: the scenes that `tensegrity_bench lattice` (bench/lattice_cmd.cpp) measures
/// the time per step on, against the number of struts. ROS-free: only the core.
#pragma once

#include <string>
#include <vector>

namespace active_tensegrity::tools
{
/// Which strut pairs the generated scene checks for contact.
enum class LatticePairs
{
  kAuto,  // `pairs: auto`: every pair of struts that share no node
  kAll,   // the same pairs as an explicit list (checks the loader's auto against an independent count)
  kNear   // an explicit list: pairs of struts in the same or adjacent cells (8-neighbourhood) sharing no node
};

/// An nx x ny lattice of quadruplex cells on the ground (4 struts per cell). See lattice.cpp for the
/// geometry; every length in m.
struct LatticeOptions
{
  int nx = 2;
  int ny = 2;
  double pitch = 1.0;       // cell width: the bottom corners lie on a square grid of this spacing
  double top_radius = 0.3;  // top nodes on a circle of this radius about the cell centre (< pitch / 2)
  double height = 0.5;      // z of the top nodes
  double strut_radius = 0.05;
  LatticePairs pairs = LatticePairs::kAuto;
  bool contact = true;
  // dynamic run: the bracing cables are pulled in at `speed` (m/s, half-cosine blends of `blend_time` s
  // at both ends) by `max_actuation` (m)
  double speed = 2.0;
  double blend_time = 0.05;
  double max_actuation = 0.4;
  double duration = 0.4;  // s
  double dt = 2e-4;       // s (the paper's step; at 1e-3 s the steel impacts throw struts across the lattice)
};

/// The scene YAML (docs/scenes.md) of the lattice; load it with core::loadSceneFromString().
std::string quadruplexLatticeYaml(const LatticeOptions& o);

/// Strut names of cell (i, j): "S<i>_<j>_<k>", k = 1..4.
std::string latticeStrutName(int i, int j, int k);

/// The cell counts (nx <= ny <= 2 nx) whose 4 nx ny struts come closest to `struts` (ties: the larger).
struct LatticeCells
{
  int nx = 1;
  int ny = 1;
  int struts() const
  {
    return 4 * nx * ny;
  }
};
LatticeCells latticeCellsFor(int struts);

/// The benchmark's ladder: about 10, 20, 50, 100, 200 and 500 struts (8, 24, 48, 100, 200, 504).
std::vector<LatticeCells> standardLatticeSizes();

}  // namespace active_tensegrity::tools
