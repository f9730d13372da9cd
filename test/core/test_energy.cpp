// The energy account (core/solvers/energy.h) and the step control built on it: each power against the rate of the
// energy it stands for, the account closing as the step shrinks, a structure at rest staying put under adaptive
// steps, and an impact's rebound against the exact law.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include <gtest/gtest.h>

#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/oracle/energy_meter.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
std::string scenePath(const std::string& name)
{
  return std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name;
}

RunResult runQuietly(const Model& m)
{
  return runAnalysis(m, [](const State&) {});
}

/// The largest distance any node moved between q0 and q1 (m).
double largestNodeMotion(const Model& m, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1)
{
  double d = 0.0;
  for (const Node& n : m.nodes)
    d = std::max(d, (pointPosition(m, n.point, q1) - pointPosition(m, n.point, q0)).norm());
  return d;
}

/// A 1 kg steel ball (radius 31.2 mm) dropped from 5 cm onto a steel ground, for `duration` s.
Model droppedBall(double restitution, bool adaptive, double duration)
{
  const std::string yaml = R"(
name: ball
materials:
  steel: {youngs_modulus: 210.0e9, poisson_ratio: 0.3, density: 7850.0}
nodes:
  P: {position: [0.0, 0.0, 0.0812], mass: 1.0, radius: 0.0312, material: steel}
gravity: {enabled: true}
ground: {enabled: true, material: steel, restitution: )" +
                           std::to_string(restitution) +
                           R"(}
analysis: {type: dynamic, duration: )" +
                           std::to_string(duration) +
                           R"(, output_interval: 0.01}
solver: {adaptive: )" + (adaptive ? "true" : "false") +
                           "}\n";
  return loadSceneFromString(yaml, "ball");
}

/// The ball's speed just before its first contact and just after it leaves the ground (m/s).
struct Bounce
{
  double in = 0.0, out = 0.0;
};
Bounce firstBounce(const Model& m, RunResult* result = nullptr)
{
  Bounce b;
  bool touched = false, left = false;
  double before = 0.0;
  const RunResult r = runAnalysis(
      m, [](const State&) {}, {},
      [&](const State& s, const std::vector<ContactPairState>* contacts)
      {
        const bool touching = contacts && !contacts->empty();
        const double vz = s.qd(2);
        if (!touched && touching)
        {
          touched = true;
          b.in = -before;
        }
        else if (touched && !touching && !left)
        {
          left = true;
          b.out = vz;
        }
        before = vz;
      });
  EXPECT_TRUE(r.summary.ok()) << r.summary.message;
  EXPECT_TRUE(touched && left);
  if (result)
    *result = r;
  return b;
}
}  // namespace

TEST(EnergyPoint, CablePullInPowerIsTheElasticEnergysRateAtFixedPositions)
{
  // the pinned prism's verticals pulled in by one actuator: at fixed positions the actuator's power is
  // dV/ds s_dot, the rest length and the material cable's stiffness EA / l0 both changing with s
  Model m = loadScene(scenePath("prism_pinned.yaml"));
  ASSERT_EQ(m.actuators.size(), 1u);
  const System sys(m);
  BodyState s = bodyInitialState(m);
  s.qd.setZero(m.nq);
  s.lambda.setZero(sys.nLambda());
  for (const double value : { 0.0005, 0.0015 })
  {
    const double rate = 0.3, ds = 1e-7;
    s.u = ActuationValues{ ActuationValue{ value, rate, 0.0 } };
    const EnergyPoint p = energyPoint(sys, s, {});
    BodyState plus = s, minus = s;
    plus.u[0].value += ds;
    minus.u[0].value -= ds;
    const double dv_ds = (energyPoint(sys, plus, {}).elastic - energyPoint(sys, minus, {}).elastic) / (2.0 * ds);
    ASSERT_GT(std::abs(dv_ds), 1.0) << "the pull-in must load the cables";
    EXPECT_NEAR(p.actuator_power, dv_ds * rate, 1e-6 * std::abs(dv_ds * rate)) << "s = " << value;
    EXPECT_EQ(p.damping_power, 0.0);
    EXPECT_EQ(p.contact_power, 0.0);
  }
}

TEST(EnergyAccount, ClosesAsTheStepShrinks)
{
  // the linear-law quadruplex driven into contact: thousands of joules of actuator work through driven
  // constraint rows, hundreds dissipated by the contacts' dampers; the rest, the integrator's, vanishes with h
  // (Newmark gamma = 0.6 is first order, but the account's own trapezoidal sums are second order)
  Model m = loadScene(scenePath("quadruplex_linear_contact.yaml"));
  double numerical[2], work[2];
  const double steps[2] = { 1e-4, 2.5e-5 };
  for (int i = 0; i < 2; ++i)
  {
    m.solver.dt = steps[i];
    const RunResult r = runQuietly(m);
    ASSERT_TRUE(r.summary.ok()) << r.summary.message;
    const EnergyAccount& e = r.energy;
    numerical[i] = e.numerical_dissipation;
    work[i] = e.actuator_work;
    EXPECT_GT(e.contact_dissipation, 0.01 * e.actuator_work);
    EXPECT_EQ(e.damping_dissipation, 0.0);
    std::printf("[ measured ] dt %g s: actuator work %.6f J, contact %.6f J, numerical %.3e J\n", steps[i],
                e.actuator_work, e.contact_dissipation, e.numerical_dissipation);
  }
  EXPECT_GT(work[0], 1000.0);
  EXPECT_NEAR(work[0], work[1], 1e-3 * work[1]);
  EXPECT_LT(std::abs(numerical[1]), 0.1 * std::abs(numerical[0]));
  EXPECT_LT(std::abs(numerical[1]), 1e-6 * work[1]);
}

TEST(EnergyAccount, PulledInCablesWorkIsWhatTheStructureStores)
{
  // the pinned prism tensioned by pulling its verticals in, slowly: the actuator's work goes into the cables
  Model m = loadScene(scenePath("prism_pinned.yaml"), { { "analysis.type", "dynamic" },
                                                        { "analysis.duration", "0.4" },
                                                        { "actuation.speed", "0.005" },
                                                        { "actuation.blend_time", "0.05" },
                                                        { "solver.dt", "5e-5" } });
  const RunResult r = runQuietly(m);
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  const EnergyAccount& e = r.energy;
  ASSERT_GT(e.actuator_work, 1e-3);
  EXPECT_LT(std::abs(e.numerical_dissipation), 1e-3 * e.actuator_work)
      << "work " << e.actuator_work << " J, stored " << e.now.elastic - e.start.elastic << " J";
}

TEST(AdaptiveSteps, AStructureAtRestStaysPut)
{
  // the tower with every member at its free length and no gravity, and the free prism in its self-stress, each
  // left alone for 60 s: nothing moves them (at steps of up to 10 ms the tower's cables, switching between slack
  // and taut, used to pump round-off up to a drift of millimetres)
  for (const std::string& name : { std::string("tower.yaml"), std::string("prism.yaml") })
  {
    Model m = loadScene(scenePath(name), { { "analysis.type", "dynamic" },
                                           { "solver.adaptive", "true" },
                                           { "actuation.start_time", "1000" },
                                           { "analysis.duration", "60" },
                                           { "analysis.output_interval", "1" } });
    const RunResult r = runQuietly(m);
    ASSERT_TRUE(r.summary.ok()) << name << ": " << r.summary.message;
    const double moved = largestNodeMotion(m, m.q0, r.final_state.q);
    std::printf("[ measured ] %s at rest for 60 s: nodes moved %.3e m, %ld steps (%ld refused for energy)\n",
                name.c_str(), moved, r.adaptive.accepted, r.adaptive.rejected_energy);
    EXPECT_LE(moved, 1e-9) << name;
  }
}

TEST(AdaptiveSteps, TheSixBarRobotSettledOnTheGroundStaysPut)
{
  // the six-bar robot starts touching the ground unloaded: it settles on its rubber feet (friction holds it)
  // within 30 s, and from there its nodes stay put for 60 s (a strut may spin about its axis: no node moves)
  Model m = loadScene(scenePath("six_bar.yaml"), { { "solver.adaptive", "true" },
                                                   { "actuation.sequence", "[{time: 1000, targets: {C14: 0.4}}]" } });
  DynamicsSolver solver(m, m.solver);
  const ActuationLaw law = [&m](double t) { return scheduledActuation(m, t); };
  State s = initialState(m);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  AdaptiveStepper stepper(solver, m.solver);
  ASSERT_TRUE(stepper.advanceTo(s, 30.0, law).ok());
  const Eigen::VectorXd settled = s.q;
  ASSERT_TRUE(stepper.advanceTo(s, 90.0, law).ok());
  const double moved = largestNodeMotion(m, settled, s.q);
  std::printf("[ measured ] six_bar settled, then 60 s at rest: nodes moved %.3e m\n", moved);
  EXPECT_LE(moved, 1e-9);
}

TEST(AdaptiveSteps, ASteelBallReboundsAsTheExactLawSays)
{
  // Hertz sphere on a plane with Lankarani-Nikravesh damping: the contact lasts about 0.22 ms; the exact law's
  // rebound comes from a fine Runge-Kutta integration of the one-degree-of-freedom impact
  for (const double e : { 1.0, 0.8 })
  {
    const Model m = droppedBall(e, true, 0.15);
    ASSERT_EQ(m.ground_contacts.size(), 1u);
    const Bounce b = firstBounce(m);
    const double exact = reboundOfOneDegreeOfFreedom(1.0, m.ground_contacts[0].stiffness, b.in, e);
    std::printf("[ measured ] restitution %.1f: impact %.5f m/s, rebound ratio %.5f, exact law %.5f\n", e, b.in,
                b.out / b.in, exact);
    // (gravity acts during the contact too: 9.81 m/s^2 for 0.22 ms is 0.2 % of the speed)
    EXPECT_NEAR(b.out / b.in, exact, 0.005 * exact) << "restitution " << e;
  }
}

TEST(FixedSteps, AnUnderResolvedImpactIsReported)
{
  // at the default fixed step (0.2 ms) the same impact falls within one or two steps: the run says so
  const Model m = droppedBall(1.0, false, 0.15);
  RunResult r;
  const Bounce b = firstBounce(m, &r);
  std::printf("[ measured ] fixed steps: rebound ratio %.4f\n", b.out / b.in);
  const auto& w = r.summary.warnings;
  EXPECT_TRUE(std::any_of(w.begin(), w.end(),
                          [](const std::string& s) { return s.find("impacts under-resolved") != std::string::npos; }));
  EXPECT_GT(r.energy.contact_unresolved_energy, 0.01 * r.energy.peak_mechanical);
}

TEST(FixedSteps, AResolvedRunIsNotReported)
{
  // the prism's smooth lift at its own fixed step: nothing under-resolved, no energy warning
  const Model m = loadScene(scenePath("prism.yaml"));
  const RunResult r = runQuietly(m);
  ASSERT_TRUE(r.summary.ok());
  for (const std::string& w : r.summary.warnings)
    EXPECT_EQ(w.find("energy"), std::string::npos) << w;
  EXPECT_GE(r.energy.numerical_dissipation, 0.0);
}
