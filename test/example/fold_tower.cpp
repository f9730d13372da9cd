// fold_tower [SCENE.yaml]: folds the tower (the default scene) for 1 s through strut contact; run from the package root
#include <cstdio>
#include <string>
#include <vector>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/peaks.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/scene/scene.h"

namespace at = active_tensegrity::core;

int main(int argc, char** argv)
{
  // the scene's quasi-static fold made a short dynamic one, as tensegrity_run --set would
  const at::Model model =
      at::loadScene(argc > 1 ? argv[1] : "config/scenes/tower.yaml",
                    { { "analysis.type", "dynamic" }, { "actuation.speed", "2" }, { "analysis.duration", "1" } });

  at::PeakTracker peaks(model);  // over every step: the largest actuation force, contact forces (N), stresses (Pa)
  // nothing per output row, no progress report; every time step's state and contacts to the peaks
  const at::RunResult run = at::runAnalysis(
      model, [](const at::State&) {}, {},
      [&](const at::State& state, const std::vector<at::ContactPairState>* contacts) { peaks.add(state, contacts); });

  std::printf("status %s: %d time steps, %d Newton iterations\n", at::toString(run.summary.status), run.solver_steps,
              run.summary.iterations);
  std::printf("final height %.3f m, %zu contacts\n", at::structureHeight(model, run.final_state.q),
              at::activeContacts(model, run.final_state).size());
  for (const at::Peak& peak : peaks.peaks())
    std::printf("peak %s %.4g at t = %.3f s\n", peak.name.c_str(), peak.value, peak.t);
  return run.summary.ok() ? 0 : 1;
}
