#include "active_tensegrity/planning/equilibria.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "active_tensegrity/core/outputs/observables.h"

namespace active_tensegrity::planning
{
double actuationDistance(const std::vector<double>& a, const std::vector<double>& b)
{
  double d = 0.0;
  for (size_t i = 0; i < a.size() && i < b.size(); ++i)
    d = std::max(d, std::abs(a[i] - b[i]));
  return d;
}

std::vector<std::vector<double>> pathWaypoints(const std::shared_ptr<const PathNode>& path)
{
  std::vector<std::vector<double>> w;
  for (const PathNode* n = path.get(); n; n = n->before.get())
    if (w.empty() || n->values != w.back())  // (a segment of no length: a follow to where it was)
      w.push_back(n->values);
  std::reverse(w.begin(), w.end());
  return w;
}

/// A StaticSolver taken from the pool for one scope (or made when the pool is empty).
class EquilibriumOracle::SolverLease
{
public:
  explicit SolverLease(const EquilibriumOracle& o) : o_(o)
  {
    const std::lock_guard<std::mutex> lock(o_.mutex_);
    if (!o_.pool_.empty())
    {
      solver_ = std::move(o_.pool_.back());
      o_.pool_.pop_back();
    }
    else
      solver_ = std::make_unique<core::StaticSolver>(o_.model_, o_.model_.solver);
  }
  ~SolverLease()
  {
    const std::lock_guard<std::mutex> lock(o_.mutex_);
    o_.pool_.push_back(std::move(solver_));
  }
  SolverLease(const SolverLease&) = delete;
  SolverLease& operator=(const SolverLease&) = delete;
  core::StaticSolver& operator*()
  {
    return *solver_;
  }

private:
  const EquilibriumOracle& o_;
  std::unique_ptr<core::StaticSolver> solver_;
};

EquilibriumOracle::EquilibriumOracle(const core::Model& model, std::vector<int> actuators, const core::State& start,
                                     ValidityLimits limits, double step)
  : model_(model), actuators_(std::move(actuators)), limits_(limits), step_(step)
{
  model_.analysis.type = core::AnalysisType::kStatic;
  core::Summary ok;
  restart(measure(start, ok));
}

EquilibriumOracle::~EquilibriumOracle() = default;

void EquilibriumOracle::restart(const Equilibrium& start)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  start_ = start;
  if (!start_.path)
    start_.path = std::make_shared<const PathNode>(PathNode{ values(start_.state), nullptr });
  cache_.clear();
  cache_.push_back({ start_, values(start_.state), ~0ul });
}

std::vector<double> EquilibriumOracle::values(const core::State& s) const
{
  std::vector<double> v;
  for (int a : actuators_)
    v.push_back(s.u[a].value);
  return v;
}

long EquilibriumOracle::solves() const
{
  const std::lock_guard<std::mutex> lock(mutex_);
  return solves_;
}

size_t EquilibriumOracle::cached() const
{
  const std::lock_guard<std::mutex> lock(mutex_);
  return cache_.size();
}

core::StepTimings EquilibriumOracle::timings() const
{
  const std::lock_guard<std::mutex> lock(mutex_);
  core::StepTimings t;
  for (const std::unique_ptr<core::StaticSolver>& s : pool_)
    t += s->timings();
  return t;
}

double EquilibriumOracle::bestDistance() const
{
  const std::lock_guard<std::mutex> lock(mutex_);
  return best_distance_;
}

double EquilibriumOracle::bestHeight() const
{
  const std::lock_guard<std::mutex> lock(mutex_);
  return best_height_;
}

std::vector<std::vector<double>> EquilibriumOracle::bestPath() const
{
  std::shared_ptr<const PathNode> path;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    path = best_path_;
  }
  return pathWaypoints(path);
}

Equilibrium EquilibriumOracle::measure(const core::State& s, const core::Summary& sum) const
{
  Equilibrium e;
  e.state = s;
  e.converged = sum.ok() && s.q.allFinite();
  e.message = sum.message;
  if (!e.converged)
    return e;
  e.min_gap = core::minimumGap(model_, s.q);
  for (const core::ContactPairState& c : core::activeContacts(model_, s))
    e.max_contact = std::max(e.max_contact, c.normal_force);
  e.max_cable_stress = core::maxCableStress(model_, s);
  e.height = core::structureHeight(model_, s.q);
  return e;
}

bool EquilibriumOracle::valid(const Equilibrium& e, std::string* why) const
{
  std::ostringstream msg;
  if (!e.converged)
    msg << "no equilibrium (" << e.message << ")";
  else if (!limits_.allow_contact && e.min_gap < limits_.min_clearance)
    msg << "gap " << e.min_gap << " m < min_clearance " << limits_.min_clearance << " m";
  else if (limits_.allow_contact && e.max_contact > limits_.max_contact_force)
    msg << "contact force " << e.max_contact << " N > max_contact_force " << limits_.max_contact_force << " N";
  else if (e.max_cable_stress > limits_.max_cable_stress)
    msg << "cable stress " << e.max_cable_stress << " Pa > max_cable_stress " << limits_.max_cable_stress << " Pa";
  else
    return true;
  if (why)
    *why = msg.str();
  return false;
}

void EquilibriumOracle::remember(const Equilibrium& e) const
{
  if (!e.converged)
    return;
  // the best counts only equilibria reached from the start through valid ones: a path to it exists
  const double d = distance_ && e.path && valid(e) ? distance_(e) : std::numeric_limits<double>::infinity();
  std::vector<double> v = values(e.state);
  const std::lock_guard<std::mutex> lock(mutex_);
  if (d < best_distance_)
  {
    best_distance_ = d;
    best_height_ = e.height;
    best_path_ = e.path;
  }
  if (cache_.size() >= kCacheCapacity)
  {
    // drop the least recently used quarter (the start, used at ~0, stays)
    std::vector<unsigned long> used;
    for (const Entry& c : cache_)
      used.push_back(c.used);
    const size_t drop = kCacheCapacity / 4;
    std::nth_element(used.begin(), used.begin() + static_cast<long>(drop), used.end());
    const unsigned long threshold = used[drop];
    cache_.erase(std::remove_if(cache_.begin(), cache_.end(), [&](const Entry& c) { return c.used < threshold; }),
                 cache_.end());
  }
  cache_.push_back({ e, std::move(v), ++clock_ });
}

bool EquilibriumOracle::follow(const Equilibrium& from, const std::vector<double>& u, Equilibrium& end, bool check,
                               const std::function<void(const Equilibrium&)>& visit) const
{
  const std::vector<double> a = values(from.state);
  const int n = std::max(1, static_cast<int>(std::ceil(actuationDistance(a, u) / step_ - 1e-9)));
  SolverLease solver(*this);
  core::State s = from.state;
  end = from;
  // the equilibria of this line are reached from the start through valid ones while `from` was and every
  // increment so far is valid: each is then the end of a straight segment from `from`
  bool connected = from.path != nullptr && valid(from);
  for (int k = 1; k <= n; ++k)
  {
    if (stop_ && stop_())
    {
      end.converged = false;
      end.message = "stopped (the request's time limit, or cancelled)";
      return false;
    }
    core::ActuationValues target = s.u;
    for (size_t i = 0; i < actuators_.size(); ++i)
    {
      target[actuators_[i]].value = k == n ? u[i] : a[i] + (u[i] - a[i]) * k / n;
      target[actuators_[i]].rate = target[actuators_[i]].accel = 0.0;
    }
    const core::Summary sum = (*solver).followPath(s, target, 1, {});
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      ++solves_;
    }
    end = measure(s, sum);
    if (!end.converged)
      return false;
    connected = connected && valid(end);
    if (connected)
      end.path = std::make_shared<const PathNode>(PathNode{ values(end.state), from.path });
    remember(end);
    if (visit)
      visit(end);
    if (check && !valid(end))
      return false;
  }
  return true;
}

bool EquilibriumOracle::known(const std::vector<double>& u, Equilibrium& e) const
{
  const std::lock_guard<std::mutex> lock(mutex_);
  for (const Entry& c : cache_)
    if (c.values == u)
    {
      e = c.equilibrium;
      return true;
    }
  return false;
}

Equilibrium EquilibriumOracle::at(const std::vector<double>& u) const
{
  Equilibrium from;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    double best = INFINITY;
    Entry* nearest = nullptr;
    for (Entry& c : cache_)
    {
      const double d = actuationDistance(c.values, u);
      if (d < best)
      {
        best = d;
        nearest = &c;
      }
    }
    if (nearest->used != ~0ul)
      nearest->used = ++clock_;
    from = nearest->equilibrium;
    if (best == 0.0)
      return from;
  }
  Equilibrium end;
  follow(from, u, end, false);
  return end;
}

}  // namespace active_tensegrity::planning
