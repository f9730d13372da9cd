/// The energy of a state in the body coordinates (the oracle's System): what the natural coordinates' energy account
/// is checked against.
#pragma once

#include <vector>

#include "active_tensegrity/oracle/body_state.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/oracle/mechanics.h"

namespace active_tensegrity::core
{
/// The energy of `state` (positions, velocities, multipliers and actuation values at state.t). `contacts`: the
/// active contacts of the state (DynamicsSolver::contactsAt, activeContacts) with their forces; their elastic
/// energy and dissipated power are summed, no other slot is evaluated.
EnergyPoint energyPoint(const System& system, const BodyState& state, const std::vector<ContactPairState>& contacts);

/// energyPoint for a sequence of states (every step of a run): the cables' point slots are found once and the
/// points' motion comes from frames formed once per state (no allocation once sized).
class EnergyMeter
{
public:
  explicit EnergyMeter(const System& system);
  /// energyPoint(system, state, contacts), the same number.
  EnergyPoint at(const BodyState& state, const std::vector<ContactPairState>& contacts);

private:
  const System& system_;
  BodyFrames frames_;
  std::vector<PointSlot> slots_;  // every cable's points, cable by cable
  std::vector<int> first_;        // each cable's first slot
  Eigen::VectorXd rhs_;           // the velocity constraints' right-hand side
};

}  // namespace active_tensegrity::core
