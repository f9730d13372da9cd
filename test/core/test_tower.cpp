// The four-stage clustered tower (paper Sec. 6.2; layout in docs/scenes.md): its layout, the quasi-static fold
// with and without contact against the paper's contact onset, and short dynamic folds.
#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/scene/scene.h"
#include "contact_checks.h"

using namespace active_tensegrity::core;

namespace
{
Model tower(const std::vector<Override>& overrides = {})
{
  return loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/tower.yaml", overrides);
}

struct Path
{
  std::vector<double> actuation, height, gap, normal;
  std::vector<int> contacts;
  RunResult result;
};

Path run(const Model& model)
{
  Path p;
  p.result = runAnalysis(model,
                         [&](const State& s)
                         {
                           p.actuation.push_back(s.u[0].value);
                           p.height.push_back(structureHeight(model, s.q));
                           p.gap.push_back(minimumGap(model, s.q));
                           const std::vector<ContactPairState> c = activeContacts(model, s);
                           p.contacts.push_back(static_cast<int>(c.size()));
                           double fn = 0.0;
                           for (const ContactPairState& x : c)
                             fn = std::max(fn, x.normal_force);
                           p.normal.push_back(fn);
                           EXPECT_TRUE(s.q.allFinite() && s.qd.allFinite() && s.natural.lambda.allFinite()) << s.t;
                         });
  return p;
}

/// y at x = at, interpolated linearly in a table with increasing x (clamped at its ends).
double interpolate(const std::vector<double>& x, const std::vector<double>& y, double at)
{
  size_t k = 1;
  while (k + 1 < x.size() && x[k] < at)
    ++k;
  return y[k - 1] + (y[k] - y[k - 1]) * (at - x[k - 1]) / (x[k] - x[k - 1]);
}

/// x where y first falls below level (linear interpolation), or NaN.
double firstBelow(const std::vector<double>& x, const std::vector<double>& y, double level)
{
  for (size_t i = 1; i < x.size(); ++i)
    if (y[i - 1] >= level && y[i] < level)
      return x[i - 1] + (x[i] - x[i - 1]) * (y[i - 1] - level) / (y[i - 1] - y[i]);
  return std::nan("");
}
}  // namespace

TEST(Tower, LayoutIsThatOfThePapersFourStageTower)
{
  const Model m = tower();
  int struts = 0, sliding = 0, springs = 0, joints = 0, pins = 0;
  for (const Body& b : m.bodies)
    if (b.kind == BodyKind::kStrut)
    {
      ++struts;
      EXPECT_NEAR(b.length, std::sqrt(1.5), 1e-12) << b.name;
      EXPECT_NEAR(b.mass, 9.86, 0.01) << b.name << ": steel core plus rubber sleeve";
      EXPECT_DOUBLE_EQ(b.radius(), 0.04);
    }
  for (const Cable& c : m.cables)
  {
    sliding += c.sliding() ? 1 : 0;
    springs += c.area == 0.0 ? 1 : 0;
    if (c.sliding())
    {
      EXPECT_EQ(c.points.size(), 6u) << c.name << ": top, small, big, small, ground pulley, driven body";
    }
  }
  for (const Constraint& c : m.constraints)
  {
    joints += c.name.find(".joint") != std::string::npos ? 1 : 0;
    pins += c.name.find(".pin") != std::string::npos ? 1 : 0;
  }
  EXPECT_EQ(struts, 16);
  EXPECT_EQ(sliding, 4);
  EXPECT_EQ(springs, 8);
  EXPECT_EQ(joints, 12);
  EXPECT_EQ(pins, 4);
  EXPECT_EQ(m.checkedPairList().size(), 16u);
  EXPECT_EQ(m.actuators.size(), 4u);
  EXPECT_EQ(m.layers.size(), 4u);
  EXPECT_DOUBLE_EQ(structureHeight(m, m.q0), 2.0);
  // unstressed at the start: every member at its free length
  const State s = initialState(m);
  EXPECT_EQ(slackCables(m, s), static_cast<int>(m.cables.size()));
}

TEST(Tower, QuasiStaticFoldMeetsThePapersContactOnsetAndContactHoldsTheStruts)
{
  // 5 mm load steps; the study (scripts/tower_study) uses 1 mm
  const Path free = run(tower({ { "contact.enabled", "false" }, { "analysis.steps", "300" } }));
  ASSERT_TRUE(free.result.summary.ok()) << free.result.summary.message;
  const double onset = firstBelow(free.actuation, free.gap, 0.0);
  const double onset_height = interpolate(free.actuation, free.height, onset);
  std::cout << "[ measured ] tower contact onset: actuation " << onset << " m, height " << onset_height
            << " m (paper 0.638 m, 0.799 m)\n";
  EXPECT_NEAR(onset, 0.638, 0.002);
  EXPECT_NEAR(onset_height, 0.799, 0.003);
  // without contact the struts pass through each other and the tower collapses soon after
  EXPECT_LT(firstBelow(free.actuation, free.height, 0.05), onset + 0.2);

  const Path touch = run(tower({ { "analysis.steps", "300" } }));
  ASSERT_TRUE(touch.result.summary.ok()) << touch.result.summary.message;
  const double radius = 0.04;
  for (size_t i = 0; i < touch.actuation.size(); ++i)
  {
    EXPECT_GT(touch.gap[i], -0.1 * radius) << "overlap above a tenth of the radius at " << touch.actuation[i];
    if (touch.actuation[i] < onset - 0.005)
    {
      EXPECT_EQ(touch.contacts[i], 0) << touch.actuation[i];
    }
    if (touch.actuation[i] > onset + 0.005)
    {
      EXPECT_EQ(touch.contacts[i], 16) << "the symmetric fold touches every checked pair at once";
    }
  }
  const double half = firstBelow(touch.actuation, touch.height, 0.5);
  std::cout << "[ measured ] tower with contact: height 0.5 m at actuation " << half << " m (paper 1.448 m)\n";
  EXPECT_NEAR(half, 1.448, 0.03);
  EXPECT_LT(touch.height.back(), 0.5);
}

TEST(Tower, FastDynamicFoldMakesFiniteContactForces)
{
  // V = 5 m/s: the struts first meet at about 0.35 s
  const Path p = run(tower({ { "analysis.type", "dynamic" },
                             { "actuation.speed", "5" },
                             { "analysis.duration", "0.45" },
                             { "analysis.output_interval", "0.005" } }));
  ASSERT_TRUE(p.result.summary.ok()) << p.result.summary.message;
  int most = 0;
  double peak = 0.0;
  for (size_t i = 0; i < p.contacts.size(); ++i)
  {
    most = std::max(most, p.contacts[i]);
    peak = std::max(peak, p.normal[i]);
    ASSERT_TRUE(std::isfinite(p.normal[i]));
  }
  std::cout << "[ measured ] tower V = 5 m/s, 0.45 s: up to " << most << " pairs in contact, largest normal force "
            << peak << " N (output steps)\n";
  EXPECT_GT(most, 0);
  EXPECT_GT(peak, 1000.0) << "a fast fold hits far harder than the quasi-static contact (about 100 N)";
  EXPECT_LT(peak, 1e6);
}

TEST(Tower, SlowDynamicFoldFollowsTheQuasiStaticHeights)
{
  // The unstressed tower folds along a soft mode (period of seconds, held by the 2000 N/m springs): at
  // V = 0.5 m/s the dynamic heights run up to 0.37 m above the quasi-static ones; at V = 0.02 m/s the
  // start excites only a small oscillation about them (undamped: no cable damping in the scene).
  const Model statics =
      tower({ { "contact.enabled", "false" }, { "analysis.steps", "40" }, { "analysis.max_actuation", "0.2" } });
  const Path qs = run(statics);
  ASSERT_TRUE(qs.result.summary.ok()) << qs.result.summary.message;
  // V = 0.02 m/s to 0.2 m (before contact): 10 s, at dt = 1e-3 s (slow enough for that step)
  const Path dyn = run(tower({ { "analysis.type", "dynamic" },
                               { "actuation.speed", "0.02" },
                               { "solver.dt", "1e-3" },
                               { "analysis.max_actuation", "0.2" },
                               { "analysis.duration", "10.0" },
                               { "analysis.output_interval", "0.1" } }));
  ASSERT_TRUE(dyn.result.summary.ok()) << dyn.result.summary.message;
  double worst = 0.0;
  for (size_t i = 0; i < dyn.actuation.size(); ++i)
  {
    const double h = interpolate(qs.actuation, qs.height, dyn.actuation[i]);
    worst = std::max(worst, std::abs(dyn.height[i] - h));
  }
  std::cout << "[ measured ] tower V = 0.02 m/s: largest height difference to the quasi-static fold " << worst
            << " m (the fold lowers it by 0.3 m)\n";
  EXPECT_LT(worst, 0.06);
}

TEST(Tower, EveryStepsContactsAreThoseOfAFullSearch)
{
  // At every step of a fast fold through contact, two shortcuts give exactly what a full search gives: ContactScan
  // (which keeps its candidates while the bodies stay within a tenth of a contact radius of where it last looked) on
  // the body poses, against a full broad and narrow phase over them; and the contacts the dynamics solver formed at
  // the step's end from its near list (runAnalysis hands them to on_step; the peaks use them), against every checked
  // pair evaluated from its natural coordinates
  const Model model = tower({ { "analysis.type", "dynamic" },
                              { "actuation.speed", "5" },
                              { "analysis.duration", "0.45" },
                              { "analysis.output_interval", "0.05" } });
  ContactScan scan(model);
  int steps = 0, touching = 0, given = 0;
  const RunResult result = runAnalysis(
      model, [](const State&) {}, {},
      [&](const State& s, const std::vector<ContactPairState>* contacts)
      {
        State body = s;  // (the body poses and the impact speeds alone: the scans search the poses)
        body.natural = NaturalState();
        body.natural.touching = s.natural.touching;
        const std::vector<ContactPairState> full = activeContacts(model, body);
        active_tensegrity::test::expectSameContacts(scan.active(body), full, s.t);
        if (contacts)
        {
          active_tensegrity::test::expectSameContacts(*contacts, active_tensegrity::test::searchEverySlot(model, s),
                                                      s.t);
          ++given;
        }
        ++steps;
        touching += full.empty() ? 0 : 1;
      });
  ASSERT_TRUE(result.summary.ok()) << result.summary.message;
  EXPECT_GT(steps, 2000);
  EXPECT_EQ(given, steps) << "every time step's contacts come from the solver";
  EXPECT_GT(touching, 50) << "the fold must reach contact for the comparison to mean anything";
}

TEST(Tower, AStepCallbackAsksForTheContactsWithoutChangingTheRun)
{
  // runAnalysis evaluates the step's contact forces (DynamicsSolver::contactsAt) only for an on_step that takes
  // them (not for one that takes the state alone); the steps themselves must not depend on whether anyone asked:
  // the same run, bit for bit, with fixed and adaptive steps
  for (const char* adaptive : { "false", "true" })
  {
    const Model model = tower({ { "analysis.type", "dynamic" },
                                { "actuation.speed", "5" },
                                { "analysis.duration", "0.3" },
                                { "solver.adaptive", adaptive } });
    int given = 0;
    const RunResult with = runAnalysis(
        model, [](const State&) {}, {},
        [&](const State&, const std::vector<ContactPairState>* contacts) { given += contacts != nullptr ? 1 : 0; });
    const RunResult without = runAnalysis(model, [](const State&) {});
    int states = 0;  // the callback that takes the state alone: no contacts asked for
    const RunResult state_only = runAnalysis(
        model, [](const State&) {}, {}, [&](const State&) { ++states; });
    ASSERT_TRUE(state_only.summary.ok()) << state_only.summary.message;
    EXPECT_EQ(states, with.solver_steps) << "adaptive " << adaptive;
    EXPECT_TRUE(state_only.final_state.q == without.final_state.q) << "adaptive " << adaptive;
    EXPECT_EQ(state_only.summary.iterations, without.summary.iterations) << "adaptive " << adaptive;
    ASSERT_TRUE(with.summary.ok()) << with.summary.message;
    ASSERT_TRUE(without.summary.ok()) << without.summary.message;
    EXPECT_EQ(given, with.solver_steps) << "adaptive " << adaptive;
    EXPECT_EQ(with.solver_steps, without.solver_steps) << "adaptive " << adaptive;
    EXPECT_EQ(with.summary.iterations, without.summary.iterations) << "adaptive " << adaptive;
    EXPECT_TRUE(with.final_state.q == without.final_state.q) << "adaptive " << adaptive;
    EXPECT_TRUE(with.final_state.qd == without.final_state.qd) << "adaptive " << adaptive;
    ASSERT_EQ(with.final_state.natural.touching.size(), without.final_state.natural.touching.size());
    for (size_t i = 0; i < with.final_state.natural.touching.size(); ++i)
    {
      EXPECT_EQ(with.final_state.natural.touching[i].slot, without.final_state.natural.touching[i].slot);
      EXPECT_EQ(with.final_state.natural.touching[i].speed, without.final_state.natural.touching[i].speed);
    }
  }
}

TEST(Tower, TheSolverGivesContactsOnlyForTheStateItsLastStepEndedIn)
{
  const Model model = tower({ { "analysis.type", "dynamic" }, { "actuation.speed", "5" } });
  const ActuationLaw law = [&model](double t) { return scheduledActuation(model, t); };
  DynamicsSolver solver(model, model.solver);
  State s = initialState(model);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  ASSERT_NE(solver.contactsAt(s), nullptr) << "initialize forms the start's contacts";
  EXPECT_TRUE(solver.contactsAt(s)->empty()) << "the tower starts apart";
  State other = s;
  other.natural = NaturalState();
  EXPECT_EQ(solver.contactsAt(other), nullptr) << "a state without natural coordinates";
  // fold into contact
  const std::vector<ContactPairState>* contacts = nullptr;
  for (int k = 0; k < 5000 && (!contacts || contacts->empty()); ++k)
  {
    ASSERT_TRUE(solver.step(s, model.solver.dt, law).ok());
    contacts = solver.contactsAt(s);
    ASSERT_NE(contacts, nullptr) << "t = " << s.t;
  }
  ASSERT_FALSE(contacts->empty());
  const int touching = contacts->front().pair;
  State moved = s;
  moved.qd[0] += 1e-12;
  EXPECT_EQ(solver.contactsAt(moved), nullptr) << "a velocity changed";
  moved = s;
  moved.q[1] -= 1e-12;
  EXPECT_EQ(solver.contactsAt(moved), nullptr) << "a position changed";
  moved = s;
  ASSERT_GT(moved.contactSpeed(touching), 0.0);
  for (NaturalTouch& c : moved.natural.touching)
    if (c.slot == touching)
      c.speed *= 2.0;
  EXPECT_EQ(solver.contactsAt(moved), nullptr) << "a touching pair's impact speed changed";
  moved = s;
  moved.t += 1e-9;  // callers round the time to their step grid
  EXPECT_NE(solver.contactsAt(moved), nullptr);
}
