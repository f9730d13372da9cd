/// Index-3 DAE time integration of a scene (paper Sec. 5) in natural coordinates (natural.h): Newmark or
/// generalized-alpha on the free nodes' positions and the struts' spin rates, with the strut lengths and the scene's
/// rows as constraints, modified Newton with exact tangents, fixed steps halved on failure or adaptive steps
/// (AdaptiveStepper). A State carries the natural coordinates (State::natural) and their body poses (State::q, qd) for
/// everything that reads a pose: a strut's frame follows its axis without twist and turns about it by the spin its
/// spin rate integrates.
#pragma once

#include <functional>
#include <memory>
#include <vector>

#include "active_tensegrity/core/model/actuation_law.h"
#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::core
{
class NaturalSolver;

class DynamicsSolver
{
public:
  /// Throws std::invalid_argument naming what the natural coordinates do not cover (buildNaturalModel).
  DynamicsSolver(const Model& model, const SolverOptions& options);
  ~DynamicsSolver();
  DynamicsSolver(DynamicsSolver&&) noexcept;
  DynamicsSolver& operator=(DynamicsSolver&&) noexcept;

  /// Makes `state` consistent at state.t: natural coordinates formed from q and qd when the state does not carry
  /// its own, positions and velocities projected onto the constraints in the mass metric, accelerations and
  /// multipliers solved, the body poses written back.
  Summary initialize(State& state, const ActuationLaw& law);
  /// Advances by h (halving it on failure); on failure `state` is left at the last good instant.
  Summary step(State& state, double h, const ActuationLaw& law);
  /// Forces from outside the scene from `s` on (on strut axes and point masses; each checked before any is
  /// applied). The forces jump there, so the integration restarts from s: its accelerations and multipliers are made
  /// consistent with them. Throws std::invalid_argument naming a load the natural coordinates cannot take.
  Summary setExternalLoads(const std::vector<PointLoad>& loads, State& s);

  /// The touching contacts of `state` with their forces, by contact slot, when it is the state the last accepted
  /// step ended in (or initialize made); else null.
  const std::vector<ContactPairState>* contactsAt(const State& state) const;
  /// Forms every actuator's force at s into State::natural.actuator_force, which observables.h's actuationForce reads
  /// (a step leaves them unformed: a driven node's reaction costs a force evaluation). s is a state this solver made,
  /// or it is initialized first at its actuation values; false when that fails.
  bool formActuatorForces(State& s);
  /// The energy of s and the powers acting on it (energy.h's account).
  EnergyPoint energyAt(const State& s);

  /// With `defer` true, step leaves the body poses (State::q, qd) to writePoses and mark the state
  /// (NaturalState::poses_pending): a loop that reads them at some steps only saves writing them at the others. The
  /// struts' frames are carried at every step (natural.h, carryBodyFrames), so the poses are the same either way. Off
  /// by default.
  void deferPoses(bool defer);
  /// Writes the body poses of s when a step deferred them (nothing otherwise).
  void writePoses(State& s);

  /// Counts of the solver's work since construction or resetTimings (StepTimings: iterations, factorizations,
  /// analyses, the most contacts touching at an accepted step's end, the time in step calls).
  const StepTimings& timings() const;
  void resetTimings();

private:
  /// Gives `state` natural coordinates formed from its q and qd (initialize) unless it carries its own (a state a step
  /// or initialize made, untouched since).
  Summary prepare(State& state, const ActuationLaw& law);

  friend class AdaptiveStepper;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Variable time steps (solver.adaptive): the step follows the local error estimate against solver.error_tolerance, a
/// step that brings a pair into contact deeper than solver.onset_depth is refused and retried at the interpolated
/// onset time, a step that gains energy no force accounts for, or loses it in contact, beyond solver.energy_tolerance
/// (energy.h) is refused and halved, and the step grows again after (docs/physics.md, "Adaptive time steps").
class AdaptiveStepper
{
public:
  /// The first step is options.dt (clamped to [dt_min, dt_max]); the adaptive settings of `options` apply to the
  /// solver's adaptive steps from now on.
  AdaptiveStepper(DynamicsSolver& solver, const SolverOptions& options);

  /// Advances `state` to t_end exactly (the last step is shortened to land on it) with the steps the control allows;
  /// calls on_step after every accepted step. On failure (a step at dt_min that still does not converge) the state
  /// stays at the last good instant and the summary says why.
  Summary advanceTo(State& state, double t_end, const ActuationLaw& law,
                    const std::function<void(const State&)>& on_step = {});

  /// The energy at the last accepted step's end (energy.h), and that step's energy check (failed only for a step
  /// accepted at dt_min).
  const EnergyPoint& lastEnergy() const;
  const StepEnergyCheck& lastEnergyCheck() const;
  /// What it did since it was made.
  const AdaptiveStats& stats() const
  {
    return stats_;
  }

private:
  DynamicsSolver& solver_;
  AdaptiveStats stats_;
  // advanceTo's call: its state and on_step, and the last accepted step's end, for each_ (made once: a lambda of
  // this size converted at each call would allocate)
  State* state_ = nullptr;
  const std::function<void(const State&)>* on_step_ = nullptr;
  double last_t_ = 0.0;
  double callback_time_ = 0.0;  // s in on_step during the call
  std::function<void(const NaturalState&)> each_;
};

}  // namespace active_tensegrity::core
