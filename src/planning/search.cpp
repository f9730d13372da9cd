// The OMPL search of a folding request: the planners by name, the seeded sampler, the height goal, a search and
// its shortcutting.
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
template <typename P>
Allocator make()
{
  return [](const ob::SpaceInformationPtr& si) { return std::make_shared<P>(si); };
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
}  // namespace

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
}  // namespace active_tensegrity::planning::detail
