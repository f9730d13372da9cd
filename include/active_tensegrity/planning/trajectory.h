/// Time parameterization of a path of waypoints in actuation space (docs/planning.md, "After planning"):
/// rest to rest along each straight segment, or through corners blended by quadratic arcs within a
/// tolerance of the path, time-optimal under per-actuator speed and acceleration limits. ROS-free.
#pragma once

#include <vector>

namespace active_tensegrity::planning
{
/// A sampled trajectory: times (s from its start) and per time a value, velocity and acceleration per
/// actuator.
struct Trajectory
{
  std::vector<double> times;
  std::vector<std::vector<double>> positions, velocities, accelerations;
  double duration = 0.0;
};

/// Rest to rest along each straight segment, all actuators together: the path parameter follows the
/// time-optimal trapezoid under the tightest of the actuators' limits (one value for all, or one per
/// actuator), sampled every sample_dt.
Trajectory restToRest(const std::vector<std::vector<double>>& waypoints, const std::vector<double>& max_speeds,
                      const std::vector<double>& max_accelerations, double sample_dt);

/// Per waypoint, the length d (m, Euclidean in actuation space) cut from the segments on both sides of its
/// corner and replaced by a quadratic arc: the largest that keeps the arc within `tolerance` (max norm) of
/// the corner, and at most half of either segment. 0 at the ends and where the path runs straight on.
std::vector<double> blendLengths(const std::vector<std::vector<double>>& waypoints, double tolerance);

/// The blended curve (blend lengths d from blendLengths, possibly reduced) as points no more than
/// `spacing` apart (max norm), from the first waypoint to the last. `corner` (when given) receives per
/// point the waypoint whose arc it lies on, or -1 on a straight part.
std::vector<std::vector<double>> blendedCurve(const std::vector<std::vector<double>>& waypoints,
                                              const std::vector<double>& d, double spacing,
                                              std::vector<int>* corner = nullptr);

/// Time-optimal along the blended curve from rest to rest: the path speed as large as the actuators'
/// speed limits and their accelerations (tangential plus centripetal) allow (forward and backward passes
/// over a fine arc-length grid, 1 mm or 1/200 of the path; 98 % of each acceleration, the rest kept for
/// the grid), sampled every sample_dt. A corner with d = 0 is passed at rest.
Trajectory timeOptimal(const std::vector<std::vector<double>>& waypoints, const std::vector<double>& d,
                       const std::vector<double>& max_speeds, const std::vector<double>& max_accelerations,
                       double sample_dt);

}  // namespace active_tensegrity::planning
