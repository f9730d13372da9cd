/// Scenes of standard tensegrity structures, generated as YAML text a person can read (docs/form_finding.md, "tensegrity_generate").
#pragma once

#include <limits>
#include <string>

namespace active_tensegrity::design
{
/// The ranges of the generators' parameters: every value in them gives a scene that loads (the generators and
/// tensegrity_generate refuse the rest, naming the parameter and the value).
constexpr double kMinGeneratedLength = 1e-3;     // m: radii, heights, lengths, widths, pitches
constexpr double kMaxGeneratedLength = 1e3;      // m
constexpr double kMinGeneratedPrestress = 1e-3;  // N
constexpr double kMaxGeneratedPrestress = 1e6;   // N
constexpr double kMaxGeneratedTwist = 360.0;     // degrees, either way
/// A tower's sliding cables run from its top through every level over a ground node to a driven body:
/// stages + 2 nodes, at most Cable::kMaxPoints (32).
constexpr int kMaxTowerStages = 30;

/// The class-1 n-strut prism: bottom nodes B1..Bn on a circle at z = 0 (B1 on the +y axis, counter-clockwise),
/// top nodes T1..Tn on the same circle at z = height, turned by `twist` about z; struts Si from Bi to Ti,
/// ring cables (one family) around the bottom and the top, verticals Vi from Bi to T(i+1). At the twist
/// -(90 deg + 180 deg / n) the prism has a self-stress with force densities
///   rings : verticals : struts = 1 : 2 sin(pi/n) : -2 sin(pi/n),
/// which the generated prestress follows (rings at `ring_prestress`); at another twist the same prestress
/// is written, and the start is not in equilibrium (a starting point for form-finding).
struct PrismSpec
{
  int struts = 3;                                           // 3 ... 64
  double radius = 0.5;                                      // m (kMinGeneratedLength ... kMaxGeneratedLength)
  double height = 0.8;                                      // m (as radius)
  double twist = std::numeric_limits<double>::quiet_NaN();  // rad, within +-kMaxGeneratedTwist degrees; NaN: the
                                                            // form's -(pi/2 + pi/n)
  double ring_prestress = 100.0;                            // N (kMinGeneratedPrestress ... kMaxGeneratedPrestress)
  bool pinned = false;                                      // the bottom nodes fixed (a static analysis)
  /// (with pinned) an actuator `press` drives the top nodes down (each along -z only, free across): a
  /// static fold to 0.3 height with contact between the struts (radius strut_radius)
  bool driven = false;
  double strut_radius = 0.012;  // m (as radius)
};

/// The twist of the n-strut prism's form, rad: -(pi/2 + pi/n).
double prismTwist(int struts);

std::string prismScene(const PrismSpec& spec);

/// The expanded octahedron: six struts of length L in three mutually orthogonal parallel pairs L/2 apart,
/// 24 cables (one family) of length L sqrt(6)/4, nodes at the cyclic permutations of (0, +-L/4, +-L/2).
/// In its form the cables' force density is q and the struts' -1.5 q.
struct OctahedronSpec
{
  double strut_length = 1.0;  // m (kMinGeneratedLength ... kMaxGeneratedLength)
  double prestress = 100.0;   // N, every cable (kMinGeneratedPrestress ... kMaxGeneratedPrestress)
  bool pinned = false;        // three nodes of one face fixed (a static analysis)
};

std::string octahedronScene(const OctahedronSpec& spec);

/// The clustered quadruplex tower: `stages` quadruplex stages of height width/2 stacked with alternating
/// handedness, joined by strut-to-strut ball joints. Levels 0..stages at z = l width / 2: even levels are
/// "big" squares (half-diagonal width/sqrt(2), corners at 45, 135, 225, 315 degrees), odd levels "small"
/// squares (half-diagonal width/2, at 0, 90, 180, 270 degrees). Ground nodes G1..G4 are pinned; level l's
/// nodes are L<l>_1..L<l>_4. In each stage the small node at azimuth phi carries strut S<s>_<k> to the big
/// node at phi + 135 degrees; the four bracing chains at one corner form one sliding cable P<k> from the top,
/// down through the tower, over its ground node to a driven body D<k> pulled down by actuator pull<k>. Big
/// squares above the ground are cables (family squares), small squares springs (family middle). Every
/// member starts at its free length (no prestress); materials and sections are those of the four-stage
/// tower of the package (tower.yaml).
struct TowerSpec
{
  int stages = 4;      // 1 ... kMaxTowerStages
  double width = 1.0;  // m: the big squares' side (kMinGeneratedLength ... kMaxGeneratedLength)
};

std::string towerScene(const TowerSpec& spec);

}  // namespace active_tensegrity::design
