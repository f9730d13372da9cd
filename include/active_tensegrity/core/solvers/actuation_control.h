/// Online actuation of a running simulation (what the ROS node's ~actuation and ~trajectory drive):
/// every actuator follows its own motion, a hold, a ramp to a target under speed and acceleration
/// limits, or a trajectory through timed points, and a new command takes over from the current
/// value and rate, so that s(t) never jumps in value or rate (the rheonomic constraint would turn a
/// jump into an impulse). Commands are checked whole before any part is applied. ROS-free.
#pragma once

#include <string>
#include <vector>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/base/schedule.h"
#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
/// s(t) of one actuator: piecewise cubic polynomials in absolute time, constant after the end.
class ActuatorMotion
{
public:
  /// Stays at `value` (rate 0) for ever.
  static ActuatorMotion hold(double value);
  /// From `start` (value and rate at t0) to rest at `target`, time-optimally under |rate| <= max_speed
  /// and |accel| <= max_accel (trapezoidal rate profile; a start rate away from the target, or too fast
  /// to stop in time, is braked first). max_speed, max_accel > 0 and finite.
  static ActuatorMotion ramp(double t0, const ActuationValue& start, double target, double max_speed, double max_accel);
  /// Through the points (times absolute, strictly increasing, the first >= t0) from `start` at t0 by
  /// cubic Hermite pieces (C1). rates: one per point, or empty for monotone (Fritsch-Carlson) rates
  /// that never overshoot the points, ending at rest. A first point at t0 must equal start.value.
  static ActuatorMotion spline(double t0, const ActuationValue& start, const std::vector<double>& times,
                               const std::vector<double>& values, const std::vector<double>& rates);

  /// Value, rate and acceleration at t; before the first piece: its start value at rest.
  ActuationValue evaluate(double t) const;
  /// Time after which the value stays constant.
  double endTime() const;
  /// Smallest and largest value over the whole motion (exact: the cubic pieces' extrema included).
  void range(double& lo, double& hi) const;

private:
  struct Piece
  {
    double t0, t1;
    double c[4];  // s = c0 + c1 tau + c2 tau^2 + c3 tau^3, tau = t - t0
  };
  void addQuadratic(double t0, double duration, double s0, double v0, double a);
  void addHermite(double t0, double t1, double s0, double v0, double s1, double v1);
  std::vector<Piece> pieces_;
  double final_value_ = 0.0;
};

/// The actuation law of a running simulation: one ActuatorMotion per actuator of the model.
class ActuationController
{
public:
  /// Every actuator held at its value in `initial` (one per actuator of the model).
  ActuationController(const Model& model, const ActuationValues& initial);

  /// Ramps the named actuators to their targets from time t. speeds, accels: empty (the defaults
  /// given here), one value for all, or one per name; > 0 and finite. Targets within the actuator's
  /// [min_value, max_value]. Returns "" when applied, else the reason (and nothing is applied).
  std::string setTargets(double t, const std::vector<std::string>& names, const std::vector<double>& targets,
                         const std::vector<double>& speeds, const std::vector<double>& accels, double default_speed,
                         double default_accel);
  /// Follows timed points from time t: times_from_start >= 0 strictly increasing; positions[k] and
  /// (optionally) velocities[k] hold one value per name. The whole curve must stay within the bounds.
  /// Returns "" when applied, else the reason (and nothing is applied).
  std::string setTrajectory(double t, const std::vector<std::string>& names,
                            const std::vector<double>& times_from_start,
                            const std::vector<std::vector<double>>& positions,
                            const std::vector<std::vector<double>>& velocities);
  /// Every actuator held at `values`.
  void reset(const ActuationValues& values);

  /// The law s(t) of every actuator.
  ActuationValues values(double t) const;
  /// The same into `u` (resized to the actuators; no allocation once it has that size).
  void values(double t, ActuationValues& u) const;
  /// Index of the named actuator, or -1.
  int index(const std::string& name) const;
  /// True while some actuator has not reached the end of its motion.
  bool moving(double t) const;

private:
  /// Checks the names (known, unique, not empty); "" or the reason.
  std::string checkNames(const std::vector<std::string>& names, std::vector<int>& indices) const;
  std::vector<std::string> names_;
  std::vector<double> min_value_, max_value_;
  std::vector<ActuatorMotion> motions_;
};

}  // namespace active_tensegrity::core
