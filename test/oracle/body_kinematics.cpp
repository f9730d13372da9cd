#include "active_tensegrity/oracle/body_kinematics.h"

#include <array>

#include "active_tensegrity/oracle/body_rotation.h"

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

void addPointForce(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Vec3& f,
                   Eigen::VectorXd& F)
{
  addSlotForce(pointSlot(model, point), q, f, F);
}

void addSlotForce(const PointSlot& point, const Eigen::VectorXd& q, const Vec3& f, Eigen::VectorXd& F)
{
  if (point.body < 0)
    return;
  F.segment<3>(point.offset) += f;
  if (point.strut)
    F.segment<4>(point.offset + 3) += pointJacobianThetaTransposeTimes(q.segment<4>(point.offset + 3), point.local, f);
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

namespace
{
// the cable's forces -T w_j at its points (w_j = n_{j-1} - n_j, n_k the unit vector of segment k) into apply(j, f)
template <class Apply>
void applyCableForces(const CableState& s, const std::array<Vec3, Cable::kMaxPoints>& p, int m, Apply&& apply)
{
  if (s.slack)
    return;
  Vec3 before = Vec3::Zero();
  for (int j = 0; j < m; ++j)
  {
    Vec3 after = Vec3::Zero();
    if (j + 1 < m)
    {
      const Vec3 d = p[j + 1] - p[j];
      const double seg = d.norm();
      if (seg > 0.0)
        after = d / seg;
    }
    apply(j, -s.tension * (before - after));
    before = after;
  }
}
}  // namespace

CableState evaluateCable(const Model& model, const Cable& cable, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                         const ActuationValues& u, bool damping, Eigen::VectorXd* F)
{
  const CableState s = evaluateCable(model, cable, q, qd, u, damping);
  if (!F)
    return s;
  std::array<Vec3, Cable::kMaxPoints> p;
  const int m = static_cast<int>(cable.points.size());
  for (int j = 0; j < m; ++j)
    p[j] = pointPosition(model, cable.points[j], q);
  applyCableForces(s, p, m, [&](int j, const Vec3& f) { addPointForce(model, cable.points[j], q, f, *F); });
  return s;
}

CableState evaluateCable(const Cable& cable, const PointSlot* points, const BodyFrames& frames,
                         const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const ActuationValues& u, bool damping,
                         PointForceSum& sum, Eigen::VectorXd& F)
{
  const CableState s = evaluateCable(cable, points, frames, q, qd, u, damping);
  std::array<Vec3, Cable::kMaxPoints> p;
  const int m = static_cast<int>(cable.points.size());
  Vec3 v;
  for (int j = 0; j < m; ++j)
    frames.motion(points[j], q, qd, p[j], v);
  applyCableForces(s, p, m, [&](int j, const Vec3& f) { sum.add(points[j], f, F); });
  return s;
}
}  // namespace active_tensegrity::core
