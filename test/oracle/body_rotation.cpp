#include "active_tensegrity/oracle/body_rotation.h"

namespace active_tensegrity::core
{
Mat34 lMatrix(const Vec4& theta)
{
  Mat34 l;
  l.col(0) = -theta.tail<3>();
  l.rightCols<3>() = -skew(theta.tail<3>()) + theta(0) * Mat3::Identity();
  return l;
}

Mat34 pointJacobianTheta(const Vec4& theta, const Vec3& u)
{
  const double e0 = theta(0);
  const Vec3 e = theta.tail<3>();
  Mat34 b;
  b.col(0) = 2.0 * (e0 * u + e.cross(u));
  b.rightCols<3>() = 2.0 * (e.dot(u) * Mat3::Identity() + e * u.transpose() - u * e.transpose() - e0 * skew(u));
  return b;
}

Mat4 lTransposeTimes(const Vec3& v)
{
  Mat4 n;
  n(0, 0) = 0.0;
  n.block<1, 3>(0, 1) = -v.transpose();
  n.block<3, 1>(1, 0) = v;
  n.block<3, 3>(1, 1) = -skew(v);
  return n;
}

Mat4 pointHessianTheta(const Vec3& u, const Vec3& f)
{
  Mat4 g;
  const Vec3 uxf = u.cross(f);
  g(0, 0) = 2.0 * u.dot(f);
  g.block<1, 3>(0, 1) = 2.0 * uxf.transpose();
  g.block<3, 1>(1, 0) = 2.0 * uxf;
  g.block<3, 3>(1, 1) = 2.0 * (f * u.transpose() + u * f.transpose() - u.dot(f) * Mat3::Identity());
  return g;
}

Vec4 spinLockCoefficients(const Vec4& theta0)
{
  // conj(theta0) (x) theta, z component: c0 t3 - t0 c3 - c1 t2 + c2 t1
  return Vec4(-theta0(3), theta0(2), -theta0(1), theta0(0));
}

}  // namespace active_tensegrity::core
