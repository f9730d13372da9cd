#include "active_tensegrity/core/solvers/adaptive.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

namespace active_tensegrity::core
{
namespace
{
constexpr double kSafety = 0.9;     // proposed step = kSafety * h * (1 / err)^(1/3)
constexpr double kMaxGrowth = 2.0;  // per accepted step
constexpr double kMinShrink = 0.1;  // per rejected step
constexpr double kKeepBand = 1.2;   // a proposal in [h, kKeepBand h] keeps h (and the factorization)
// after a step refused for its energy gain, the steps stay below kEnergyMargin times the refused one, a bound that
// grows by kEnergyRelease per accepted step (the event that made it may pass)
constexpr double kEnergyMargin = 0.9;
constexpr double kEnergyRelease = 1.01;
}  // namespace

StepSizeControl::StepSizeControl(const SolverOptions& options)
  : options_(options), h_(std::clamp(options.dt, options.dt_min, options.dt_max))
{
}

StepSizeControl::Trial StepSizeControl::next(double remaining) const
{
  // land on the end without a sliver of a step: the last one or two steps share what is left
  Trial t;
  t.h = std::min(h_, options_.dt_max);
  // (what is left is never split into pieces below dt_min: the callers' stops are dt_min apart at least)
  const bool indivisible = 0.5 * remaining < options_.dt_min;
  if (remaining <= 1.05 * t.h || indivisible)
  {
    t.clipped = remaining < t.h;
    t.h = remaining;
  }
  else if (remaining < 2.0 * t.h)
  {
    t.h = 0.5 * remaining;
    t.clipped = true;
  }
  t.at_min = t.h <= options_.dt_min * (1.0 + 1e-9) || (indivisible && t.h == remaining);
  return t;
}

void StepSizeControl::failed(double h)
{
  h_ = std::max(options_.dt_min, 0.5 * h);
}

void StepSizeControl::tooDeep(double h, double onset_gap, double onset_depth)
{
  // the gap closed from onset_gap to -onset_depth: aim at half the allowed depth
  const double fraction = (onset_gap + 0.5 * options_.onset_depth) / (onset_gap + onset_depth);
  h_ = std::max(options_.dt_min, h * std::clamp(fraction, 0.02, 0.9));
}

void StepSizeControl::tooLarge(double h, double err)
{
  h_ = std::max(options_.dt_min, h * std::clamp(kSafety * std::cbrt(1.0 / err), kMinShrink, kSafety));
}

void StepSizeControl::energyRefused(double h)
{
  h_ = std::max(options_.dt_min, 0.5 * h);
  energy_bound_ = kEnergyMargin * h;
}

void StepSizeControl::accepted(const Trial& t, double err)
{
  double ratio = std::clamp(kSafety * std::cbrt(1.0 / std::max(err, 1e-12)), kMinShrink, kMaxGrowth);
  if (ratio >= 1.0 && ratio <= kKeepBand)
    ratio = 1.0;
  energy_bound_ *= kEnergyRelease;
  const double proposal =
      std::clamp(std::min(t.h * ratio, std::max(energy_bound_, t.h)), options_.dt_min, options_.dt_max);
  // a step shortened to land on the end says little about the longer one: only shrink from it
  if (!t.clipped || proposal < t.h)
    h_ = proposal;
}

}  // namespace active_tensegrity::core
