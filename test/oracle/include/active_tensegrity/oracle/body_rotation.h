/// Derivatives of the Euler-parameter rotation (core/base/rotation.h) with respect to Theta: what the body coordinates'
/// tangents (the test oracle) build on.
#pragma once

#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
/// L(Theta) = [-e, -skew(e) + e0 I] (3x4); body angular velocity omega_bar = 2 L(Theta) Theta_dot.
Mat34 lMatrix(const Vec4& theta);

/// B_Theta(Theta, u) = d(A(Theta) u)/dTheta (3x4), linear in Theta; B_Theta(Theta, u) Theta = 2 A(Theta) u.
Mat34 pointJacobianTheta(const Vec4& theta, const Vec3& u);

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

}  // namespace active_tensegrity::core
