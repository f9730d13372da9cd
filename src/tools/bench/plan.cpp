//   tensegrity_bench plan SCENE --actuators a,b,... (--height H | --values v,...) [options]
// plans with several seeds from the scene's start equilibrium (or, with --start, from the equilibrium
// the chosen actuators reach at those values by continuation) and prints status, planning time,
// equilibrium solves, waypoints and figures per seed, the median planning time and the process's peak
// memory; with --planner all, every planner once (seed 1) with its overrun of the time limit; with
// --speed-limit, the time scale (and the largest speed) that keeps the dynamic peaks under the limits.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <sys/resource.h>
#include <string>
#include <vector>

#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/planning/folding_planner.h"
#include "../cli.h"
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
namespace
{
namespace ap = active_tensegrity::planning;

double peakMemoryMB()
{
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

/// The equilibrium where the named actuators are at `values`, by continuation (0.02 m increments) from start.
std::string startAt(const at::Model& statics, const std::vector<std::string>& names, const std::vector<double>& values,
                    at::State& start)
{
  if (values.size() != names.size())
    return std::to_string(values.size()) + " values for " + std::to_string(names.size()) + " actuators";
  at::ActuationValues u = start.u;
  double distance = 0.0;
  for (size_t i = 0; i < names.size(); ++i)
  {
    const int a = statics.findActuator(names[i]);
    if (a < 0)
      return "unknown actuator '" + names[i] + "'";
    if (!std::isfinite(values[i]) || values[i] < statics.actuators[a].min_value ||
        values[i] > statics.actuators[a].max_value)
      return "value " + std::to_string(values[i]) + " of '" + names[i] + "' outside its range";
    distance = std::max(distance, std::abs(values[i] - u[a].value));
    u[a].value = values[i];
  }
  at::StaticSolver solver(statics, statics.solver);
  const int steps = std::max(1, static_cast<int>(std::ceil(distance / 0.02)));
  const at::Summary sum = solver.followPath(start, u, steps, {});
  return sum.ok() ? std::string() : "no equilibrium on the way: " + sum.message;
}

/// Every planner by name, seed 1: status, planning time and its overrun of the time limit.
int everyPlanner(const at::Model& model, const at::State& start, ap::PlanRequest req)
{
  std::printf("%-16s %-22s %9s %11s %7s %12s\n", "planner", "status", "time s", "overrun s", "solves", "final h (m)");
  double worst = -INFINITY;
  for (const std::string& name : ap::plannerNames())
  {
    req.planner = name;
    req.seed = 1;
    const ap::PlanResult p = ap::planFolding(model, start, req);
    if (p.status == ap::PlanStatus::kInvalidRequest)
    {
      std::cerr << "tensegrity_bench: " << p.message << "\n";
      return 2;
    }
    worst = std::max(worst, p.planning_time - req.time_limit);
    std::printf("%-16s %-22s %9.3f %11.3f %7ld %12.4f\n", name.c_str(), ap::toString(p.status), p.planning_time,
                p.planning_time - req.time_limit, p.equilibrium_solves, p.final_height);
  }
  std::printf("largest overrun of the %g s time limit: %.3f s; peak memory (max RSS) %.1f MB\n", req.time_limit, worst,
              peakMemoryMB());
  return 0;
}
}  // namespace

int plan(const std::string& scene, const std::vector<std::string>& args)
{
  std::vector<at::Override> overrides;
  ap::PlanRequest req;
  req.max_speeds = { 0.5 };
  req.max_accelerations = { 5.0 };
  req.time_limit = 60.0;
  req.limits.min_clearance = 0.005;
  int seeds = 5;
  bool speed_limit = false;
  std::vector<double> start_values;
  Args in(args);
  while (in.more())
  {
    const std::string a = in.option();
    const auto next = [&]() { return in.value(a); };
    if (a == "--set")
      overrides.push_back(at::parseOverride(next()));
    else if (a == "--actuators")
      req.actuators = splitList(next());
    else if (a == "--height")
      req.target_height = std::stod(next());
    else if (a == "--values")
      for (const std::string& v : splitList(next()))
        req.target_values.push_back(std::stod(v));
    else if (a == "--clearance")
      req.limits.min_clearance = std::stod(next());
    else if (a == "--contact-limit")
    {
      req.limits.allow_contact = true;
      req.limits.max_contact_force = std::stod(next());
    }
    else if (a == "--bending-limit")
      req.max_bending_stress = std::stod(next());
    else if (a == "--speed")
      req.max_speeds = { std::stod(next()) };
    else if (a == "--accel")
      req.max_accelerations = { std::stod(next()) };
    else if (a == "--planner")
      req.planner = next();
    else if (a == "--time-limit")
      req.time_limit = std::stod(next());
    else if (a == "--seeds")
      seeds = std::max(1, std::stoi(next()));
    else if (a == "--speed-limit")
      speed_limit = true;
    else if (a == "--verify")
      req.verify_dynamics = true;
    else if (a == "--step")
      req.continuation_step = std::stod(next());
    else if (a == "--settle-time")
      req.settle_time = std::stod(next());
    else if (a == "--blend")
      req.blend_tolerance = std::stod(next());
    else if (a == "--start")
      for (const std::string& v : splitList(next()))
        start_values.push_back(std::stod(v));
    else
      throw BadArgument("unknown argument '" + a + "'");
  }
  const at::Model model = at::loadScene(scene, overrides);
  at::State start = at::initialState(model);
  at::Model statics = model;
  statics.analysis.type = at::AnalysisType::kStatic;
  at::StaticSolver solver(statics, statics.solver);
  const at::Summary eq = solver.solve(start, start.u);
  if (!eq.ok())
  {
    std::cerr << "tensegrity_bench: no start equilibrium: " << eq.message << "\n";
    return 3;
  }
  if (!start_values.empty())
  {
    const std::string err = startAt(statics, req.actuators, start_values, start);
    if (!err.empty())
    {
      std::cerr << "tensegrity_bench: --start: " << err << "\n";
      return 2;
    }
  }
  if (req.planner == "all")
    return everyPlanner(model, start, req);
  std::printf("scene: %s, actuators:", scene.c_str());
  for (const std::string& n : req.actuators)
    std::printf(" %s", n.c_str());
  std::printf(
      "; goal: %s; %s; planner %s, time limit %g s\n",
      req.target_values.empty() ? ("height <= " + std::to_string(req.target_height) + " m").c_str() : "target values",
      req.limits.allow_contact ? ("contact up to " + std::to_string(req.limits.max_contact_force) + " N").c_str() :
                                 ("clearance " + std::to_string(req.limits.min_clearance) + " m").c_str(),
      req.planner.c_str(), req.time_limit);
  std::printf("%5s %-16s %9s %7s %9s %12s %10s %12s\n", "seed", "status", "time s", "solves", "waypoints",
              "final h (m)", "min gap", "peak F_N (N)");
  std::vector<double> times;
  for (int seed = 1; seed <= seeds; ++seed)
  {
    req.seed = static_cast<unsigned>(seed);
    const ap::PlanResult p = ap::planFolding(model, start, req);
    if (p.status == ap::PlanStatus::kInvalidRequest)
    {
      std::cerr << "tensegrity_bench: " << p.message << "\n";
      return 2;
    }
    times.push_back(p.planning_time);
    std::printf("%5d %-16s %9.2f %7ld %9zu %12.4f %10.4f %12.1f\n", seed, ap::toString(p.status), p.planning_time,
                p.equilibrium_solves, p.waypoints.size(), p.final_height, p.min_gap, p.peak_contact_force);
    if (p.status != ap::PlanStatus::kExactSolution)
      std::printf("      %s\n", p.message.c_str());
    if (p.equilibrium_solves > 0)
    {
      const at::StepTimings& t = p.solver_timings;
      const double n = static_cast<double>(p.equilibrium_solves), ms = 1e3 / n;
      std::printf("      per solve: %.3f ms (factorization %.3f, forces %.3f, contact %.3f, constraints %.3f, "
                  "triangular solves %.3f), %.2f factorizations, %.2f Newton iterations\n",
                  t.total * ms, t.factorization * ms, t.forces * ms, t.contact * ms, t.constraints * ms, t.solve * ms,
                  t.factorizations / n, t.newton_iterations / n);
    }
    if (req.blend_tolerance > 0.0)
      std::printf("      trajectory %.3f s (rest to rest %.3f s): %s\n", p.duration, p.rest_to_rest_duration,
                  p.message.c_str());
    if (req.verify_dynamics)
      std::printf("      dynamics: verified %s, within limits %s; peak F_N %.1f N, bending %.1f MPa, min gap %.4f m, "
                  "settled %.2f s after the end; %s\n",
                  p.dynamics_verified ? "yes" : "no", p.dynamics_within_limits ? "yes" : "no",
                  p.dynamic_peak_contact_force, 1e-6 * p.dynamic_peak_bending_stress, p.dynamic_min_gap,
                  p.settle_duration, p.message.c_str());
  }
  std::sort(times.begin(), times.end());
  std::printf("median planning time: %.2f s over %d seeds; peak memory (max RSS) %.1f MB\n", times[times.size() / 2],
              seeds, peakMemoryMB());
  if (speed_limit)
  {
    req.seed = 1;
    req.verify_dynamics = req.find_speed_limit = true;
    const ap::PlanResult p = ap::planFolding(model, start, req);
    double vmax = 0.0;
    for (const auto& v : p.velocities)
      for (double x : v)
        vmax = std::max(vmax, std::abs(x));
    std::printf("speed limit (seed 1, dt %g s): %s; time scale %.3f after %d dynamic runs -> largest actuation speed "
                "%.4f m/s (planned at %.4f m/s); dynamic peaks: contact %.1f N, bending %.1f MPa; within limits: %s\n",
                model.solver.dt, ap::toString(p.status), p.time_scale, p.dynamic_runs, vmax, req.max_speeds[0],
                p.dynamic_peak_contact_force, 1e-6 * p.dynamic_peak_bending_stress,
                p.dynamics_within_limits ? "yes" : "no");
  }
  return 0;
}
}  // namespace active_tensegrity::tools::bench
