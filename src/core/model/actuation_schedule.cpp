#include "active_tensegrity/core/model/actuation_schedule.h"

#include <algorithm>
#include <cmath>

namespace active_tensegrity::core
{
namespace
{
/// Calls f(ramp, from, to) for each ramp of actuator a in the sequence, in time order.
template <class F>
void forEachRamp(const AnalysisSettings& an, int a, F&& f)
{
  double value = 0.0;
  for (const ActuationStep& step : an.sequence)
    for (size_t k = 0; k < step.actuators.size(); ++k)
      if (step.actuators[k] == a)
      {
        f(an.schedule.startingAt(step.time, std::abs(step.targets[k] - value)), value, step.targets[k]);
        value = step.targets[k];
      }
}
}  // namespace

ActuationValues scheduledActuation(const Model& model, double t)
{
  ActuationValues out;
  scheduledActuation(model, t, out);
  return out;
}

void scheduledActuation(const Model& model, double t, ActuationValues& out)
{
  const AnalysisSettings& an = model.analysis;
  if (an.sequence.empty())
  {
    out.assign(model.actuators.size(), an.schedule.evaluate(t));
    return;
  }
  out.assign(model.actuators.size(), ActuationValue{});
  for (size_t a = 0; a < model.actuators.size(); ++a)
    forEachRamp(an, static_cast<int>(a),
                [&](const RampSchedule& r, double from, double to)
                {
                  if (t < r.start_time)
                    return;
                  const ActuationValue v = r.evaluate(t);
                  const double sign = to >= from ? 1.0 : -1.0;
                  out[a] = ActuationValue{ from + sign * v.value, sign * v.rate, sign * v.accel };
                });
}

double actuationEndTime(const Model& model)
{
  const AnalysisSettings& an = model.analysis;
  if (an.sequence.empty())
    return an.schedule.endTime();
  double end = 0.0;
  for (size_t a = 0; a < model.actuators.size(); ++a)
    forEachRamp(an, static_cast<int>(a),
                [&](const RampSchedule& r, double, double) { end = std::max(end, r.endTime()); });
  return end;
}

std::vector<double> actuationBreakpoints(const Model& model)
{
  const AnalysisSettings& an = model.analysis;
  if (an.sequence.empty())
    return an.schedule.breakpoints();
  std::vector<double> out;
  for (size_t a = 0; a < model.actuators.size(); ++a)
    forEachRamp(an, static_cast<int>(a),
                [&](const RampSchedule& r, double, double)
                {
                  const std::vector<double> b = r.breakpoints();
                  out.insert(out.end(), b.begin(), b.end());
                });
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace active_tensegrity::core
