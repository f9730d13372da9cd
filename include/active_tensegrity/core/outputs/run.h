/// Running a scene's analysis (static path or dynamic run): the run driver, its result and where its time went.
#pragma once

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "active_tensegrity/core/base/summary.h"
#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
struct RunResult
{
  Summary summary;
  int steps = 0;           // output steps written
  int solver_steps = 0;    // time steps or load increments taken
  double wall_time = 0.0;  // s
  /// Dynamic runs: where the solver's time went. Both: wall time spent in on_step and on_output (s).
  StepTimings timings;
  double callback_time = 0.0;
  /// Dynamic runs with solver.adaptive: accepted and rejected steps, smallest and largest step.
  AdaptiveStats adaptive;
  /// Dynamic runs: the energy account over every accepted step (energy.h).
  EnergyAccount energy;
  State final_state;
};

/// Where a run's wall time went, in order: forces, contact, constraints, factorization, solve,
/// solver_other (the rest of step(): vector work, step bookkeeping), callbacks (on_step and on_output:
/// output rows, peak tracking, writing), rest (setup, initialization, the loop itself); seconds that
/// sum to wall_time. Static runs have only callbacks and rest (the step split is dynamic only).
std::vector<std::pair<std::string, double>> timeBreakdown(const RunResult& result);

/// runAnalysis's per-step callback: the state after a time step or load step, and its active contacts (as
/// activeContacts gives them) when the solver evaluated them there (dynamics: DynamicsSolver::contactsAt), else
/// null (statics).
using StepCallback = std::function<void(const State&, const std::vector<ContactPairState>* contacts)>;

/// Runs model.analysis; calls on_output for every output step (the initial state included) and
/// on_step, when given, after every time step or load step (for peaks between output steps).
RunResult runAnalysis(const Model& model, const std::function<void(const State&)>& on_output,
                      const std::function<void(double fraction)>& on_progress = {}, const StepCallback& on_step = {});
/// As above, with a per-step callback that takes the state alone.
RunResult runAnalysis(const Model& model, const std::function<void(const State&)>& on_output,
                      const std::function<void(double fraction)>& on_progress,
                      const std::function<void(const State&)>& on_step);

}  // namespace active_tensegrity::core
