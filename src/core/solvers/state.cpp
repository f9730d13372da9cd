#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
State initialState(const Model& model)
{
  State s;
  s.q = model.q0;
  s.qd.setZero(model.nq);
  s.u.assign(model.actuators.size(), ActuationValue{});
  return s;
}

}  // namespace active_tensegrity::core
