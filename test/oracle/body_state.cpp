#include "active_tensegrity/oracle/body_state.h"

#include "active_tensegrity/core/outputs/observables.h"

namespace active_tensegrity::core
{
double bodyActuationForce(const Model& model, const BodyState& s, int actuator)
{
  double force = 0.0;
  for (int c : model.actuators[actuator].constraints)
  {
    int row = 0;  // (a few constraints per actuator: summed here rather than kept in a table)
    for (int i = 0; i < c; ++i)
      row += model.constraints[i].rows();
    force -= s.lambda(row);
  }
  // the cables it pulls in: observables.h's force at a state without natural coordinates
  State poses = s;
  poses.natural = NaturalState();
  return force + actuationForce(model, poses, actuator);
}

}  // namespace active_tensegrity::core
