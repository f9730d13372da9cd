#include "active_tensegrity/core/kinematics.h"

#include "active_tensegrity/core/rotation.h"

namespace active_tensegrity::core
{
void pointKinematics(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                     bool rate_jacobian, PointKinematics& k)
{
  // every member written once (no zero-filled temporary to copy: this runs for every cable point of
  // every residual)
  k.body = point.body;
  if (point.body < 0)
  {
    k.p = point.local;
    k.v.setZero();
    k.jac.setZero();
    k.dv_dq.setZero();
    k.nq = 0;
    return;
  }
  const Body& b = model.bodies[point.body];
  k.nq = b.nq;
  k.jac.leftCols<3>().setIdentity();
  k.dv_dq.leftCols<3>().setZero();
  if (b.kind == BodyKind::kPointMass)
  {
    k.p = q.segment<3>(b.offset) + point.local;
    k.v = qd.segment<3>(b.offset);
    k.jac.rightCols<4>().setZero();
    k.dv_dq.rightCols<4>().setZero();
    return;
  }
  const Vec4 th = thetaOf(q, b);
  const Vec4 thd = thetaOf(qd, b);
  k.jac.rightCols<4>() = pointJacobianTheta(th, point.local);
  // R(Theta) u is quadratic in Theta, so B_Theta(Theta, u) Theta = 2 R(Theta) u (Euler)
  k.p = q.segment<3>(b.offset) + 0.5 * (k.jac.rightCols<4>() * th);
  k.v = qd.segment<3>(b.offset) + k.jac.rightCols<4>() * thd;
  if (rate_jacobian)
    k.dv_dq.rightCols<4>() = pointJacobianTheta(thd, point.local);
  else
    k.dv_dq.rightCols<4>().setZero();
}

PointKinematics pointKinematics(const Model& model, const PointRef& point, const Eigen::VectorXd& q,
                                const Eigen::VectorXd& qd, bool rate_jacobian)
{
  PointKinematics k;
  pointKinematics(model, point, q, qd, rate_jacobian, k);
  return k;
}

void pointMotion(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                 Vec3& p, Vec3& v)
{
  p = pointPosition(model, point, q);
  if (point.body < 0)
  {
    v.setZero();
    return;
  }
  const Body& b = model.bodies[point.body];
  v = qd.segment<3>(b.offset);
  if (b.kind == BodyKind::kStrut)
    v += pointJacobianThetaTimes(thetaOf(q, b), point.local, thetaOf(qd, b));
}

void addPointForce(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Vec3& f,
                   Eigen::VectorXd& F)
{
  if (point.body < 0)
    return;
  const Body& b = model.bodies[point.body];
  F.segment<3>(b.offset) += f;
  if (b.kind == BodyKind::kStrut)
    F.segment<4>(b.offset + 3) += pointJacobianThetaTransposeTimes(thetaOf(q, b), point.local, f);
}

Vec3 pointPosition(const Model& model, const PointRef& point, const Eigen::VectorXd& q)
{
  if (point.body < 0)
    return point.local;
  const Body& b = model.bodies[point.body];
  if (b.kind == BodyKind::kPointMass)
    return q.segment<3>(b.offset) + point.local;
  return q.segment<3>(b.offset) + rotate(thetaOf(q, b), point.local);
}

}  // namespace active_tensegrity::core
