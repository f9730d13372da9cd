// Clustered (sliding) cables: one tension over a path through several points (docs/physics.md,
// "Force elements").
// Tangents against central differences (taut, damped, pulled in; slack), the frictionless pulley
// against its closed form, pull-in actuation, and energy conservation of an undamped system.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "fd_check.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
constexpr double kTol = 1e-6;

/// A strut pinned at its lower end, two point masses, one sliding cable
///   ground A -> strut tip -> mass M1 -> strut foot (pinned) -> mass M2 -> ground B,
/// passing the strut twice (same body at its two ends) and starting and ending on the ground.
Model slidingModel(double rest_length, double damping)
{
  Model m;
  m.name = "sliding";
  m.bodies.push_back(makeStrut("S", 1.0, 0.02, 7800.0));
  m.bodies.push_back(makePointMass("M1", 0.8));
  m.bodies.push_back(makePointMass("M2", 1.3));
  finalizeModel(m);
  Cable c;
  c.name = "slide";
  c.points = { PointRef{ -1, Vec3(-1.0, 0.2, 0.0) }, PointRef{ 0, Vec3(0.0, 0.0, 0.5) },
               PointRef{ 1, Vec3::Zero() },          PointRef{ 0, Vec3(0.0, 0.0, -0.5) },
               PointRef{ 2, Vec3::Zero() },          PointRef{ -1, Vec3(1.2, -0.3, 0.1) } };
  c.rest_length = rest_length;
  c.stiffness = 5000.0;
  c.area = 1e-5;  // a material cable: pulling in keeps EA = k l0
  c.damping = damping;
  m.cables.push_back(c);
  const Vec3 centre(0.1, 0.05, 0.5), axis = Vec3(0.2, 0.1, 1.0).normalized();
  m.constraints.push_back(
      pointConstraint("pin", PointRef{ 0, Vec3(0.0, 0.0, -0.5) }, PointRef{ -1, Vec3(centre - 0.5 * axis) }));
  Constraint norm;
  norm.kind = Constraint::Kind::kQuatNorm;
  norm.name = "S.norm";
  norm.body = 0;
  m.constraints.push_back(norm);
  m.actuators.push_back(Actuator{ "winch", -0.5, 0.5, {}, { 0 } });
  m.cables[0].actuator = 0;
  finalizeModel(m);
  m.q0.setZero(m.nq);
  m.q0.segment<3>(0) = centre;
  m.q0.segment<4>(3) = thetaFromZAxis(axis);
  m.q0.segment<3>(7) = Vec3(-0.3, 0.6, 0.9);
  m.q0.segment<3>(10) = Vec3(0.7, 0.4, 0.6);
  return m;
}

ActuationValues pullIn(double value, double rate)
{
  ActuationValue v;
  v.value = value;
  v.rate = rate;
  return { v };
}

Eigen::MatrixXd tangent(const System& sys, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                        const ActuationValues& u, double kw, double cw)
{
  BlockSparseMatrix m = sys.makeMatrix();
  Eigen::VectorXd F;
  sys.appliedForce(q, qd, u, F, &m, kw, cw);
  return denseBlock(m, sys.nq(), sys.nq());
}

Eigen::VectorXd minusForce(const System& sys, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                           const ActuationValues& u)
{
  Eigen::VectorXd F;
  sys.appliedForce(q, qd, u, F, nullptr, 0, 0);
  return -F;
}
}  // namespace

TEST(SlidingCable, LengthIsTheSumOfSegmentsAndOneTensionActsAlongEach)
{
  const Model m = slidingModel(2.0, 0.0);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.nq);
  const Cable& c = m.cables[0];
  double l = 0.0;
  for (size_t k = 0; k + 1 < c.points.size(); ++k)
    l += (pointPosition(m, c.points[k + 1], m.q0) - pointPosition(m, c.points[k], m.q0)).norm();
  const CableState s = evaluateCable(m, c, m.q0, zero, {}, false);
  EXPECT_NEAR(s.length, l, 1e-12);
  ASSERT_FALSE(s.slack);
  EXPECT_NEAR(s.tension, 5000.0 * (l - 2.0), 1e-9);
  // the force on M1 is T times the sum of the unit vectors towards its two neighbours
  const Vec3 p1 = pointPosition(m, c.points[1], m.q0);
  const Vec3 pm = pointPosition(m, c.points[2], m.q0);
  const Vec3 p3 = pointPosition(m, c.points[3], m.q0);
  const System sys(m);
  Eigen::VectorXd F;
  sys.appliedForce(m.q0, zero, {}, F, nullptr, 0, 0);
  const Vec3 expected = s.tension * ((p1 - pm).normalized() + (p3 - pm).normalized());
  EXPECT_LT((F.segment<3>(7) - expected).norm(), 1e-9 * s.tension);
}

TEST(SlidingCable, ThroughCollinearPointsItIsAStraightCable)
{
  // a cable from a to b through a point on the segment between them carries the classical tension
  Model m = slidingModel(1.0, 0.0);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.nq);
  const Vec3 a(0.0, 0.0, 0.0), b(1.0, 1.0, 2.0);
  m.q0.segment<3>(7) = a + 0.3 * (b - a);
  Cable straight = m.cables[0];
  straight.points = { PointRef{ -1, a }, PointRef{ -1, b } };
  Cable through = straight;
  through.points = { PointRef{ -1, a }, PointRef{ 1, Vec3::Zero() }, PointRef{ -1, b } };
  EXPECT_NEAR(evaluateCable(m, through, m.q0, zero, {}, false).tension,
              evaluateCable(m, straight, m.q0, zero, {}, false).tension, 1e-9);
}

TEST(SlidingCable, TautDampedTangentsMatchFiniteDifferences)
{
  std::mt19937 rng(7);
  for (int trial = 0; trial < 10; ++trial)
  {
    const Model m = slidingModel(1.5, 40.0);
    const System sys(m);
    const Eigen::VectorXd q = perturbed(m.q0, 0.05, rng);
    const Eigen::VectorXd qd = randomVector(m.nq, 0.5, rng);
    const ActuationValues u = pullIn(0.05 * trial, 0.2);
    const CableState s = evaluateCable(m, m.cables[0], q, qd, u, true);
    ASSERT_FALSE(s.slack);
    ASSERT_GT(s.length - s.rest_length, 0.1) << "away from the kink";
    ASSERT_NEAR(s.rest_length, 1.5 - 0.05 * trial, 1e-12);
    const auto Fq = [&](const Eigen::VectorXd& x) { return minusForce(sys, x, qd, u); };
    const auto Fqd = [&](const Eigen::VectorXd& x) { return minusForce(sys, q, x, u); };
    const FdComparison ck = compareJacobians(tangent(sys, q, qd, u, 1, 0), fdJacobian(Fq, q), kTol, 1.0);
    EXPECT_TRUE(ck.ok) << "K, trial " << trial << ": " << ck.message;
    const FdComparison cc = compareJacobians(tangent(sys, q, qd, u, 0, 1), fdJacobian(Fqd, qd), kTol, 1.0);
    EXPECT_TRUE(cc.ok) << "C, trial " << trial << ": " << cc.message;
  }
}

TEST(SlidingCable, SlackHasNoForceAndNoTangent)
{
  const Model m = slidingModel(20.0, 40.0);  // longer than the path
  const System sys(m);
  std::mt19937 rng(3);
  const Eigen::VectorXd qd = randomVector(m.nq, 0.5, rng);
  Eigen::VectorXd F;
  BlockSparseMatrix jac = sys.makeMatrix();
  sys.appliedForce(m.q0, qd, {}, F, &jac, 1, 1);
  EXPECT_TRUE(evaluateCable(m, m.cables[0], m.q0, qd, {}, true).slack);
  EXPECT_EQ(F.norm(), 0.0);
  EXPECT_EQ(Eigen::MatrixXd(jac.matrix()).norm(), 0.0);
  // and pulling it in far enough makes it taut: the pull-in shortens the rest length
  EXPECT_FALSE(evaluateCable(m, m.cables[0], m.q0, qd, pullIn(19.0, 0.0), true).slack);
}

namespace
{
/// A pulley P (point mass) on a cable from ground A = (0, 0, 0) to ground B = (d, 0, h), loaded by
/// W downwards: frictionless, so P sits where both segments make the same angle theta with the
/// vertical, sin(theta) = d / L with L = l0 (1 + T / EA) the stretched length, T = W / (2 cos theta),
/// and l1 = (L - h / cos(theta)) / 2 is the segment from A.
struct Pulley
{
  double d = 1.2, h = 0.3, l0 = 2.0, ea = 2.0e4, weight = 300.0;

  Model model() const
  {
    Model m;
    m.name = "pulley";
    m.bodies.push_back(makePointMass("P", 1.0));
    finalizeModel(m);
    Cable c;
    c.name = "rope";
    c.points = { PointRef{ -1, Vec3::Zero() }, PointRef{ 0, Vec3::Zero() }, PointRef{ -1, Vec3(d, 0.0, h) } };
    c.rest_length = l0;
    c.stiffness = ea / l0;
    c.area = 1e-5;
    m.cables.push_back(c);
    m.loads.push_back(PointLoad{ "W", PointRef{ 0, Vec3::Zero() }, Vec3(0.0, 0.0, -weight) });
    m.actuators.push_back(Actuator{ "winch", -0.5, 0.5, {}, { 0 } });
    m.cables[0].actuator = 0;
    finalizeModel(m);
    // off the equilibrium (also out of the plane); set entry by entry: GCC 12 warned (-Warray-bounds) on the
    // vectorized copy of a Vec3 temporary into the VectorXd
    m.q0.resize(3);
    m.q0 << 0.4, 0.05, -0.9;
    return m;
  }

  /// Closed-form position of P and tension with the rest length pulled in by s.
  std::pair<Vec3, double> closedForm(double s) const
  {
    const double rest = l0 - s;
    double tension = weight / 2.0;
    double theta = 0.0;
    for (int it = 0; it < 200; ++it)
    {
      const double length = rest + tension * rest / ea;
      theta = std::asin(d / length);
      tension = weight / (2.0 * std::cos(theta));
    }
    const double length = rest + tension * rest / ea;
    const double l1 = 0.5 * (length - h / std::cos(theta));
    return { Vec3(l1 * std::sin(theta), 0.0, -l1 * std::cos(theta)), tension };
  }
};
}  // namespace

TEST(SlidingCable, FrictionlessPulleyMatchesClosedFormAndPullInRaisesIt)
{
  const Pulley pulley;
  const Model m = pulley.model();
  SolverOptions opt;
  opt.newton_tolerance = 1e-12;
  opt.max_iterations = 50;
  StaticSolver solver(m, opt);
  State s = initialState(m);
  double previous_z = -1e9;
  for (double pull : { 0.0, 0.2, 0.4 })
  {
    const Summary r = solver.solve(s, pullIn(pull, 0.0));
    ASSERT_TRUE(r.ok()) << r.message;
    const auto [p, tension] = pulley.closedForm(pull);
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.nq);
    const CableState cs = evaluateCable(m, m.cables[0], s.q, zero, s.u, false);
    EXPECT_LT((s.q.head<3>() - p).norm(), 1e-9) << "pull-in " << pull << ": P at " << s.q.transpose();
    EXPECT_NEAR(cs.tension, tension, 1e-7 * tension) << pull;
    // equal tension on both sides, so the cable's force on the pulley bisects the two segments
    // and balances the load
    const Vec3 to_a = (Vec3::Zero() - s.q.head<3>()).normalized();
    const Vec3 to_b = (Vec3(pulley.d, 0.0, pulley.h) - s.q.head<3>()).normalized();
    const Vec3 force = cs.tension * (to_a + to_b);
    EXPECT_NEAR(force.normalized().dot(to_a), force.normalized().dot(to_b), 1e-12);
    EXPECT_LT((force + Vec3(0.0, 0.0, -pulley.weight)).norm(), 1e-7 * pulley.weight);
    // the actuation force of a pull-in actuator is the tension it holds
    EXPECT_NEAR(actuationForce(m, s, 0), cs.tension, 1e-9 * cs.tension);
    EXPECT_GT(s.q(2), previous_z) << "pulling the rope in lifts the pulley";
    previous_z = s.q(2);
  }
}

TEST(SlidingCable, UndampedSystemKeepsItsEnergy)
{
  // trapezoidal Newmark (gamma 1/2, beta 1/4): energy bounded with no drift at a small step
  Model m = slidingModel(1.0, 0.0);
  m.bodies[1].mass = m.bodies[2].mass = 5.0;
  // 0.3 m of stretch (about 1500 N): the cable stays taut through the motion
  m.cables[0].rest_length = evaluateCable(m, m.cables[0], m.q0, Eigen::VectorXd::Zero(m.nq), {}, false).length - 0.3;
  SolverOptions opt;
  opt.dt = 2e-4;
  opt.newmark_gamma = 0.5;
  opt.newmark_beta = 0.25;
  opt.newton_tolerance = 1e-9;
  DynamicsSolver solver(m, opt);
  State s = initialState(m);
  std::mt19937 rng(5);
  s.qd = randomVector(m.nq, 0.3, rng);
  s.qd.head<7>().setZero();  // the masses move, the strut starts at rest (a spin of the thin strut would
                             // need a far smaller step)
  const ActuationLaw law = [](double) { return pullIn(0.0, 0.0); };
  ASSERT_TRUE(solver.initialize(s, law).ok());
  const System sys(m);
  const auto energy = [&] { return sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q, s.u); };
  const double e0 = energy();
  const double p0 = sys.potentialEnergy(s.q, s.u);
  ASSERT_GT(p0, 0.05 * e0) << "the cable must be taut and carry energy";
  double max_dev = 0.0, min_tension = 1e9, max_tension = 0.0, max_spin = 0.0;
  for (int k = 0; k < 5000; ++k)
  {
    const Summary r = solver.step(s, opt.dt, law);
    ASSERT_TRUE(r.ok()) << r.message;
    max_dev = std::max(max_dev, std::abs(energy() - e0) / e0);
    const double t = evaluateCable(m, m.cables[0], s.q, s.qd, s.u, false).tension;
    min_tension = std::min(min_tension, t);
    max_spin = std::max(max_spin, s.qd.segment<4>(3).norm());
    max_tension = std::max(max_tension, t);
  }
  std::cout << "[ measured ] sliding cable, 1 s undamped: energy deviation " << max_dev << " of " << e0
            << " J; tension " << min_tension << " .. " << max_tension << " N; largest |Theta_dot| " << max_spin << "\n";
  EXPECT_LT(max_dev, 1e-3);
  EXPECT_GT(max_tension - min_tension, 1.0) << "the motion must load and unload the cable";
}
