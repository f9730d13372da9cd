#include "active_tensegrity/core/base/rotation.h"

#include <cmath>

namespace active_tensegrity::core
{

Mat3 rotationMatrix(const Vec4& theta)
{
  // (e0^2 - e.e) I + 2 e e^T + 2 e0 [e]x, entry by entry
  const double e0 = theta(0), e1 = theta(1), e2 = theta(2), e3 = theta(3);
  const double s0 = e0 * e0 - e1 * e1 - e2 * e2 - e3 * e3;
  Mat3 a;
  a(0, 0) = s0 + 2.0 * e1 * e1;
  a(1, 1) = s0 + 2.0 * e2 * e2;
  a(2, 2) = s0 + 2.0 * e3 * e3;
  a(0, 1) = 2.0 * (e1 * e2 - e0 * e3);
  a(1, 0) = 2.0 * (e1 * e2 + e0 * e3);
  a(0, 2) = 2.0 * (e1 * e3 + e0 * e2);
  a(2, 0) = 2.0 * (e1 * e3 - e0 * e2);
  a(1, 2) = 2.0 * (e2 * e3 - e0 * e1);
  a(2, 1) = 2.0 * (e2 * e3 + e0 * e1);
  return a;
}

Mat3 rotationMatrixRate(const Vec4& theta, const Vec4& x)
{
  // 2 (e0 x0 - e.x_v) I + 2 (x_v e^T + e x_v^T) + 2 [x0 e + e0 x_v]x, entry by entry
  const double e0 = theta(0), e1 = theta(1), e2 = theta(2), e3 = theta(3);
  const double d0 = x(0), d1 = x(1), d2 = x(2), d3 = x(3);
  const double t0 = 2.0 * (e0 * d0 - e1 * d1 - e2 * d2 - e3 * d3);
  const double w1 = 2.0 * (d0 * e1 + e0 * d1), w2 = 2.0 * (d0 * e2 + e0 * d2), w3 = 2.0 * (d0 * e3 + e0 * d3);
  Mat3 r;
  r(0, 0) = t0 + 4.0 * e1 * d1;
  r(1, 1) = t0 + 4.0 * e2 * d2;
  r(2, 2) = t0 + 4.0 * e3 * d3;
  r(0, 1) = 2.0 * (d1 * e2 + e1 * d2) - w3;
  r(1, 0) = 2.0 * (d2 * e1 + e2 * d1) + w3;
  r(0, 2) = 2.0 * (d1 * e3 + e1 * d3) + w2;
  r(2, 0) = 2.0 * (d3 * e1 + e3 * d1) - w2;
  r(1, 2) = 2.0 * (d2 * e3 + e2 * d3) - w1;
  r(2, 1) = 2.0 * (d3 * e2 + e3 * d2) + w1;
  return r;
}

Vec4 thetaFromZAxis(const Vec3& d)
{
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitZ(), d.normalized());
  return fromEigenQuaternion(q.normalized());
}

Eigen::Quaterniond toEigenQuaternion(const Vec4& theta)
{
  return Eigen::Quaterniond(theta(0), theta(1), theta(2), theta(3));
}

Vec4 fromEigenQuaternion(const Eigen::Quaterniond& q)
{
  return Vec4(q.w(), q.x(), q.y(), q.z());
}

}  // namespace active_tensegrity::core
