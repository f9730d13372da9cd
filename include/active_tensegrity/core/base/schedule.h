/// Rheonomic actuation laws s(t): a ramp at constant speed from a start time up to a final value,
/// optionally blended in and out with a half-cosine speed profile so that the acceleration stays
/// finite (smooth start).
#pragma once

#include <vector>

namespace active_tensegrity::core
{
struct ActuationValue
{
  double value = 0.0;  // s, m
  double rate = 0.0;   // ds/dt, m/s
  double accel = 0.0;  // d2s/dt2, m/s^2
};

struct RampSchedule
{
  double speed = 0.0;        // m/s, cruise speed (> 0)
  double start_time = 0.0;   // s
  double final_value = 0.0;  // m
  double blend_time = 0.0;   // s, duration of the smooth start and of the smooth stop (0 = sharp ramp)

  /// Value, rate and acceleration at time t.
  ActuationValue evaluate(double t) const;
  /// Time at which the final value is reached.
  double endTime() const;
  /// The times where s(t) is not smooth (start, end of the smooth start, start of the smooth stop,
  /// end), ascending and distinct: a variable-step integrator steps exactly onto them.
  std::vector<double> breakpoints() const;
  /// The same speed and blend, starting at `time` and travelling `travel` (m, >= 0): one move of a sequence.
  RampSchedule startingAt(double time, double travel) const
  {
    RampSchedule r = *this;
    r.start_time = time;
    r.final_value = travel;
    return r;
  }
};

}  // namespace active_tensegrity::core
