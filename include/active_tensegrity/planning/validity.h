/// The OMPL adapters of the folding planner (docs/planning.md, "The problem as planned"): a state is valid
/// when its equilibrium (EquilibriumOracle) is within the limits; an edge is valid when continuation from
/// the equilibrium at its start reaches its end through valid equilibria only. States are OMPL
/// RealVectorStateSpace states of the chosen actuators' values. ROS-free; thread-safe as the oracle is.
#pragma once

#include <utility>
#include <vector>

#include <ompl/base/MotionValidator.h>
#include <ompl/base/SpaceInformation.h>
#include <ompl/base/StateValidityChecker.h>

#include "active_tensegrity/planning/equilibria.h"

namespace active_tensegrity::planning
{
/// The actuation values of a RealVectorStateSpace state (its first n values), and back.
std::vector<double> stateValues(const ompl::base::State* s, size_t n);
void setStateValues(ompl::base::State* s, const std::vector<double>& v);

class EquilibriumChecker : public ompl::base::StateValidityChecker
{
public:
  EquilibriumChecker(const ompl::base::SpaceInformationPtr& si, const EquilibriumOracle& oracle, size_t n);
  bool isValid(const ompl::base::State* s) const override;
  /// the margin to the binding limit (m of gap, or N of contact force over 1e4: a common order); 0 when
  /// there is no equilibrium
  double clearance(const ompl::base::State* s) const override;

private:
  const EquilibriumOracle& oracle_;
  size_t n_;
};

/// An edge is valid when continuation from the equilibrium at its start reaches its end through valid
/// equilibria only (increments <= the oracle's step).
class ContinuationValidator : public ompl::base::MotionValidator
{
public:
  ContinuationValidator(const ompl::base::SpaceInformationPtr& si, const EquilibriumOracle& oracle, size_t n);
  bool checkMotion(const ompl::base::State* s1, const ompl::base::State* s2) const override;
  /// as above; when invalid, `last` (when last.first is given) receives the last valid point of the edge
  /// and its fraction of the edge (the start, 0, when the start itself has no valid equilibrium)
  bool checkMotion(const ompl::base::State* s1, const ompl::base::State* s2,
                   std::pair<ompl::base::State*, double>& last) const override;

private:
  const EquilibriumOracle& oracle_;
  size_t n_;
};

}  // namespace active_tensegrity::planning
