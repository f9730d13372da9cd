#include "active_tensegrity/core/outputs/run.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "active_tensegrity/core/base/text.h"
#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/solvers/structure_check.h"

namespace active_tensegrity::core
{
std::vector<std::pair<std::string, double>> timeBreakdown(const RunResult& result)
{
  const StepTimings& t = result.timings;
  const double parts = t.forces + t.contact + t.constraints + t.factorization + t.solve;
  return { { "forces", t.forces },
           { "contact", t.contact },
           { "constraints", t.constraints },
           { "factorization", t.factorization },
           { "solve", t.solve },
           { "solver_other", std::max(0.0, t.total - parts) },
           { "callbacks", result.callback_time },
           { "rest", std::max(0.0, result.wall_time - t.total - result.callback_time) } };
}

namespace
{
/// The dynamic loop with solver.adaptive: steps to every output time and every actuation breakpoint.
void runAdaptive(const Model& model, DynamicsSolver& solver, const ActuationLaw& law, State& state, RunResult& result,
                 const std::function<void(const State&)>& on_output, const std::function<void(double)>& on_progress,
                 const std::function<void(const State&)>& after_step, bool wants_steps)
{
  const AnalysisSettings& an = model.analysis;
  const double eps = 1e-12 * std::max(1.0, an.duration);
  const double interval = an.output_interval;  // 0 or at least dt_min (the loader sees to it)
  // no step is shorter than dt_min: a breakpoint closer than that to an output time, the end or the
  // breakpoint before is left to the step that lands there (the actuation law is evaluated exactly anyway)
  const double gap = model.solver.dt_min;
  std::vector<double> stops;
  for (double t : actuationBreakpoints(model))
  {
    const double to_output = interval > 0.0 ? std::abs(t - interval * std::round(t / interval)) : gap;
    if (t >= gap && t <= an.duration - gap && to_output >= gap && (stops.empty() || t - stops.back() >= gap))
      stops.push_back(t);
  }
  const int every = interval > 0.0 ? 0 : 1;  // no output interval: a row per accepted step
  // an output time closer than dt_min to the end is the end's
  const auto output_after = [&](double t) { return t > an.duration - gap ? an.duration : t; };
  double next_output = interval > 0.0 ? output_after(std::min(interval, an.duration)) : an.duration;
  size_t next_stop = 0;
  AdaptiveStepper stepper(solver, model.solver);
  long accepted = 0;
  const auto timed = [&](const auto& f)
  {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    result.callback_time += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  // (a std::function made once: advanceTo takes one, and a lambda of this size converted at each call allocates)
  double last_t = state.t;
  const std::function<void(const State&)> each_step = [&](const State& s)
  {
    // (the body poses and the actuators' forces for whoever reads this step: the caller's on_step, the yield watch or a
    // row)
    const bool row = every && s.t < an.duration - eps;
    if (wants_steps || row)
      solver.writePoses(state);  // (s is state)
    if (!model.actuators.empty() && (wants_steps || row))
      solver.formActuatorForces(state);
    result.energy.add(stepper.lastEnergy(), s.t - last_t, s.t, stepper.lastEnergyCheck());
    last_t = s.t;
    timed(
        [&]()
        {
          after_step(s);
          if (every && s.t < an.duration - eps)
          {
            on_output(s);
            ++result.steps;
          }
        });
    if (on_progress && ++accepted % 256 == 0)
      on_progress(s.t / an.duration);
  };
  while (state.t < an.duration - eps)
  {
    double stop = std::min(next_output, an.duration);
    if (next_stop < stops.size())
      stop = std::min(stop, stops[next_stop]);
    const Summary s = stepper.advanceTo(state, stop, law, each_step);
    result.summary.iterations += s.iterations;
    result.summary.step_cuts += s.step_cuts;
    result.summary.crossings_refused += s.crossings_refused;
    result.summary.residual = s.residual;
    if (!s.ok())
    {
      result.summary.status = s.status;
      result.summary.message = s.message;
      break;
    }
    if (next_stop < stops.size() && stop >= stops[next_stop] - eps)
      ++next_stop;
    if (stop >= next_output - eps || stop >= an.duration - eps)
    {
      solver.writePoses(state);
      if (!model.actuators.empty())
        solver.formActuatorForces(state);
      timed([&]() { on_output(state); });
      ++result.steps;
      next_output = output_after(next_output + (interval > 0.0 ? interval : an.duration));
    }
  }
  result.adaptive = stepper.stats();
  result.solver_steps = static_cast<int>(stepper.stats().accepted);
}
/// Both runAnalysis: `contacts_wanted` says whether on_step reads the step's contacts (the dynamics solver forms
/// their forces for it alone; the state-only callback never sees them).
RunResult run(const Model& model, const std::function<void(const State&)>& user_output,
              const std::function<void(double)>& on_progress, const StepCallback& on_step, bool contacts_wanted);
}  // namespace

RunResult runAnalysis(const Model& model, const std::function<void(const State&)>& on_output,
                      const std::function<void(double)>& on_progress, const std::function<void(const State&)>& on_step)
{
  StepCallback each;
  if (on_step)
    each = [&on_step](const State& s, const std::vector<ContactPairState>*) { on_step(s); };
  return run(model, on_output, on_progress, each, false);
}

RunResult runAnalysis(const Model& model, const std::function<void(const State&)>& on_output,
                      const std::function<void(double)>& on_progress, const StepCallback& on_step)
{
  return run(model, on_output, on_progress, on_step, static_cast<bool>(on_step));
}

namespace
{
RunResult run(const Model& model, const std::function<void(const State&)>& user_output,
              const std::function<void(double)>& on_progress, const StepCallback& on_step, bool contacts_wanted)
{
  // cables that run through a strut, at the output steps: once per cable and strut, at most kMaxCrossingWarnings
  constexpr size_t kMaxCrossingWarnings = 20;
  std::vector<std::pair<int, int>> crossed;
  std::vector<std::string> crossing_warnings;
  const std::function<void(const State&)> on_output = [&](const State& s)
  {
    for (const CableStrutGap& g : cableStrutCrossings(model, s.q))
    {
      if (std::find(crossed.begin(), crossed.end(), std::make_pair(g.cable, g.strut)) != crossed.end())
        continue;
      crossed.emplace_back(g.cable, g.strut);
      if (crossed.size() <= kMaxCrossingWarnings)
        crossing_warnings.push_back(
            "cable " + quoted(model.cables[g.cable].name) + " runs through strut " +
            quoted(model.bodies[g.strut].name) + " (its segment from point " + std::to_string(g.segment + 1) + ", " +
            roundedNumber(-g.gap * 1e3, 3) + " mm inside the strut's surface) first at " +
            (model.analysis.type == AnalysisType::kStatic ? "path parameter " + roundedNumber(s.t) :
                                                            "t = " + roundedNumber(s.t) + " s") +
            " (min_cable_strut_gap; cables do not touch struts in the model)");
    }
    user_output(s);
  };
  const auto with_crossing_warnings = [&](Summary& sum)
  {
    sum.warnings.insert(sum.warnings.end(), crossing_warnings.begin(), crossing_warnings.end());
    if (crossed.size() > kMaxCrossingWarnings)
      sum.warnings.push_back("and " + std::to_string(crossed.size() - kMaxCrossingWarnings) +
                             " more cable and strut pairs where the cable runs through the strut");
  };
  const auto start = std::chrono::steady_clock::now();
  RunResult result;
  State state = initialState(model);
  const AnalysisSettings& an = model.analysis;
  // what the start is: in equilibrium, slack elements, prestress stable (structure_check.h)
  std::vector<std::string> start_warnings = startWarnings(model, state);
  const double actuation_end = actuationEndTime(model);
  const bool ends_early = an.type == AnalysisType::kDynamic && !model.actuators.empty() &&
                          an.duration < actuation_end - 1e-9 * std::max(1.0, an.duration);
  if (ends_early && !an.sequence.empty())
    start_warnings.push_back("analysis.duration " + shortestNumber(an.duration) +
                             " s ends before actuation.sequence does (its last ramp ends at " +
                             roundedNumber(actuation_end) + " s)");
  else if (ends_early)
    start_warnings.push_back("analysis.duration " + shortestNumber(an.duration) +
                             " s ends before the actuators reach analysis.max_actuation " +
                             shortestNumber(an.max_actuation) + " m (the ramp ends at " +
                             roundedNumber(an.schedule.endTime()) + " s): the run stops at actuation " +
                             roundedNumber(an.schedule.evaluate(an.duration).value) + " m");
  const auto with_start_warnings = [&](Summary& s)
  { s.warnings.insert(s.warnings.begin(), start_warnings.begin(), start_warnings.end()); };
  // members above their material's yield strength: the first time each one is, over every step
  std::vector<size_t> watched;  // material cables with a yield strength not yet passed
  for (size_t i = 0; i < model.cables.size(); ++i)
    if (model.cables[i].yield_strength > 0.0 && model.cables[i].area > 0.0)
      watched.push_back(i);
  std::vector<std::string> yield_warnings;
  const auto watch = [&](const State& s)
  {
    for (auto it = watched.begin(); it != watched.end();)
    {
      const size_t i = *it;
      const Cable& c = model.cables[i];
      const CableState cable = evaluateCable(model, c, s.q, s.qd, s.u, model.damping_enabled);
      const double stress = cable.tension / c.area;
      if (!(stress > c.yield_strength))
      {
        ++it;
        continue;
      }
      it = watched.erase(it);
      yield_warnings.push_back("cable " + quoted(c.name) + " is above its material's yield_strength " +
                               shortestNumber(c.yield_strength) + " Pa: " + roundedNumber(stress, 6) + " Pa (tension " +
                               roundedNumber(cable.tension, 6) + " N) first at " +
                               (an.type == AnalysisType::kStatic ? "path parameter " + roundedNumber(s.t) :
                                                                   "t = " + roundedNumber(s.t) + " s"));
    }
  };
  const StepCallback step_hook = [&](const State& s, const std::vector<ContactPairState>* contacts)
  {
    watch(s);
    if (on_step)
      on_step(s, contacts);
  };
  const auto with_yield_warnings = [&](Summary& s)
  { s.warnings.insert(s.warnings.end(), yield_warnings.begin(), yield_warnings.end()); };

  if (an.type == AnalysisType::kStatic)
  {
    StaticSolver solver(model, model.solver);
    solver.setLoadPath(an.load_factor_start, an.load_factor_end);
    solver.setArcLength(an.arc_length);
    // the initial equilibrium (prestress, no actuation, the loads at their first factor)
    Summary first = solver.solve(state, state.u);
    result.summary.iterations += first.iterations;
    if (!first.ok())
    {
      result.summary = first;
      result.summary.message = "initial equilibrium: " + first.message;
      with_start_warnings(result.summary);
      result.final_state = state;
      return result;
    }
    watch(state);
    on_output(state);
    ++result.steps;
    ActuationValues u_end = state.u;
    for (auto& v : u_end)
      v.value = an.max_actuation;
    Summary path =
        solver.followPath(state, u_end, an.steps,
                          [&](const State& s, const Summary&)
                          {
                            const auto callbacks = std::chrono::steady_clock::now();
                            step_hook(s, nullptr);
                            on_output(s);
                            result.callback_time +=
                                std::chrono::duration<double>(std::chrono::steady_clock::now() - callbacks).count();
                            ++result.steps;
                            if (on_progress)
                              on_progress(s.t);
                          });
    path.iterations += first.iterations;
    result.summary = path;
    with_start_warnings(result.summary);
    with_yield_warnings(result.summary);
    result.solver_steps = an.arc_length ? result.steps - 1 : an.steps + path.step_cuts;
    result.timings = solver.timings();
  }
  else
  {
    DynamicsSolver solver(model, model.solver);
    const ActuationLaw law =
        ActuationLaw::writing([&model](double t, ActuationValues& u) { scheduledActuation(model, t, u); });
    result.summary = solver.initialize(state, law);
    with_start_warnings(result.summary);
    if (!result.summary.ok())
    {
      result.final_state = state;
      return result;
    }
    if (!model.actuators.empty())
      solver.formActuatorForces(state);  // (what the rows and callbacks read; a step leaves them unformed)
    solver.deferPoses(true);             // (written below for the steps that are read)
    watch(state);
    on_output(state);
    ++result.steps;
    result.energy.begin(solver.energyAt(state));
    // after each step: the yield watch, and the caller's on_step with the step's contacts (formed when asked)
    const auto after_step = [&](const State& s) { step_hook(s, contacts_wanted ? solver.contactsAt(s) : nullptr); };
    if (model.solver.adaptive)
      runAdaptive(model, solver, law, state, result, on_output, on_progress, after_step, on_step || !watched.empty());
    else
    {
      const double dt = model.solver.dt;
      long n_steps = std::lround(std::ceil(an.duration / dt - 1e-9));
      // a last step shorter than dt_min is merged into the one before
      if (n_steps > 1 && an.duration - static_cast<double>(n_steps - 1) * dt < model.solver.dt_min)
        --n_steps;
      // output rows: every step (output_interval 0), else the first step at or after each multiple of the interval
      // (counted, not summed: a sum of intervals drifts from the step times and skips or doubles rows)
      const bool every_step = !(an.output_interval > 0.0);
      const double interval = an.output_interval;
      long next_row = 1;
      double step_start = state.t;
      bool touched = false;  // contacts active at the last step's end
      for (long k = 1; k <= n_steps; ++k)
      {
        const double t_target = k == n_steps ? an.duration : std::min(an.duration, k * dt);
        const Summary s = solver.step(state, t_target - state.t, law);
        result.summary.iterations += s.iterations;
        result.summary.step_cuts += s.step_cuts;
        result.summary.crossings_refused += s.crossings_refused;
        result.summary.residual = s.residual;
        ++result.solver_steps;
        if (!s.ok())
        {
          result.summary.status = s.status;
          result.summary.message = s.message;
          break;
        }
        const double h = t_target - step_start;
        step_start = t_target;
        state.t = t_target;  // no drift from summing steps
        {
          const EnergyPoint end = solver.energyAt(state);
          const bool touching = !state.natural.touching.empty();
          result.energy.add(end, h, state.t,
                            checkStepEnergy(result.energy.now, end, h, model.solver.energy_tolerance,
                                            stepEnergyRoundoff(model, state.natural.x, h), touched || touching));
          touched = touching;
        }
        const auto callbacks = std::chrono::steady_clock::now();
        const bool row = every_step || k == n_steps || state.t >= static_cast<double>(next_row) * interval - 1e-9 * dt;
        // (the body poses and the actuators' forces for whoever reads this step: the caller's on_step, the yield watch
        // or a row)
        if (on_step || !watched.empty() || row)
          solver.writePoses(state);
        if (!model.actuators.empty() && (on_step || row))
          solver.formActuatorForces(state);
        after_step(state);
        if (row)
        {
          on_output(state);
          ++result.steps;
          if (!every_step)
            while (static_cast<double>(next_row) * interval - 1e-9 * dt <= state.t)
              ++next_row;
        }
        result.callback_time += std::chrono::duration<double>(std::chrono::steady_clock::now() - callbacks).count();
        if (on_progress && k % 256 == 0)
          on_progress(state.t / an.duration);
      }
    }
    result.timings = solver.timings();
    const EnergyAccount& e = result.energy;
    const std::string where =
        model.solver.adaptive ? " (at solver.dt_min; lower it)" : " at solver.dt (use solver.adaptive or a smaller dt)";
    const auto percent = [&e](double energy)
    { return roundedNumber(100.0 * energy / std::max(e.peak_mechanical, 1e-300), 3) + " %"; };
    if (e.gainedMaterially(model.solver.energy_tolerance))
      result.summary.warnings.push_back(
          "the integrator gained " + roundedNumber(-e.numerical_dissipation, 3) + " J over the run (" +
          percent(-e.numerical_dissipation) + " of the largest kinetic and elastic energy; " +
          std::to_string(e.gaining_steps) + " steps gained more than solver.energy_tolerance " +
          shortestNumber(model.solver.energy_tolerance) + ", the first at t = " + roundedNumber(e.first_unresolved_t) +
          " s): impacts, cables going slack and taut or an actuator starting without blend_time were under-resolved" +
          where + " (energy in the summary)");
    if (e.contactsUnresolved(model.solver.energy_tolerance))
      result.summary.warnings.push_back(
          "impacts under-resolved" + where + ": steps in contact changed the energy by " +
          roundedNumber(e.contact_unresolved_energy, 3) + " J (" + percent(e.contact_unresolved_energy) +
          " of the largest kinetic and elastic energy) that no force accounts for, each more than "
          "solver.energy_tolerance " +
          shortestNumber(model.solver.energy_tolerance) + " (" + std::to_string(e.gaining_steps) + " gained, " +
          std::to_string(e.contact_loss_steps) + " lost; the first at t = " + roundedNumber(e.first_unresolved_t) +
          " s): rebounds and contact forces are off by about as much (energy in the summary)");
    with_yield_warnings(result.summary);
    solver.writePoses(state);  // (a failed step's last good state included)
    if (!model.actuators.empty())
      solver.formActuatorForces(state);  // (the final state's, for whoever reads it)
  }
  with_crossing_warnings(result.summary);
  result.final_state = state;
  result.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}
}  // namespace

}  // namespace active_tensegrity::core
