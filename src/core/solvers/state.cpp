#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
State initialState(const Model& model)
{
  State s;
  s.q = model.q0;
  s.qd.setZero(model.nq);
  s.qdd.setZero(model.nq);
  s.acc.setZero(model.nq);
  s.lambda.setZero(model.n_lambda);
  s.u.assign(model.actuators.size(), ActuationValue{});
  s.contact_speed.reset(model.contactSlots(), 0.0);
  return s;
}

}  // namespace active_tensegrity::core
