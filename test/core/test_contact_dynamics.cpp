// Contact in time integration: the Hertz impact of two crossed free cylinders against its closed-form
// solution, the Lankarani-Nikravesh rebound against an independent 1-D integration and against c_e,
// energy kept by frictionless elastic contact and never gained with friction, momentum kept, layered struts
// (cores inside sleeves) stopped at the energy balance's overlap, the
// full Newton Jacobian with contact against finite differences, and no step that tunnels.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/oracle/body_dynamics.h"
#include "fd_check.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
constexpr double kSpeed = 1.0;  // m/s, approach speed

SolverOptions options(double dt)
{
  return trapezoidalOptions(dt, 1e-13);
}

ActuationLaw noActuation()
{
  return [](double) { return ActuationValues(); };
}

// strut A along x at the origin, strut B along y (or at `angle` to A) above it, moving down at kSpeed,
// surfaces `gap` apart; both free (only the quaternion norms)
Model crossedCylinders(double restitution, double mu, double angle_deg = 90.0, double offset_a = 0.0)
{
  Model m;
  m.name = "impact";
  m.bodies.push_back(makeStrut("A", 1.0, 0.02, 7800.0));
  m.bodies.push_back(makeStrut("B", 1.0, 0.02, 7800.0));
  for (Body& b : m.bodies)
  {
    b.layers.back().youngs_modulus = 2.0e8;
    b.layers.back().poisson_ratio = 0.3;
  }
  for (int i = 0; i < 2; ++i)
  {
    Constraint c;
    c.kind = Constraint::Kind::kQuatNorm;
    c.body = i;
    m.constraints.push_back(c);
  }
  finalizeModel(m);
  m.contact.enabled = true;
  m.contact.restitution = restitution;
  m.contact.friction = mu;
  m.listed_pairs.push_back(makeStrutPair(m, 0, 1));
  const double gap = 5e-4;
  const double a = angle_deg * M_PI / 180.0;
  m.q0.setZero(m.nq);
  m.q0.segment<3>(0) = Vec3(offset_a, 0.0, 0.0);
  m.q0.segment<4>(3) = thetaFromZAxis(Vec3::UnitX());
  m.q0.segment<3>(7) = Vec3(0.0, 0.0, 0.04 + gap);
  m.q0.segment<4>(10) = thetaFromZAxis(Vec3(std::cos(a), std::sin(a), 0.0));
  return m;
}

struct ImpactRecord
{
  double max_penetration = 0.0;
  double max_force = 0.0;
  double t_start = -1.0, t_end = -1.0;  // contact onset and separation, interpolated
  double rebound_ratio = 0.0;           // relative normal speed after / before
  double energy_start = 0.0, energy_end = 0.0, energy_max_error = 0.0;
  Vec3 momentum_start = Vec3::Zero(), momentum_end = Vec3::Zero();
  bool ok = true;
};

Vec3 momentum(const Model& m, const State& s)
{
  Vec3 p = Vec3::Zero();
  for (const Body& b : m.bodies)
    p += b.mass * s.qd.segment<3>(b.offset);
  return p;
}

ImpactRecord simulateImpact(const Model& m, double dt, double duration, const Vec3& velocity_b)
{
  DynamicsSolver solver(m, options(dt));
  State s = initialState(m);
  s.qd.segment<3>(7) = velocity_b;
  ImpactRecord rec;
  rec.ok = solver.initialize(s, noActuation()).ok();
  const System sys(m);
  rec.energy_start = sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q);
  rec.momentum_start = momentum(m, s);
  const double v_in = (s.qd.segment<3>(0) - s.qd.segment<3>(7)).dot(contactGeometry(m, 0, s.q).normal);
  double prev_gap = contactGeometry(m, 0, s.q).gap;
  const long n = std::lround(duration / dt);
  for (long k = 0; k < n && rec.ok; ++k)
  {
    const double t0 = s.t;
    rec.ok = solver.step(s, dt, noActuation()).ok();
    const ContactPairState g = contactGeometry(m, 0, s.q);
    if (prev_gap >= 0.0 && g.gap < 0.0 && rec.t_start < 0.0)
      rec.t_start = t0 + dt * prev_gap / (prev_gap - g.gap);
    if (prev_gap < 0.0 && g.gap >= 0.0 && rec.t_end < 0.0)
      rec.t_end = t0 + dt * prev_gap / (prev_gap - g.gap);
    prev_gap = g.gap;
    rec.max_penetration = std::max(rec.max_penetration, g.penetration);
    for (const ContactPairState& c : activeContacts(m, s))
      rec.max_force = std::max(rec.max_force, c.normal_force);
    const double e = sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q);
    rec.energy_max_error = std::max(rec.energy_max_error, std::abs(e - rec.energy_start));
  }
  rec.energy_end = sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q);
  rec.momentum_end = momentum(m, s);
  const double v_out = (s.qd.segment<3>(0) - s.qd.segment<3>(7)).dot(contactGeometry(m, 0, s.q).normal);
  rec.rebound_ratio = -v_out / v_in;
  return rec;
}

}  // namespace

TEST(HertzImpact, CrossedCylindersMatchTheClosedFormSolution)
{
  const Model m = crossedCylinders(1.0, 0.0);
  const ImpactRecord r = simulateImpact(m, 1e-5, 0.012, Vec3(0.0, 0.0, -kSpeed));
  ASSERT_TRUE(r.ok);
  // Hertz: m* d'' = -K d^1.5 from d' = v: d_max = (5 m* v^2 / (4 K))^(2/5), F_max = K d_max^1.5,
  // duration 2 d_max / v * int_0^1 dx / sqrt(1 - x^2.5) = 2.9432 d_max / v
  const double mstar = m.bodies[0].mass * m.bodies[1].mass / (m.bodies[0].mass + m.bodies[1].mass);
  const double k = m.checkedPairList()[0].stiffness90;
  const double dmax = std::pow(5.0 * mstar * kSpeed * kSpeed / (4.0 * k), 0.4);
  const double fmax = k * std::pow(dmax, 1.5);
  const double tc = 2.9432 * dmax / kSpeed;
  std::printf("[ measured ] penetration %.5g m (closed form %.5g), force %.5g N (%.5g), duration %.5g s (%.5g), "
              "rebound %.5f\n",
              r.max_penetration, dmax, r.max_force, fmax, r.t_end - r.t_start, tc, r.rebound_ratio);
  EXPECT_NEAR(r.max_penetration, dmax, 0.002 * dmax);
  EXPECT_NEAR(r.max_force, fmax, 0.002 * fmax);
  ASSERT_GT(r.t_start, 0.0);
  ASSERT_GT(r.t_end, r.t_start);
  EXPECT_NEAR(r.t_end - r.t_start, tc, 0.002 * tc);
  EXPECT_NEAR(r.rebound_ratio, 1.0, 0.01);
  // no friction, no damping: nothing rotates, momentum is kept
  EXPECT_LT((r.momentum_end - r.momentum_start).norm(), 1e-9 * r.momentum_start.norm());
}

class LankaraniNikravesh : public ::testing::TestWithParam<double>
{
};

TEST_P(LankaraniNikravesh, ReboundMatchesTheOneDegreeOfFreedomModelAndRestitution)
{
  const double ce = GetParam();
  const Model m = crossedCylinders(ce, 0.0);
  const ImpactRecord r = simulateImpact(m, 1e-5, 0.012, Vec3(0.0, 0.0, -kSpeed));
  ASSERT_TRUE(r.ok);
  const double mstar = 0.5 * m.bodies[0].mass;
  const double exact = reboundOfOneDegreeOfFreedom(mstar, m.checkedPairList()[0].stiffness90, kSpeed, ce);
  std::printf("[ measured ] c_e %.2f: rebound %.5f, 1-D model %.5f\n", ce, r.rebound_ratio, exact);
  // the multibody run reproduces the 1-D model of its own force law
  EXPECT_NEAR(r.rebound_ratio, exact, 5e-3);
  // and the model's design value c_e, to the accuracy of Lankarani and Nikravesh's derivation
  // (it assumes small losses: the effective restitution exceeds c_e as c_e falls)
  EXPECT_NEAR(r.rebound_ratio, ce, ce >= 0.9 ? 0.02 : 0.06);
  EXPECT_GE(r.rebound_ratio, ce - 0.005);
  EXPECT_LT(r.energy_end, r.energy_start);
}

INSTANTIATE_TEST_SUITE_P(Contact, LankaraniNikravesh, ::testing::Values(0.95, 0.9, 0.8));

class LinearImpactTest : public ::testing::TestWithParam<double>
{
};

TEST_P(LinearImpactTest, CrossedCylindersMatchTheClosedFormSpringDashpot)
{
  // the linear law (MuJoCo's contact) at damping ratio xi: penetration, peak force, how long the force acts and
  // the rebound against the closed form of a mass on a spring-dashpot that never pulls
  const double xi = GetParam();
  Model m = crossedCylinders(1.0, 0.0);
  const double mstar = 0.5 * m.bodies[0].mass, k = 1e6;
  m.contact.law = ContactLaw::kLinear;
  m.contact.linear_stiffness = k;
  m.contact.linear_damping = 2.0 * xi * std::sqrt(k * mstar);
  m.analysis.type = AnalysisType::kDynamic;  // (activeContacts reports the damped force)
  // (2 us: the damper's force jumps to c v at the onset, a first-order error of about c dt / m in the speed)
  const ImpactRecord r = simulateImpact(m, 2e-6, 0.012, Vec3(0.0, 0.0, -kSpeed));
  ASSERT_TRUE(r.ok);
  const LinearImpact exact = linearImpact(mstar, k, m.contact.linear_damping, kSpeed);
  std::printf("[ measured ] xi %.2f: penetration %.6g m (closed form %.6g), force %.6g N (%.6g), rebound %.5f "
              "(%.5f)\n",
              xi, r.max_penetration, exact.max_penetration, r.max_force, exact.max_force, r.rebound_ratio,
              exact.rebound);
  EXPECT_NEAR(r.max_penetration, exact.max_penetration, 2e-3 * exact.max_penetration);
  EXPECT_NEAR(r.max_force, exact.max_force, 2e-3 * exact.max_force);
  EXPECT_NEAR(r.rebound_ratio, exact.rebound, 2e-3);
  ASSERT_GT(r.t_start, 0.0);
  if (xi == 0.0)  // elastic: the overlap ends when the force does, after half a period
  {
    EXPECT_NEAR(r.t_end - r.t_start, exact.force_time, 2e-3 * exact.force_time);
    EXPECT_NEAR(r.energy_end, r.energy_start, 1e-4 * r.energy_start);
  }
  EXPECT_LT((r.momentum_end - r.momentum_start).norm(), 1e-9 * r.momentum_start.norm());
}

INSTANTIATE_TEST_SUITE_P(Contact, LinearImpactTest, ::testing::Values(0.0, 0.1, 0.4));

TEST(ContactEnergy, FrictionlessElasticObliqueImpactKeepsEnergy)
{
  // crossing at 60 degrees, off the centres and with sideways motion: the struts turn and slide
  const Model m = crossedCylinders(1.0, 0.0, 60.0, 0.2);
  const ImpactRecord r = simulateImpact(m, 1e-5, 0.012, Vec3(0.3, -0.2, -kSpeed));
  ASSERT_TRUE(r.ok);
  ASSERT_GT(r.max_force, 0.0);
  std::printf("[ measured ] energy: largest error %.3g of %.5g J, final error %.3g J\n", r.energy_max_error,
              r.energy_start, r.energy_end - r.energy_start);
  EXPECT_LT(r.energy_max_error, 2e-3 * r.energy_start);
  EXPECT_LT(std::abs(r.energy_end - r.energy_start), 1e-3 * r.energy_start);
  EXPECT_LT((r.momentum_end - r.momentum_start).norm(), 1e-9 * r.momentum_start.norm());
}

TEST(ContactEnergy, FrictionNeverAddsEnergy)
{
  const Model m = crossedCylinders(1.0, 0.3, 60.0, 0.2);
  const ImpactRecord r = simulateImpact(m, 1e-5, 0.012, Vec3(0.3, -0.2, -kSpeed));
  ASSERT_TRUE(r.ok);
  const Model frictionless = crossedCylinders(1.0, 0.0, 60.0, 0.2);
  const ImpactRecord r0 = simulateImpact(frictionless, 1e-5, 0.012, Vec3(0.3, -0.2, -kSpeed));
  // friction took energy out (more than the integrator's error) and momentum is still kept
  EXPECT_LT(r.energy_end, r0.energy_end - 10.0 * r0.energy_max_error);
  EXPECT_LT((r.momentum_end - r.momentum_start).norm(), 1e-9 * r.momentum_start.norm());
}

TEST(ContactNewton, FullJacobianWithContactMatchesFiniteDifferences)
{
  // one step inside the contact with friction sliding: the body coordinates' Newton matrix over [qdd; lambda]
  const Model m = crossedCylinders(0.8, 0.3, 60.0, 0.2);
  BodyDynamicsSolver solver(m, options(1e-4));
  BodyState s = bodyInitialState(m);
  s.qd.segment<3>(7) = Vec3(0.3, -0.2, -kSpeed);
  ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
  for (int k = 0; k < 10; ++k)  // 1 ms: the surfaces overlap by about 0.5 mm
    ASSERT_TRUE(solver.step(s, 1e-4, noActuation()).ok());
  ASSERT_TRUE(contactGeometry(m, 0, s.q).active);
  ASSERT_GT(s.contact_speed[0], 0.0);
  const double h = 1e-3;  // the Jacobian of a 1 ms step from there (q moves by beta h^2 qdd)
  const ActuationValues u;
  std::mt19937 rng(5);
  const Eigen::VectorXd qdd = s.qdd + randomVector(m.nq, 1.0, rng);
  const Eigen::VectorXd lambda = s.lambda;
  const System sys(m);
  BlockSparseMatrix jac = sys.makeMatrix();
  Eigen::VectorXd r;
  solver.residualAndJacobian(s, h, u, qdd, lambda, r, &jac);
  const auto f = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd
  {
    Eigen::VectorXd out;
    solver.residualAndJacobian(s, h, u, x.head(m.nq), x.tail(sys.nLambda()), out, nullptr);
    return out;
  };
  Eigen::VectorXd x(sys.size());
  x << qdd, lambda;
  const Eigen::MatrixXd analytic = Eigen::MatrixXd(jac.matrix());
  const FdComparison c = compareJacobians(analytic, fdJacobian(f, x, 1e-2), 1e-6, 1.0);
  EXPECT_TRUE(c.ok) << c.message;
}

TEST(LayeredImpact, CoresStopTheStrutsBeyondTheSleevesAtTheEnergyBalancesOverlap)
{
  // The crossed cylinders with steel cores (radius 8 mm) in their sleeves (20 mm, E = 200 MPa): the cores meet
  // at an overlap t = 24 mm. Elastic, frictionless, contact at both centres (no rotation): the largest
  // overlap solves 1/2 mu v^2 = 2/5 K z^5/2 + 2/5 K_c (z - t)^5/2 (mu the reduced mass, K and K_c at the right
  // crossing). At 5 and 10 m/s the sleeves stop the struts; at 25 and 40 m/s the cores do, within a few mm.
  Model m = crossedCylinders(1.0, 0.0);
  for (Body& b : m.bodies)
    addSteelCore(b, 0.008);
  m.listed_pairs[0] = makeStrutPair(m, 0, 1);
  const StrutPair p = m.checkedPairList()[0];
  ASSERT_NEAR(p.core_gap, 0.024, 1e-15);
  const double mu = 0.5 * m.bodies[0].mass;
  const auto work = [&](double z)
  {
    return 0.4 * p.stiffness90 * std::pow(z, 2.5) +
           0.4 * p.core_stiffness90 * std::pow(std::max(0.0, z - p.core_gap), 2.5);
  };
  for (double v : { 5.0, 10.0, 25.0, 40.0 })
  {
    double lo = 0.0, hi = 0.04;
    for (int k = 0; k < 200; ++k)
      (work(0.5 * (lo + hi)) < 0.5 * mu * v * v ? lo : hi) = 0.5 * (lo + hi);
    const double expected = 0.5 * (lo + hi);
    const ImpactRecord r = simulateImpact(m, 1e-6, 6e-3, Vec3(0.0, 0.0, -v));
    ASSERT_TRUE(r.ok) << v;
    EXPECT_NEAR(r.max_penetration, expected, 2e-3 * expected) << v;
    EXPECT_EQ(r.max_penetration > p.core_gap, v > 20.0) << v;
    if (v > 20.0)
    {
      EXPECT_LT(r.max_penetration - p.core_gap, 5e-3) << v;  // the steel's Hertz overlap: a few mm
    }
    EXPECT_LT(r.energy_max_error, 1e-3 * r.energy_start) << v;
    EXPECT_GT(r.t_end, r.t_start) << v;  // they part again
    EXPECT_NEAR(r.rebound_ratio, 1.0, 2e-3) << v;
  }
}

TEST(ContactTunnelling, AStepThroughAStrutIsCutNotAcceptedOrEndsTheRunNamingThePair)
{
  // 30 m/s against 4 cm struts with a 5 ms step: the first try jumps through. With cuts allowed, the step is cut
  // until the contact catches it, and the struts end apart on the side they came from; with none, the step
  // fails with status passed_through, the struts named, and the state is left where it was
  const Model m = crossedCylinders(0.5, 0.0);
  for (int cuts : { 16, 0 })
  {
    SolverOptions o = options(5e-3);
    o.max_step_cuts = cuts;
    DynamicsSolver solver(m, o);
    State s = initialState(m);
    s.qd.segment<3>(7) = Vec3(0.0, 0.0, -30.0);
    ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
    if (cuts == 0)
    {
      const Eigen::VectorXd before = s.q;
      const Summary r = solver.step(s, 5e-3, noActuation());
      EXPECT_EQ(r.status, SolveStatus::kPassedThrough);
      EXPECT_NE(r.message.find("'A'"), std::string::npos) << r.message;
      EXPECT_NE(r.message.find("'B'"), std::string::npos) << r.message;
      EXPECT_EQ(s.q, before);
      continue;
    }
    Summary total;
    for (int k = 0; k < 4; ++k)
    {
      const Summary r = solver.step(s, 5e-3, noActuation());
      total.step_cuts += r.step_cuts;
      ASSERT_TRUE(r.ok()) << r.message;
    }
    EXPECT_GT(total.step_cuts, 0);
    EXPECT_GT(s.q(9), s.q(2));  // B is still above A
    EXPECT_GT(s.qd(9), 0.0);    // and moving up after the rebound
  }
}

TEST(AdaptiveSteps, HertzImpactOnsetLocatedClosedFormKeptAndStepGrowsAfter)
{
  // the Hertz impact above with variable steps from 1 ms: the step that starts the contact is cut to
  // end at most onset_depth inside, the steps in the contact follow the error estimate, and after the
  // rebound they grow back to dt_max; the closed-form peak, duration and rebound are kept
  const Model m = crossedCylinders(1.0, 0.0);
  SolverOptions o = options(1e-3);
  o.adaptive = true;
  o.error_tolerance = 1e-8;
  o.newton_tolerance = 1e-11;
  o.onset_depth = 1e-6;
  o.dt_max = 2e-3;
  DynamicsSolver solver(m, o);
  State s = initialState(m);
  s.qd.segment<3>(7) = Vec3(0.0, 0.0, -kSpeed);
  ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
  AdaptiveStepper stepper(solver, o);
  double first_depth = -1.0, max_force = 0.0, t_start = -1.0, t_end = -1.0, prev_gap = 5e-4, prev_t = 0.0;
  double contact_steps_max = 0.0, h_after = 0.0;
  const auto record = [&](const State& st)
  {
    const double h = st.t - prev_t;
    const double gap = contactGeometry(m, 0, st.q).gap;
    if (gap < 0.0 && first_depth < 0.0)
      first_depth = -gap;
    if (prev_gap >= 0.0 && gap < 0.0 && t_start < 0.0)
      t_start = prev_t + h * prev_gap / (prev_gap - gap);
    if (prev_gap < 0.0 && gap >= 0.0 && t_end < 0.0)
      t_end = prev_t + h * prev_gap / (prev_gap - gap);
    if (gap < 0.0)
      contact_steps_max = std::max(contact_steps_max, h);
    else if (t_end > 0.0)
      h_after = std::max(h_after, h);
    for (const ContactPairState& c : activeContacts(m, st))
      max_force = std::max(max_force, c.normal_force);
    prev_gap = gap;
    prev_t = st.t;
  };
  const Summary r = stepper.advanceTo(s, 0.03, noActuation(), record);
  ASSERT_TRUE(r.ok()) << r.message;
  const double mstar = 0.5 * m.bodies[0].mass;
  const double k = m.checkedPairList()[0].stiffness90;
  const double dmax = std::pow(5.0 * mstar * kSpeed * kSpeed / (4.0 * k), 0.4);
  const double fmax = k * std::pow(dmax, 1.5);
  const double tc = 2.9432 * dmax / kSpeed;
  const AdaptiveStats& st = stepper.stats();
  std::printf("[ measured ] %ld steps (%ld refused for error, %ld at the onset), first depth %.3g m, force %.5g N "
              "(%.5g), duration %.5g s (%.5g), steps in contact <= %.3g s, after %.3g s, rebound %.5f\n",
              st.accepted, st.rejected_error, st.rejected_onset, first_depth, max_force, fmax, t_end - t_start, tc,
              contact_steps_max, h_after, (s.qd(9) - s.qd(2)) / kSpeed);
  EXPECT_GT(st.rejected_onset, 0);
  EXPECT_GT(first_depth, 0.0);
  EXPECT_LE(first_depth, o.onset_depth);
  EXPECT_NEAR(max_force, fmax, 0.005 * fmax);
  EXPECT_NEAR(t_end - t_start, tc, 0.005 * tc);
  EXPECT_NEAR(s.qd(9) - s.qd(2), kSpeed, 0.01 * kSpeed);  // equal masses: A leaves at the speed B came
  EXPECT_GE(h_after, o.dt_max * (1.0 - 1e-9));
  EXPECT_LT(contact_steps_max, 0.1 * o.dt_max);
  EXPECT_LT(st.accepted, 600);  // the fixed 1e-5 s step of the test above takes 3000 for this span
}
