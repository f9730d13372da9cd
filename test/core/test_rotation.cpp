// Euler-parameter kinematics: exact derivatives in all four numbers, identities, conversions.
#include <random>

#include <gtest/gtest.h>

#include "active_tensegrity/oracle/body_rotation.h"
#include "active_tensegrity/core/base/rotation.h"
#include "fd_check.h"

namespace at = active_tensegrity::core;
using active_tensegrity::test::compareJacobians;
using active_tensegrity::test::fdJacobian;

namespace
{
at::Vec4 randomTheta(std::mt19937& rng, bool unit)
{
  std::normal_distribution<double> n(0.0, 1.0);
  at::Vec4 t(n(rng), n(rng), n(rng), n(rng));
  return unit ? at::Vec4(t.normalized()) : at::Vec4(1.3 * t);
}
}  // namespace

TEST(Rotation, UnitThetaGivesRotationMatrixEqualToEigens)
{
  std::mt19937 rng(1);
  for (int i = 0; i < 20; ++i)
  {
    const at::Vec4 th = randomTheta(rng, true);
    const at::Mat3 a = at::rotationMatrix(th);
    EXPECT_TRUE((a * a.transpose()).isApprox(at::Mat3::Identity(), 1e-12));
    EXPECT_NEAR(a.determinant(), 1.0, 1e-12);
    EXPECT_TRUE(a.isApprox(at::toEigenQuaternion(th).toRotationMatrix(), 1e-12));
    EXPECT_TRUE(at::fromEigenQuaternion(at::toEigenQuaternion(th)).isApprox(th));
  }
}

TEST(Rotation, PointJacobianIsExactDerivativeForAnyTheta)
{
  std::mt19937 rng(2);
  for (int i = 0; i < 20; ++i)
  {
    const at::Vec4 th = randomTheta(rng, false);
    const at::Vec3 u(0.3 * i - 2.0, 0.7, -0.4 + 0.1 * i);
    const Eigen::MatrixXd num =
        fdJacobian([&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return at::rotationMatrix(x) * u; }, th);
    const auto c = compareJacobians(at::pointJacobianTheta(th, u), num, 1e-8, 1e-6);
    EXPECT_TRUE(c.ok) << c.message;
    // on unit Theta it equals -2 A skew(u) L (paper Eq. 5) along the sphere's tangent directions
    // (B Theta = 2 A u, whereas L Theta = 0, so the two differ in the radial direction only)
    const at::Vec4 tu = th.normalized();
    const at::Mat4 tangent = at::Mat4::Identity() - tu * tu.transpose();
    EXPECT_TRUE((at::pointJacobianTheta(tu, u) * tangent)
                    .isApprox(-2.0 * at::rotationMatrix(tu) * at::skew(u) * at::lMatrix(tu), 1e-12));
    // homogeneous quadratic: B(Theta) Theta = 2 A(Theta) u
    EXPECT_TRUE((at::pointJacobianTheta(th, u) * th).isApprox(2.0 * at::rotationMatrix(th) * u, 1e-12));
    // the products without the matrix
    EXPECT_TRUE(at::rotate(th, u).isApprox(at::rotationMatrix(th) * u, 1e-13));
    const at::Vec4 x = randomTheta(rng, false);
    const at::Vec3 f(0.2 - 0.05 * i, -1.1, 0.6);
    EXPECT_TRUE(at::pointJacobianThetaTimes(th, u, x).isApprox(at::pointJacobianTheta(th, u) * x, 1e-13));
    EXPECT_TRUE(
        at::pointJacobianThetaTransposeTimes(th, u, f).isApprox(at::pointJacobianTheta(th, u).transpose() * f, 1e-13));
    // dA/dt along x, column by column, and against central differences of A along x
    const at::Mat3 rate = at::rotationMatrixRate(th, x);
    for (int j = 0; j < 3; ++j)
      EXPECT_TRUE(rate.col(j).isApprox(at::pointJacobianTheta(th, at::Vec3::Unit(j)) * x, 1e-14));
    const double step = 1e-6;
    const at::Mat3 fd = (at::rotationMatrix(th + step * x) - at::rotationMatrix(th - step * x)) / (2.0 * step);
    EXPECT_LT((rate - fd).norm(), 1e-8 * rate.norm());
    // the body z axis's rate and transposed product, written out, against the general forms at e_z
    EXPECT_TRUE(at::bodyZAxisRate(th, x).isApprox(at::pointJacobianThetaTimes(th, at::Vec3::UnitZ(), x), 1e-14));
    EXPECT_TRUE(at::bodyZAxisTransposeTimes(th, f).isApprox(
        at::pointJacobianThetaTransposeTimes(th, at::Vec3::UnitZ(), f), 1e-14));
    // the body z axis, written out, is the matrix's third column for any Theta
    EXPECT_TRUE(at::bodyZAxis(th).isApprox(at::rotationMatrix(th).col(2), 1e-14));
  }
}

TEST(Rotation, HessianAndLTransposeMatricesMatchDerivatives)
{
  std::mt19937 rng(3);
  for (int i = 0; i < 10; ++i)
  {
    const at::Vec4 th = randomTheta(rng, false);
    const at::Vec3 u(0.2, -0.5, 0.9 - 0.1 * i), f(1.0 + i, -3.0, 0.5);
    const Eigen::MatrixXd num = fdJacobian(
        [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return at::pointJacobianTheta(x, u).transpose() * f; }, th);
    const auto c = compareJacobians(at::pointHessianTheta(u, f), num, 1e-8, 1e-6);
    EXPECT_TRUE(c.ok) << c.message;
    EXPECT_TRUE(at::pointHessianTheta(u, f).isApprox(at::pointHessianTheta(u, f).transpose()));
    // L(x)^T v = N(v) x
    const at::Vec4 x = randomTheta(rng, false);
    EXPECT_TRUE((at::lMatrix(x).transpose() * f).isApprox(at::lTransposeTimes(f) * x, 1e-12));
    // the products without the matrix
    EXPECT_TRUE(at::lTimes(th, x).isApprox(at::lMatrix(th) * x, 1e-13));
    EXPECT_TRUE(at::lMatrixTransposeTimes(th, f).isApprox(at::lMatrix(th).transpose() * f, 1e-13));
    // L(a) b = -L(b) a and L(a) a = 0
    EXPECT_TRUE((at::lMatrix(th) * x).isApprox(-at::lMatrix(x) * th, 1e-12));
    EXPECT_LT((at::lMatrix(th) * th).norm(), 1e-12);
  }
}

TEST(Rotation, SpinLockMeasuresTwistAboutBodyZOnly)
{
  std::mt19937 rng(4);
  const at::Vec4 th0 = randomTheta(rng, true);
  const at::Vec4 a = at::spinLockCoefficients(th0);
  EXPECT_NEAR(a.dot(th0), 0.0, 1e-14);
  const Eigen::Quaterniond q0 = at::toEigenQuaternion(th0);
  // a swing about a body axis perpendicular to z keeps it zero; a twist about body z does not
  const Eigen::Quaterniond swing(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1.0, 2.0, 0.0).normalized()));
  const Eigen::Quaterniond twist(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  EXPECT_NEAR(a.dot(at::fromEigenQuaternion(q0 * swing)), 0.0, 1e-14);
  EXPECT_NEAR(a.dot(at::fromEigenQuaternion(q0 * twist)), std::sin(0.15), 1e-12);
}

TEST(Rotation, ThetaFromZAxisPointsTheBodyAxis)
{
  for (const at::Vec3& d : { at::Vec3(0, 0, 1), at::Vec3(0, 0, -1), at::Vec3(1, 2, 3), at::Vec3(-1, 0, 0) })
  {
    const at::Vec4 th = at::thetaFromZAxis(d);
    EXPECT_NEAR(th.norm(), 1.0, 1e-12);
    EXPECT_TRUE((at::rotationMatrix(th).col(2)).isApprox(d.normalized(), 1e-12)) << d.transpose();
  }
}
