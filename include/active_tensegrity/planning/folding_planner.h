/// Collision-aware folding (docs/planning.md): OMPL plans in the space of the chosen actuators' values;
/// a state is valid when its quasi-static equilibrium (EquilibriumOracle) keeps the strut gaps, contact
/// forces and cable stresses within limits; edges are checked by continuation, so a plan is a connected
/// path of equilibria. The path is simplified, time-parameterized under speed and acceleration limits
/// (rest to rest at every waypoint, straight in actuation space), and optionally simulated to find the
/// dynamic peaks and the slowest-needed time scale. ROS-free.
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/planning/equilibria.h"

namespace active_tensegrity::core
{
class ActuationController;
}

namespace active_tensegrity::planning
{
/// One value per OMPL PlannerStatus (same order), plus a request refused before planning.
enum class PlanStatus
{
  kUnknown,
  kInvalidStart,
  kInvalidGoal,
  kUnrecognizedGoalType,
  kTimeout,
  kApproximateSolution,
  kExactSolution,
  kCrash,
  kAbort,
  kInvalidRequest
};
const char* toString(PlanStatus s);

struct PlanRequest
{
  std::vector<std::string> actuators;  // names of the actuators to plan for
  /// goal: height <= target_height (when target_values is empty), else these values (one per actuator)
  double target_height = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> target_values;
  ValidityLimits limits;
  /// per actuator or one for all (m/s, m/s^2), > 0
  std::vector<double> max_speeds{ 0.1 };
  std::vector<double> max_accelerations{ 0.5 };
  std::string planner = "RRTConnect";
  /// s of wall time for the whole request: search, shortcutting, following the path from the start and
  /// the dynamic verification; the answer comes within time_limit + 0.5 s
  double time_limit = 10.0;
  unsigned seed = 1;
  double continuation_step = 0.02;  // m: largest actuation increment between checked equilibria
  double range = 0.0;               // m: planner step (0: 0.2 of the largest actuator range)
  double sample_dt = 0.05;          // s between trajectory points
  /// before searching, cheap necessary conditions answered at once as kInvalidGoal: for height goals, one
  /// continuation to every actuator's upper bound, and a target below the lowest height met on it; for
  /// target values, their equilibrium reached straight from the start outside the limits. Hold for
  /// structures that fold as their cables are pulled in and whose equilibria do not depend on the path
  /// taken to them; turn off for others.
  bool reachability_check = true;
  /// dynamic verification: simulate the trajectory (DynamicsSolver) from the state planFolding was given, as
  /// it is (positions, velocities, contact memory, actuation values and rates, under the actuation law it was
  /// given), until the structure is at rest again; report peak contact force, strut bending stress and the
  /// smallest gap; with find_speed_limit, slow it down (time scale, bisection) until they stay within
  /// the limits (max_contact_force or min_clearance, max_bending_stress)
  bool verify_dynamics = false;
  bool find_speed_limit = false;
  double max_bending_stress = std::numeric_limits<double>::infinity();  // Pa
  /// s simulated after the trajectory ends; 0: until at rest (every body's speed, as the RMS over the
  /// mass, below rest_speed for a whole window of the structure's longest natural period), at most
  /// max_settle_time
  double settle_time = 0.0;
  double rest_speed = 1e-3;             // m/s
  double max_settle_time = 30.0;        // s
  double speed_limit_tolerance = 0.05;  // relative width of the final time-scale bracket (> 0)
  /// `start` is any state (folded, moving): the path is planned from the equilibrium nearest to it where the
  /// actuators come to rest (startEquilibrium, within the request's deadline): the chosen actuators braked
  /// from their rates at max_accelerations, the others where their law ends. false: `start` is a converged
  /// equilibrium already, its actuators at rest
  bool relax_start = false;
  /// corners blended within this tube (m, max norm in actuation space) around the validated path,
  /// the blended curve checked by continuation; 0: rest to rest at every waypoint
  double blend_tolerance = 0.0;
};

/// What a running request reports (PlanControl::progress).
struct PlanProgress
{
  double elapsed = 0.0;         // s of wall time since the request started
  long equilibrium_solves = 0;  // continuation increments so far
  /// the best valid equilibrium seen so far: its height (m) and its distance to the goal (m: height
  /// above the target, or the max-norm distance to the target values); +inf before the first
  double best_height = std::numeric_limits<double>::infinity();
  double best_distance = std::numeric_limits<double>::infinity();
  /// "start", "reachability", "search", "shortcut", "follow", "blend", "verify"; "done" once, last, when the
  /// answer is made: best_height and best_distance are then those of the returned path's end (+inf without one)
  std::string phase;
};

/// Hooks of a running request (all optional). Both are called from the planning thread.
struct PlanControl
{
  /// polled often (between equilibrium increments); true stops the request, which answers within
  /// 0.5 s with the best path found so far (approximate) and PlanResult::cancelled set
  std::function<bool()> cancelled;
  /// called at most every progress_period s, and once more with phase "done" when the answer is made. During
  /// the search the best equilibrium is the one nearest the goal among those reached from the start through
  /// valid equilibria only: a stopped request answers with the path to it (followed again from the start)
  std::function<void(const PlanProgress&)> progress;
  double progress_period = 0.2;
};

struct PlanResult
{
  PlanStatus status = PlanStatus::kUnknown;
  std::string message;
  std::vector<std::string> names;
  std::vector<std::vector<double>> waypoints;  // the simplified path (actuation values)
  // the trajectory: times (s from its start) and per time a value per actuator. It starts at the chosen
  // actuators' values and rates at the start (those of the actuation law planFolding was given) and, when they
  // moved, first brings them to rest (stop_duration s, each braked at its acceleration limit), then drives the
  // path from there
  std::vector<double> times;
  std::vector<std::vector<double>> positions, velocities, accelerations;
  double duration = 0.0;
  double rest_to_rest_duration = 0.0;  // the same path stopping at every waypoint (== duration unblended)
  double stop_duration = 0.0;          // s of braking at the trajectory's start (0: the actuators were at rest)
  // along the path (quasi-static, every continuation increment)
  double min_gap = std::numeric_limits<double>::infinity();
  double peak_contact_force = 0.0;
  double final_height = 0.0;
  long equilibrium_solves = 0;
  core::StepTimings solver_timings;    // the static solver's work in those solves
  double planning_time = 0.0;          // s wall, the whole request
  bool stopped_by_time_limit = false;  // the request's deadline ended the search (or a later phase)
  bool cancelled = false;              // PlanControl::cancelled ended it
  // dynamic verification
  bool dynamics_verified = false;       // the simulation ran to rest (or settle_time) without failing
  bool dynamics_within_limits = false;  // verified, and the peaks and the gap within the limits
  double dynamic_peak_contact_force = 0.0;
  double dynamic_peak_bending_stress = 0.0;
  double dynamic_min_gap = std::numeric_limits<double>::infinity();  // m
  double settle_duration = 0.0;                                      // s simulated after the trajectory's end
  double time_scale = 1.0;  // the returned trajectory is the planned one slowed by this factor
  int dynamic_runs = 0;
};

/// Plans from `start` (a converged quasi-static equilibrium of `model`: startEquilibrium below, or any state
/// with request.relax_start). `actuation` is the law the actuators follow from start.t (a running simulation's
/// controller): the returned trajectory takes the chosen actuators over from it at start.t, the others keep
/// it; null: every actuator at rest at its value in `start`. The dynamic verification simulates exactly that
/// from `start` as it is (positions, velocities, contact memory): what running the trajectory from `start`
/// does. Never throws on a bad request: status kInvalidRequest and a message naming the field and the value.
PlanResult planFolding(const core::Model& model, const core::State& start, const PlanRequest& request,
                       const PlanControl& control = {}, const core::ActuationController* actuation = nullptr);

/// The quasi-static equilibrium to plan from, nearest to `state` (folded, moving: velocities and rates
/// are dropped, then StaticSolver::relax at its actuation, polling `stop`). Empty message on success, else
/// why not.
std::string startEquilibrium(const core::Model& model, const core::State& state, core::State& start,
                             const std::function<bool()>& stop = {});

/// Names of the OMPL geometric planners planFolding accepts.
std::vector<std::string> plannerNames();

}  // namespace active_tensegrity::planning
