//   tensegrity_bench steps SCENE [--set key=value]... [--repeat N] [--peaks]
// runs the scene's analysis N times and prints the wall time per solver step (median and minimum
// over the runs), Newton iterations per step, for dynamic runs the real-time factor, and where the
// time of the last run went (forces, contact, constraints, factorization, solve, the rest); with
// --peaks the run also tracks the summary's peaks after every step as tensegrity_run does (PeakTracker), so
// that the cost of that tracking shows under "callbacks".
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/core/outputs/peaks.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/scene/scene.h"
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
int steps(const std::string& scene, const std::vector<at::Override>& overrides, int repeat, bool peaks)
{
  const at::Model model = at::loadScene(scene, overrides);
  std::vector<double> per_step;
  at::RunResult last;
  long allocations = 0;
  for (int r = 0; r < repeat; ++r)
  {
    at::PeakTracker tracker(model);
    const auto track = [&tracker](const at::State& s, const std::vector<at::ContactPairState>* contacts)
    { tracker.add(s, contacts); };
    // allocations from the first step on (setup and initialization excluded)
    long at_first_step = -1;
    const auto count = [&at_first_step](const at::State&)
    {
      if (at_first_step < 0)
        at_first_step = heapAllocations();
    };
    last = peaks ? at::runAnalysis(
                       model, [](const at::State&) {}, {}, track) :
                   at::runAnalysis(model, count);
    allocations = at_first_step < 0 ? 0 : heapAllocations() - at_first_step;
    if (!last.summary.ok())
    {
      std::cerr << "tensegrity_bench: the analysis failed: " << last.summary.message << "\n";
      return 3;
    }
    per_step.push_back(last.wall_time / std::max(1, last.solver_steps));
  }
  std::sort(per_step.begin(), per_step.end());
  const double median = per_step[per_step.size() / 2];
  const bool dynamic = model.analysis.type == at::AnalysisType::kDynamic;
  std::printf("scene: %s\n", scene.c_str());
  // (the solvers' natural coordinates: statics has no spin rates, dynamics one per strut in a scene with friction)
  const at::NaturalModel nm = at::buildNaturalModel(model, dynamic);
  std::printf("analysis: %s, %d bodies, %zu cables; solved in natural coordinates: %d coordinates, %zu rows\n",
              dynamic ? "dynamic" : "static", static_cast<int>(model.bodies.size()), model.cables.size(),
              nm.coordinates, nm.struts.size() + nm.rows.size());
  if (dynamic)
    std::printf("dt: %g s, integrator: %s, duration: %g s\n", model.solver.dt,
                model.solver.integrator == at::Integrator::kNewmark ? "newmark" : "generalized_alpha",
                model.analysis.duration);
  std::printf("solver steps: %d, step cuts: %d\n", last.solver_steps, last.summary.step_cuts);
  std::printf("newton iterations per step: %.3f\n",
              static_cast<double>(last.summary.iterations) / std::max(1, last.solver_steps));
  std::printf("wall time per step: median %.3f us, min %.3f us over %d runs\n", 1e6 * median, 1e6 * per_step.front(),
              repeat);
  if (heapAllocations() < 0)
    std::printf("heap allocations per step: not counted (built with AddressSanitizer)\n");
  else if (!peaks)
    std::printf("heap allocations per step (solver and loop, after the first output): %.2f\n",
                static_cast<double>(allocations) / std::max(1, last.solver_steps));
  std::printf("factorizations per step: %.3f, symbolic analyses: %ld\n",
              static_cast<double>(last.timings.factorizations) / std::max(1, last.solver_steps), last.timings.analyses);
  std::printf("where the time goes (last run, us per step, share of its wall time):\n");
  const int n = std::max(1, last.solver_steps);
  for (const auto& [part, seconds] : at::timeBreakdown(last))
    std::printf("  %-14s %10.2f us %6.1f %%\n", part.c_str(), 1e6 * seconds / n,
                last.wall_time > 0.0 ? 100.0 * seconds / last.wall_time : 0.0);
  if (dynamic)
    // (the mean simulated time per step: dt for fixed steps, the mean step with solver.adaptive)
    std::printf("real-time factor (simulated / wall, median): %.1f\n",
                model.analysis.duration / std::max(1, last.solver_steps) / median);
  return 0;
}
}  // namespace active_tensegrity::tools::bench
