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
  addSlotForce(pointSlot(model, point), q, f, F);
}

PointSlot pointSlot(const Model& model, const PointRef& point)
{
  PointSlot slot;
  slot.local = point.local;
  slot.body = point.body;
  if (point.body >= 0)
  {
    const Body& b = model.bodies[point.body];
    slot.offset = b.offset;
    slot.strut = b.kind == BodyKind::kStrut;
  }
  return slot;
}

Vec3 slotPosition(const PointSlot& point, const Eigen::VectorXd& q)
{
  if (point.body < 0)
    return point.local;
  if (!point.strut)
    return q.segment<3>(point.offset) + point.local;
  return q.segment<3>(point.offset) + rotate(q.segment<4>(point.offset + 3), point.local);
}

void addSlotForce(const PointSlot& point, const Eigen::VectorXd& q, const Vec3& f, Eigen::VectorXd& F)
{
  if (point.body < 0)
    return;
  F.segment<3>(point.offset) += f;
  if (point.strut)
    F.segment<4>(point.offset + 3) += pointJacobianThetaTransposeTimes(q.segment<4>(point.offset + 3), point.local, f);
}

void BodyFrames::update(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& qd)
{
  rotation_.resize(model.bodies.size());
  rate_.resize(model.bodies.size());
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const Body& b = model.bodies[i];
    if (b.kind != BodyKind::kStrut)
      continue;
    rotation_[i] = rotationMatrix(thetaOf(q, b));
    rate_[i] = rotationMatrixRate(thetaOf(q, b), thetaOf(qd, b));
  }
}

void PointForceSum::reset(const Model& model)
{
  moment_.resize(model.bodies.size());
  loaded_.assign(model.bodies.size(), 0);
}

void PointForceSum::flush(const Model& model, const Eigen::VectorXd& q, Eigen::VectorXd& F)
{
  // With M = sum_j f_j u_j^T, sum_j B_Theta(Theta, u_j)^T f_j = 2 [e0 tr M + e.a; M e + M^T e - tr(M) e + e0 a],
  // a = sum_j u_j x f_j (from M's antisymmetric part): pointJacobianThetaTransposeTimes summed
  for (size_t i = 0; i < loaded_.size(); ++i)  // (moment_ has as many, from reset)
  {
    if (!loaded_[i])
      continue;
    loaded_[i] = 0;
    const Body& b = model.bodies[i];
    const Mat3& m = moment_[i];
    const Vec4 th = thetaOf(q, b);
    const double e0 = th(0);
    const Vec3 e = th.tail<3>();
    const double tr = m.trace();
    const Vec3 a(m(2, 1) - m(1, 2), m(0, 2) - m(2, 0), m(1, 0) - m(0, 1));
    F(b.offset + 3) += 2.0 * (e0 * tr + e.dot(a));
    F.segment<3>(b.offset + 4) += 2.0 * (m * e + m.transpose() * e - tr * e + e0 * a);
  }
}

Vec3 pointPosition(const Model& model, const PointRef& point, const Eigen::VectorXd& q)
{
  return slotPosition(pointSlot(model, point), q);
}

}  // namespace active_tensegrity::core
