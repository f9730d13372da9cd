/// Kinematics of material points: world position and velocity of a point fixed on a body (or on the
/// ground) and their derivatives with respect to the coordinates, in the body coordinates: what the outputs' force
/// evaluations (cable.h, contact.h) and the test oracle's assembly build on.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/model.h"
#include "active_tensegrity/core/schedule.h"

namespace active_tensegrity::core
{
using Mat37 = Eigen::Matrix<double, 3, 7>;

/// Actuation values of every actuator at one instant.
using ActuationValues = std::vector<ActuationValue>;

/// Position, velocity and their derivatives of a material point. Only the first nq columns of the
/// matrices are meaningful (7 for a strut, 3 for a point mass, 0 for the ground).
struct PointKinematics
{
  Vec3 p = Vec3::Zero();        // world position, m
  Vec3 v = Vec3::Zero();        // world velocity, m/s
  Mat37 jac = Mat37::Zero();    // B_P = dp/dq = dv/dqd
  Mat37 dv_dq = Mat37::Zero();  // dv/dq = [0, B_Theta(Theta_dot, u)]
  int body = -1;
  int nq = 0;
};

/// rate_jacobian = false leaves dv_dq zero (not needed without velocity-dependent tangents).
PointKinematics pointKinematics(const Model& model, const PointRef& point, const Eigen::VectorXd& q,
                                const Eigen::VectorXd& qd, bool rate_jacobian = true);
/// The same into `out` (every member written), for loops that keep their kinematics in a buffer.
void pointKinematics(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                     bool rate_jacobian, PointKinematics& out);
/// The world position of a material point alone (as pointKinematics(...).p, without the Jacobians).
Vec3 pointPosition(const Model& model, const PointRef& point, const Eigen::VectorXd& q);

/// The world position and velocity of a material point alone (as pointKinematics' p and v, without the
/// Jacobians).
void pointMotion(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                 Vec3& p, Vec3& v);
/// Adds the generalized force of the world force f acting at a material point (B_P^T f) into F; nothing for
/// a point on the ground.
void addPointForce(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Vec3& f,
                   Eigen::VectorXd& F);

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
/// Adds the generalized force of the world force f at a point slot into F (as addPointForce).
void addSlotForce(const PointSlot& point, const Eigen::VectorXd& q, const Vec3& f, Eigen::VectorXd& F);

/// The rotation matrix A(Theta) of every strut at one configuration and its rate dA/dt, formed once so that
/// each material point on a strut then costs two 3x3 products instead of pointMotion's quaternion forms: the
/// cable loop of a residual visits every strut's points several times (on the tower the applied forces take
/// 31 % fewer instructions so). Non-unit Theta (Newton iterates) keep the same quadratic form.
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

/// Sums the generalized forces of world forces at material points (as repeated addPointForce): translations
/// go straight into F; on a strut, sum_j B_Theta(Theta, u_j)^T f_j is linear in the moment matrix
/// sum_j f_j u_j^T, which add() accumulates and flush() turns into the Euler-parameter force once per strut.
class PointForceSum
{
public:
  /// Clears the moments (sized to the model's bodies).
  void reset(const Model& model);
  /// Adds the force f at a material point: its translation part into F, its moment into the sum.
  void add(const PointSlot& point, const Vec3& f, Eigen::VectorXd& F)
  {
    if (point.body < 0)
      return;
    F.segment<3>(point.offset) += f;
    if (!point.strut)
      return;
    Mat3& m = moment_[point.body];
    if (loaded_[point.body])
      m.noalias() += f * point.local.transpose();
    else
    {
      m.noalias() = f * point.local.transpose();
      loaded_[point.body] = 1;
    }
  }
  /// Adds the Euler-parameter forces of the summed moments into F (at the struts' Theta in q) and clears them.
  void flush(const Model& model, const Eigen::VectorXd& q, Eigen::VectorXd& F);

private:
  std::vector<Mat3> moment_;  // sum_j f_j u_j^T per body
  std::vector<char> loaded_;  // whether a strut's moment is nonzero
};

}  // namespace active_tensegrity::core
