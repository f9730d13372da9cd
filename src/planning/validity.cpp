#include "active_tensegrity/planning/validity.h"

#include <algorithm>

#include <ompl/base/spaces/RealVectorStateSpace.h>

namespace active_tensegrity::planning
{
namespace ob = ompl::base;

std::vector<double> stateValues(const ob::State* s, size_t n)
{
  const auto* r = s->as<ob::RealVectorStateSpace::StateType>();
  return std::vector<double>(r->values, r->values + n);
}

void setStateValues(ob::State* s, const std::vector<double>& v)
{
  auto* r = s->as<ob::RealVectorStateSpace::StateType>();
  std::copy(v.begin(), v.end(), r->values);
}

EquilibriumChecker::EquilibriumChecker(const ob::SpaceInformationPtr& si, const EquilibriumOracle& oracle, size_t n)
  : ob::StateValidityChecker(si), oracle_(oracle), n_(n)
{
}

bool EquilibriumChecker::isValid(const ob::State* s) const
{
  return oracle_.valid(oracle_.at(stateValues(s, n_)));
}

double EquilibriumChecker::clearance(const ob::State* s) const
{
  const Equilibrium e = oracle_.at(stateValues(s, n_));
  if (!e.converged)
    return 0.0;
  const ValidityLimits& l = oracle_.limits();
  return l.allow_contact ? std::max(0.0, (l.max_contact_force - e.max_contact) * 1e-4) :
                           std::max(0.0, e.min_gap - l.min_clearance);
}

ContinuationValidator::ContinuationValidator(const ob::SpaceInformationPtr& si, const EquilibriumOracle& oracle,
                                             size_t n)
  : ob::MotionValidator(si), oracle_(oracle), n_(n)
{
}

bool ContinuationValidator::checkMotion(const ob::State* s1, const ob::State* s2) const
{
  const Equilibrium from = oracle_.at(stateValues(s1, n_));
  if (!oracle_.valid(from))
    return false;
  Equilibrium end;
  return oracle_.follow(from, stateValues(s2, n_), end, true);
}

bool ContinuationValidator::checkMotion(const ob::State* s1, const ob::State* s2,
                                        std::pair<ob::State*, double>& last) const
{
  const std::vector<double> a = stateValues(s1, n_), b = stateValues(s2, n_);
  const Equilibrium from = oracle_.at(a);
  if (!oracle_.valid(from))
  {
    // no valid equilibrium at the start (none found, or the request stopped): nothing of the edge is valid
    if (last.first)
    {
      setStateValues(last.first, a);
      last.second = 0.0;
    }
    return false;
  }
  Equilibrium end;
  const bool ok = oracle_.follow(from, b, end, true);
  if (!ok && last.first)
  {
    // the last valid point: the equilibrium before the failed increment, as a fraction of the edge
    const double total = actuationDistance(a, b);
    const double reached = actuationDistance(a, oracle_.values(end.state));
    const double frac =
        total > 0.0 ? std::max(0.0, (oracle_.valid(end) ? reached : reached - oracle_.step()) / total) : 0.0;
    std::vector<double> v(a.size());
    for (size_t i = 0; i < a.size(); ++i)
      v[i] = a[i] + frac * (b[i] - a[i]);
    setStateValues(last.first, v);
    last.second = frac;
  }
  return ok;
}

}  // namespace active_tensegrity::planning
