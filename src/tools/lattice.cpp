// Lattices of quadruplex cells, the scenes of `tensegrity_bench lattice` (bench/lattice_cmd.cpp: time per
// step against the number of struts).
//
// Geometry (chosen so that every cell is a quadruplex like config/scenes/quadruplex.yaml in its own
// prestressed equilibrium, neighbouring cells are joined, and a dynamic run folds it into contact
// and converges; why not otherwise is noted at the end):
// - Cell (i, j), i < nx, j < ny, has its centre at ((i + 1/2) p, (j + 1/2) p, 0), p = pitch (1 m).
//   Its bottom corners P1..P4 are at the centre + (h, h), (-h, h), (-h, -h), (h, -h), h = p / 2: nodes
//   G<a>_<b> of a square grid, fixed, and SHARED by up to four cells. The (up to four) struts ending at
//   one corner are joined there by ball joints (the loader pins the first, the others join it).
// - Its top nodes P5..P8 (T<i>_<j>_<k>) are at the centre + (a, 0, H), (0, a, H), (-a, 0, H), (0, -a, H),
//   a = top_radius (0.3 m), H = height (0.5 m): the quadruplex's top square (turned by 45 degrees), a
//   smaller one (a = h in quadruplex.yaml) so that the tips of facing struts of neighbouring cells start
//   p - 2a = 0.4 m apart.
// - Struts S1..S4: [P2, P5], [P3, P6], [P4, P7], [P1, P8], as in quadruplex.yaml. Cells with i + j odd are
//   the mirror image in x (a checkerboard of left- and right-handed cells), so that when the cells twist
//   as they fold, facing top nodes of neighbours move the same way.
// - Cables: upper square P5-P6-P7-P8 (U), bracing P5-P1, P6-P2, P7-P3, P8-P4 (B), and ties between facing
//   top nodes of neighbouring cells (X along x, Y along y). The ground square of quadruplex.yaml joins
//   fixed nodes only and is left out.
// - Prestress: with the bottom pinned, a top node balances for any a and H when the bracing and strut
//   force densities are equal (q = 400 N/m as in quadruplex.yaml) and the upper cables carry
//   T = sqrt(2) h q (282.84 N for h = 0.5 m); the bracing prestress is q times its length. The ties start
//   at their free length. So every cell, hence the lattice, starts in equilibrium.
// - Materials as quadruplex.yaml (steel struts of radius 0.05 m, cables EA = 2463 N); no gravity.
// - Actuator `pull`: every bracing cable pulled in together (rest length l0 - s) at 2 m/s with 50 ms
//   half-cosine blends, to s = 0.4 m (of l0 = 0.66 m): the tops come down from 0.5 to about 0.31 m and
//   struts touch from about t = 0.26-0.31 s on, so the default 0.4 s run includes contact. Contact:
//   restitution 0.5, friction 0.1, as tower.yaml.
// Why not otherwise: shared top nodes (two struts pinned at their far ends on one node) would make the
// drive singular at the start, the node being driven down from the top of the circle it can move on;
// driving the top nodes down (as quadruplex.yaml's `top`) locks struts of neighbouring cells against each
// other near the shared corners (contact forces of 10-500 MN, then Newton fails); with a = 0.4 m the tips,
// 0.2 m apart, touch across cells first.
#include "lattice.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace active_tensegrity::tools
{
namespace
{
constexpr double kCableEA = 7.84e6 * M_PI * 0.01 * 0.01;  // N: the cable material and radius below

std::string num(double x)
{
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17g", x);
  return buf;
}

std::string cornerName(int a, int b)
{
  return "G" + std::to_string(a) + "_" + std::to_string(b);
}

std::string topName(int i, int j, int k)
{
  return "T" + std::to_string(i) + "_" + std::to_string(j) + "_" + std::to_string(k);
}

// cells with i + j odd are the mirror image (in x about the cell centre) of the others: a checkerboard
bool mirrored(int i, int j)
{
  return (i + j) % 2 != 0;
}

// grid indices of corner k (1..4 for P1..P4) of cell (i, j)
std::pair<int, int> corner(int i, int j, int k)
{
  if (mirrored(i, j))
    k = k == 1 ? 2 : k == 2 ? 1 : k == 3 ? 4 : 3;  // x negated: P1 <-> P2, P3 <-> P4
  switch (k)
  {
    case 1:
      return { i + 1, j + 1 };
    case 2:
      return { i, j + 1 };
    case 3:
      return { i, j };
    default:
      return { i + 1, j };
  }
}

// the top node (5..8) of cell (i, j) on its +x side (P5, or P7 in a mirrored cell); -x: the other
int topPlusX(int i, int j)
{
  return mirrored(i, j) ? 7 : 5;
}

// corner (P1..P4) at the foot of strut k of a cell: S1 [P2, P5], S2 [P3, P6], S3 [P4, P7], S4 [P1, P8]
int strutFoot(int k)
{
  return k % 4 + 1;
}

void checkOptions(const LatticeOptions& o)
{
  const auto bad = [](const std::string& what, double v)
  { throw std::invalid_argument("lattice: " + what + ", got '" + num(v) + "'"); };
  if (o.nx < 1)
    bad("nx must be at least 1", o.nx);
  if (o.ny < 1)
    bad("ny must be at least 1", o.ny);
  if (!(o.pitch > 0.0))
    bad("pitch must be positive", o.pitch);
  if (!(o.top_radius > 0.0 && o.top_radius < 0.5 * o.pitch))
    bad("top_radius must be in (0, pitch / 2)", o.top_radius);
  if (!(o.height > 0.0))
    bad("height must be positive", o.height);
  if (!(o.strut_radius > 0.0))
    bad("strut_radius must be positive", o.strut_radius);
}
}  // namespace

std::string latticeStrutName(int i, int j, int k)
{
  return "S" + std::to_string(i) + "_" + std::to_string(j) + "_" + std::to_string(k);
}

std::string quadruplexLatticeYaml(const LatticeOptions& o)
{
  checkOptions(o);
  const double p = o.pitch, h = 0.5 * p, a = o.top_radius, H = o.height;
  const double q = 400.0;  // N/m: force density of struts and bracings (quadruplex.yaml)
  const double upper = std::sqrt(2.0) * h * q;
  const double bracing_length = std::sqrt((h - a) * (h - a) + h * h + H * H);
  const double bracing = q * bracing_length;
  const double bracing_rest = bracing_length / (1.0 + bracing / kCableEA);
  std::ostringstream y;
  y << "# generated by active_tensegrity::tools::quadruplexLatticeYaml (src/tools/lattice.cpp)\n";
  y << "name: quadruplex_lattice_" << o.nx << "x" << o.ny << "\n";
  y << "description: " << o.nx << " x " << o.ny
    << " quadruplex cells sharing their ground corners, top nodes tied by cables, bracings pulled in\n";
  y << "materials:\n";
  y << "  steel: {youngs_modulus: 210.0e9, poisson_ratio: 0.31, density: 7850.0}\n";
  y << "  cable: {youngs_modulus: 7.84e6, density: 1000.0}\n";
  y << "nodes:\n";
  for (int b = 0; b <= o.ny; ++b)
    for (int c = 0; c <= o.nx; ++c)
      y << "  " << cornerName(c, b) << ": {position: [" << num(c * p) << ", " << num(b * p) << ", 0.0], fixed: true}\n";
  const double dx[4] = { a, 0.0, -a, 0.0 }, dy[4] = { 0.0, a, 0.0, -a };
  for (int j = 0; j < o.ny; ++j)
    for (int i = 0; i < o.nx; ++i)
      for (int k = 0; k < 4; ++k)
        y << "  " << topName(i, j, k + 5) << ": {position: [" << num((i + 0.5) * p + (mirrored(i, j) ? -dx[k] : dx[k]))
          << ", " << num((j + 0.5) * p + dy[k]) << ", " << num(H) << "]}\n";
  y << "struts:\n  radius: " << num(o.strut_radius) << "\n  material: steel\n  members:\n";
  for (int j = 0; j < o.ny; ++j)
    for (int i = 0; i < o.nx; ++i)
      for (int k = 1; k <= 4; ++k)
      {
        const auto [c, b] = corner(i, j, strutFoot(k));
        y << "    " << latticeStrutName(i, j, k) << ": [" << cornerName(c, b) << ", " << topName(i, j, k + 4) << "]\n";
      }
  y << "cables:\n";
  const auto family = [&](const char* name, double prestress)
  {
    y << "  " << name << ":\n    material: cable\n    radius: 0.01\n";
    if (prestress > 0.0)
      y << "    prestress: " << num(prestress) << "\n";
    y << "    members:\n";
  };
  family("upper", upper);
  for (int j = 0; j < o.ny; ++j)
    for (int i = 0; i < o.nx; ++i)
      for (int k = 5; k <= 8; ++k)
        y << "      U" << i << "_" << j << "_" << k << ": [" << topName(i, j, k) << ", "
          << topName(i, j, k == 8 ? 5 : k + 1) << "]\n";
  family("bracing", bracing);
  for (int j = 0; j < o.ny; ++j)
    for (int i = 0; i < o.nx; ++i)
      for (int k = 5; k <= 8; ++k)
      {
        const auto [c, b] = corner(i, j, k - 4);  // P5-P1, P6-P2, P7-P3, P8-P4
        y << "      B" << i << "_" << j << "_" << k << ": [" << topName(i, j, k) << ", " << cornerName(c, b) << "]\n";
      }
  if (o.nx > 1 || o.ny > 1)
  {
    family("ties", 0.0);
    for (int j = 0; j < o.ny; ++j)
      for (int i = 0; i < o.nx; ++i)
      {
        if (i + 1 < o.nx)
          y << "      X" << i << "_" << j << ": [" << topName(i, j, topPlusX(i, j)) << ", "
            << topName(i + 1, j, 12 - topPlusX(i + 1, j)) << "]\n";
        if (j + 1 < o.ny)
          y << "      Y" << i << "_" << j << ": [" << topName(i, j, 6) << ", " << topName(i, j + 1, 8) << "]\n";
      }
  }
  // one actuator pulls every bracing cable in (rest length l0 - s)
  y << "actuators:\n  pull:\n    cables: [";
  for (int j = 0; j < o.ny; ++j)
    for (int i = 0; i < o.nx; ++i)
      for (int k = 5; k <= 8; ++k)
        y << (i == 0 && j == 0 && k == 5 ? "" : ", ") << "B" << i << "_" << j << "_" << k;
  y << "]\n    range: [0.0, " << num(0.9 * bracing_rest) << "]\n";
  y << "contact:\n  enabled: " << (o.contact ? "true" : "false") << "\n";
  y << "  restitution: 0.5\n  friction: 0.1\n";
  if (o.pairs == LatticePairs::kAuto)
    y << "  pairs: auto\n";
  else
  {
    // all: every pair of struts sharing no node (struts of one cell share none; of two cells, at most a
    // ground corner); near: only those of cells (i, j) and (i2, j2) with |i - i2| <= 1 and |j - j2| <= 1.
    // Each unordered pair once.
    const bool near = o.pairs == LatticePairs::kNear;
    y << "  pairs:\n";
    const int n = o.nx * o.ny;
    for (int c1 = 0; c1 < n; ++c1)
      for (int c2 = c1; c2 < n; ++c2)
      {
        const int i1 = c1 % o.nx, j1 = c1 / o.nx, i2 = c2 % o.nx, j2 = c2 / o.nx;
        if (near && (std::abs(i1 - i2) > 1 || std::abs(j1 - j2) > 1))
          continue;
        for (int k1 = 1; k1 <= 4; ++k1)
          for (int k2 = c1 == c2 ? k1 + 1 : 1; k2 <= 4; ++k2)
          {
            if (corner(i1, j1, strutFoot(k1)) == corner(i2, j2, strutFoot(k2)))
              continue;
            y << "    - [" << latticeStrutName(i1, j1, k1) << ", " << latticeStrutName(i2, j2, k2) << "]\n";
          }
      }
  }
  y << "solver:\n  dt: " << num(o.dt) << "\n  newton_tolerance: 1.0e-8\n  max_iterations: 30\n  max_step_cuts: 12\n";
  y << "actuation: {speed: " << num(o.speed) << ", blend_time: " << num(o.blend_time) << "}\n";
  y << "analysis:\n  type: dynamic\n  max_actuation: " << num(o.max_actuation) << "\n  duration: " << num(o.duration)
    << "\n  output_interval: 0.01\n";
  return y.str();
}

LatticeCells latticeCellsFor(int struts)
{
  LatticeCells best;
  int best_error = std::numeric_limits<int>::max();
  for (int nx = 1; 4 * nx * nx <= std::max(4, 2 * struts); ++nx)
    for (int ny = nx; ny <= 2 * nx; ++ny)
    {
      const int error = std::abs(4 * nx * ny - struts);
      if (error < best_error || (error == best_error && nx * ny > best.nx * best.ny))
      {
        best = { nx, ny };
        best_error = error;
      }
    }
  return best;
}

std::vector<LatticeCells> standardLatticeSizes()
{
  std::vector<LatticeCells> out;
  for (int n : { 10, 20, 50, 100, 200, 500 })
    out.push_back(latticeCellsFor(n));
  return out;
}

}  // namespace active_tensegrity::tools
