#include "active_tensegrity/core/model/kinematics.h"

#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
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

Vec3 pointPosition(const Model& model, const PointRef& point, const Eigen::VectorXd& q)
{
  return slotPosition(pointSlot(model, point), q);
}

}  // namespace active_tensegrity::core
