/// Kinematics of material points: world position and velocity of a point fixed on a body (or on the
/// ground) and their derivatives with respect to the coordinates. What force elements (cable.h),
/// constraints (constraints.h) and the assembly (mechanics.h) build on.
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

}  // namespace active_tensegrity::core
