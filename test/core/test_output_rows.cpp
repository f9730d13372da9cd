// runAnalysis's output rows at fixed steps: a row per step at output_interval 0, one per interval otherwise, each
// at the step it belongs to, none lost or doubled over tens of thousands of steps.
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/scene/scene.h"

using namespace active_tensegrity::core;

namespace
{
std::vector<double> rowTimes(double dt, double duration, double interval, int* solver_steps = nullptr)
{
  const Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/prism.yaml",
                            { { "solver.dt", std::to_string(dt) },
                              { "analysis.duration", std::to_string(duration) },
                              { "analysis.output_interval", std::to_string(interval) } });
  std::vector<double> t;
  const RunResult r = runAnalysis(m, [&t](const State& s) { t.push_back(s.t); });
  EXPECT_TRUE(r.summary.ok()) << r.summary.message;
  EXPECT_EQ(r.steps, static_cast<int>(t.size()));
  if (solver_steps)
    *solver_steps = r.solver_steps;
  return t;
}
}  // namespace

TEST(OutputRows, IntervalZeroWritesTheStartAndEveryStep)
{
  // (a sum of 2e-4 s steps drifts from k dt: compared with it, t = 4.2882 s fell out)
  for (const double dt : { 2e-4, 3e-4 })
  {
    int steps = 0;
    const std::vector<double> t = rowTimes(dt, 5.0, 0.0, &steps);
    const long n = std::lround(5.0 / dt);
    ASSERT_EQ(steps, n) << "dt " << dt;
    ASSERT_EQ(static_cast<long>(t.size()), n + 1) << "dt " << dt;
    for (long k = 0; k <= n; ++k)
      ASSERT_NEAR(t[k], k == n ? 5.0 : static_cast<double>(k) * dt, 1e-12) << "row " << k << ", dt " << dt;
  }
}

TEST(OutputRows, AnIntervalWritesOneRowAtTheFirstStepOfEachMultiple)
{
  // 1 ms rows from 0.3 ms steps: the rows fall at 0, then the first step at or after each millisecond
  const std::vector<double> t = rowTimes(3e-4, 2.0, 1e-3);
  ASSERT_EQ(t.size(), 2001u);
  for (size_t k = 1; k < t.size(); ++k)
  {
    const double due = static_cast<double>(k) * 1e-3;
    ASSERT_GE(t[k], due - 1e-12) << "row " << k;
    ASSERT_LT(t[k], std::min(due + 3e-4, 2.0) + 1e-12) << "row " << k;
  }
}
