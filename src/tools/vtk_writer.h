/// A run as VTK files for ParaView: one XML PolyData file (.vtp) per output state and a .pvd collection
/// that lists them with their times (docs/tools.md, `--vtk`).
///
/// Each .vtp holds
/// - points: the nodes (in the scene's order), then every other point a member runs through, then the two
///   contact points of every touching pair (point data `contact_force`, N: the contact force on each strut
///   at its point, normal and friction; zero elsewhere);
/// - vertices: one per contact point (so ParaView draws them and a Glyph filter shows the force);
/// - lines: one per strut (its two ends), one polyline per cable or spring (through every point it runs
///   over, so a sliding cable is one cell);
/// - cell data, for vertices and lines alike: `kind` (0 strut, 1 cable, 2 spring, 3 contact point),
///   `force` (N: a strut's axial force, a cable's or spring's tension, a contact's normal force), `radius`
///   (m: a strut's outer radius, a material cable's sqrt(A / pi), 0 for springs and contact points) and
///   `member` (the strut's index among the struts, the cable's index in the scene, the pair's index among
///   the checked pairs).
/// Text (ASCII) files, numbers to 10 significant digits.
#pragma once

#include <fstream>
#include <string>
#include <vector>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::tools
{
class VtkWriter
{
public:
  /// Files go to `directory` (created when missing) as <stem>_<k>.vtp, k = 000000, 000001 ..., and
  /// <stem>.pvd. Throws std::runtime_error when the directory cannot be made or written.
  VtkWriter(const core::Model& model, const std::string& directory, const std::string& stem = "run");
  /// Writes the next .vtp and adds it to the .pvd (which is complete after every write, so that a run
  /// stopped early still has a collection). Throws std::runtime_error when a file cannot be written.
  void write(const core::State& state);
  int written() const
  {
    return written_;
  }
  std::string collectionPath() const;

private:
  const core::Model& model_;
  std::string directory_, stem_;
  int written_ = 0;
  std::ofstream pvd_;
  std::streampos pvd_tail_;       // where the closing tags start
  std::vector<int> strut_index_;  // per body: its index among the struts, -1 for point masses
};

}  // namespace active_tensegrity::tools
