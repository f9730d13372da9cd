// The finite-difference checker must fail on a wrong Jacobian (a checker that cannot fail proves nothing).
#include <gtest/gtest.h>

#include "fd_check.h"

using active_tensegrity::test::compareJacobians;
using active_tensegrity::test::fdJacobian;

namespace
{
Eigen::VectorXd f(const Eigen::VectorXd& x)
{
  return Eigen::Vector2d(x(0) * x(0) * x(1), std::sin(x(1)) + 3.0 * x(0));
}
Eigen::MatrixXd df(const Eigen::VectorXd& x)
{
  Eigen::Matrix2d j;
  j << 2.0 * x(0) * x(1), x(0) * x(0), 3.0, std::cos(x(1));
  return j;
}
}  // namespace

TEST(FdCheck, AcceptsTheRightJacobian)
{
  const Eigen::Vector2d x(0.7, -1.3);
  const auto c = compareJacobians(df(x), fdJacobian(f, x), 1e-8, 1e-6);
  EXPECT_TRUE(c.ok) << c.message;
}

TEST(FdCheck, RejectsAWrongJacobian)
{
  const Eigen::Vector2d x(0.7, -1.3);
  Eigen::MatrixXd wrong = df(x);
  wrong(1, 1) *= 1.001;  // one entry off by 0.1 %
  const auto c = compareJacobians(wrong, fdJacobian(f, x), 1e-6, 1e-6);
  EXPECT_FALSE(c.ok) << c.message;
  EXPECT_EQ(c.row, 1);
  EXPECT_EQ(c.col, 1);
  // a dropped term (transposed Jacobian) is caught too
  EXPECT_FALSE(compareJacobians(df(x).transpose(), fdJacobian(f, x), 1e-6, 1e-6).ok);
}
