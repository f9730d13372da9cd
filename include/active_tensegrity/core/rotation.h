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
Mat3 skew(const Vec3& a);

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

/// L(Theta) = [-e, -skew(e) + e0 I] (3x4); body angular velocity omega_bar = 2 L(Theta) Theta_dot.
Mat34 lMatrix(const Vec4& theta);

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

/// B_Theta(Theta, u) = d(A(Theta) u)/dTheta (3x4), linear in Theta; B_Theta(Theta, u) Theta = 2 A(Theta) u.
Mat34 pointJacobianTheta(const Vec4& theta, const Vec3& u);

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

/// B_Theta(Theta, u)^T f without forming the matrix (the generalized force of f at point u on Theta).
inline Vec4 pointJacobianThetaTransposeTimes(const Vec4& theta, const Vec3& u, const Vec3& f)
{
  const double e0 = theta(0);
  const Vec3 e = theta.tail<3>();
  Vec4 g;
  g(0) = 2.0 * (e0 * u.dot(f) + e.cross(u).dot(f));
  g.tail<3>() = 2.0 * (e.dot(u) * f + e.dot(f) * u - u.dot(f) * e + e0 * u.cross(f));
  return g;
}

/// B_Theta(Theta, e_z) x: the rate of bodyZAxis(Theta) for Theta moving at x (pointJacobianThetaTimes at the
/// body z axis, written out: the contact's strut axes need it for every pair of every residual).
inline Vec3 bodyZAxisRate(const Vec4& theta, const Vec4& x)
{
  const double e0 = theta(0), e1 = theta(1), e2 = theta(2), e3 = theta(3);
  return 2.0 * Vec3(e2 * x(0) + e3 * x(1) + e0 * x(2) + e1 * x(3), -e1 * x(0) - e0 * x(1) + e3 * x(2) + e2 * x(3),
                    e0 * x(0) - e1 * x(1) - e2 * x(2) + e3 * x(3));
}

/// B_Theta(Theta, e_z)^T f: the generalized force on Theta of f at the body z axis's unit point
/// (pointJacobianThetaTransposeTimes at e_z, written out).
inline Vec4 bodyZAxisTransposeTimes(const Vec4& theta, const Vec3& f)
{
  const double e0 = theta(0), e1 = theta(1), e2 = theta(2), e3 = theta(3);
  return 2.0 * Vec4(e2 * f.x() - e1 * f.y() + e0 * f.z(), e3 * f.x() - e0 * f.y() - e1 * f.z(),
                    e0 * f.x() + e3 * f.y() - e2 * f.z(), e1 * f.x() + e2 * f.y() + e3 * f.z());
}

/// N(v) with L(x)^T v = N(v) x for every x (4x4).
Mat4 lTransposeTimes(const Vec3& v);

/// G(u, f) = d(B_Theta(Theta, u)^T f)/dTheta (4x4, symmetric, independent of Theta): the Hessian of
/// f . A(Theta) u.
Mat4 pointHessianTheta(const Vec3& u, const Vec3& f);

/// Coefficients a with (conj(Theta0) (x) Theta)_z = a . Theta: the twist of Theta relative to Theta0
/// about the body z axis is zero iff a . Theta = 0 (for swings below 180 degrees).
Vec4 spinLockCoefficients(const Vec4& theta0);

/// Unit Theta that rotates the body z axis onto the unit vector d with no twist about the shortest arc.
Vec4 thetaFromZAxis(const Vec3& d);

/// Conversions to and from Eigen's quaternion (x, y, z, w storage): the only place the orders meet.
Eigen::Quaterniond toEigenQuaternion(const Vec4& theta);
Vec4 fromEigenQuaternion(const Eigen::Quaterniond& q);

}  // namespace active_tensegrity::core
