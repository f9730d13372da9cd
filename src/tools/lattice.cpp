// Lattices of quadruplex cells and the `tensegrity_bench lattice` command (the scaling benchmark: time per
// step against the number of struts; docs/benchmarks.md).
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
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "active_tensegrity/core/analysis.h"
#include "active_tensegrity/core/scene.h"
#include "cli.h"

namespace at = active_tensegrity::core;

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

namespace
{
using Clock = std::chrono::steady_clock;

struct Row
{
  LatticeCells cells;
  int bodies = 0, coordinates = 0, constraint_rows = 0;
  size_t checked_pairs = 0;
  long nonzeros = 0;
  int steps = 0;
  double iterations = 0.0, factorizations = 0.0;  // per step
  long analyses = 0;                              // symbolic analyses (a new pair touching grows the pattern)
  double us_per_step = 0.0;                       // step() calls only, median over repeats
  double forces = 0.0, contact = 0.0, constraints = 0.0, factorization = 0.0, solve = 0.0;  // us per step
  int peak_contacts = 0;
  double setup_ms = 0.0;  // loading the scene and building the solver's system (not timed per step)
  std::string status;
};

Row measure(const LatticeCells& cells, const LatticeOptions& base, const std::vector<at::Override>& overrides,
            int repeat)
{
  LatticeOptions o = base;
  o.nx = cells.nx;
  o.ny = cells.ny;
  Row row;
  row.cells = cells;
  const Clock::time_point t0 = Clock::now();
  const at::Model model = at::loadSceneFromString(
      quadruplexLatticeYaml(o), "lattice " + std::to_string(o.nx) + "x" + std::to_string(o.ny), overrides);
  row.bodies = static_cast<int>(model.bodies.size());
  row.coordinates = model.nq;
  row.constraint_rows = model.n_lambda;
  row.checked_pairs = model.checked_pairs.size();
  {
    const at::System system(model);
    row.nonzeros = system.makeMatrix().matrix().nonZeros();
  }
  row.setup_ms = 1e3 * std::chrono::duration<double>(Clock::now() - t0).count();
  struct Run
  {
    double per_step;
    at::RunResult result;
  };
  std::vector<Run> runs;
  for (int r = 0; r < repeat; ++r)
  {
    int peak = 0;
    at::RunResult res = at::runAnalysis(
        model, [](const at::State&) {}, {},
        [&peak](const at::State& s)
        {
          const int live = static_cast<int>(
              std::count_if(s.contact_speed.begin(), s.contact_speed.end(), [](double v) { return v > 0.0; }));
          peak = std::max(peak, live);
        });
    row.peak_contacts = std::max(row.peak_contacts, peak);
    const double per_step = res.timings.total / std::max(1, res.solver_steps);
    runs.push_back({ per_step, std::move(res) });
    if (!runs.back().result.summary.ok())
      break;
  }
  std::sort(runs.begin(), runs.end(), [](const Run& x, const Run& y) { return x.per_step < y.per_step; });
  const Run& mid = runs[runs.size() / 2];
  const at::RunResult& res = mid.result;
  const int n = std::max(1, res.solver_steps);
  row.steps = res.solver_steps;
  row.iterations = static_cast<double>(res.summary.iterations) / n;
  row.factorizations = static_cast<double>(res.timings.factorizations) / n;
  row.analyses = res.timings.analyses;
  row.us_per_step = 1e6 * mid.per_step;
  row.forces = 1e6 * res.timings.forces / n;
  row.contact = 1e6 * res.timings.contact / n;
  row.constraints = 1e6 * res.timings.constraints / n;
  row.factorization = 1e6 * res.timings.factorization / n;
  row.solve = 1e6 * res.timings.solve / n;
  row.status = res.summary.ok() ? "converged" : at::toString(res.summary.status);
  // a failed run stops early: its partial timings are still printed, with the status
  for (const Run& r : runs)
    if (!r.result.summary.ok())
      row.status = at::toString(r.result.summary.status);
  return row;
}

const char* kColumns =
    "struts,nx,ny,bodies,coordinates,constraint_rows,checked_pairs,matrix_nonzeros,steps,newton_per_step,"
    "factorizations_per_step,analyses,us_per_step,us_per_step_per_strut,forces_us,contact_us,constraints_us,"
    "factorization_us,solve_us,peak_contacts,setup_ms,status";

std::string csvLine(const Row& r)
{
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "%d,%d,%d,%d,%d,%d,%zu,%ld,%d,%.4f,%.4f,%ld,%.2f,%.3f,%.2f,%.2f,%.2f,%.2f,%.2f,%d,%.1f,%s",
                r.cells.struts(), r.cells.nx, r.cells.ny, r.bodies, r.coordinates, r.constraint_rows, r.checked_pairs,
                r.nonzeros, r.steps, r.iterations, r.factorizations, r.analyses, r.us_per_step,
                r.us_per_step / r.cells.struts(), r.forces, r.contact, r.constraints, r.factorization, r.solve,
                r.peak_contacts, r.setup_ms, r.status.c_str());
  return buf;
}

/// Least-squares slope of log(y) against log(x); NaN with fewer than two distinct x.
double logLogSlope(const std::vector<double>& x, const std::vector<double>& y)
{
  const size_t n = x.size();
  if (n < 2)
    return std::nan("");
  double mx = 0.0, my = 0.0;
  for (size_t i = 0; i < n; ++i)
  {
    mx += std::log(x[i]) / n;
    my += std::log(y[i]) / n;
  }
  double sxy = 0.0, sxx = 0.0;
  for (size_t i = 0; i < n; ++i)
  {
    sxy += (std::log(x[i]) - mx) * (std::log(y[i]) - my);
    sxx += (std::log(x[i]) - mx) * (std::log(x[i]) - mx);
  }
  return sxx > 0.0 ? sxy / sxx : std::nan("");
}

int runLattice(const std::vector<std::string>& args)
{
  LatticeOptions base;
  base.pairs = LatticePairs::kAuto;  // what a user writes; `all` lists the same pairs
  std::vector<LatticeCells> sizes = standardLatticeSizes();
  std::vector<int> strut_counts;  // --struts
  int width = 0;                  // --width: strips of this many cells across (0: nx <= ny <= 2 nx)
  std::vector<at::Override> overrides;
  int repeat = 3, max_struts = 0;
  bool print_scene = false;
  std::string csv_path;
  for (size_t i = 0; i < args.size(); ++i)
  {
    const std::string& a = args[i];
    const auto value = [&]() -> std::string
    {
      if (i + 1 >= args.size())
        throw BadArgument(a + " needs a value");
      return args[++i];
    };
    if (a == "--struts")
    {
      sizes.clear();
      for (const std::string& s : splitList(value()))
        strut_counts.push_back(parsePositive<int>("--struts", s));
      if (strut_counts.empty())
        throw BadArgument("--struts: expected a list of strut counts, got ''");
    }
    else if (a == "--width")
      width = parsePositive<int>(a, value());
    else if (a == "--max-struts")
      max_struts = parsePositive<int>(a, value());
    else if (a == "--duration")
      base.duration = parsePositive<double>(a, value());
    else if (a == "--repeat")
      repeat = parsePositive<int>(a, value());
    else if (a == "--pairs")
    {
      const std::string v = value();
      if (v == "all")
        base.pairs = LatticePairs::kAll;
      else if (v == "auto")
        base.pairs = LatticePairs::kAuto;
      else if (v == "near")
        base.pairs = LatticePairs::kNear;
      else
        throw BadArgument("--pairs: expected 'all', 'auto' or 'near', got '" + v + "'");
    }
    else if (a == "--csv")
      csv_path = value();
    else if (a == "--print-scene")
      print_scene = true;
    else if (a == "--set")
    {
      const std::string v = value();
      try
      {
        overrides.push_back(at::parseOverride(v));
      }
      catch (const std::exception& e)
      {
        throw BadArgument(std::string("--set: ") + e.what());
      }
    }
    else
      throw BadArgument("unknown argument '" + a + "'");
  }
  if (strut_counts.empty() && width > 0)
    for (const LatticeCells& cells : sizes)
      strut_counts.push_back(cells.struts());
  if (!strut_counts.empty())
  {
    sizes.clear();
    for (int n : strut_counts)
    {
      if (width == 0)
      {
        sizes.push_back(latticeCellsFor(n));
        continue;
      }
      // a strip: `width` cells across, as many along as give the nearest strut count (at least one)
      LatticeCells cells;
      cells.nx = width;
      cells.ny = std::max(1, static_cast<int>(std::lround(n / (4.0 * width))));
      sizes.push_back(cells);
    }
  }
  if (max_struts > 0)
    sizes.erase(std::remove_if(sizes.begin(), sizes.end(),
                               [&](const LatticeCells& c) { return c.struts() > max_struts; }),
                sizes.end());
  if (sizes.empty())
    throw BadArgument("--max-struts: no lattice size left at " + std::to_string(max_struts) + " struts");
  if (print_scene)
  {
    // the scenes as YAML (without the --set overrides), for tensegrity_run and for a look
    for (const LatticeCells& cells : sizes)
    {
      LatticeOptions o = base;
      o.nx = cells.nx;
      o.ny = cells.ny;
      std::printf("%s", quadruplexLatticeYaml(o).c_str());
    }
    return 0;
  }
  std::ofstream csv;
  if (!csv_path.empty())
  {
    csv.open(csv_path);
    if (!csv)
      throw BadArgument("--csv: cannot write '" + csv_path + "'");
    csv << kColumns << "\n";
  }
  std::printf("quadruplex lattice: cells sharing ground corners, ties between top nodes; bracings pulled in at %g m/s "
              "by %g m, dt %g s, %g s simulated; contact pairs: %s; %d run(s) per size%s\n",
              base.speed, base.max_actuation, base.dt, base.duration,
              base.pairs == LatticePairs::kAll  ? "all (a list of every pair sharing no node)" :
              base.pairs == LatticePairs::kAuto ? "'auto'" :
                                                  "near (same or adjacent cells)",
              repeat, overrides.empty() ? "" : " (with --set overrides)");
  std::printf("us/step: wall time of the solver's step() calls / steps, median over the runs; breakdown in us/step\n");
  std::printf("%6s %6s %6s %6s %6s %8s %9s %6s %6s %6s %5s %10s %8s %9s %9s %9s %9s %9s %5s %9s %s\n", "struts",
              "cells", "bodies", "coords", "rows", "pairs", "nnz", "steps", "newton", "factor", "anal", "us/step",
              "us/strut", "forces", "contact", "constr", "factorize", "solve", "peakC", "setup ms", "status");
  std::fflush(stdout);
  std::vector<double> xs, ys;
  bool all_ok = true;
  for (const LatticeCells& cells : sizes)
  {
    const Row r = measure(cells, base, overrides, repeat);
    std::printf(
        "%6d %6s %6d %6d %6d %8zu %9ld %6d %6.2f %6.3f %5ld %10.1f %8.2f %9.1f %9.1f %9.1f %9.1f %9.1f %5d %9.1f %s\n",
        r.cells.struts(), (std::to_string(r.cells.nx) + "x" + std::to_string(r.cells.ny)).c_str(), r.bodies,
        r.coordinates, r.constraint_rows, r.checked_pairs, r.nonzeros, r.steps, r.iterations, r.factorizations,
        r.analyses, r.us_per_step, r.us_per_step / r.cells.struts(), r.forces, r.contact, r.constraints,
        r.factorization, r.solve, r.peak_contacts, r.setup_ms, r.status.c_str());
    std::fflush(stdout);
    if (csv.is_open())
      csv << csvLine(r) << "\n" << std::flush;
    if (r.status == "converged")
    {
      xs.push_back(r.cells.struts());
      ys.push_back(r.us_per_step);
    }
    else
      all_ok = false;
  }
  const double slope = logLogSlope(xs, ys);
  if (std::isnan(slope))
    std::printf("fitted exponent: needs two converged sizes\n");
  else
    std::printf("fitted exponent of us/step vs struts (least squares in log-log over %zu sizes): %.3f\n", xs.size(),
                slope);
  return all_ok ? 0 : 3;
}
}  // namespace

int latticeCommand(const std::vector<std::string>& args)
{
  try
  {
    return runLattice(args);
  }
  catch (const BadArgument& e)
  {
    std::cerr << "tensegrity_bench lattice: " << e.what() << "\n";
    return 2;
  }
  catch (const at::SceneError& e)
  {
    // a --set that the scene refuses names the key and value
    std::cerr << "tensegrity_bench lattice: " << e.what() << "\n";
    return 2;
  }
}

}  // namespace active_tensegrity::tools
