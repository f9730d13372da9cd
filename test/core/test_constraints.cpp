// The constraint kinds of core/constraints, each on its own: every kind's Jacobian against central
// differences of its value, its lambda-Hessian against central differences of its reaction Phi_q^T lambda,
// the reaction against the Jacobian's transpose, and its velocity and acceleration right-hand sides
// against the time derivatives of its value along a motion. (The assembled System: test_mechanics.)
#include <random>
#include <stdexcept>

#include <gtest/gtest.h>

#include "active_tensegrity/oracle/body_rotation.h"
#include "active_tensegrity/oracle/constraints.h"
#include "fd_check.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
constexpr double kTol = 1e-6;

std::string kindName(Constraint::Kind kind)
{
  switch (kind)
  {
    case Constraint::Kind::kPoints:
      return "points";
    case Constraint::Kind::kQuatNorm:
      return "quaternion norm";
    case Constraint::Kind::kSpinLock:
      return "spin lock";
  }
  return "?";
}

/// One constraint of mixedModel (or a spin lock on strut A) alone in a model: its functions, its slot (the
/// residual's value and reaction read it), its matrix (groups: the bodies, then the constraint) and a random
/// state.
struct OneConstraint
{
  Model model = mixedModel();
  Constraint c;
  const ConstraintKindFunctions& kind;
  int group;
  ConstraintTables tables;
  ConstraintSlot slot;
  std::mt19937 rng{ 17 };
  Eigen::VectorXd q, qd, qdd;

  explicit OneConstraint(const Constraint& constraint)
    : c(constraint), kind(constraintKind(constraint.kind)), group(static_cast<int>(model.bodies.size()))
  {
    model.constraints = { c };
    finalizeModel(model);
    slot = constraintSlot(model, c, 0, tables);
    q = perturbed(model.q0, 0.05, rng);
    qd = randomVector(model.nq, 0.8, rng);
    qdd = randomVector(model.nq, 3.0, rng);
  }

  Eigen::VectorXd value(const Eigen::VectorXd& x, const ActuationValues& u) const
  {
    Eigen::VectorXd phi = Eigen::VectorXd::Zero(c.rows());
    kind.value(slot, tables, x, u, phi);
    return phi;
  }

  Eigen::VectorXd force(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda) const
  {
    Eigen::VectorXd out = Eigen::VectorXd::Zero(model.nq);
    kind.addForce(slot, tables, x, lambda, out);
    return out;
  }

  BlockSparseMatrix matrix() const
  {
    return System(model).makeMatrix();
  }
};

std::vector<Constraint> everyKind()
{
  const Model m = mixedModel();
  std::vector<Constraint> out = m.constraints;
  Constraint lock;
  lock.kind = Constraint::Kind::kSpinLock;
  lock.name = "A.spin";
  lock.body = 0;
  lock.coefficients = spinLockCoefficients(m.q0.segment<4>(3));
  out.push_back(lock);
  return out;
}
}  // namespace

TEST(ConstraintKinds, EveryKindHasEveryFunction)
{
  for (Constraint::Kind k : { Constraint::Kind::kPoints, Constraint::Kind::kQuatNorm, Constraint::Kind::kSpinLock })
  {
    const ConstraintKindFunctions& f = constraintKind(k);
    EXPECT_TRUE(f.check && f.bodies && f.value && f.addJacobian && f.addForce && f.addLambdaHessian && f.velocityRhs &&
                f.accelerationRhs)
        << kindName(k);
  }
  EXPECT_NE(&constraintKind(Constraint::Kind::kPoints), &constraintKind(Constraint::Kind::kQuatNorm));
  EXPECT_NE(&constraintKind(Constraint::Kind::kQuatNorm), &constraintKind(Constraint::Kind::kSpinLock));
}

TEST(ConstraintKinds, JacobianMatchesFiniteDifferencesOfTheValue)
{
  const ActuationValues u = { ActuationValue{ 0.2, 0.1, -0.3 } };
  for (const Constraint& constraint : everyKind())
  {
    OneConstraint f(constraint);
    BlockSparseMatrix m = f.matrix();
    f.kind.addJacobian(f.model, f.c, f.group, f.q, m);
    const Eigen::MatrixXd dense(m.matrix());
    const Eigen::MatrixXd jq = dense.bottomLeftCorner(f.c.rows(), f.model.nq);
    const auto c =
        compareJacobians(jq, fdJacobian([&](const Eigen::VectorXd& x) { return f.value(x, u); }, f.q), kTol, 1e-3);
    EXPECT_TRUE(c.ok) << f.c.name << " (" << kindName(f.c.kind) << "): " << c.message;
    EXPECT_TRUE(dense.topRightCorner(f.model.nq, f.c.rows()).isApprox(jq.transpose())) << f.c.name;
    // the reaction Phi_q^T lambda is the Jacobian's transpose times lambda
    const Eigen::VectorXd lambda = randomVector(f.c.rows(), 50.0, f.rng);
    EXPECT_TRUE(f.force(f.q, lambda).isApprox(jq.transpose() * lambda, 1e-12)) << f.c.name;
  }
}

TEST(ConstraintKinds, LambdaHessianMatchesFiniteDifferencesOfTheReaction)
{
  for (const Constraint& constraint : everyKind())
  {
    OneConstraint f(constraint);
    const Eigen::VectorXd lambda = randomVector(f.c.rows(), 50.0, f.rng);
    BlockSparseMatrix h = f.matrix();
    f.kind.addLambdaHessian(f.model, f.c, f.q, lambda, h, 1.0);
    const auto c = compareJacobians(
        denseBlock(h, f.model.nq, f.model.nq),
        fdJacobian([&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return f.force(x, lambda); }, f.q), kTol, 1e-3);
    EXPECT_TRUE(c.ok) << f.c.name << " (" << kindName(f.c.kind) << "): " << c.message;
    // weighted
    BlockSparseMatrix h2 = f.matrix();
    f.kind.addLambdaHessian(f.model, f.c, f.q, lambda, h2, -2.5);
    EXPECT_TRUE(denseBlock(h2, f.model.nq, f.model.nq).isApprox(-2.5 * denseBlock(h, f.model.nq, f.model.nq)))
        << f.c.name;
  }
}

TEST(ConstraintKinds, RightHandSidesMatchTimeDerivativesOfTheValue)
{
  // along q(t) = q + t qd + t^2/2 qdd and s(t) = s + t s_dot + t^2/2 s_ddot:
  // dPhi/dt = Phi_q qd - rhs_v, d2Phi/dt2 = Phi_q qdd - gamma
  const ActuationValue s0{ 0.2, 0.4, -1.1 };
  for (const Constraint& constraint : everyKind())
  {
    const OneConstraint f(constraint);
    const auto phiAt = [&](double t)
    {
      const Eigen::VectorXd q = f.q + t * f.qd + 0.5 * t * t * f.qdd;
      return f.value(q, { ActuationValue{ s0.value + t * s0.rate + 0.5 * t * t * s0.accel, 0, 0 } });
    };
    const double h = 1e-4;
    const Eigen::VectorXd d1 = (phiAt(h) - phiAt(-h)) / (2 * h);
    const Eigen::VectorXd d2 = (phiAt(h) - 2 * phiAt(0) + phiAt(-h)) / (h * h);
    BlockSparseMatrix m = f.matrix();
    f.kind.addJacobian(f.model, f.c, f.group, f.q, m);
    const Eigen::MatrixXd jq = Eigen::MatrixXd(m.matrix()).bottomLeftCorner(f.c.rows(), f.model.nq);
    Eigen::VectorXd vrhs = Eigen::VectorXd::Constant(f.c.rows(), 99.0);  // every row written
    Eigen::VectorXd arhs = vrhs;
    f.kind.velocityRhs(f.c, { s0 }, vrhs);
    f.kind.accelerationRhs(f.model, f.c, f.q, f.qd, { s0 }, arhs);
    EXPECT_LT((jq * f.qd - vrhs - d1).lpNorm<Eigen::Infinity>(), 1e-6) << f.c.name;
    EXPECT_LT((jq * f.qdd - arhs - d2).lpNorm<Eigen::Infinity>(), 1e-5) << f.c.name;
  }
}

TEST(ConstraintKinds, BodiesAreTheEndsOnBodiesOrTheStrut)
{
  const Model m = mixedModel();
  const auto bodies = [](const Constraint& c) { return constraintKind(c.kind).bodies(c); };
  const ConstraintBodies joint = bodies(m.constraints[0]);  // strut A to strut B
  ASSERT_EQ(joint.count, 2);
  EXPECT_EQ(joint.body[0], 0);
  EXPECT_EQ(joint.body[1], 1);
  const ConstraintBodies pin = bodies(m.constraints[1]);  // strut B to the ground
  ASSERT_EQ(pin.count, 1);
  EXPECT_EQ(pin.body[0], 1);
  const ConstraintBodies norm = bodies(m.constraints[5]);  // B.norm
  ASSERT_EQ(norm.count, 1);
  EXPECT_EQ(norm.body[0], 1);
}

TEST(ConstraintKinds, PointsConstraintWithTooManyRowsIsRefused)
{
  Model m = mixedModel();
  Constraint& c = m.constraints[0];
  c.directions.assign(kMaxPointRows + 1, Vec3::UnitX());
  c.offsets.assign(kMaxPointRows + 1, 0.0);
  EXPECT_THROW(constraintKind(c.kind).check(c), std::invalid_argument);
  finalizeModel(m);
  EXPECT_THROW(System{ m }, std::invalid_argument);
  c.directions.resize(kMaxPointRows);
  c.offsets.resize(kMaxPointRows);
  EXPECT_NO_THROW(constraintKind(c.kind).check(c));
}
