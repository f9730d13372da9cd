// Heap allocations of the dynamics solver's step, counted by interposing malloc in this executable, and the two
// forms of an actuation law.
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "../../src/tools/heap_counter.h"  // (defines malloc, calloc and realloc for this executable)
#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/scene/scene.h"

using namespace active_tensegrity::core;
using active_tensegrity::tools::heapAllocationCount;

namespace
{
/// The tower's fast fold (five times the scene's speed): its struts touch from 0.45 s on, up to 16 pairs at once.
Model fastTowerFold()
{
  return loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/tower.yaml",
                   { parseOverride("analysis.type=dynamic"), parseOverride("actuation.speed=2.5") });
}

ActuationLaw writingLaw(const Model& m)
{
  return ActuationLaw::writing([&m](double t, ActuationValues& u) { scheduledActuation(m, t, u); });
}

/// The fold twice with one solver and one state, put back at the start for the second pass: the first pass grows
/// their buffers (contact lists, factorizations, the stepper's trial state, the state's touching contacts), the second
/// must not allocate at all. `advance(state, pass)` takes the state through the fold; the allocations of each pass
/// are counted from after initialize. Empty after a fatal failure.
template <class Advance>
std::vector<long> allocationsOfTwoPasses(const Model& m, DynamicsSolver& solver, const ActuationLaw& law,
                                         const Advance& advance)
{
  std::vector<long> allocations;
  State s = initialState(m);
  for (int pass = 0; pass < 2; ++pass)
  {
    s.t = 0.0;
    s.q = m.q0;
    s.qd.setZero();
    EXPECT_TRUE(solver.initialize(s, law).ok());
    solver.resetTimings();
    const long before = heapAllocationCount();
    advance(s, pass);
    if (::testing::Test::HasFatalFailure())
      return {};
    allocations.push_back(heapAllocationCount() - before);
    EXPECT_GE(solver.timings().most_touching, 2) << "the fold must reach contact for this test to mean anything";
    EXPECT_GT(solver.timings().factorizations, 1) << "and build more than one Newton matrix";
  }
  return allocations;
}
}  // namespace

TEST(Allocations, FixedStepsThroughContactAllocateNothingOnceTheirBuffersHaveGrown)
{
  if (heapAllocationCount() < 0)
    GTEST_SKIP() << "built with AddressSanitizer: allocations are not counted";
  const Model m = fastTowerFold();
  DynamicsSolver solver(m, m.solver);
  const ActuationLaw law = writingLaw(m);
  constexpr int kSteps = 4000;  // 0.8 s: the struts come into contact, slide and part
  const std::vector<long> allocations =
      allocationsOfTwoPasses(m, solver, law,
                             [&](State& s, int pass)
                             {
                               for (int k = 0; k < kSteps; ++k)
                               {
                                 const Summary sum = solver.step(s, m.solver.dt, law);
                                 ASSERT_TRUE(sum.ok()) << "pass " << pass << ", t = " << s.t << ": " << sum.message;
                               }
                             });
  ASSERT_EQ(allocations.size(), 2u);
  EXPECT_EQ(allocations[1], 0) << "first pass: " << allocations[0] << " allocations over " << kSteps << " steps";
}

TEST(Allocations, AdaptiveStepsThroughContactAllocateNothingOnceTheirBuffersHaveGrown)
{
  if (heapAllocationCount() < 0)
    GTEST_SKIP() << "built with AddressSanitizer: allocations are not counted";
  Model m = fastTowerFold();
  m.solver.adaptive = true;
  DynamicsSolver solver(m, m.solver);
  const ActuationLaw law = writingLaw(m);
  // as above, with the error control's steps: refused steps, step-size changes and the exact factorizations
  // that they ask for
  AdaptiveStepper stepper(solver, m.solver);  // (one for both passes: its trial state is a buffer too)
  const std::vector<long> allocations =
      allocationsOfTwoPasses(m, solver, law,
                             [&](State& s, int pass)
                             {
                               for (int k = 1; k <= 80; ++k)  // to 0.8 s in outputs of 0.01 s
                               {
                                 const Summary sum = stepper.advanceTo(s, 0.01 * k, law);
                                 ASSERT_TRUE(sum.ok()) << "pass " << pass << ", t = " << s.t << ": " << sum.message;
                               }
                             });
  ASSERT_EQ(allocations.size(), 2u);
  EXPECT_GT(stepper.stats().rejected_error + stepper.stats().rejected_onset, 1) << "some steps refused";
  EXPECT_EQ(allocations[1], 0) << "first pass: " << allocations[0] << " allocations";
}

TEST(Allocations, AReturningLawCostsOneAllocationPerStep)
{
  if (heapAllocationCount() < 0)
    GTEST_SKIP() << "built with AddressSanitizer: allocations are not counted";
  const Model m = fastTowerFold();
  DynamicsSolver solver(m, m.solver);
  const ActuationLaw law = [&m](double t) { return scheduledActuation(m, t); };
  State s = initialState(m);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  for (int k = 0; k < 50; ++k)
    ASSERT_TRUE(solver.step(s, m.solver.dt, law).ok());
  const long before = heapAllocationCount();
  constexpr int kSteps = 20;  // long before contact: nothing else in the step allocates
  for (int k = 0; k < kSteps; ++k)
    ASSERT_TRUE(solver.step(s, m.solver.dt, law).ok());
  EXPECT_EQ(heapAllocationCount() - before, kSteps);
}

TEST(ActuationLaw, ItsTwoFormsGiveTheSameValuesAndTheSameRunBitForBit)
{
  const Model m = fastTowerFold();
  const ActuationLaw writing = writingLaw(m);
  const ActuationLaw returning = [&m](double t) { return scheduledActuation(m, t); };
  ActuationValues u(7, ActuationValue{ 9.0, 9.0, 9.0 });  // the wrong size and values: resized and overwritten
  for (double t : { 0.0, 0.013, 0.05, 0.2, 3.0 })
  {
    writing(t, u);
    const ActuationValues r = returning(t);
    ASSERT_EQ(u.size(), m.actuators.size());
    ASSERT_EQ(r.size(), m.actuators.size());
    for (size_t a = 0; a < u.size(); ++a)
    {
      EXPECT_EQ(u[a].value, r[a].value) << t;
      EXPECT_EQ(u[a].rate, r[a].rate) << t;
      EXPECT_EQ(u[a].accel, r[a].accel) << t;
    }
    EXPECT_EQ(writing(t)[0].value, r[0].value);  // the returning call of a writing law
  }
  EXPECT_GT(returning(0.2)[0].value, 0.0);  // the ramp has begun by then
  State a = initialState(m), b = initialState(m);
  DynamicsSolver sa(m, m.solver), sb(m, m.solver);
  ASSERT_TRUE(sa.initialize(a, writing).ok());
  ASSERT_TRUE(sb.initialize(b, returning).ok());
  for (int k = 0; k < 300; ++k)
  {
    ASSERT_TRUE(sa.step(a, m.solver.dt, writing).ok());
    ASSERT_TRUE(sb.step(b, m.solver.dt, returning).ok());
  }
  EXPECT_EQ(a.q, b.q);
  EXPECT_EQ(a.natural.lambda, b.natural.lambda);
  EXPECT_EQ(a.u[0].value, b.u[0].value);
}
