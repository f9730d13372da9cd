#include "active_tensegrity/oracle/body_adaptive.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <utility>

#include "active_tensegrity/core/outputs/observables.h"

namespace active_tensegrity::core
{
BodyAdaptiveStepper::BodyAdaptiveStepper(BodyDynamicsSolver& solver, const SolverOptions& options)
  : solver_(solver)
  , options_(options)
  , control_(options)
  , energy_meter_(solver.system())
  , contacts_(std::make_unique<ContactScan>(solver.system().model()))
{
  solver_.setVariableSteps(true);
}

BodyAdaptiveStepper::~BodyAdaptiveStepper() = default;

const EnergyPoint& BodyAdaptiveStepper::startEnergy(const BodyState& s)
{
  // (kept only for the very state it was formed at: a caller may put another state in, as the node's reset does)
  if (!start_energy_valid_ || start_energy_t_ != s.t || start_energy_q_ != s.q ||
      start_energy_loads_ != solver_.system().externalLoadsEpoch())
  {
    const std::vector<ContactPairState>* contacts = solver_.contactsAt(s);
    if (!contacts)
      contacts = &contacts_->active(s);
    start_energy_ = energy_meter_.at(s, *contacts);
    in_contact_ = !contacts->empty();
    start_energy_t_ = s.t;
    start_energy_q_ = s.q;
    start_energy_loads_ = solver_.system().externalLoadsEpoch();
    start_energy_valid_ = true;
  }
  return start_energy_;
}

Summary BodyAdaptiveStepper::advanceTo(BodyState& s, double t_end, const ActuationLaw& law,
                                       const std::function<void(const BodyState&)>& on_step)
{
  Summary total;
  const double eps = 1e-12 * std::max(1.0, std::abs(t_end));
  while (t_end - s.t > eps)
  {
    const StepSizeControl::Trial step = control_.next(t_end - s.t);
    const double h = step.h;
    const bool at_min = step.at_min;
    trial_ = s;
    const Summary r = solver_.tryStep(trial_, h, law);
    total.iterations += r.iterations;
    total.residual = r.residual;
    if (!r.ok())
    {
      ++stats_.rejected_solver;
      ++total.step_cuts;
      if (r.status == SolveStatus::kPassedThrough)
        ++total.crossings_refused;
      if (at_min)
      {
        total.status = r.status;
        std::ostringstream msg;
        msg << r.message << " at t = " << s.t << " s with the step at its minimum " << h << " s";
        total.message = msg.str();
        return total;
      }
      control_.failed(h);
      continue;
    }
    const StepEstimate& e = solver_.estimate();
    const double err = e.error / options_.error_tolerance;
    if (!at_min && e.onset_depth > options_.onset_depth)
    {
      ++stats_.rejected_onset;
      solver_.stepRefused();
      control_.tooDeep(h, e.onset_gap, e.onset_depth);
      continue;
    }
    if (!at_min && err > 1.0)
    {
      ++stats_.rejected_error;
      solver_.stepRefused();
      control_.tooLarge(h, err);
      continue;
    }
    // a step that gained energy no force accounts for did not resolve a stiff event (a contact or a cable going taut
    // within it), one that lost it in contact damped an impact numerically: halved, as a failed step
    const std::vector<ContactPairState>* contacts = solver_.contactsAt(trial_);
    if (!contacts)
      contacts = &contacts_->active(trial_);
    const EnergyPoint end_energy = energy_meter_.at(trial_, *contacts);
    const StepEnergyCheck energy =
        checkStepEnergy(startEnergy(s), end_energy, h, options_.energy_tolerance,
                        stepEnergyRoundoff(solver_.system().model(), s.q, h), in_contact_ || !contacts->empty());
    if (!at_min && !energy.ok())
    {
      ++stats_.rejected_energy;
      solver_.stepRefused();
      control_.energyRefused(h);
      continue;
    }
    if (at_min && (err > 1.0 || e.onset_depth > options_.onset_depth || !energy.ok()))
      ++stats_.at_min_step;
    std::swap(s, trial_);
    start_energy_ = end_energy;
    start_energy_t_ = s.t;
    start_energy_q_ = s.q;
    start_energy_loads_ = solver_.system().externalLoadsEpoch();
    start_energy_valid_ = true;
    last_check_ = energy;
    in_contact_ = !contacts->empty();
    ++stats_.accepted;
    stats_.h_min = stats_.accepted == 1 ? h : std::min(stats_.h_min, h);
    stats_.h_max = std::max(stats_.h_max, h);
    if (on_step)
      on_step(s);
    control_.accepted(step, err);
  }
  s.t = t_end;  // no drift from summing steps
  if (start_energy_valid_)
    start_energy_t_ = s.t;  // (the loop ends at an accepted step's end, or where the last call left it)
  return total;
}

}  // namespace active_tensegrity::core
