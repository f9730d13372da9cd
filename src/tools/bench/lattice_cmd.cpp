//   tensegrity_bench lattice [--struts a,b,..] [--width W] [--max-struts N] [--duration S] [--repeat N]
//                            [--pairs all|auto|near] [--csv FILE] [--set key=value]... [--print-scene]
// lattices of quadruplex cells of about 10 to 500 struts (../lattice.cpp), each run dynamically with contact: one row per
// size (sizes, Newton matrix non-zeros, us per step and its breakdown, peak contacts) and the fitted exponent of
// the time per step against the number of struts. Exit status 2 on a bad argument, 3 when a size did not converge.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/oracle/mechanics.h"
#include "../cli.h"
#include "../lattice.h"
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
namespace
{
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
  row.checked_pairs = static_cast<size_t>(model.checkedPairCount());
  {
    const at::System system(model);
    row.nonzeros = system.makeMatrix().matrix().nonZeros();
  }
  row.setup_ms = 1e3 * seconds(t0, Clock::now());
  struct Run
  {
    double per_step;
    at::RunResult result;
  };
  std::vector<Run> runs;
  for (int r = 0; r < repeat; ++r)
  {
    at::RunResult res = at::runAnalysis(model, [](const at::State&) {});
    row.peak_contacts = std::max(row.peak_contacts, static_cast<int>(res.timings.most_touching));
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
    "factorizations_per_step,analyses,us_per_step,us_per_step_per_strut,forces_us,contact_us,"
    "constraints_us,"
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
  std::printf("peakC: the most strut pairs touching at the end of a step\n");
  std::printf("%6s %6s %6s %6s %6s %8s %9s %6s %6s %6s %5s %10s %8s %9s %9s %9s %9s %9s %5s %9s %s\n", "struts",
              "cells", "bodies", "coords", "rows", "pairs", "nnz", "steps", "newton", "factor", "anal", "us/step",
              "us/strut", "forces", "contact", "constr", "factorize", "solve", "peakC", "setup ms", "status");
  std::fflush(stdout);
  std::vector<double> xs, ys;
  bool all_ok = true;
  for (const LatticeCells& cells : sizes)
  {
    const Row r = measure(cells, base, overrides, repeat);
    std::printf("%6d %6s %6d %6d %6d %8zu %9ld %6d %6.2f %6.3f %5ld %10.1f %8.2f %9.1f %9.1f %9.1f %9.1f %9.1f "
                "%5d %9.1f %s\n",
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

int lattice(const std::vector<std::string>& args)
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

}  // namespace active_tensegrity::tools::bench
