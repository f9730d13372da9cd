// Forces, inertia and constraints of core/mechanics: every analytic tangent against central
// differences in all 7 numbers of each strut (Theta off the unit sphere too), per regime.
#include <random>

#include <gtest/gtest.h>

#include "active_tensegrity/oracle/body_rotation.h"
#include "fd_check.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
constexpr double kTol = 1e-6;

struct Fixture
{
  Model model = mixedModel();
  std::mt19937 rng{ 42 };
  Eigen::VectorXd q, qd, qdd;
  Fixture()
  {
    q = perturbed(model.q0, 0.05, rng);
    qd = randomVector(model.nq, 0.8, rng);
    qdd = randomVector(model.nq, 3.0, rng);
  }
};

Eigen::MatrixXd appliedTangent(const System& sys, const Eigen::VectorXd& q, const Eigen::VectorXd& qd, double kw,
                               double cw)
{
  BlockSparseMatrix m = sys.makeMatrix();
  Eigen::VectorXd F;
  sys.appliedForce(q, qd, {}, F, &m, kw, cw);
  return denseBlock(m, sys.nq(), sys.nq());
}
}  // namespace

TEST(Cable, ResidualForcesWithoutTangentsEqualThoseWithThem)
{
  // the residual's loop reads the cables' points from System's own table and the struts' frames; the tangent
  // path reads the model's point lists: on strut, point-mass and ground points alike, the same forces
  Fixture f;
  const System sys(f.model);
  BlockSparseMatrix m = sys.makeMatrix();
  Eigen::VectorXd with_tangents, without;
  sys.appliedForce(f.q, f.qd, {}, with_tangents, &m, 1, 1);
  sys.appliedForce(f.q, f.qd, {}, without, nullptr, 0, 0);
  ASSERT_GT(with_tangents.norm(), 1.0);
  EXPECT_LT((without - with_tangents).norm(), 1e-12 * with_tangents.norm());
}

TEST(Cable, TautDampedTangentsMatchFiniteDifferences)
{
  Fixture f;
  const System sys(f.model);
  for (const Cable& c : f.model.cables)
  {
    const CableState s = evaluateCable(f.model, c, f.q, f.qd, {}, true);
    ASSERT_FALSE(s.slack) << c.name << " should be taut in this configuration";
    ASSERT_GT(s.length - c.rest_length, 0.05);  // away from the kink
  }
  // K = -dF/dq, C = -dF/dqd
  const auto Fq = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd
  {
    Eigen::VectorXd F;
    sys.appliedForce(x, f.qd, {}, F, nullptr, 0, 0);
    return -F;
  };
  const auto Fqd = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd
  {
    Eigen::VectorXd F;
    sys.appliedForce(f.q, x, {}, F, nullptr, 0, 0);
    return -F;
  };
  auto ck = compareJacobians(appliedTangent(sys, f.q, f.qd, 1, 0), fdJacobian(Fq, f.q), kTol, 1.0);
  EXPECT_TRUE(ck.ok) << "K: " << ck.message;
  auto cc = compareJacobians(appliedTangent(sys, f.q, f.qd, 0, 1), fdJacobian(Fqd, f.qd), kTol, 1.0);
  EXPECT_TRUE(cc.ok) << "C: " << cc.message;
  // weights combine linearly
  EXPECT_TRUE(appliedTangent(sys, f.q, f.qd, 2, 3)
                  .isApprox(2 * appliedTangent(sys, f.q, f.qd, 1, 0) + 3 * appliedTangent(sys, f.q, f.qd, 0, 1)));
}

TEST(Cable, SlackCableHasNoForceNoTangent)
{
  Fixture f;
  for (Cable& c : f.model.cables)
    c.rest_length = 10.0;  // longer than any cable here
  f.model.loads.clear();
  const System sys(f.model);
  f.model.gravity_enabled = false;
  Eigen::VectorXd F;
  BlockSparseMatrix m = sys.makeMatrix();
  sys.appliedForce(f.q, f.qd, {}, F, &m, 1, 1);
  EXPECT_EQ(F.norm(), 0.0);
  EXPECT_EQ(Eigen::MatrixXd(m.matrix()).norm(), 0.0);
  for (const Cable& c : f.model.cables)
    EXPECT_TRUE(evaluateCable(f.model, c, f.q, f.qd, {}, true).slack);
}

TEST(Cable, DampingNeverPushes)
{
  // a taut cable shortening fast: elastic tension small, damping would make it negative -> clamped to 0
  Model m = mixedModel();
  m.cables = { makeCable("c", PointRef{ -1, Vec3::Zero() }, PointRef{ 2, Vec3::Zero() }, 100.0, 0.0, 50.0) };
  m.q0.segment<3>(14) = Vec3(1.0, 0.0, 0.0);
  m.cables[0].rest_length = 0.99;
  Eigen::VectorXd qd = Eigen::VectorXd::Zero(m.nq);
  qd(14) = -1.0;  // l_dot = -1 m/s: T = 100 * 0.01 - 50 < 0
  const CableState s = evaluateCable(m, m.cables[0], m.q0, qd, {}, true);
  EXPECT_TRUE(s.slack);
  EXPECT_EQ(s.tension, 0.0);
  qd(14) = 0.01;  // lengthening: T = 1 + 0.5
  EXPECT_NEAR(evaluateCable(m, m.cables[0], m.q0, qd, {}, true).tension, 1.5, 1e-12);
  EXPECT_NEAR(evaluateCable(m, m.cables[0], m.q0, qd, {}, false).tension, 1.0, 1e-12);
}

TEST(Cable, ForceIsEqualAndOppositeAlongTheCable)
{
  Model m = mixedModel();
  m.gravity_enabled = false;
  m.loads.clear();
  m.cables = { makeCable("c", PointRef{ 2, Vec3::Zero() }, PointRef{ -1, Vec3(0.0, 0.0, 0.0) }, 1000.0, 1.0, 0.0) };
  m.q0.segment<3>(14) = Vec3(0.0, 0.0, 1.5);
  const System sys(m);
  Eigen::VectorXd F;
  sys.appliedForce(m.q0, Eigen::VectorXd::Zero(m.nq), {}, F, nullptr, 0, 0);
  // T = 1000 * 0.5 = 500 N pulling the mass down to the ground point
  EXPECT_NEAR(F(16), -500.0, 1e-9);
  EXPECT_NEAR(F.segment<2>(14).norm(), 0.0, 1e-12);
  EXPECT_NEAR(sys.potentialEnergy(m.q0), 0.5 * 1000.0 * 0.25, 1e-9);
}

TEST(Inertia, MassQuadraticVelocityAndTheirTangentsMatchFiniteDifferences)
{
  Fixture f;
  const System sys(f.model);
  const auto tangent = [&](double mw, double kw, double cw)
  {
    BlockSparseMatrix m = sys.makeMatrix();
    Eigen::VectorXd out;
    sys.inertialForce(f.q, f.qd, f.qdd, out, &m, mw, kw, cw);
    return denseBlock(m, sys.nq(), sys.nq());
  };
  const auto g = [&](const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd)
  {
    Eigen::VectorXd out;
    sys.inertialForce(q, qd, qdd, out, nullptr, 0, 0, 0);
    return out;
  };
  auto c1 =
      compareJacobians(tangent(1, 0, 0),
                       fdJacobian([&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return g(f.q, f.qd, x); }, f.qdd),
                       kTol, 1e-3);
  EXPECT_TRUE(c1.ok) << "M: " << c1.message;
  auto c2 =
      compareJacobians(tangent(0, 1, 0),
                       fdJacobian([&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return g(x, f.qd, f.qdd); }, f.q),
                       kTol, 1e-3);
  EXPECT_TRUE(c2.ok) << "d(M qdd + Qv)/dq: " << c2.message;
  auto c3 =
      compareJacobians(tangent(0, 0, 1),
                       fdJacobian([&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return g(f.q, x, f.qdd); }, f.qd),
                       kTol, 1e-3);
  EXPECT_TRUE(c3.ok) << "dQv/dqd: " << c3.message;
}

TEST(Inertia, KineticEnergyMatchesBodyAngularVelocity)
{
  // T = 1/2 m |R_dot|^2 + 1/2 w^T J w with w = 2 L Theta_dot, for unit Theta and Theta_dot . Theta = 0
  Fixture f;
  const System sys(f.model);
  Eigen::VectorXd q = f.model.q0, qd = f.qd;
  double expected = 0.0;
  for (const Body& b : f.model.bodies)
  {
    expected += 0.5 * b.mass * qd.segment<3>(b.offset).squaredNorm();
    if (b.kind != BodyKind::kStrut)
      continue;
    const Vec4 th = q.segment<4>(b.offset + 3);
    Vec4 thd = qd.segment<4>(b.offset + 3);
    thd -= th * th.dot(thd);
    qd.segment<4>(b.offset + 3) = thd;
    const Vec3 w = 2.0 * lMatrix(th) * thd;
    expected += 0.5 * w.dot(b.inertia.asDiagonal() * w);
  }
  EXPECT_NEAR(sys.kineticEnergy(q, qd), expected, 1e-12 * expected);
}

TEST(Constraints, JacobianAndLambdaHessianMatchFiniteDifferences)
{
  Fixture f;
  const System sys(f.model);
  const ActuationValues u = { ActuationValue{ 0.2, 0.1, -0.3 } };
  const auto phi = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd
  {
    Eigen::VectorXd p;
    sys.constraintValue(x, u, p);
    return p;
  };
  const auto c1 = compareJacobians(sys.constraintJacobianDense(f.q), fdJacobian(phi, f.q), kTol, 1e-3);
  EXPECT_TRUE(c1.ok) << "Phi_q: " << c1.message;

  // the transposed blocks are the transpose
  BlockSparseMatrix m = sys.makeMatrix();
  sys.addConstraintJacobian(f.q, m);
  const Eigen::MatrixXd dense(m.matrix());
  EXPECT_TRUE(dense.topRightCorner(sys.nq(), sys.nLambda())
                  .isApprox(dense.bottomLeftCorner(sys.nLambda(), sys.nq()).transpose()));

  const Eigen::VectorXd lambda = randomVector(sys.nLambda(), 50.0, f.rng);
  BlockSparseMatrix h = sys.makeMatrix();
  sys.addLambdaHessian(f.q, lambda, h, 1.0);
  const auto cf = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd
  {
    Eigen::VectorXd out;
    sys.constraintForce(x, lambda, out);
    return out;
  };
  const auto c2 = compareJacobians(denseBlock(h, sys.nq(), sys.nq()), fdJacobian(cf, f.q), kTol, 1e-3);
  EXPECT_TRUE(c2.ok) << "d(Phi_q^T lambda)/dq: " << c2.message;
  // Phi_q^T lambda agrees with the dense Jacobian
  Eigen::VectorXd out;
  sys.constraintForce(f.q, lambda, out);
  EXPECT_TRUE(out.isApprox(sys.constraintJacobianDense(f.q).transpose() * lambda, 1e-12));
}

TEST(Constraints, VelocityAndAccelerationRightHandSidesMatchTimeDerivatives)
{
  // along q(t) = q + t qd + t^2/2 qdd and s(t) = s + t s_dot + t^2/2 s_ddot:
  // dPhi/dt = Phi_q qd - s_dot, d2Phi/dt2 = Phi_q qdd - gamma  =>  gamma = Phi_q qdd - d2Phi/dt2
  Fixture f;
  const System sys(f.model);
  const ActuationValue s0{ 0.2, 0.4, -1.1 };
  const auto phiAt = [&](double t)
  {
    const Eigen::VectorXd q = f.q + t * f.qd + 0.5 * t * t * f.qdd;
    const ActuationValues u = { ActuationValue{ s0.value + t * s0.rate + 0.5 * t * t * s0.accel, 0, 0 } };
    Eigen::VectorXd p;
    sys.constraintValue(q, u, p);
    return p;
  };
  const double h = 1e-4;
  const Eigen::VectorXd d1 = (phiAt(h) - phiAt(-h)) / (2 * h);
  const Eigen::VectorXd d2 = (phiAt(h) - 2 * phiAt(0) + phiAt(-h)) / (h * h);
  const Eigen::MatrixXd jq = sys.constraintJacobianDense(f.q);
  Eigen::VectorXd vrhs, arhs;
  sys.velocityRhs({ s0 }, vrhs);
  sys.accelerationRhs(f.q, f.qd, { s0 }, arhs);
  EXPECT_LT((jq * f.qd - vrhs - d1).lpNorm<Eigen::Infinity>(), 1e-6);
  EXPECT_LT((jq * f.qdd - arhs - d2).lpNorm<Eigen::Infinity>(), 1e-5);
}

TEST(Constraints, SpinLockIsLinearAndPatternHoldsExtraConstraints)
{
  Fixture f;
  Constraint lock;
  lock.kind = Constraint::Kind::kSpinLock;
  lock.body = 0;
  lock.coefficients = spinLockCoefficients(f.model.q0.segment<4>(3));
  const System sys(f.model, { lock });
  EXPECT_EQ(sys.nLambda(), f.model.n_lambda + 1);
  Eigen::VectorXd p;
  sys.constraintValue(f.model.q0, { ActuationValue{} }, p);
  EXPECT_NEAR(p(sys.nLambda() - 1), 0.0, 1e-14);
  const auto phi = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd
  {
    Eigen::VectorXd v;
    sys.constraintValue(x, { ActuationValue{} }, v);
    return v;
  };
  const auto c = compareJacobians(sys.constraintJacobianDense(f.q), fdJacobian(phi, f.q), kTol, 1e-3);
  EXPECT_TRUE(c.ok) << c.message;
}

TEST(BlockSparse, AddsBlocksInPlaceAndRefusesBlocksOutsideThePattern)
{
  BlockSparseMatrix m;
  m.init({ 2, 3, 1 }, { { 0, 1 }, { 1, 0 } });
  Eigen::MatrixXd b(2, 3);
  b << 1, 2, 3, 4, 5, 6;
  m.add(0, 1, b);
  m.add(0, 1, b, 2.0);
  m.addTransposed(0, 1, b);
  const Eigen::MatrixXd d(m.matrix());
  EXPECT_TRUE(d.block(0, 2, 2, 3).isApprox(3.0 * b));
  EXPECT_TRUE(d.block(2, 0, 3, 2).isApprox(b.transpose()));
  EXPECT_THROW(m.add(0, 2, Eigen::MatrixXd::Ones(2, 1)), std::logic_error);
  m.setZero();
  EXPECT_EQ(Eigen::MatrixXd(m.matrix()).norm(), 0.0);
  EXPECT_EQ(m.matrix().nonZeros(), 2 * 2 + 3 * 3 + 1 + 2 * 6);
}

TEST(Energy, PotentialEnergyGradientIsMinusTheConservativeForces)
{
  // cables, springs, gravity and constant loads are conservative: F = -dV/dq when damping is off
  Fixture f;
  f.model.damping_enabled = false;
  const System sys(f.model);
  Eigen::VectorXd F;
  sys.appliedForce(f.q, f.qd, {}, F, nullptr, 0, 0);
  const Eigen::MatrixXd grad = fdJacobian([&](const Eigen::VectorXd& x) -> Eigen::VectorXd
                                          { return Eigen::VectorXd::Constant(1, sys.potentialEnergy(x)); },
                                          f.q);
  const auto c = compareJacobians(-F.transpose(), grad, kTol, 1.0);
  EXPECT_TRUE(c.ok) << c.message;
}

TEST(Loads, ConstantLoadAddsItsForceAndAGeometricStiffness)
{
  Fixture f;
  Model m = f.model;
  m.cables.clear();
  m.gravity_enabled = false;
  const System sys(m);
  Eigen::VectorXd F;
  BlockSparseMatrix k = sys.makeMatrix();
  sys.appliedForce(f.q, f.qd, {}, F, &k, 1, 0);
  // translational parts carry the loads themselves
  EXPECT_TRUE(F.segment<3>(0).isApprox(m.loads[0].force));
  EXPECT_TRUE(F.segment<3>(14).isApprox(m.loads[1].force));
  EXPECT_GT(denseBlock(k, sys.nq(), sys.nq()).norm(), 1.0);  // the load on the strut turns with it
}
