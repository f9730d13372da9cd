//   tensegrity_bench stress [--quick] [--case TEXT]... [--skip TEXT]...
// runs the stability stress cases (tower and quadruplex: fast folding, large steps, bare steel, thin
// struts, slack cables, impulsive actuation; two nearly parallel struts pressed together) and prints one table row per
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/scene/scene.h"
#include "../cli.h"
#include "bench.h"

namespace at = active_tensegrity::core;

namespace active_tensegrity::tools::bench
{
namespace
{
struct StressCase
{
  const char* name;
  const char* scene;
  std::vector<std::string> overrides;
  bool quick;  // short enough for the test suite's version (test_stress)
};
}  // namespace

int stress(const StressSelection& select)
{
  const std::string dir = tools::sceneDirectory(ACTIVE_TENSEGRITY_SCENE_DIR) + "/";
  std::fprintf(stderr, "stress: scenes from %s\n", dir.c_str());
  const std::vector<std::string> tower = { "analysis.type=dynamic" };
  const std::vector<std::string> quad = { "analysis.type=dynamic", "contact.enabled=true",
                                          "analysis.max_actuation=1.2" };
  const auto with = [](std::vector<std::string> base, std::initializer_list<std::string> more)
  {
    base.insert(base.end(), more);
    return base;
  };
  const std::vector<StressCase> cases = {
    { "tower V = 5 m/s", "tower.yaml", with(tower, { "actuation.speed=5", "analysis.duration=0.8" }), false },
    { "tower V = 10 m/s", "tower.yaml", with(tower, { "actuation.speed=10", "analysis.duration=0.5" }), false },
    { "tower V = 20 m/s", "tower.yaml", with(tower, { "actuation.speed=20", "analysis.duration=0.3" }), true },
    { "tower V = 50 m/s", "tower.yaml", with(tower, { "actuation.speed=50", "analysis.duration=0.2" }), true },
    { "tower V = 0.5 m/s, dt = 1e-3 s", "tower.yaml", with(tower, { "solver.dt=1e-3", "analysis.duration=4" }), false },
    { "tower V = 0.5 m/s, dt = 5e-3 s", "tower.yaml", with(tower, { "solver.dt=5e-3", "analysis.duration=4" }), true },
    { "tower V = 0.5 m/s, dt = 1e-2 s", "tower.yaml", with(tower, { "solver.dt=1e-2", "analysis.duration=4" }), true },
    { "tower bare steel struts, V = 5 m/s", "tower.yaml",
      with(tower, { "struts.material=steel", "actuation.speed=5", "analysis.duration=0.8" }), false },
    { "tower thin struts (r 5 mm), V = 5 m/s", "tower.yaml",
      with(tower, { "struts.radius=0.005", "struts.core.radius=0.0025", "actuation.speed=5", "analysis.duration=0.8" }),
      false },
    { "tower thin struts (r 5 mm), V = 20 m/s", "tower.yaml",
      with(tower, { "struts.radius=0.005", "struts.core.radius=0.0025", "actuation.speed=20", "analysis.duration=0.3" }),
      true },
    { "tower impulsive: 10 cm in 2 ms", "tower.yaml",
      with(tower, { "actuation.speed=50", "analysis.max_actuation=0.1", "analysis.duration=0.3" }), true },
    { "quadruplex V = 5 m/s", "quadruplex.yaml", with(quad, { "actuation.speed=5", "analysis.duration=0.6" }), true },
    { "quadruplex V = 10 m/s", "quadruplex.yaml", with(quad, { "actuation.speed=10", "analysis.duration=0.4" }), true },
    { "quadruplex V = 20 m/s", "quadruplex.yaml", with(quad, { "actuation.speed=20", "analysis.duration=0.3" }), true },
    { "quadruplex V = 50 m/s", "quadruplex.yaml", with(quad, { "actuation.speed=50", "analysis.duration=0.2" }), true },
    { "quadruplex dt = 1e-2 s, V = 0.5 m/s", "quadruplex.yaml",
      with(quad, { "solver.dt=1e-2", "actuation.speed=0.5", "analysis.duration=3" }), true },
    { "two struts 1 degree apart pressed side by side, 1 m/s", "parallel.yaml", { "actuation.speed=1" }, true },
    { "two struts 1 degree apart pressed side by side, 10 m/s", "parallel.yaml", { "actuation.speed=10" }, true },
    { "quadruplex all cables slack (no prestress), V = 1 m/s", "quadruplex.yaml",
      with(quad, { "cables.lower.prestress=0", "cables.upper.prestress=0", "cables.bracing.prestress=0",
                   "actuation.speed=1", "analysis.duration=1.5" }),
      true },
  };
  // every text must name a case (a misspelt one would silently run, or skip, nothing)
  const auto names = [&](const std::string& text, const StressCase& c)
  { return std::string(c.name).find(text) != std::string::npos; };
  for (const std::vector<std::string>* texts : { &select.cases, &select.skipped })
    for (const std::string& text : *texts)
      if (std::none_of(cases.begin(), cases.end(), [&](const StressCase& c) { return names(text, c); }))
      {
        std::fprintf(stderr, "tensegrity_bench stress: no case's name contains '%s' (--%s)\n", text.c_str(),
                     texts == &select.cases ? "case" : "skip");
        return 2;
      }
  const auto selected = [&](const StressCase& c)
  {
    const auto in = [&](const std::vector<std::string>& texts)
    { return std::any_of(texts.begin(), texts.end(), [&](const std::string& t) { return names(t, c); }); };
    return (!select.quick_only || c.quick) && (select.cases.empty() || in(select.cases)) && !in(select.skipped);
  };
  if (std::none_of(cases.begin(), cases.end(), selected))
  {
    std::fprintf(stderr, "tensegrity_bench stress: the selection leaves no case to run\n");
    return 2;
  }
  std::printf("| case | ended | simulated (s) | steps | step cuts | crossings refused | max F_N (N) | min gap (mm) | "
              "finite | wall (s) |\n|---|---|---|---|---|---|---|---|---|---|\n");
  int bad = 0;
  for (const StressCase& c : cases)
  {
    if (!selected(c))
      continue;
    std::vector<at::Override> o;
    for (const std::string& kv : c.overrides)
      o.push_back(at::parseOverride(kv));
    const at::Model model = at::loadScene(dir + c.scene, o);
    double max_force = 0.0, min_gap = INFINITY;
    bool finite = true;
    const at::RunResult r = at::runAnalysis(
        model, [](const at::State&) {}, {},
        [&](const at::State& s)
        {
          finite = finite && s.q.allFinite() && s.qd.allFinite() && s.natural.lambda.allFinite();
          for (const at::ContactPairState& p : at::activeContacts(model, s))
            max_force = std::max(max_force, p.normal_force);
          min_gap = std::min(min_gap, at::minimumGap(model, s.q));
        });
    const at::State& f = r.final_state;
    finite = finite && f.q.allFinite() && f.qd.allFinite();
    bad += finite ? 0 : 1;
    std::string ended = at::toString(r.summary.status);
    if (!r.summary.ok())
      ended += ": " + r.summary.message;
    std::printf("| %s | %s | %.4g | %d | %d | %d | %.0f | %.2f | %s | %.1f |\n", c.name, ended.c_str(), f.t,
                r.solver_steps, r.summary.step_cuts, r.summary.crossings_refused, max_force, 1e3 * min_gap,
                finite ? "yes" : "NO", r.wall_time);
    std::fflush(stdout);
  }
  return bad == 0 ? 0 : 3;
}
}  // namespace active_tensegrity::tools::bench
