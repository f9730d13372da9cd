/// Euler-parameter (unit quaternion) kinematics of Kan et al. 2019, Sec. 2.
///
/// Theta = (e0, e1, e2, e3) is stored scalar first in an Eigen::Vector4d. This header is the only
/// place that converts between that order and Eigen's / ROS's (x, y, z, w) order.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace active_tensegrity::core
{
using Vec3 = Eigen::Vector3d;
using Vec4 = Eigen::Vector4d;
using Mat3 = Eigen::Matrix3d;
using Mat4 = Eigen::Matrix4d;
using Mat34 = Eigen::Matrix<double, 3, 4>;

/// Cross-product matrix: skew(a) * b = a x b.
inline Mat3 skew(const Vec3& a)
{
  Mat3 s;
  s << 0.0, -a.z(), a.y(), a.z(), 0.0, -a.x(), -a.y(), a.x(), 0.0;
  return s;
}

/// A(Theta) = (e0^2 - e.e) I + 2 e e^T + 2 e0 skew(e); the exact quadratic form, valid for any Theta
/// (orthonormal only when |Theta| = 1).
Mat3 rotationMatrix(const Vec4& theta);
/// dA/dt for Theta moving at x: sum_i dA/dTheta_i x_i, whose column j is B_Theta(Theta, e_j) x.
Mat3 rotationMatrixRate(const Vec4& theta, const Vec4& x);
/// rotationMatrix(theta) * (0, 0, 1): the body z axis in the world (the same quadratic form, so it is
/// scaled by |theta|^2 when theta is not unit).
inline Vec3 bodyZAxis(const Vec4& theta)
{
  const double e0 = theta(0), e1 = theta(1), e2 = theta(2), e3 = theta(3);
  return Vec3(2.0 * (e1 * e3 + e0 * e2), 2.0 * (e2 * e3 - e0 * e1), e0 * e0 - e1 * e1 - e2 * e2 + e3 * e3);
}

/// L(Theta) x without forming the matrix: e0 x_v - x0 e - e x x_v (x = (x0, x_v)).
inline Vec3 lTimes(const Vec4& theta, const Vec4& x)
{
  const Vec3 e = theta.tail<3>(), xv = x.tail<3>();
  return theta(0) * xv - x(0) * e - e.cross(xv);
}

/// L(Theta)^T w without forming the matrix: (-e.w, e x w + e0 w).
inline Vec4 lMatrixTransposeTimes(const Vec4& theta, const Vec3& w)
{
  const Vec3 e = theta.tail<3>();
  Vec4 out;
  out(0) = -e.dot(w);
  out.tail<3>() = e.cross(w) + theta(0) * w;
  return out;
}

/// A(Theta) u without forming the matrix (the same quadratic form as rotationMatrix).
inline Vec3 rotate(const Vec4& theta, const Vec3& u)
{
  const double e0 = theta(0);
  const Vec3 e = theta.tail<3>();
  return (e0 * e0 - e.squaredNorm()) * u + 2.0 * e.dot(u) * e + 2.0 * e0 * e.cross(u);
}

/// B_Theta(Theta, u) x without forming the matrix (the velocity of point u for Theta moving at x).
inline Vec3 pointJacobianThetaTimes(const Vec4& theta, const Vec3& u, const Vec4& x)
{
  // B = 2 [e0 u + e x u, (e.u) I + e u^T - u e^T - e0 skew(u)]
  const double e0 = theta(0);
  const Vec3 e = theta.tail<3>(), xv = x.tail<3>();
  return 2.0 * (x(0) * (e0 * u + e.cross(u)) + e.dot(u) * xv + u.dot(xv) * e - e.dot(xv) * u - e0 * u.cross(xv));
}

/// Unit Theta that rotates the body z axis onto the unit vector d with no twist about the shortest arc.
Vec4 thetaFromZAxis(const Vec3& d);

/// Conversions to and from Eigen's quaternion (x, y, z, w storage): the only place the orders meet.
Eigen::Quaterniond toEigenQuaternion(const Vec4& theta);
Vec4 fromEigenQuaternion(const Eigen::Quaterniond& q);

}  // namespace active_tensegrity::core
