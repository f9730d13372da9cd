// A folding path's goal, its following from the start through equilibria and its blending into a trajectory.
#include "folding_steps.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <sstream>

#include <ompl/base/PlannerTerminationCondition.h>
#include <ompl/base/ProblemDefinition.h>
#include <ompl/base/SpaceInformation.h>
#include <ompl/base/StateSampler.h>
#include <ompl/base/goals/GoalSampleableRegion.h>
#include <ompl/base/goals/GoalState.h>
#include <ompl/base/objectives/MaximizeMinClearanceObjective.h>
#include <ompl/base/objectives/PathLengthOptimizationObjective.h>
#include <ompl/base/spaces/RealVectorStateProjections.h>
#include <ompl/base/spaces/RealVectorStateSpace.h>
#include <ompl/datastructures/NearestNeighborsLinear.h>
#include <ompl/geometric/PathGeometric.h>
#include <ompl/util/Console.h>

#include "active_tensegrity/planning/folding_planner.h"
#include "active_tensegrity/core/solvers/actuation_control.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/modal.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/base/text.h"
#include "active_tensegrity/planning/trajectory.h"
#include "active_tensegrity/planning/validity.h"

namespace active_tensegrity::planning::detail
{
namespace og = ompl::geometric;

std::function<double(const Equilibrium&)> goalDistance(const EquilibriumOracle& oracle, const PlanRequest& r)
{
  if (r.target_values.empty())
    return [target = r.target_height](const Equilibrium& e) { return std::max(0.0, e.height - target); };
  return [&oracle, target = r.target_values](const Equilibrium& e)
  { return actuationDistance(oracle.values(e.state), target); };
}

bool meetsGoal(const EquilibriumOracle& oracle, const PlanRequest& r, const Equilibrium& e)
{
  if (!oracle.valid(e))
    return false;
  if (r.target_values.empty())
    return e.height <= r.target_height;
  return actuationDistance(oracle.values(e.state), r.target_values) <= 1e-9;
}

void stayAtStart(const EquilibriumOracle& oracle, PlanResult& out)
{
  const Values v = oracle.values(oracle.start().state);
  out.status = PlanStatus::kExactSolution;
  out.message = "exact solution: the start meets the goal";
  out.waypoints = { v };
  out.times = { 0.0 };
  out.positions = { v };
  out.velocities = out.accelerations = { Values(v.size(), 0.0) };
  out.min_gap = oracle.start().min_gap;
  out.peak_contact_force = oracle.start().max_contact;
  out.final_height = oracle.start().height;
}

std::string reachability(const EquilibriumOracle& oracle, const PlanRequest& r, const std::vector<double>& upper)
{
  if (!r.target_values.empty())
  {
    // the target's own equilibrium, by continuation straight from the start
    const Equilibrium goal = oracle.at(r.target_values);
    std::string why;
    if (!goal.converged || oracle.valid(goal, &why))
      return "";
    return "the equilibrium at the target values (by continuation straight from the start) is not valid: " + why +
           " (set reachability_check off to search anyway)";
  }
  double lowest = oracle.start().height;
  Equilibrium end;
  const bool done = oracle.follow(oracle.start(), upper, end, false,
                                  [&lowest](const Equilibrium& e) { lowest = std::min(lowest, e.height); });
  if (!done || r.target_height >= lowest)
    return "";
  std::ostringstream msg;
  msg << "target_height " << core::shortestNumber(r.target_height)
      << " m is below the lowest height met when every actuator is pulled to its upper bound ("
      << core::shortestNumber(lowest) << " m, by continuation from the start): taken as unreachable "
      << "(a structure that folds as its cables are pulled in goes no lower; set reachability_check off to search "
         "anyway)";
  return msg.str();
}

Equilibrium followFromStart(const EquilibriumOracle& oracle, const PlanRequest& r, const std::vector<Values>& simple,
                            RequestClock& clock, PlanResult& out, std::string& cut, size_t offset)
{
  Equilibrium e = oracle.start();
  out.waypoints = { simple.front() };
  // the figures of a segment count once it is followed to its end: a trajectory cut at the last valid
  // waypoint reports the gap and force along what it drives, not along the segment that failed
  double segment_gap = INFINITY;
  double segment_force = 0.0;
  const auto visit = [&segment_gap, &segment_force](const Equilibrium& q)
  {
    segment_gap = std::min(segment_gap, q.min_gap);
    segment_force = std::max(segment_force, q.max_contact);
  };
  const auto keep = [&]()
  {
    out.min_gap = std::min(out.min_gap, segment_gap);
    out.peak_contact_force = std::max(out.peak_contact_force, segment_force);
    segment_gap = INFINITY;
    segment_force = 0.0;
  };
  visit(e);
  keep();
  std::string why;
  for (size_t k = 1; k < simple.size(); ++k)
  {
    Equilibrium end;
    if (!oracle.follow(e, simple[k], end, true, visit))
    {
      oracle.valid(end, &why);
      cut = "stopped being valid before waypoint " + std::to_string(k + offset) + " (" + why + ")";
      out.message = (clock.stop() ? "following the path from the start was stopped by the time limit before waypoint " :
                                    "followed from the start, the path stops being valid before waypoint ") +
                    std::to_string(k + offset) + " (" + why + "); the trajectory ends at the last valid waypoint";
      break;
    }
    keep();
    e = end;
    out.waypoints.push_back(simple[k]);
  }
  out.final_height = e.height;
  const bool followed = out.waypoints.size() == simple.size();
  if (meetsGoal(oracle, r, e))
  {
    out.status = PlanStatus::kExactSolution;
    out.message = "exact solution";
  }
  else
  {
    out.status = PlanStatus::kApproximateSolution;
    if (followed)
    {
      std::ostringstream msg;
      if (r.target_values.empty())
        msg << "approximate: followed from the start, the path ends at height " << e.height << " m, above the target "
            << r.target_height << " m";
      else
        msg << "approximate: followed from the start, the path ends at "
            << actuationDistance(oracle.values(e.state), r.target_values) << " m from the target values";
      out.message = msg.str();
    }
  }
  return e;
}

void setTrajectory(const Trajectory& t, PlanResult& out)
{
  out.times = t.times;
  out.positions = t.positions;
  out.velocities = t.velocities;
  out.accelerations = t.accelerations;
  out.duration = t.duration;
}

void blend(const EquilibriumOracle& oracle, const PlanRequest& r, RequestClock& clock, PlanResult& out)
{
  std::vector<double> d = blendLengths(out.waypoints, r.blend_tolerance);
  std::vector<int> tightened(d.size(), 0);
  for (size_t attempt = 0; attempt <= 4 * d.size(); ++attempt)
  {
    std::vector<int> corner;
    const std::vector<Values> curve = blendedCurve(out.waypoints, d, oracle.step(), &corner);
    double min_gap = oracle.start().min_gap, peak = oracle.start().max_contact;
    const auto visit = [&](const Equilibrium& q)
    {
      min_gap = std::min(min_gap, q.min_gap);
      peak = std::max(peak, q.max_contact);
    };
    Equilibrium e = oracle.start();
    size_t k = 1;
    for (; k < curve.size(); ++k)
    {
      Equilibrium end;
      if (!oracle.follow(e, curve[k], end, true, visit))
        break;
      e = end;
    }
    if (k == curve.size())
    {
      if (!meetsGoal(oracle, r, e) && out.status == PlanStatus::kExactSolution)
        break;  // the blended curve ends on another branch
      setTrajectory(timeOptimal(out.waypoints, d, r.max_speeds, r.max_accelerations, r.sample_dt), out);
      out.min_gap = min_gap;
      out.peak_contact_force = peak;
      out.final_height = e.height;
      const long tight = std::count_if(tightened.begin(), tightened.end(), [](int t) { return t > 0; });
      if (tight > 0)
        out.message += "; " + std::to_string(tight) + " of " + std::to_string(out.waypoints.size() - 2) +
                       " corners blended tighter than blend_tolerance (" +
                       std::to_string(std::count(d.begin(), d.end(), 0.0) - 2) + " passed at rest) to keep the limits";
      return;
    }
    const int c = corner[k];
    if (clock.stop() || c < 0)
      break;
    d[c] = ++tightened[c] <= 3 ? 0.5 * d[c] : 0.0;
  }
  out.message += "; corners not blended (the blended path could not be checked within the limits and the time)";
}
}  // namespace active_tensegrity::planning::detail
