#include "active_tensegrity/core/outputs/peaks.h"

#include <algorithm>
#include <cmath>

#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/outputs/observables.h"

namespace active_tensegrity::core
{
PeakTracker::PeakTracker(const Model& model) : model_(model), contacts_(model), cable_stress_(model)
{
  for (const char* name :
       { "actuation_force", "max_normal_force", "max_friction_force", "max_strut_bending_stress", "max_cable_stress" })
    peaks_.push_back({ name, 0.0, 0.0 });
}

void PeakTracker::add(const State& state, const std::vector<ContactPairState>* given)
{
  // the five columns as csvRow computes them, and nothing else of the row (this runs at every step)
  double max_normal = 0.0, max_friction = 0.0;
  const std::vector<ContactPairState>& contacts = given ? *given : contacts_.active(state);
  for (const ContactPairState& c : contacts)
    if (c.body_b >= 0)
    {
      max_normal = std::max(max_normal, c.normal_force);
      max_friction = std::max(max_friction, c.friction_force);
    }
  const double values[] = { model_.actuators.empty() ? 0.0 : actuationForce(model_, state, 0), max_normal, max_friction,
                            maxStrutBendingStress(model_, state.q, contacts), cable_stress_.largest(state) };
  for (size_t k = 0; k < peaks_.size(); ++k)
    if (std::abs(values[k]) > std::abs(peaks_[k].value))
    {
      peaks_[k].value = values[k];
      peaks_[k].t = state.t;
    }
}

}  // namespace active_tensegrity::core
