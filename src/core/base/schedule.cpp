#include "active_tensegrity/core/base/schedule.h"

#include <algorithm>
#include <cmath>

namespace active_tensegrity::core
{
namespace
{
// speed profile v(t) = V (1 - cos(pi t / tb)) / 2 over a blend of length tb: the distance it covers
// is V tb / 2
ActuationValue blendIn(double speed, double tb, double t)
{
  const double w = M_PI / tb;
  return { speed * (0.5 * t - std::sin(w * t) / (2.0 * w)), 0.5 * speed * (1.0 - std::cos(w * t)),
           0.5 * speed * w * std::sin(w * t) };
}
}  // namespace

double RampSchedule::endTime() const
{
  if (speed <= 0.0 || final_value <= 0.0)
    return start_time;
  // the two blends together cover V tb, the same as cruising for tb
  const double tb = std::min(blend_time, final_value / speed);
  return start_time + final_value / speed + tb;
}

std::vector<double> RampSchedule::breakpoints() const
{
  if (speed <= 0.0 || final_value <= 0.0)
    return {};
  const double tb = std::min(blend_time, final_value / speed);
  const double end = endTime();
  std::vector<double> out = { start_time, start_time + tb, end - tb, end };
  out.erase(std::unique(out.begin(), out.end(), [](double a, double b) { return b - a <= 1e-12 * (1.0 + b); }),
            out.end());
  return out;
}

ActuationValue RampSchedule::evaluate(double t) const
{
  if (speed <= 0.0 || final_value <= 0.0 || t <= start_time)
    return {};
  const double tb = std::min(blend_time, final_value / speed);
  const double tau = t - start_time;
  const double t_end = endTime() - start_time;
  if (tau >= t_end)
    return { final_value, 0.0, 0.0 };
  if (tb <= 0.0)
    return { speed * tau, speed, 0.0 };
  if (tau < tb)
    return blendIn(speed, tb, tau);
  const double cruise_end = t_end - tb;
  if (tau <= cruise_end)
    return { 0.5 * speed * tb + speed * (tau - tb), speed, 0.0 };
  // smooth stop: mirror image of the smooth start
  const ActuationValue m = blendIn(speed, tb, t_end - tau);
  return { final_value - m.value, m.rate, -m.accel };
}

}  // namespace active_tensegrity::core
