#include "active_tensegrity/planning/folding_planner.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <sstream>

#include <ompl/base/MotionValidator.h>
#include <ompl/base/PlannerTerminationCondition.h>
#include <ompl/base/ProblemDefinition.h>
#include <ompl/base/SpaceInformation.h>
#include <ompl/base/StateSampler.h>
#include <ompl/base/StateValidityChecker.h>
#include <ompl/base/goals/GoalSampleableRegion.h>
#include <ompl/base/goals/GoalState.h>
#include <ompl/base/objectives/MaximizeMinClearanceObjective.h>
#include <ompl/base/objectives/PathLengthOptimizationObjective.h>
#include <ompl/base/spaces/RealVectorStateSpace.h>
#include <ompl/datastructures/NearestNeighborsLinear.h>
#include <ompl/geometric/PathGeometric.h>
#include <ompl/geometric/planners/est/BiEST.h>
#include <ompl/geometric/planners/est/EST.h>
#include <ompl/geometric/planners/fmt/BFMT.h>
#include <ompl/geometric/planners/fmt/FMT.h>
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

#include "active_tensegrity/core/actuation_control.h"
#include "active_tensegrity/core/analysis.h"
#include "active_tensegrity/core/contact.h"
#include "active_tensegrity/core/dynamics.h"
#include "active_tensegrity/core/statics.h"
#include "active_tensegrity/core/text.h"

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
    { "FMT", make<og::FMT>() },
    { "BFMT", make<og::BFMT>() },
    { "BITstar", make<og::BITstar>() },
  };
  return m;
}

Values valuesOf(const ob::State* s, size_t n)
{
  const auto* r = s->as<ob::RealVectorStateSpace::StateType>();
  return Values(r->values, r->values + n);
}

void setValues(ob::State* s, const Values& v)
{
  auto* r = s->as<ob::RealVectorStateSpace::StateType>();
  std::copy(v.begin(), v.end(), r->values);
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

class EquilibriumChecker : public ob::StateValidityChecker
{
public:
  EquilibriumChecker(const ob::SpaceInformationPtr& si, const EquilibriumOracle& oracle, size_t n)
    : ob::StateValidityChecker(si), oracle_(oracle), n_(n)
  {
  }
  bool isValid(const ob::State* s) const override
  {
    return oracle_.valid(oracle_.at(valuesOf(s, n_)));
  }
  /// the margin to the binding limit (m of gap, or N of contact force over 1e4: a common order)
  double clearance(const ob::State* s) const override
  {
    const Equilibrium e = oracle_.at(valuesOf(s, n_));
    if (!e.converged)
      return 0.0;
    const ValidityLimits& l = oracle_.limits();
    return l.allow_contact ? std::max(0.0, (l.max_contact_force - e.max_contact) * 1e-4) :
                             std::max(0.0, e.min_gap - l.min_clearance);
  }

private:
  const EquilibriumOracle& oracle_;
  size_t n_;
};

/// An edge is valid when continuation from the equilibrium at its start reaches its end through
/// valid equilibria only (increments <= the oracle's step).
class ContinuationValidator : public ob::MotionValidator
{
public:
  ContinuationValidator(const ob::SpaceInformationPtr& si, const EquilibriumOracle& oracle, size_t n)
    : ob::MotionValidator(si), oracle_(oracle), n_(n)
  {
  }
  bool checkMotion(const ob::State* s1, const ob::State* s2) const override
  {
    const Equilibrium from = oracle_.at(valuesOf(s1, n_));
    if (!oracle_.valid(from))
      return false;
    Equilibrium end;
    return oracle_.follow(from, valuesOf(s2, n_), end, true);
  }
  bool checkMotion(const ob::State* s1, const ob::State* s2, std::pair<ob::State*, double>& last) const override
  {
    const Values a = valuesOf(s1, n_), b = valuesOf(s2, n_);
    const Equilibrium from = oracle_.at(a);
    Equilibrium end;
    const bool ok = oracle_.valid(from) && oracle_.follow(from, b, end, true);
    if (!ok && last.first)
    {
      // the last valid point: the equilibrium before the failed increment, as a fraction of the edge
      const double total = actuationDistance(a, b);
      const double reached = actuationDistance(a, oracle_.values(end.state));
      const double frac =
          total > 0.0 ? std::max(0.0, (oracle_.valid(end) ? reached : reached - oracle_.step()) / total) : 0.0;
      Values v(a.size());
      for (size_t i = 0; i < a.size(); ++i)
        v[i] = a[i] + frac * (b[i] - a[i]);
      setValues(last.first, v);
      last.second = frac;
    }
    return ok;
  }

private:
  const EquilibriumOracle& oracle_;
  size_t n_;
};

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
    const Equilibrium e = oracle_.at(valuesOf(s, n_));
    return e.converged ? std::max(0.0, e.height - target_) : std::numeric_limits<double>::infinity();
  }
  bool isSatisfied(const ob::State* s) const override
  {
    const Equilibrium e = oracle_.at(valuesOf(s, n_));
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
      if (oracle_.at(point(1.0)).height > target_)
        continue;  // not even at the upper bounds
      double f0 = 0.0, f1 = 1.0;
      if (oracle_.at(point(0.0)).height > target_)
        for (int k = 0; k < 8; ++k)
        {
          const double f = 0.5 * (f0 + f1);
          (oracle_.at(point(f)).height <= target_ ? f1 : f0) = f;
        }
      else
        f1 = 0.0;
      const Values v = point(f1);
      if (oracle_.valid(oracle_.at(v)))
      {
        setValues(st, v);
        return;
      }
    }
    setValues(st, Values(b.high.begin(), b.high.end()));
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
      if (!std::isfinite(r.target_values[k]) || r.target_values[k] < a.min_value || r.target_values[k] > a.max_value)
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
         std::make_tuple(r.settle_time, "settle_time", false), std::make_tuple(r.range, "range", false) })
    if (!(err = nonneg(x, what, inf)).empty())
      return err;
  for (const auto& [x, what] :
       { std::make_pair(r.time_limit, "time_limit"), std::make_pair(r.continuation_step, "continuation_step"),
         std::make_pair(r.sample_dt, "sample_dt") })
    if (!std::isfinite(x) || x <= 0.0)
    {
      msg << what << " must be finite and > 0, got " << x;
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

double perActuator(const std::vector<double>& v, size_t i)
{
  return v.size() == 1 ? v[0] : v[i];
}

/// Rest to rest along each straight segment, all actuators together: the path parameter follows the
/// time-optimal trapezoid under the tightest of the actuators' limits.
void timeParameterize(const std::vector<Values>& waypoints, const PlanRequest& r, PlanResult& out)
{
  const size_t n = waypoints.front().size();
  out.times = { 0.0 };
  out.positions = { waypoints.front() };
  out.velocities = { Values(n, 0.0) };
  out.accelerations = { Values(n, 0.0) };
  double t0 = 0.0;
  for (size_t w = 0; w + 1 < waypoints.size(); ++w)
  {
    const Values& a = waypoints[w];
    const Values& b = waypoints[w + 1];
    double vs = INFINITY, as = INFINITY;
    for (size_t i = 0; i < n; ++i)
    {
      const double d = std::abs(b[i] - a[i]);
      if (d > 0.0)
      {
        vs = std::min(vs, perActuator(r.max_speeds, i) / d);
        as = std::min(as, perActuator(r.max_accelerations, i) / d);
      }
    }
    if (!std::isfinite(vs))
      continue;  // a repeated waypoint
    core::ActuationValue rest;
    const core::ActuatorMotion s = core::ActuatorMotion::ramp(0.0, rest, 1.0, vs, as);
    const double T = s.endTime();
    const int samples = std::max(2, static_cast<int>(std::ceil(T / r.sample_dt)));
    for (int k = 1; k <= samples; ++k)
    {
      const double t = T * k / samples;
      const core::ActuationValue p = s.evaluate(t);
      Values pos(n), vel(n), acc(n);
      for (size_t i = 0; i < n; ++i)
      {
        const double d = b[i] - a[i];
        pos[i] = k == samples ? b[i] : a[i] + p.value * d;
        vel[i] = k == samples ? 0.0 : p.rate * d;
        acc[i] = p.accel * d;
      }
      out.times.push_back(t0 + t);
      out.positions.push_back(pos);
      out.velocities.push_back(vel);
      out.accelerations.push_back(acc);
    }
    t0 += T;
  }
  out.duration = t0;
}

struct DynamicPeaks
{
  bool ok = false;  // the simulation ran to the end
  std::string message;
  double contact = 0.0, bending = 0.0;
};

DynamicPeaks simulate(const core::Model& model, const core::State& start, const std::vector<std::string>& names,
                      const PlanResult& plan, double scale, double settle)
{
  DynamicPeaks peaks;
  core::Model dyn = model;
  dyn.analysis.type = core::AnalysisType::kDynamic;
  core::State s = start;
  s.t = 0.0;
  s.qd.setZero(dyn.nq);
  core::ActuationController control(dyn, s.u);
  std::vector<double> times;
  std::vector<Values> vel;
  for (size_t k = 0; k < plan.times.size(); ++k)
  {
    times.push_back(plan.times[k] * scale);
    Values v = plan.velocities[k];
    for (double& x : v)
      x /= scale;
    vel.push_back(v);
  }
  const std::string err = control.setTrajectory(0.0, names, times, plan.positions, vel);
  if (!err.empty())
  {
    peaks.message = "trajectory refused: " + err;
    return peaks;
  }
  core::DynamicsSolver solver(dyn, dyn.solver);
  const core::ActuationLaw law = [&control](double t) { return control.values(t); };
  core::Summary sum = solver.initialize(s, law);
  const double dt = dyn.solver.dt;
  const long steps = std::lround(std::ceil((times.back() + settle) / dt));
  for (long k = 1; k <= steps && sum.ok(); ++k)
  {
    sum = solver.step(s, k * dt - s.t, law);
    if (!sum.ok())
      break;
    s.t = k * dt;
    const std::vector<core::ContactPairState> contacts = core::activeContacts(dyn, s);
    for (const core::ContactPairState& c : contacts)
      peaks.contact = std::max(peaks.contact, c.normal_force);
    if (!contacts.empty())
      peaks.bending = std::max(peaks.bending, core::maxStrutBendingStress(dyn, s.q, contacts));
  }
  peaks.ok = sum.ok();
  peaks.message = sum.message;
  return peaks;
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

std::string startEquilibrium(const core::Model& model, const core::State& state, core::State& start)
{
  start = state;
  for (core::ActuationValue& u : start.u)
    u.rate = u.accel = 0.0;
  start.qd.setZero();
  core::Model statics = model;
  statics.analysis.type = core::AnalysisType::kStatic;
  core::StaticSolver solver(statics, statics.solver);
  const core::Summary eq = solver.relax(start, start.u);
  return eq.ok() ? std::string() : "no quasi-static equilibrium at the current actuation: " + eq.message;
}

PlanResult planFolding(const core::Model& model, const core::State& start, const PlanRequest& r,
                       const PlanControl& control)
{
  PlanResult out;
  std::vector<int> idx;
  out.message = checkRequest(model, r, idx);
  if (!out.message.empty())
  {
    out.status = PlanStatus::kInvalidRequest;
    return out;
  }
  out.names = r.actuators;
  const size_t n = idx.size();
  const auto wall0 = std::chrono::steady_clock::now();
  ompl::msg::setLogLevel(ompl::msg::LOG_WARN);

  EquilibriumOracle oracle(model, idx, start, r.limits, r.continuation_step);
  std::string why;
  if (!oracle.valid(oracle.start(), &why))
  {
    out.status = PlanStatus::kInvalidStart;
    out.message = "the start is not valid: " + why;
    return out;
  }

  auto space = std::make_shared<ob::RealVectorStateSpace>(static_cast<unsigned>(n));
  ob::RealVectorBounds bounds(static_cast<unsigned>(n));
  double extent = 0.0;
  for (size_t i = 0; i < n; ++i)
  {
    bounds.setLow(i, model.actuators[idx[i]].min_value);
    bounds.setHigh(i, model.actuators[idx[i]].max_value);
    extent = std::max(extent, model.actuators[idx[i]].max_value - model.actuators[idx[i]].min_value);
  }
  space->setBounds(bounds);
  const unsigned seed = r.seed;
  space->setStateSamplerAllocator([seed](const ob::StateSpace* sp)
                                  { return std::make_shared<SeededSampler>(sp, seed); });
  auto si = std::make_shared<ob::SpaceInformation>(space);
  si->setStateValidityChecker(std::make_shared<EquilibriumChecker>(si, oracle, n));
  si->setMotionValidator(std::make_shared<ContinuationValidator>(si, oracle, n));
  si->setup();

  auto pdef = std::make_shared<ob::ProblemDefinition>(si);
  ob::ScopedState<> s0(space);
  setValues(s0.get(), oracle.values(start));
  pdef->addStartState(s0);
  if (r.target_values.empty())
    pdef->setGoal(std::make_shared<HeightGoal>(si, oracle, n, r.target_height, r.seed));
  else
  {
    auto goal = std::make_shared<ob::GoalState>(si);
    ob::ScopedState<> g(space);
    setValues(g.get(), r.target_values);
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
  // the time limit as OMPL's timed condition, remembering whether it fired (it stays true once it has)
  std::atomic<bool> time_limit_reached{ false };
  const ob::PlannerTerminationCondition timed = ob::timedPlannerTerminationCondition(r.time_limit);
  const ob::PlannerTerminationCondition ptc(
      [&timed, &time_limit_reached, &control]
      {
        if (!time_limit_reached && timed())
          time_limit_reached = true;
        return time_limit_reached.load() || (control.cancelled && control.cancelled());
      });
  const ob::PlannerStatus status = planner->solve(ptc);
  out.stopped_by_time_limit = time_limit_reached;
  out.status = static_cast<PlanStatus>(static_cast<int>(ob::PlannerStatus::StatusType(status)));
  if (!pdef->hasSolution())
  {
    out.message = std::string("no path: ") + status.asString();
    out.equilibrium_solves = oracle.solves();
    out.planning_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    return out;
  }

  // deterministic shortcutting: from each kept waypoint, the farthest one reachable in one valid edge
  auto path = pdef->getSolutionPath()->as<og::PathGeometric>();
  std::vector<Values> raw;
  for (size_t k = 0; k < path->getStateCount(); ++k)
    raw.push_back(valuesOf(path->getState(k), n));
  std::vector<Values> simple = { raw.front() };
  for (size_t i = 0; i + 1 < raw.size();)
  {
    size_t j = raw.size() - 1;
    for (; j > i + 1; --j)
    {
      ob::ScopedState<> a(space), b(space);
      setValues(a.get(), raw[i]);
      setValues(b.get(), raw[j]);
      if (si->checkMotion(a.get(), b.get()))
        break;
    }
    simple.push_back(raw[j]);
    i = j;
  }

  // the path as it will be followed: continuation from the start through every waypoint
  Equilibrium e = oracle.start();
  out.waypoints = { simple.front() };
  const auto visit = [&out](const Equilibrium& q)
  {
    out.min_gap = std::min(out.min_gap, q.min_gap);
    out.peak_contact_force = std::max(out.peak_contact_force, q.max_contact);
  };
  visit(e);
  bool followed = true;
  for (size_t k = 1; k < simple.size(); ++k)
  {
    Equilibrium end;
    if (!oracle.follow(e, simple[k], end, true, visit))
    {
      oracle.valid(end, &why);
      out.message = "followed from the start, the path stops being valid before waypoint " + std::to_string(k) + " (" +
                    why + "); the trajectory ends at the last valid waypoint";
      followed = false;
      break;
    }
    e = end;
    out.waypoints.push_back(simple[k]);
  }
  out.final_height = e.height;
  // the goal as reached by following the path from the start (equilibria depend on the path: a goal
  // state's equilibrium found from elsewhere may lie on another branch)
  bool reached = true;
  if (followed && r.target_values.empty() && e.height > r.target_height)
  {
    reached = false;
    std::ostringstream msg;
    msg << "followed from the start, the path ends at height " << e.height << " m, above the target " << r.target_height
        << " m (the goal state's equilibrium was found on another branch)";
    out.message = msg.str();
  }
  if (!followed || !reached)
    out.status = PlanStatus::kApproximateSolution;
  else if (out.status == PlanStatus::kExactSolution)
    out.message = "exact solution";
  else
    out.message = std::string(status.asString()) + " (the goal is not reached)";
  timeParameterize(out.waypoints, r, out);
  out.planning_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();

  if (r.verify_dynamics || r.find_speed_limit)
  {
    const auto within = [&](const DynamicPeaks& p)
    {
      const double force_limit = r.limits.allow_contact ? r.limits.max_contact_force : 0.0;
      return p.ok && p.contact <= force_limit && p.bending <= r.max_bending_stress;
    };
    const auto run = [&](double scale)
    {
      ++out.dynamic_runs;
      return simulate(model, start, r.actuators, out, scale, r.settle_time);
    };
    double scale = 1.0;
    DynamicPeaks peaks = run(scale);
    if (r.find_speed_limit && !within(peaks))
    {
      // double the time scale until within, then bisect (geometric) to the tolerance
      double lo = 1.0, hi = 2.0;
      DynamicPeaks at_hi = run(hi);
      while (!within(at_hi) && hi < 64.0)
      {
        lo = hi;
        hi *= 2.0;
        at_hi = run(hi);
      }
      if (within(at_hi))
        while (hi / lo > 1.0 + r.speed_limit_tolerance)
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
    }
    out.dynamics_verified = peaks.ok;
    out.dynamics_within_limits = within(peaks);
    out.dynamic_peak_contact_force = peaks.contact;
    out.dynamic_peak_bending_stress = peaks.bending;
    out.time_scale = scale;
    if (!peaks.ok)
      out.message += "; dynamic verification failed: " + peaks.message;
    if (scale != 1.0)
    {
      for (size_t k = 0; k < out.times.size(); ++k)
      {
        out.times[k] *= scale;
        for (size_t i = 0; i < n; ++i)
        {
          out.velocities[k][i] /= scale;
          out.accelerations[k][i] /= scale * scale;
        }
      }
      out.duration *= scale;
    }
  }
  out.equilibrium_solves = oracle.solves();
  return out;
}

}  // namespace active_tensegrity::planning
