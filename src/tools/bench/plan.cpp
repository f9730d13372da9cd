//   tensegrity_bench plan SCENE --actuators a,b,... (--height H | --values v,...) [options]
// plans with several seeds from the scene's start equilibrium and prints status, planning time,
// equilibrium solves, waypoints and figures per seed and the median planning time; with
// --speed-limit, the time scale (and the largest speed) that keeps the dynamic peaks under the limits.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/core/scene.h"
#include "active_tensegrity/core/statics.h"
#include "active_tensegrity/planning/folding_planner.h"
#include "../cli.h"
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
int plan(const std::string& scene, const std::vector<std::string>& args)
{
  namespace ap = active_tensegrity::planning;
  std::vector<at::Override> overrides;
  ap::PlanRequest req;
  req.max_speeds = { 0.5 };
  req.max_accelerations = { 5.0 };
  req.time_limit = 60.0;
  req.limits.min_clearance = 0.005;
  int seeds = 5;
  bool speed_limit = false;
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
    else
      throw std::invalid_argument("unknown argument '" + a + "'");
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
  }
  std::sort(times.begin(), times.end());
  std::printf("median planning time: %.2f s over %d seeds\n", times[times.size() / 2], seeds);
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
