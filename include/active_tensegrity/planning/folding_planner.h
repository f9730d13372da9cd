/// Collision-aware folding (docs/planning.md): OMPL plans in the space of the chosen actuators' values;
/// a state is valid when its quasi-static equilibrium (EquilibriumOracle) keeps the strut gaps, contact
/// forces and cable stresses within limits; edges are checked by continuation, so a plan is a connected
/// path of equilibria. The path is simplified, time-parameterized under speed and acceleration limits
/// (rest to rest at every waypoint, straight in actuation space), and optionally simulated to find the
/// dynamic peaks and the slowest-needed time scale. ROS-free.
#pragma once

#include <limits>
#include <string>
#include <vector>

#include "active_tensegrity/core/model.h"
#include "active_tensegrity/core/state.h"
#include "active_tensegrity/planning/equilibria.h"

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
  double time_limit = 10.0;  // s of planning
  unsigned seed = 1;
  double continuation_step = 0.02;  // m: largest actuation increment between checked equilibria
  double range = 0.0;               // m: planner step (0: 0.2 of the largest actuator range)
  double sample_dt = 0.05;          // s between trajectory points
  /// dynamic verification: simulate the trajectory (DynamicsSolver), report peak contact force and strut
  /// bending stress; with find_speed_limit, slow it down (time scale, bisection) until they stay below
  /// limits.max_contact_force and max_bending_stress
  bool verify_dynamics = false;
  bool find_speed_limit = false;
  double max_bending_stress = std::numeric_limits<double>::infinity();  // Pa
  double settle_time = 0.5;                                             // s simulated after the trajectory ends
  double speed_limit_tolerance = 0.05;  // relative width of the final time-scale bracket (> 0)
};

struct PlanResult
{
  PlanStatus status = PlanStatus::kUnknown;
  std::string message;
  std::vector<std::string> names;
  std::vector<std::vector<double>> waypoints;  // the simplified path (actuation values)
  // the trajectory: times (s from its start) and per time a value per actuator
  std::vector<double> times;
  std::vector<std::vector<double>> positions, velocities, accelerations;
  double duration = 0.0;
  // along the path (quasi-static, every continuation increment)
  double min_gap = std::numeric_limits<double>::infinity();
  double peak_contact_force = 0.0;
  double final_height = 0.0;
  long equilibrium_solves = 0;
  double planning_time = 0.0;          // s wall, OMPL solve and simplification
  bool stopped_by_time_limit = false;  // the search ran until its time_limit (its termination condition fired)
  // dynamic verification
  bool dynamics_verified = false;
  bool dynamics_within_limits = false;
  double dynamic_peak_contact_force = 0.0;
  double dynamic_peak_bending_stress = 0.0;
  double time_scale = 1.0;  // the returned trajectory is the planned one slowed by this factor
  int dynamic_runs = 0;
};

/// Plans from `start` (a converged quasi-static equilibrium of `model`, e.g. StaticSolver::solve at the
/// current actuation). Never throws on a bad request: status kInvalidRequest and a message.
PlanResult planFolding(const core::Model& model, const core::State& start, const PlanRequest& request);

/// Names of the OMPL geometric planners planFolding accepts.
std::vector<std::string> plannerNames();

}  // namespace active_tensegrity::planning
