/// A state of the body coordinates' solvers (BodyDynamicsSolver, BodyStaticSolver, BodyAdaptiveStepper): the core's
/// State and what these solvers keep beside it.
#pragma once

#include <Eigen/Core>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/oracle/slot_values.h"

namespace active_tensegrity::core
{
struct BodyState : State
{
  BodyState() = default;
  /// s's poses, rates and actuation, with the accelerations, multipliers and contact memory zero (of a model's size
  /// once a solver or bodyInitialState sets them).
  explicit BodyState(const State& s) : State(s) {}

  Eigen::VectorXd qdd;     // accelerations of q
  Eigen::VectorXd acc;     // generalized-alpha's pseudo-accelerations (qdd with Newmark)
  Eigen::VectorXd lambda;  // multipliers of the model's constraints, then of any the solver adds (spin locks)
  /// Per contact slot (strut pairs, then ground contacts): the impact speed v_0 (m/s) of a live contact, 0 when apart.
  SlotValues contact_speed;
  double contactSpeed(int slot) const
  {
    return slot < contact_speed.size() ? contact_speed[slot] : 0.0;
  }
};

/// The force actuator `actuator` exerts at s (N): each driven point's multiplier (the constraint force on a body is
/// -Phi_q^T lambda, so each target contributes -lambda) plus the tension of each cable it pulls in.
double bodyActuationForce(const Model& model, const BodyState& s, int actuator);

/// At rest in the model's initial configuration (initialState), accelerations, multipliers and contact memory zero.
inline BodyState bodyInitialState(const Model& model)
{
  BodyState s(initialState(model));
  s.qdd.setZero(model.nq);
  s.acc.setZero(model.nq);
  s.lambda.setZero(model.n_lambda);
  s.contact_speed.reset(model.contactSlots(), 0.0);
  return s;
}

}  // namespace active_tensegrity::core
