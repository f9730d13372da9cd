// The dynamic verification of a folding plan: the stop of moving actuators, the trajectory executed, its
// simulation and the peaks over every step.
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

namespace
{
struct DynamicPeaks
{
  bool ran = false;       // the simulation ran to its end without failing
  bool settled = false;   // ... and the structure came to rest, or its motion decays (or settle_time was simulated)
  bool decaying = false;  // settled by decay: still moving, every extreme already passed
  std::string message;
  double contact = 0.0, bending = 0.0;
  double min_gap = std::numeric_limits<double>::infinity();
  double settle = 0.0;  // s simulated after the trajectory's end
};

/// The window of the settling check: 1.5 of the structure's longest natural period at the end of the path
/// (0.25 to 5 s; 1 s when the modal analysis fails or the end is a mechanism).
double restWindow(const core::Model& model, const core::State& end)
{
  try
  {
    const core::ModalAnalysis m = core::naturalModes(model, end, 1);
    if (!m.modes.empty() && m.modes.front().omega > 0.0)
      return std::clamp(1.5 * 2.0 * M_PI / m.modes.front().omega, 0.25, 5.0);
  }
  catch (const std::exception&)
  {
  }
  return 1.0;
}

/// Simulates `trajectory` (times from start.t) from `start` as it is (positions, velocities, contact memory),
/// the chosen actuators taken over from `law` at start.t, the others following it; then until the structure
/// is at rest or its motion decays (or for settle_time); polls `stop` every step.
DynamicPeaks simulate(const core::Model& model, const core::State& start, const core::ActuationController& law_given,
                      const PlanRequest& r, const Trajectory& trajectory, double rest_window,
                      const std::function<bool()>& stop)
{
  DynamicPeaks peaks;
  core::Model dyn = model;
  dyn.analysis.type = core::AnalysisType::kDynamic;
  core::State s = start;
  if (s.qd.size() != dyn.nq)
    s.qd.setZero(dyn.nq);
  core::ActuationController control = law_given;
  const std::string err =
      control.setTrajectory(s.t, r.actuators, trajectory.times, trajectory.positions, trajectory.velocities);
  if (!err.empty())
  {
    peaks.message = "trajectory refused: " + err;
    return peaks;
  }
  core::DynamicsSolver solver(dyn, dyn.solver);
  double mass = 0.0;
  for (const core::Body& b : dyn.bodies)
    mass += b.mass;
  const core::ActuationLaw law =
      core::ActuationLaw::writing([&control](double t, core::ActuationValues& u) { control.values(t, u); });
  core::Summary sum = solver.initialize(s, law);
  const double dt = dyn.solver.dt;
  const double t0 = s.t;
  const double t_end = t0 + trajectory.duration;
  const double settle_limit = r.settle_time > 0.0 ? r.settle_time : r.max_settle_time;
  // after the end, windows of rest_window s: at rest when the RMS speed stayed under rest_speed through one;
  // decaying when one set no new extreme (gap, contact force, bending stress) and its largest kinetic
  // energy is below the window's before
  struct Window
  {
    double kinetic = 0.0;
    bool quiet = true, new_extreme = false;
  } window, previous;
  int windows = 0;
  double window_start = t_end;
  // the extremes of the state s (a new one after the trajectory's end is the window's)
  const auto record = [&](bool after)
  {
    const std::vector<core::ContactPairState> contacts = core::activeContacts(dyn, s);
    for (const core::ContactPairState& c : contacts)
      if (c.normal_force > peaks.contact)
      {
        peaks.contact = c.normal_force;
        window.new_extreme = window.new_extreme || after;
      }
    const double bending = contacts.empty() ? 0.0 : core::maxStrutBendingStress(dyn, s.q, contacts);
    if (bending > peaks.bending)
    {
      peaks.bending = bending;
      window.new_extreme = window.new_extreme || after;
    }
    const double gap = core::minimumGap(dyn, s.q);
    if (gap < peaks.min_gap)
    {
      peaks.min_gap = gap;
      window.new_extreme = window.new_extreme || after;
    }
  };
  if (sum.ok())
    record(false);  // the start itself: moving, it may already press struts together
  for (long k = 1; sum.ok(); ++k)
  {
    if (stop())
    {
      std::ostringstream msg;
      msg << "stopped by the time limit (or cancelled) at t = " << s.t - t0 << " s of " << t_end - t0 << " s";
      peaks.message = msg.str();
      return peaks;
    }
    sum = solver.step(s, t0 + static_cast<double>(k) * dt - s.t, law);
    if (!sum.ok())
      break;
    s.t = t0 + static_cast<double>(k) * dt;
    const bool after = s.t > t_end;
    record(after);
    if (!after)
      continue;
    peaks.settle = s.t - t_end;
    if (r.settle_time > 0.0)
    {
      if (peaks.settle >= r.settle_time - 0.5 * dt)
      {
        peaks.settled = true;
        break;
      }
      continue;
    }
    const double kinetic = solver.energyAt(s).kinetic;
    window.kinetic = std::max(window.kinetic, kinetic);
    window.quiet = window.quiet && (mass <= 0.0 || std::sqrt(2.0 * kinetic / mass) < r.rest_speed);
    if (s.t - window_start >= rest_window - 0.5 * dt)
    {
      ++windows;
      if (window.quiet)
      {
        peaks.settled = true;
        break;
      }
      if (windows >= 2 && !window.new_extreme && window.kinetic < previous.kinetic)
      {
        peaks.settled = peaks.decaying = true;
        break;
      }
      previous = window;
      window = Window();
      window_start = s.t;
    }
    if (peaks.settle >= settle_limit - 0.5 * dt)
      break;
  }
  peaks.ran = sum.ok();
  if (!sum.ok())
    peaks.message = "the simulation failed at t = " + core::shortestNumber(s.t - t0) + " s: " + sum.message;
  else if (!peaks.settled)
  {
    std::ostringstream msg;
    msg << "still moving " << peaks.settle << " s after the trajectory's end, its extremes still growing (windows of "
        << rest_window << " s)";
    peaks.message = msg.str();
  }
  return peaks;
}
}  // namespace

std::string stopping(const core::Model& model, const std::vector<int>& idx, const core::ActuationValues& now,
                     const PlanRequest& r, Stop& stop)
{
  const size_t n = idx.size();
  std::vector<double> value(n), rate(n), accel(n), at_rest(n, 0.0);
  stop.values.assign(n, 0.0);
  stop.duration = 0.0;
  stop.prefix = Trajectory();
  for (size_t i = 0; i < n; ++i)
  {
    const core::Actuator& a = model.actuators[idx[i]];
    value[i] = now[idx[i]].value;
    rate[i] = now[idx[i]].rate;
    accel[i] = r.max_accelerations[r.max_accelerations.size() == 1 ? 0 : i];
    stop.values[i] = value[i];
    if (rate[i] == 0.0)
      continue;
    at_rest[i] = std::abs(rate[i]) / accel[i];
    stop.values[i] = value[i] + 0.5 * rate[i] * at_rest[i];
    stop.duration = std::max(stop.duration, at_rest[i]);
    if (stop.values[i] < a.min_value - 1e-9 || stop.values[i] > a.max_value + 1e-9)
    {
      std::ostringstream msg;
      msg << "actuator " << core::quoted(a.name) << " moves at " << rate[i] << " m/s at " << value[i]
          << " m: braked at its max_acceleration " << accel[i] << " m/s^2 it stops at " << stop.values[i]
          << " m, outside its range [" << a.min_value << ", " << a.max_value << "] m";
      return msg.str();
    }
  }
  if (stop.duration == 0.0)
    return "";
  // every sample_dt, and where each actuator comes to rest (so that the controller's cubic pieces between the
  // points are exactly the quadratic braking and the rest after it)
  std::vector<double> times;
  for (long k = 0; static_cast<double>(k) * r.sample_dt < stop.duration; ++k)
    times.push_back(static_cast<double>(k) * r.sample_dt);
  for (double t : at_rest)
    if (t > 0.0)
      times.push_back(t);
  std::sort(times.begin(), times.end());
  std::vector<double> kept;
  for (double t : times)
  {
    // a grid point just before a stop time goes (strictly increasing times, no piece shorter than 1e-6 s)
    if (!kept.empty() && t - kept.back() < 1e-6)
    {
      if (kept.size() > 1)
        kept.back() = t;
      continue;
    }
    kept.push_back(t);
  }
  for (double t : kept)
  {
    std::vector<double> p(n), v(n), acc(n);
    for (size_t i = 0; i < n; ++i)
    {
      if (t >= at_rest[i])
      {
        p[i] = stop.values[i];
        continue;
      }
      const double dir = rate[i] > 0.0 ? 1.0 : -1.0;
      p[i] = value[i] + rate[i] * t - 0.5 * dir * accel[i] * t * t;
      v[i] = rate[i] - dir * accel[i] * t;
      acc[i] = -dir * accel[i];
    }
    stop.prefix.times.push_back(t);
    stop.prefix.positions.push_back(p);
    stop.prefix.velocities.push_back(v);
    stop.prefix.accelerations.push_back(acc);
  }
  stop.prefix.duration = stop.duration;
  return "";
}

Trajectory executed(const Stop& stop, const PlanResult& path, double scale)
{
  Trajectory t = stop.prefix;
  for (size_t k = 0; k < path.times.size(); ++k)
  {
    if (k == 0 && !t.times.empty())
      continue;
    t.times.push_back(stop.duration + path.times[k] * scale);
    t.positions.push_back(path.positions[k]);
    Values v = path.velocities[k], a = path.accelerations[k];
    for (double& x : v)
      x /= scale;
    for (double& x : a)
      x /= scale * scale;
    t.velocities.push_back(v);
    t.accelerations.push_back(a);
  }
  t.duration = stop.duration + path.duration * scale;
  return t;
}

void verify(const core::Model& model, const core::State& start, const core::ActuationController& law, const Stop& stop,
            const PlanRequest& r, const core::State& end, RequestClock& clock, PlanResult& out)
{
  const double window = r.settle_time > 0.0 ? 0.0 : restWindow(model, end);
  const auto within = [&](const DynamicPeaks& p)
  {
    const double force_limit = r.limits.allow_contact ? r.limits.max_contact_force : 0.0;
    const bool gap_ok = r.limits.allow_contact || p.min_gap >= r.limits.min_clearance;
    return p.ran && p.settled && p.contact <= force_limit && p.bending <= r.max_bending_stress && gap_ok;
  };
  const auto run = [&](double scale)
  {
    ++out.dynamic_runs;
    return simulate(model, start, law, r, executed(stop, out, scale), window, [&clock] { return clock.stop(); });
  };
  double scale = 1.0;
  DynamicPeaks peaks = run(scale);
  if (r.find_speed_limit && !within(peaks) && out.duration > 0.0 && !clock.out())
  {
    // double the time scale until within, then bisect (geometrically) to the tolerance
    double lo = 1.0, hi = 2.0;
    DynamicPeaks at_hi = run(hi);
    while (!within(at_hi) && hi < 64.0 && !clock.out())
    {
      lo = hi;
      hi *= 2.0;
      at_hi = run(hi);
    }
    if (within(at_hi))
      while (hi / lo > 1.0 + r.speed_limit_tolerance && !clock.out())
      {
        const double mid = std::sqrt(lo * hi);
        const DynamicPeaks p = run(mid);
        if (within(p))
        {
          hi = mid;
          at_hi = p;
        }
        else
          lo = mid;
      }
    scale = hi;
    peaks = at_hi;
    if (clock.out() && within(at_hi))
      out.message += "; the speed-limit search was stopped by the time limit: the time scale is an upper bound";
  }
  out.dynamics_verified = peaks.ran && peaks.settled;
  out.dynamics_within_limits = within(peaks);
  out.dynamic_peak_contact_force = peaks.contact;
  out.dynamic_peak_bending_stress = peaks.bending;
  out.dynamic_min_gap = peaks.min_gap;
  out.settle_duration = peaks.settle;
  if (peaks.decaying)
    out.message += "; verified until the motion decayed (still moving, every extreme passed)";
  out.time_scale = scale;
  if (!out.dynamics_verified)
    out.message += "; dynamic verification incomplete: " + peaks.message;
  if (scale != 1.0)
  {
    for (size_t k = 0; k < out.times.size(); ++k)
    {
      out.times[k] *= scale;
      for (size_t i = 0; i < out.velocities[k].size(); ++i)
      {
        out.velocities[k][i] /= scale;
        out.accelerations[k][i] /= scale * scale;
      }
    }
    out.duration *= scale;
    out.rest_to_rest_duration *= scale;
  }
}
}  // namespace active_tensegrity::planning::detail
