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
#include <ompl/geometric/planners/est/BiEST.h>
#include <ompl/geometric/planners/est/EST.h>
#include <ompl/geometric/planners/informedtrees/BITstar.h>
#include <ompl/geometric/planners/kpiece/BKPIECE1.h>
#include <ompl/geometric/planners/kpiece/KPIECE1.h>
#include <ompl/geometric/planners/kpiece/LBKPIECE1.h>
#include <ompl/geometric/planners/prm/LazyPRM.h>
#include <ompl/geometric/planners/prm/LazyPRMstar.h>
#include <ompl/geometric/planners/prm/PRM.h>
#include <ompl/geometric/planners/prm/PRMstar.h>
#include <ompl/geometric/planners/rrt/BiTRRT.h>
#include <ompl/geometric/planners/rrt/InformedRRTstar.h>
#include <ompl/geometric/planners/rrt/LazyRRT.h>
#include <ompl/geometric/planners/rrt/RRT.h>
#include <ompl/geometric/planners/rrt/RRTConnect.h>
#include <ompl/geometric/planners/rrt/RRTstar.h>
#include <ompl/geometric/planners/rrt/TRRT.h>
#include <ompl/geometric/planners/sbl/SBL.h>
#include <ompl/util/Console.h>

#include "active_tensegrity/core/solvers/actuation_control.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/modal.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/base/text.h"
#include "active_tensegrity/planning/trajectory.h"
#include "active_tensegrity/planning/validity.h"

namespace ob = ompl::base;
namespace og = ompl::geometric;

namespace active_tensegrity::planning
{
namespace
{
using Values = std::vector<double>;
using Allocator = std::function<ob::PlannerPtr(const ob::SpaceInformationPtr&)>;

template <typename P>
Allocator make()
{
  return [](const ob::SpaceInformationPtr& si) { return std::make_shared<P>(si); };
}

const std::map<std::string, Allocator>& planners()
{
  static const std::map<std::string, Allocator> m = {
    { "RRTConnect", make<og::RRTConnect>() },
    { "RRT", make<og::RRT>() },
    { "RRTstar", make<og::RRTstar>() },
    { "InformedRRTstar", make<og::InformedRRTstar>() },
    { "LazyRRT", make<og::LazyRRT>() },
    { "TRRT", make<og::TRRT>() },
    { "BiTRRT", make<og::BiTRRT>() },
    { "PRM", make<og::PRM>() },
    { "PRMstar", make<og::PRMstar>() },
    { "LazyPRM", make<og::LazyPRM>() },
    { "LazyPRMstar", make<og::LazyPRMstar>() },
    { "EST", make<og::EST>() },
    { "BiEST", make<og::BiEST>() },
    { "KPIECE1", make<og::KPIECE1>() },
    { "BKPIECE1", make<og::BKPIECE1>() },
    { "LBKPIECE1", make<og::LBKPIECE1>() },
    { "SBL", make<og::SBL>() },
    { "BITstar", make<og::BITstar>() },
  };
  return m;
}

/// Uniform sampling from the request's seed (OMPL's own RNG seeds come from one process-wide
/// generator, so two requests with one seed would differ).
class SeededSampler : public ob::StateSampler
{
public:
  SeededSampler(const ob::StateSpace* space, unsigned seed) : ob::StateSampler(space), gen_(seed) {}
  void sampleUniform(ob::State* s) override
  {
    const auto& b = space_->as<ob::RealVectorStateSpace>()->getBounds();
    auto* r = s->as<ob::RealVectorStateSpace::StateType>();
    for (size_t i = 0; i < b.low.size(); ++i)
      r->values[i] = std::uniform_real_distribution<double>(b.low[i], b.high[i])(gen_);
  }
  void sampleUniformNear(ob::State* s, const ob::State* near, double distance) override
  {
    const auto& b = space_->as<ob::RealVectorStateSpace>()->getBounds();
    auto* r = s->as<ob::RealVectorStateSpace::StateType>();
    const auto* c = near->as<ob::RealVectorStateSpace::StateType>();
    for (size_t i = 0; i < b.low.size(); ++i)
      r->values[i] = std::uniform_real_distribution<double>(std::max(b.low[i], c->values[i] - distance),
                                                            std::min(b.high[i], c->values[i] + distance))(gen_);
  }
  void sampleGaussian(ob::State* s, const ob::State* mean, double stdDev) override
  {
    const auto& b = space_->as<ob::RealVectorStateSpace>()->getBounds();
    auto* r = s->as<ob::RealVectorStateSpace::StateType>();
    const auto* c = mean->as<ob::RealVectorStateSpace::StateType>();
    for (size_t i = 0; i < b.low.size(); ++i)
      r->values[i] = std::clamp(std::normal_distribution<double>(c->values[i], stdDev)(gen_), b.low[i], b.high[i]);
  }

private:
  std::mt19937 gen_;
};

/// Goal states are sampled this far (m) below a target height.
constexpr double kGoalMargin = 1e-3;

/// height <= target at a valid equilibrium. Goal states are sampled (for bidirectional planners) on
/// rays from the start towards the upper bounds in random proportions, where the height first drops
/// to the target (bisection on the equilibria along the ray).
class HeightGoal : public ob::GoalSampleableRegion
{
public:
  HeightGoal(const ob::SpaceInformationPtr& si, const EquilibriumOracle& oracle, size_t n, double target, unsigned seed)
    : ob::GoalSampleableRegion(si), oracle_(oracle), n_(n), target_(target), gen_(seed + 7919u)
  {
    setThreshold(0.0);
  }
  double distanceGoal(const ob::State* s) const override
  {
    const Equilibrium e = oracle_.at(stateValues(s, n_));
    return e.converged ? std::max(0.0, e.height - target_) : std::numeric_limits<double>::infinity();
  }
  bool isSatisfied(const ob::State* s) const override
  {
    const Equilibrium e = oracle_.at(stateValues(s, n_));
    return e.converged && e.height <= target_ && oracle_.valid(e);
  }
  void sampleGoal(ob::State* st) const override
  {
    const auto& b = si_->getStateSpace()->as<ob::RealVectorStateSpace>()->getBounds();
    for (int attempt = 0; attempt < 20; ++attempt)
    {
      // a ray from the start towards the upper bounds, every actuator pulled in some proportion
      // (0.6 to 1 of the largest): folding pulls all cables, in an order the planner then finds
      const Values lo = oracle_.values(oracle_.start().state);
      Values w(n_), hi(n_);
      double wmax = 0.0;
      for (size_t i = 0; i < n_; ++i)
        wmax = std::max(wmax, w[i] = std::uniform_real_distribution<double>(0.6, 1.0)(gen_));
      for (size_t i = 0; i < n_; ++i)
        hi[i] = lo[i] + (w[i] / wmax) * (b.high[i] - lo[i]);
      const auto point = [&](double f)
      {
        Values v(n_);
        for (size_t i = 0; i < n_; ++i)
          v[i] = lo[i] + f * (hi[i] - lo[i]);
        return v;
      };
      // aimed 1 mm below the target: the equilibrium reached along another path may lie a little higher
      const auto above = [this](const Equilibrium& e) { return !e.converged || e.height > target_ - kGoalMargin; };
      // the first tenth of the ray where the height is below the target (continuation along the ray, which
      // may fail further out), then bisection inside it
      double f0 = 0.0, f1 = -1.0;
      for (int j = 1; j <= 10; ++j)
      {
        const Equilibrium e = oracle_.at(point(0.1 * j));
        if (!e.converged)
          break;  // no equilibrium further along (or stopped)
        if (!above(e))
        {
          f1 = 0.1 * j;
          break;
        }
        f0 = 0.1 * j;
      }
      if (f1 < 0.0)
        continue;  // not below the target on this ray
      for (int k = 0; k < 6; ++k)
      {
        const double f = 0.5 * (f0 + f1);
        (above(oracle_.at(point(f))) ? f0 : f1) = f;
      }
      const Values v = point(f1);
      if (oracle_.valid(oracle_.at(v)))
      {
        setStateValues(st, v);
        return;
      }
    }
    setStateValues(st, Values(b.high.begin(), b.high.end()));
  }
  unsigned int maxSampleCount() const override
  {
    return 1000;
  }

private:
  const EquilibriumOracle& oracle_;
  size_t n_;
  double target_;
  mutable std::mt19937 gen_;
};

std::string checkRequest(const core::Model& model, const PlanRequest& r, std::vector<int>& idx)
{
  std::ostringstream msg;
  if (r.actuators.empty())
    return "no actuators named";
  std::set<std::string> seen;
  for (const std::string& n : r.actuators)
  {
    const int i = model.findActuator(n);
    if (i < 0)
    {
      msg << "unknown actuator " << core::quoted(n) << " (the scene has:";
      for (const core::Actuator& a : model.actuators)
        msg << " " << a.name;
      msg << ")";
      return msg.str();
    }
    if (!seen.insert(n).second)
      return "actuator " + core::quoted(n) + " named twice";
    idx.push_back(i);
  }
  const size_t n = idx.size();
  if (r.target_values.empty())
  {
    if (!std::isfinite(r.target_height))
      return "give a finite target_height or target_values";
  }
  else
  {
    if (r.target_values.size() != n)
    {
      msg << r.target_values.size() << " target_values for " << n << " actuators";
      return msg.str();
    }
    for (size_t k = 0; k < n; ++k)
    {
      const core::Actuator& a = model.actuators[idx[k]];
      if (!std::isfinite(r.target_values[k]))
      {
        msg << "target value of '" << a.name << "' is " << r.target_values[k] << ": not a finite number";
        return msg.str();
      }
      if (r.target_values[k] < a.min_value || r.target_values[k] > a.max_value)
      {
        msg << "target value of '" << a.name << "' is " << r.target_values[k] << ", outside its range [" << a.min_value
            << ", " << a.max_value << "]";
        return msg.str();
      }
    }
  }
  const auto positive = [&](const std::vector<double>& v, const char* what) -> std::string
  {
    if (v.size() != 1 && v.size() != n)
    {
      std::ostringstream m;
      m << v.size() << " " << what << " for " << n << " actuators (give one for all, or one each)";
      return m.str();
    }
    for (double x : v)
      if (!std::isfinite(x) || x <= 0.0)
      {
        std::ostringstream m;
        m << what << " must be finite and > 0, got " << x;
        return m.str();
      }
    return "";
  };
  std::string err = positive(r.max_speeds, "max_speeds");
  if (err.empty())
    err = positive(r.max_accelerations, "max_accelerations");
  if (!err.empty())
    return err;
  const auto nonneg = [&](double x, const char* what, bool allow_inf) -> std::string
  {
    if (std::isnan(x) || x < 0.0 || (!allow_inf && !std::isfinite(x)))
    {
      std::ostringstream m;
      m << what << " must be " << (allow_inf ? ">= 0" : "finite and >= 0") << ", got " << x;
      return m.str();
    }
    return "";
  };
  for (const auto& [x, what, inf] :
       { std::make_tuple(r.limits.min_clearance, "min_clearance", false),
         std::make_tuple(r.limits.max_contact_force, "max_contact_force", true),
         std::make_tuple(r.limits.max_cable_stress, "max_cable_stress", true),
         std::make_tuple(r.max_bending_stress, "max_bending_stress", true),
         std::make_tuple(r.settle_time, "settle_time", false), std::make_tuple(r.range, "range", false),
         std::make_tuple(r.blend_tolerance, "blend_tolerance", false) })
    if (!(err = nonneg(x, what, inf)).empty())
      return err;
  for (const auto& [x, what] :
       { std::make_pair(r.time_limit, "time_limit"), std::make_pair(r.continuation_step, "continuation_step"),
         std::make_pair(r.sample_dt, "sample_dt"), std::make_pair(r.rest_speed, "rest_speed"),
         std::make_pair(r.max_settle_time, "max_settle_time"),
         std::make_pair(r.speed_limit_tolerance, "speed_limit_tolerance") })
    if (!std::isfinite(x) || x <= 0.0)
    {
      msg << what << " must be finite and > 0, got " << x;
      return msg.str();
    }
  if (r.planner == "FMT" || r.planner == "BFMT")
  {
    // not offered: OMPL 1.5's FMT, stopped by the deadline, crashed the process when it was released (a
    // segmentation fault in FMT::freeMemory, the quadruplex's top to 0.888 m with a 0.1 s limit), and BFMT crashed
    // once in a run of random requests
    msg << "planner " << core::quoted(r.planner)
        << " is not offered: OMPL 1.5's FMT and BFMT can crash the process when a deadline stops them (BITstar and "
           "PRMstar are asymptotically optimal too)";
    return msg.str();
  }
  if (!planners().count(r.planner))
  {
    msg << "unknown planner " << core::quoted(r.planner) << " (known:";
    for (const std::string& p : plannerNames())
      msg << " " << p;
    msg << ")";
    return msg.str();
  }
  return "";
}

/// Searches of one request at most: a path cut when followed from the start (another branch of equilibria) is
/// searched on from where it stopped being valid, with the next seed, while the deadline allows.
constexpr int kSearchesMost = 8;

/// The request's one deadline, its cancel and its progress reports (PlanControl). Planners may poll from
/// several threads: the flags are atomic, the reports serialized.
class RequestClock
{
public:
  using Clock = std::chrono::steady_clock;

  RequestClock(double time_limit, const PlanControl& control)
    : control_(control)
    , t0_(Clock::now())
    , main_(t0_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(time_limit)))
    , end_(main_)
  {
  }
  void watch(const EquilibriumOracle* oracle)
  {
    oracle_ = oracle;
  }
  double elapsed() const
  {
    return std::chrono::duration<double>(Clock::now() - t0_).count();
  }
  void phase(const char* name)
  {
    const std::lock_guard<std::mutex> lock(report_mutex_);
    phase_ = name;
  }
  /// Whether the current phase must stop: past its end, or cancelled (before the answer is being made).
  bool stop()
  {
    report();
    const Clock::time_point t = Clock::now();
    if (t > main_)
      timed_out_ = true;
    if (!answering_ && !cancelled_ && control_.cancelled && control_.cancelled())
      cancelled_ = true;
    return t > end_.load() || (!answering_ && cancelled_);
  }
  /// The request ran out: its deadline passed or it was cancelled.
  bool out()
  {
    stop();
    if (!cancelled_ && control_.cancelled && control_.cancelled())
      cancelled_ = true;
    return timed_out_ || cancelled_;
  }
  /// From now on the answer is being made: a cancel no longer stops the phase, which ends at the deadline
  /// or, when that is less than `grace` s away, `grace` s from now.
  void answering(double grace)
  {
    answering_ = true;
    end_ = std::max(main_,
                    Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(grace)));
  }
  /// Back to searching (from an answer phase that found the path cut): the deadline ends the phase, and a cancel
  /// stops it again.
  void searching()
  {
    answering_ = false;
    end_ = main_;
  }
  /// The last report, once the answer is made: phase "done" with the figures of the returned path's end.
  void done(double best_height, double best_distance)
  {
    if (!control_.progress)
      return;
    const std::lock_guard<std::mutex> lock(report_mutex_);
    PlanProgress p;
    p.elapsed = elapsed();
    p.phase = "done";
    p.best_height = best_height;
    p.best_distance = best_distance;
    if (oracle_)
      p.equilibrium_solves = oracle_->solves();
    control_.progress(p);
  }
  bool timedOut() const
  {
    return timed_out_;
  }
  bool cancelled() const
  {
    return cancelled_;
  }

private:
  void report()
  {
    if (!control_.progress)
      return;
    std::unique_lock<std::mutex> lock(report_mutex_, std::try_to_lock);
    if (!lock.owns_lock())
      return;
    const double now = elapsed();
    if (reported_ && now - last_report_ < control_.progress_period)
      return;
    reported_ = true;
    last_report_ = now;
    PlanProgress p;
    p.elapsed = now;
    p.phase = phase_;
    if (oracle_)
    {
      p.equilibrium_solves = oracle_->solves();
      p.best_distance = oracle_->bestDistance();
      p.best_height = oracle_->bestHeight();
    }
    control_.progress(p);
  }

  const PlanControl& control_;
  const EquilibriumOracle* oracle_ = nullptr;
  Clock::time_point t0_, main_;
  std::atomic<Clock::time_point> end_;
  std::atomic<bool> timed_out_{ false }, cancelled_{ false }, answering_{ false };
  std::mutex report_mutex_;
  std::string phase_ = "search";
  bool reported_ = false;
  double last_report_ = 0.0;
};

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

/// How the chosen actuators, moving at the start, come to rest: each braked from its rate at its acceleration
/// limit (the time-optimal stop), sampled as the first part of the trajectory.
struct Stop
{
  std::vector<double> values;  // where each comes to rest
  double duration = 0.0;       // s until the last is at rest (0: all at rest already)
  Trajectory prefix;           // from the start's values and rates to rest (no points when duration is 0)
};

/// The stop of the chosen actuators from `now` (their values and rates at the start); "" or why not (a stop
/// outside an actuator's range).
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

/// The trajectory as it runs: the stop, then the path's trajectory from where it ends (its first point, at
/// rest there, is the stop's last), slowed by `scale`.
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

/// The goal's distance of an equilibrium (0 at the goal).
std::function<double(const Equilibrium&)> goalDistance(const EquilibriumOracle& oracle, const PlanRequest& r)
{
  if (r.target_values.empty())
    return [target = r.target_height](const Equilibrium& e) { return std::max(0.0, e.height - target); };
  return [&oracle, target = r.target_values](const Equilibrium& e)
  { return actuationDistance(oracle.values(e.state), target); };
}

/// The end of the followed path meets the goal (valid, at or below the target height, or at the target values).
bool meetsGoal(const EquilibriumOracle& oracle, const PlanRequest& r, const Equilibrium& e)
{
  if (!oracle.valid(e))
    return false;
  if (r.target_values.empty())
    return e.height <= r.target_height;
  return actuationDistance(oracle.values(e.state), r.target_values) <= 1e-9;
}

/// A one-point plan: the start meets the goal.
void stayAtStart(const EquilibriumOracle& oracle, PlanResult& out)
{
  const Values v = oracle.values(oracle.start().state);
  out.status = PlanStatus::kExactSolution;
  out.message = "exact solution: the start meets the goal";
  out.waypoints = { v };
  out.times = { 0.0 };
  out.positions = { v };
  out.velocities = out.accelerations = { Values(v.size(), 0.0) };
  out.min_gap = oracle.start().min_gap;
  out.peak_contact_force = oracle.start().max_contact;
  out.final_height = oracle.start().height;
}

/// Cheap necessary conditions: for a height target, one continuation to every actuator's upper bound, and a
/// target below the lowest height met on it is reported as unreachable; for target values, their
/// equilibrium reached straight from the start must be valid. Empty when the goal may be reachable.
std::string reachability(const EquilibriumOracle& oracle, const PlanRequest& r, const std::vector<double>& upper)
{
  if (!r.target_values.empty())
  {
    // the target's own equilibrium, by continuation straight from the start
    const Equilibrium goal = oracle.at(r.target_values);
    std::string why;
    if (!goal.converged || oracle.valid(goal, &why))
      return "";
    return "the equilibrium at the target values (by continuation straight from the start) is not valid: " + why +
           " (set reachability_check off to search anyway)";
  }
  double lowest = oracle.start().height;
  Equilibrium end;
  const bool done = oracle.follow(oracle.start(), upper, end, false,
                                  [&lowest](const Equilibrium& e) { lowest = std::min(lowest, e.height); });
  if (!done || r.target_height >= lowest)
    return "";
  std::ostringstream msg;
  msg << "target_height " << core::shortestNumber(r.target_height)
      << " m is below the lowest height met when every actuator is pulled to its upper bound ("
      << core::shortestNumber(lowest) << " m, by continuation from the start): taken as unreachable "
      << "(a structure that folds as its cables are pulled in goes no lower; set reachability_check off to search "
         "anyway)";
  return msg.str();
}

/// Greedy deterministic shortcutting: from each kept waypoint, the farthest one reachable in one valid edge.
/// Once `stop` fires the remaining waypoints are kept as they are.
std::vector<Values> shortcut(const ob::SpaceInformationPtr& si, const std::vector<Values>& raw, RequestClock& clock)
{
  const ob::StateSpacePtr& space = si->getStateSpace();
  std::vector<Values> simple = { raw.front() };
  for (size_t i = 0; i + 1 < raw.size();)
  {
    size_t j = raw.size() - 1;
    for (; j > i + 1 && !clock.stop(); --j)
    {
      ob::ScopedState<> a(space), b(space);
      setStateValues(a.get(), raw[i]);
      setStateValues(b.get(), raw[j]);
      if (si->checkMotion(a.get(), b.get()))
        break;
    }
    if (clock.stop())
      j = i + 1;
    simple.push_back(raw[j]);
    i = j;
  }
  return simple;
}

/// One search from the oracle's start: the OMPL problem, its sampler and goal seeded by `seed`, solved within the
/// clock. `raw` is the solution path (`solved`), or, when the clock stopped a search without an exact one, the path
/// to the valid equilibrium nearest the goal reached from the request's start through valid equilibria (the
/// oracle's best, which the progress reports) when that is nearer the goal than the oracle's start and than the end
/// of the planner's approximate path; empty when there is none.
struct Search
{
  ob::PlannerStatus status;
  ob::SpaceInformationPtr si;
  bool solved = false;
  std::vector<Values> raw;
};

Search searchOnce(const EquilibriumOracle& oracle, const PlanRequest& r, const ob::RealVectorBounds& bounds,
                  double extent, unsigned seed, RequestClock& clock)
{
  const size_t n = bounds.low.size();
  auto space = std::make_shared<ob::RealVectorStateSpace>(static_cast<unsigned>(n));
  space->setBounds(bounds);
  if (n <= 2)
  {
    // OMPL 1.5's default projection below three dimensions (the identity) copies as many values as its byte
    // count and fails Eigen's size check, which aborts the process: the planners that project (KPIECE1,
    // BKPIECE1, LBKPIECE1, SBL ...) get an orthogonal projection on every value instead, its cells a tenth of
    // each range (OMPL's default), set explicitly so that the space's setup keeps it
    std::vector<unsigned> components(n);
    std::vector<double> cells(n);
    for (size_t i = 0; i < n; ++i)
    {
      components[i] = static_cast<unsigned>(i);
      cells[i] = std::max(0.1 * (bounds.high[i] - bounds.low[i]), 1e-9);
    }
    space->registerDefaultProjection(
        std::make_shared<ob::RealVectorOrthogonalProjectionEvaluator>(space, cells, components));
  }
  space->setStateSamplerAllocator([seed](const ob::StateSpace* sp)
                                  { return std::make_shared<SeededSampler>(sp, seed); });
  auto si = std::make_shared<ob::SpaceInformation>(space);
  si->setStateValidityChecker(std::make_shared<EquilibriumChecker>(si, oracle, n));
  si->setMotionValidator(std::make_shared<ContinuationValidator>(si, oracle, n));
  si->setup();

  auto pdef = std::make_shared<ob::ProblemDefinition>(si);
  ob::ScopedState<> s0(space);
  setStateValues(s0.get(), oracle.values(oracle.start().state));
  pdef->addStartState(s0);
  if (r.target_values.empty())
    pdef->setGoal(std::make_shared<HeightGoal>(si, oracle, n, r.target_height, seed));
  else
  {
    auto goal = std::make_shared<ob::GoalState>(si);
    ob::ScopedState<> g(space);
    setStateValues(g.get(), r.target_values);
    goal->setState(g);
    pdef->setGoal(goal);
  }
  auto objective = std::make_shared<ob::MultiOptimizationObjective>(si);
  objective->addObjective(std::make_shared<ob::PathLengthOptimizationObjective>(si), 1.0);
  objective->addObjective(std::make_shared<ob::MaximizeMinClearanceObjective>(si), 0.1);
  pdef->setOptimizationObjective(objective);

  ob::PlannerPtr planner = planners().at(r.planner)(si);
  const double range = r.range > 0.0 ? r.range : 0.2 * extent;
  if (auto rrtc = std::dynamic_pointer_cast<og::RRTConnect>(planner))
  {
    rrtc->setRange(range);
    rrtc->setNearestNeighbors<ompl::NearestNeighborsLinear>();  // deterministic
  }
  else if (auto rrt = std::dynamic_pointer_cast<og::RRT>(planner))
  {
    rrt->setRange(range);
    rrt->setNearestNeighbors<ompl::NearestNeighborsLinear>();
  }
  planner->setProblemDefinition(pdef);  // solve() runs setup()
  clock.phase("search");
  const ob::PlannerStatus status = planner->solve(ob::PlannerTerminationCondition([&clock] { return clock.stop(); }));
  Search out;
  out.status = status;
  out.si = si;
  if (pdef->hasSolution())
  {
    out.solved = true;
    auto path = pdef->getSolutionPath()->as<og::PathGeometric>();
    for (size_t k = 0; k < path->getStateCount(); ++k)
      out.raw.push_back(stateValues(path->getState(k), n));
  }
  if (clock.out() && !(out.solved && pdef->hasExactSolution()))
  {
    // stopped without reaching the goal: the best the request has, the oracle's best path (what the progress
    // reported), unless the planner's own approximate path ends nearer the goal
    const auto distance = goalDistance(oracle, r);
    double have = distance(oracle.start());
    Equilibrium e;
    if (out.solved && !out.raw.empty() && oracle.known(out.raw.back(), e) && oracle.valid(e))
      have = std::min(have, distance(e));
    if (oracle.bestDistance() < have)
    {
      out.raw = oracle.bestPath();
      out.solved = false;
    }
  }
  return out;
}

/// Follows the path from the start through every waypoint (the path the trajectory drives); fills the
/// figures along it, the waypoints reached and the status; `cut` says where the path stopped being valid (untouched
/// when it did not; waypoints numbered from `offset`, the waypoints before this path's start). Returns the last
/// equilibrium reached.
Equilibrium followFromStart(const EquilibriumOracle& oracle, const PlanRequest& r, const std::vector<Values>& simple,
                            RequestClock& clock, PlanResult& out, std::string& cut, size_t offset = 0)
{
  Equilibrium e = oracle.start();
  out.waypoints = { simple.front() };
  // the figures of a segment count once it is followed to its end: a trajectory cut at the last valid
  // waypoint reports the gap and force along what it drives, not along the segment that failed
  double segment_gap = INFINITY;
  double segment_force = 0.0;
  const auto visit = [&segment_gap, &segment_force](const Equilibrium& q)
  {
    segment_gap = std::min(segment_gap, q.min_gap);
    segment_force = std::max(segment_force, q.max_contact);
  };
  const auto keep = [&]()
  {
    out.min_gap = std::min(out.min_gap, segment_gap);
    out.peak_contact_force = std::max(out.peak_contact_force, segment_force);
    segment_gap = INFINITY;
    segment_force = 0.0;
  };
  visit(e);
  keep();
  std::string why;
  for (size_t k = 1; k < simple.size(); ++k)
  {
    Equilibrium end;
    if (!oracle.follow(e, simple[k], end, true, visit))
    {
      oracle.valid(end, &why);
      cut = "stopped being valid before waypoint " + std::to_string(k + offset) + " (" + why + ")";
      out.message = (clock.stop() ? "following the path from the start was stopped by the time limit before waypoint " :
                                    "followed from the start, the path stops being valid before waypoint ") +
                    std::to_string(k + offset) + " (" + why + "); the trajectory ends at the last valid waypoint";
      break;
    }
    keep();
    e = end;
    out.waypoints.push_back(simple[k]);
  }
  out.final_height = e.height;
  const bool followed = out.waypoints.size() == simple.size();
  if (meetsGoal(oracle, r, e))
  {
    out.status = PlanStatus::kExactSolution;
    out.message = "exact solution";
  }
  else
  {
    out.status = PlanStatus::kApproximateSolution;
    if (followed)
    {
      std::ostringstream msg;
      if (r.target_values.empty())
        msg << "approximate: followed from the start, the path ends at height " << e.height << " m, above the target "
            << r.target_height << " m";
      else
        msg << "approximate: followed from the start, the path ends at "
            << actuationDistance(oracle.values(e.state), r.target_values) << " m from the target values";
      out.message = msg.str();
    }
  }
  return e;
}

void setTrajectory(const Trajectory& t, PlanResult& out)
{
  out.times = t.times;
  out.positions = t.positions;
  out.velocities = t.velocities;
  out.accelerations = t.accelerations;
  out.duration = t.duration;
}

/// Corners blended within r.blend_tolerance: the blended curve followed from the start by continuation; a
/// corner whose arc fails is tightened (halved three times, then passed at rest) and the curve checked
/// again. On success the trajectory is the time-optimal one along the curve and the figures are the
/// curve's; otherwise (out of time, a curve that ends elsewhere) the rest-to-rest one stays, with a note.
void blend(const EquilibriumOracle& oracle, const PlanRequest& r, RequestClock& clock, PlanResult& out)
{
  std::vector<double> d = blendLengths(out.waypoints, r.blend_tolerance);
  std::vector<int> tightened(d.size(), 0);
  for (size_t attempt = 0; attempt <= 4 * d.size(); ++attempt)
  {
    std::vector<int> corner;
    const std::vector<Values> curve = blendedCurve(out.waypoints, d, oracle.step(), &corner);
    double min_gap = oracle.start().min_gap, peak = oracle.start().max_contact;
    const auto visit = [&](const Equilibrium& q)
    {
      min_gap = std::min(min_gap, q.min_gap);
      peak = std::max(peak, q.max_contact);
    };
    Equilibrium e = oracle.start();
    size_t k = 1;
    for (; k < curve.size(); ++k)
    {
      Equilibrium end;
      if (!oracle.follow(e, curve[k], end, true, visit))
        break;
      e = end;
    }
    if (k == curve.size())
    {
      if (!meetsGoal(oracle, r, e) && out.status == PlanStatus::kExactSolution)
        break;  // the blended curve ends on another branch
      setTrajectory(timeOptimal(out.waypoints, d, r.max_speeds, r.max_accelerations, r.sample_dt), out);
      out.min_gap = min_gap;
      out.peak_contact_force = peak;
      out.final_height = e.height;
      const long tight = std::count_if(tightened.begin(), tightened.end(), [](int t) { return t > 0; });
      if (tight > 0)
        out.message += "; " + std::to_string(tight) + " of " + std::to_string(out.waypoints.size() - 2) +
                       " corners blended tighter than blend_tolerance (" +
                       std::to_string(std::count(d.begin(), d.end(), 0.0) - 2) + " passed at rest) to keep the limits";
      return;
    }
    const int c = corner[k];
    if (clock.stop() || c < 0)
      break;
    d[c] = ++tightened[c] <= 3 ? 0.5 * d[c] : 0.0;
  }
  out.message += "; corners not blended (the blended path could not be checked within the limits and the time)";
}

/// The dynamic verification (and the speed-limit search) of out's trajectory, run after `stop` from `start` under
/// `law`; scales out's trajectory in place (not the stop).
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
}  // namespace

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
