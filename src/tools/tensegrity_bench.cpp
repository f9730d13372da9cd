// tensegrity_bench: measurements that print numbers (never timed tests).
//   tensegrity_bench steps SCENE [--set key=value]... [--repeat N]
// runs the scene's analysis N times and prints the wall time per solver step (median and minimum
// over the runs), Newton iterations per step, and for dynamic runs the real-time factor.
#include <algorithm>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/core/analysis.h"
#include "active_tensegrity/core/scene.h"

namespace at = active_tensegrity::core;

namespace
{
const char* kUsage =
    "usage: tensegrity_bench steps SCENE.yaml [--set key=value]... [--repeat N]\n"
    "  Runs the scene's analysis N times (default 5) and prints wall time and Newton iterations per step.\n";

int steps(const std::string& scene, const std::vector<at::Override>& overrides, int repeat)
{
  const at::Model model = at::loadScene(scene, overrides);
  std::vector<double> per_step;
  at::RunResult last;
  for (int r = 0; r < repeat; ++r)
  {
    last = at::runAnalysis(model, [](const at::State&) {});
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
  std::printf("analysis: %s, %d bodies, %d coordinates, %d constraint rows, %zu cables\n",
              dynamic ? "dynamic" : "static", static_cast<int>(model.bodies.size()), model.nq, model.n_lambda,
              model.cables.size());
  if (dynamic)
    std::printf("dt: %g s, integrator: %s, duration: %g s\n", model.solver.dt,
                model.solver.integrator == at::Integrator::kNewmark ? "newmark" : "generalized_alpha",
                model.analysis.duration);
  std::printf("solver steps: %d, step cuts: %d\n", last.solver_steps, last.summary.step_cuts);
  std::printf("newton iterations per step: %.3f\n",
              static_cast<double>(last.summary.iterations) / std::max(1, last.solver_steps));
  std::printf("wall time per step: median %.3f us, min %.3f us over %d runs\n", 1e6 * median, 1e6 * per_step.front(),
              repeat);
  if (dynamic)
    std::printf("real-time factor (simulated / wall, median): %.1f\n", model.solver.dt / median);
  return 0;
}
}  // namespace

int main(int argc, char** argv)
{
  if (argc < 3 || std::string(argv[1]) != "steps")
  {
    std::cerr << kUsage;
    return 2;
  }
  std::vector<at::Override> overrides;
  int repeat = 5;
  const std::string scene = argv[2];
  try
  {
    for (int i = 3; i < argc; ++i)
    {
      const std::string arg = argv[i];
      if (arg == "--set" && i + 1 < argc)
        overrides.push_back(at::parseOverride(argv[++i]));
      else if (arg == "--repeat" && i + 1 < argc)
        repeat = std::max(1, std::stoi(argv[++i]));
      else
      {
        std::cerr << "tensegrity_bench: unknown argument '" << arg << "'\n" << kUsage;
        return 2;
      }
    }
    return steps(scene, overrides, repeat);
  }
  catch (const std::exception& e)
  {
    std::cerr << "tensegrity_bench: " << e.what() << "\n";
    return 1;
  }
}
