/// Kinematics of material points in the body coordinates: the world position and velocity of a point fixed on a
/// body (or on the ground), what the outputs read from a state's body poses.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/base/schedule.h"

namespace active_tensegrity::core
{
/// Actuation values of every actuator at one instant.
using ActuationValues = std::vector<ActuationValue>;

/// The world position of a material point alone (as pointKinematics(...).p, without the Jacobians).
Vec3 pointPosition(const Model& model, const PointRef& point, const Eigen::VectorXd& q);

/// The world position and velocity of a material point alone (as pointKinematics' p and v, without the
/// Jacobians).
void pointMotion(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                 Vec3& p, Vec3& v);
/// The Euler parameters Theta of strut b in a vector laid out like q (q, qd or qdd).
inline Vec4 thetaOf(const Eigen::VectorXd& x, const Body& b)
{
  return x.segment<4>(b.offset + 3);
}

/// A material point with its body's first coordinate and kind beside it. Residual loops read such points from
/// contiguous tables (System's cable points, the constraints' slots) instead of each cable's own point list
/// and the model's bodies: on a lattice of 2000 struts those scattered reads were most of the cable loop's time.
struct PointSlot
{
  Vec3 local = Vec3::Zero();  // body frame (m), or the world position on the ground
  int body = -1;              // -1: the ground
  int offset = 0;             // the body's first coordinate in q
  bool strut = false;
};

/// The slot of a material point of the model.
PointSlot pointSlot(const Model& model, const PointRef& point);
/// The world position of a point slot at q (as pointPosition).
Vec3 slotPosition(const PointSlot& point, const Eigen::VectorXd& q);
/// The rotation matrix A(Theta) of every strut at one configuration and its rate dA/dt, formed once so that
/// each material point on a strut then costs two 3x3 products instead of pointMotion's quaternion forms (a scan
/// over the cables visits every strut's points several times). Non-unit Theta keep the same quadratic form.
class BodyFrames
{
public:
  /// Forms the frames at q, qd for every strut of the model (no allocation once sized).
  void update(const Model& model, const Eigen::VectorXd& q, const Eigen::VectorXd& qd);
  /// As pointMotion for the point's slot, from the frames last formed (at the same q, qd).
  void motion(const PointSlot& point, const Eigen::VectorXd& q, const Eigen::VectorXd& qd, Vec3& p, Vec3& v) const
  {
    if (point.body < 0)
    {
      p = point.local;
      v.setZero();
      return;
    }
    p = q.segment<3>(point.offset);
    v = qd.segment<3>(point.offset);
    if (!point.strut)
    {
      p += point.local;
      return;
    }
    p.noalias() += rotation_[point.body] * point.local;
    v.noalias() += rate_[point.body] * point.local;
  }

private:
  std::vector<Mat3> rotation_;  // A(Theta) per body (unused for point masses)
  std::vector<Mat3> rate_;      // dA/dt = sum_i dA/dTheta_i Theta_dot_i
};

}  // namespace active_tensegrity::core
