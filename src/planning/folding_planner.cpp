#include "active_tensegrity/planning/folding_planner.h"

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

#include "folding_steps.h"

namespace ob = ompl::base;
namespace og = ompl::geometric;

namespace active_tensegrity::planning
{
using namespace detail;

const char* toString(PlanStatus s)
{
  switch (s)
  {
    case PlanStatus::kUnknown:
      return "unknown";
    case PlanStatus::kInvalidStart:
      return "invalid_start";
    case PlanStatus::kInvalidGoal:
      return "invalid_goal";
    case PlanStatus::kUnrecognizedGoalType:
      return "unrecognized_goal_type";
    case PlanStatus::kTimeout:
      return "timeout";
    case PlanStatus::kApproximateSolution:
      return "approximate_solution";
    case PlanStatus::kExactSolution:
      return "exact_solution";
    case PlanStatus::kCrash:
      return "crash";
    case PlanStatus::kAbort:
      return "abort";
    case PlanStatus::kInvalidRequest:
      return "invalid_request";
  }
  return "?";
}

std::vector<std::string> plannerNames()
{
  std::vector<std::string> names;
  for (const auto& kv : planners())
    names.push_back(kv.first);
  return names;
}

std::string startEquilibrium(const core::Model& model, const core::State& state, core::State& start,
                             const std::function<bool()>& stop)
{
  start = state;
  for (core::ActuationValue& u : start.u)
    u.rate = u.accel = 0.0;
  start.qd.setZero();
  core::Model statics = model;
  statics.analysis.type = core::AnalysisType::kStatic;
  core::StaticSolver solver(statics, statics.solver);
  const core::Summary eq = solver.relax(start, start.u, 20000, stop);
  return eq.ok() ? std::string() : "no quasi-static equilibrium at the current actuation: " + eq.message;
}

PlanResult planFolding(const core::Model& model, const core::State& given, const PlanRequest& r,
                       const PlanControl& control, const core::ActuationController* actuation)
{
  PlanResult out;
  std::vector<int> idx;
  out.message = checkRequest(model, r, idx);
  if (given.u.size() != model.actuators.size() && out.message.empty())
    out.message = "the start state has " + std::to_string(given.u.size()) + " actuation values for " +
                  std::to_string(model.actuators.size()) + " actuators";
  if (!out.message.empty())
  {
    out.status = PlanStatus::kInvalidRequest;
    return out;
  }
  out.names = r.actuators;
  const size_t n = idx.size();
  RequestClock clock(r.time_limit, control);
  // what the actuators do from the start: the caller's law, or every one at rest where it is
  const core::ActuationController law = actuation ? *actuation : core::ActuationController(model, given.u);
  const core::ActuationValues now = law.values(given.t);
  const auto invalidStart = [&](const std::string& why) -> PlanResult&
  {
    out.status = PlanStatus::kInvalidStart;
    out.message = why;
    out.stopped_by_time_limit = clock.timedOut();
    out.cancelled = clock.cancelled();
    out.planning_time = clock.elapsed();
    clock.done(std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity());
    return out;
  };
  // the chosen actuators, when they move, are first brought to rest: the path starts where they stop
  Stop stop;
  std::string why = stopping(model, idx, now, r, stop);
  if (!why.empty())
    return invalidStart(why);
  if (stop.duration > 0.0 && !r.relax_start)
    return invalidStart("the chosen actuators move at the start (relax_start plans from where they stop)");
  core::State start = given;
  if (r.relax_start)
  {
    // the equilibrium nearest to the structure where the actuators come to rest: the chosen ones where they
    // stop, the others where their law ends
    core::State resting = given;
    resting.u = law.values(std::numeric_limits<double>::infinity());
    for (size_t i = 0; i < n; ++i)
      resting.u[idx[i]].value = stop.values[i];
    clock.phase("start");
    why = startEquilibrium(model, resting, start, [&clock] { return clock.stop(); });
    if (!why.empty())
      return invalidStart(why);
  }
  out.stop_duration = stop.duration;
  // OMPL's own console output off: what it would say (no valid goal sampled, skipped states) is in the
  // status and the message
  ompl::msg::setLogLevel(ompl::msg::LOG_NONE);

  EquilibriumOracle oracle(model, idx, start, r.limits, r.continuation_step);
  oracle.setStop([&clock] { return clock.stop(); });
  oracle.setGoalDistance(goalDistance(oracle, r));
  clock.watch(&oracle);
  const auto finish = [&]() -> PlanResult&
  {
    out.stopped_by_time_limit = clock.timedOut();
    out.cancelled = clock.cancelled();
    out.equilibrium_solves = oracle.solves();
    out.solver_timings = oracle.timings();
    out.planning_time = clock.elapsed();
    // the last progress report: where the returned path ends
    double height = std::numeric_limits<double>::infinity(), distance = height;
    if (!out.waypoints.empty())
    {
      height = out.final_height;
      distance = r.target_values.empty() ? std::max(0.0, out.final_height - r.target_height) :
                                           actuationDistance(out.waypoints.back(), r.target_values);
    }
    clock.done(height, distance);
    return out;
  };
  // the trajectory from the start: the stop, then the path's (slowed by the verification's time scale)
  const auto withStop = [&]()
  {
    const Trajectory t = executed(stop, out, 1.0);
    setTrajectory(t, out);
    out.rest_to_rest_duration += stop.duration;
  };
  if (!oracle.valid(oracle.start(), &why))
  {
    out.status = PlanStatus::kInvalidStart;
    out.message = "the start is not valid: " + why;
    return finish();
  }
  if (meetsGoal(oracle, r, oracle.start()))
  {
    stayAtStart(oracle, out);
    if (r.verify_dynamics || r.find_speed_limit)
    {
      if (r.relax_start)
      {
        // the structure may still move (or its actuators): simulated from where it is
        clock.phase("verify");
        verify(model, given, law, stop, r, oracle.start().state, clock, out);
      }
      else
      {
        // no motion: the start is an equilibrium at rest
        out.dynamics_verified = out.dynamics_within_limits = true;
        out.dynamic_peak_contact_force = oracle.start().max_contact;
        out.dynamic_min_gap = oracle.start().min_gap;
      }
    }
    withStop();
    return finish();
  }

  ob::RealVectorBounds bounds(static_cast<unsigned>(n));
  double extent = 0.0;
  std::vector<double> upper(n);
  for (size_t i = 0; i < n; ++i)
  {
    const core::Actuator& a = model.actuators[idx[i]];
    bounds.setLow(i, a.min_value);
    bounds.setHigh(i, upper[i] = a.max_value);
    extent = std::max(extent, a.max_value - a.min_value);
  }
  if (r.reachability_check)
  {
    clock.phase("reachability");
    out.message = reachability(oracle, r, upper);
    if (!out.message.empty())
    {
      out.status = PlanStatus::kInvalidGoal;
      return finish();
    }
  }

  // Search, shortcut, follow from the start. A path valid edge by edge can still stop being valid when it is
  // followed from the start: a bidirectional tree joins branches of equilibria that continuation from the start
  // does not connect, and near a bifurcation the branch taken depends on the increments. While the deadline
  // allows, the search then starts again from the last equilibrium the followed path reached (the oracle's
  // cache emptied down to it), with the next seed, and the paths are joined.
  const Equilibrium first = oracle.start();
  std::vector<std::string> cuts;  // why each earlier search's path stopped being valid
  Equilibrium end;
  int search = 0;  // after the loop: the last search's
  for (;; ++search)
  {
    const unsigned seed = r.seed + static_cast<unsigned>(search);
    const Search found = searchOnce(oracle, r, bounds, extent, seed, clock);
    const std::vector<Values>& raw = found.raw;
    const std::string why_none = std::string("no path: ") + (clock.cancelled() ? "cancelled" :
                                                             clock.timedOut()  ? "the time limit ended the search" :
                                                                                 found.status.asString());
    if (raw.size() < 2 && search > 0)
    {
      // the path of the earlier searches stands, cut where it stopped being valid
      out.message += "; searched again from there: " + why_none;
      break;
    }
    if (raw.size() < 2)
    {
      out.status = static_cast<PlanStatus>(static_cast<int>(ob::PlannerStatus::StatusType(found.status)));
      // a planner that found no valid goal (or start) state before the deadline or the cancel says
      // invalid_goal: it ran out of time, the goal is not known to be invalid
      if (clock.out() && (out.status == PlanStatus::kInvalidGoal || out.status == PlanStatus::kInvalidStart))
        out.status = PlanStatus::kTimeout;
      out.message = why_none;
      return finish();
    }
    std::vector<Values> simple = raw;
    if (found.solved)
    {
      clock.phase("shortcut");
      simple = shortcut(found.si, raw, clock);
    }

    // the answer from here: the path as it will be followed, within the deadline or, past it, a grace period
    clock.answering(0.3);
    clock.phase("follow");
    // a later search stopped without a path answers with the oracle's best path, which starts at the request's
    // start: it replaces the earlier searches' path (it gets nearer the goal than where that one was cut)
    const bool from_first = search > 0 && !found.solved;
    if (from_first)
    {
      oracle.restart(first);
      out.waypoints.clear();
      out.min_gap = std::numeric_limits<double>::infinity();
      out.peak_contact_force = 0.0;
    }
    const std::vector<Values> before = out.waypoints;  // followed by the earlier searches, ending at this start
    std::string cut_at;
    end = followFromStart(oracle, r, simple, clock, out, cut_at, before.empty() ? 0 : before.size() - 1);
    if (search > 0 && !from_first)
    {
      std::vector<Values> joined = before;
      joined.insert(joined.end(), out.waypoints.begin() + 1, out.waypoints.end());
      out.waypoints = std::move(joined);
    }
    if (cut_at.empty() && found.solved && out.status != PlanStatus::kExactSolution)
    {
      // followed to its end, the path reached another branch of equilibria than the search's (near the symmetric
      // fold's bifurcation the branch taken depends on the increments): searched on from there as well
      std::ostringstream msg;
      msg << "ended at height " << end.height << " m, on another branch of equilibria than the search's";
      cut_at = msg.str();
    }
    if (cut_at.empty() || out.status == PlanStatus::kExactSolution || clock.out() || search + 1 >= kSearchesMost)
      break;
    cuts.push_back("search " + std::to_string(search + 1) + "'s path, followed from its start, " + cut_at);
    clock.searching();
    oracle.restart(end);
  }
  if (!cuts.empty())
  {
    oracle.restart(first);  // what follows (blend) follows the whole path from the request's start
    out.message += " (" + std::to_string(search + 1) + " searches, seeds " + std::to_string(r.seed) + " to " +
                   std::to_string(r.seed + static_cast<unsigned>(search)) + ": ";
    for (size_t k = 0; k < cuts.size(); ++k)
      out.message += (k ? "; " : "") + cuts[k];
    out.message += ")";
  }
  if (out.waypoints.size() < 2 && out.status != PlanStatus::kExactSolution && clock.out())
  {
    // the best path of a stopped search could not be followed one waypoint from the start: there is nothing to
    // drive, as when the search had no path at all
    out.status = PlanStatus::kTimeout;
    out.message = "no path: " + std::string(clock.cancelled() ? "cancelled" : "the time limit ended the search") +
                  "; the best path so far, " + out.message;
    out.waypoints.clear();
    out.final_height = 0.0;
    out.min_gap = std::numeric_limits<double>::infinity();
    out.peak_contact_force = 0.0;
    return finish();
  }
  if (clock.cancelled())
    out.message += " (cancelled: the best path found so far)";
  else if (clock.timedOut() && out.status != PlanStatus::kExactSolution)
    out.message += " (the time limit ended the search)";
  setTrajectory(restToRest(out.waypoints, r.max_speeds, r.max_accelerations, r.sample_dt), out);
  out.rest_to_rest_duration = out.duration;
  if (r.blend_tolerance > 0.0 && out.waypoints.size() > 2)
  {
    clock.phase("blend");
    blend(oracle, r, clock, out);
  }

  if ((r.verify_dynamics || r.find_speed_limit) && out.waypoints.size() > 1)
  {
    clock.phase("verify");
    if (clock.out())
      out.message += clock.cancelled() ? "; no dynamic verification: cancelled" :
                                         "; no dynamic verification: the time limit was reached";
    else
      verify(model, given, law, stop, r, end.state, clock, out);
  }
  withStop();
  return finish();
}

}  // namespace active_tensegrity::planning
