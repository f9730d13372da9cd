/// Variable time steps for the body coordinates' BodyDynamicsSolver (the comparison `tensegrity_bench natural` runs):
/// the step-size rules of core/solvers/adaptive.h (StepSizeControl) with the error, onset and energy checks of the
/// package's AdaptiveStepper.
#pragma once

#include <functional>
#include <memory>

#include "active_tensegrity/oracle/body_state.h"
#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/oracle/body_dynamics.h"
#include "active_tensegrity/oracle/energy_meter.h"

namespace active_tensegrity::core
{
class ContactScan;

class BodyAdaptiveStepper
{
public:
  /// The first step is options.dt (clamped to [dt_min, dt_max]).
  BodyAdaptiveStepper(BodyDynamicsSolver& solver, const SolverOptions& options);
  ~BodyAdaptiveStepper();

  /// Advances `state` to t_end exactly (the last step is shortened to land on it) with the steps the
  /// error control allows; calls on_step after every accepted step. On failure (a step below dt_min
  /// that still does not converge) the state stays at the last good instant and the summary says why.
  Summary advanceTo(BodyState& state, double t_end, const ActuationLaw& law,
                    const std::function<void(const BodyState&)>& on_step = {});

  /// The energy at the last accepted step's end (energy.h), and that step's energy check (failed only for a step
  /// accepted at dt_min).
  const EnergyPoint& lastEnergy() const
  {
    return start_energy_;
  }
  const StepEnergyCheck& lastEnergyCheck() const
  {
    return last_check_;
  }

  /// The step the controller will try next (s).
  double nextStep() const
  {
    return control_.nextStep();
  }
  const AdaptiveStats& stats() const
  {
    return stats_;
  }

private:
  /// The energy of `s` (the start of the next step): kept from the last accepted step's end when s is that state.
  const EnergyPoint& startEnergy(const BodyState& s);

  BodyDynamicsSolver& solver_;
  SolverOptions options_;
  StepSizeControl control_;
  BodyState trial_;
  AdaptiveStats stats_;
  EnergyPoint start_energy_;
  double start_energy_t_ = 0.0;
  Eigen::VectorXd start_energy_q_;        // the state start_energy_ was formed at (its time and positions)
  unsigned long start_energy_loads_ = 0;  // and the external loads in force (System::externalLoadsEpoch)
  bool start_energy_valid_ = false;
  StepEnergyCheck last_check_;
  bool in_contact_ = false;  // contacts active at the last accepted step's end
  EnergyMeter energy_meter_;
  std::unique_ptr<ContactScan> contacts_;  // the contacts of a state the solver did not end a step in (analysis.h)
};

}  // namespace active_tensegrity::core
