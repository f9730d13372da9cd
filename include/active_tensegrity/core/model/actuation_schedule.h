/// The scene's own actuation law (analysis.schedule's ramp, or actuation.sequence's ramps), as dynamic runs and
/// the node follow it.
#pragma once

#include <vector>

#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
/// The scene's actuation law of a dynamic run at time t, one value per actuator: every actuator on
/// analysis.schedule's ramp to max_actuation, or each on its own ramps of actuation.sequence.
ActuationValues scheduledActuation(const Model& model, double t);
/// The same into `out` (resized to the actuators; no allocation once it has that size).
void scheduledActuation(const Model& model, double t, ActuationValues& out);
/// When the last ramp of that law ends (s).
double actuationEndTime(const Model& model);
/// Where that law is not smooth (s, ascending, distinct): an adaptive run steps onto them.
std::vector<double> actuationBreakpoints(const Model& model);

}  // namespace active_tensegrity::core
