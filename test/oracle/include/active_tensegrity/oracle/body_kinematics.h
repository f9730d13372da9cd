/// Derivatives of material points and forces at them in the body coordinates (the test oracle's assembly): a
/// point's Jacobians, generalized forces of world forces at points, and a cable's generalized forces.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/core/model/kinematics.h"

namespace active_tensegrity::core
{
using Mat37 = Eigen::Matrix<double, 3, 7>;

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
/// Adds the generalized force of the world force f acting at a material point (B_P^T f) into F; nothing for
/// a point on the ground.
void addPointForce(const Model& model, const PointRef& point, const Eigen::VectorXd& q, const Vec3& f,
                   Eigen::VectorXd& F);

/// Adds the generalized force of the world force f at a point slot into F (as addPointForce).
void addSlotForce(const PointSlot& point, const Eigen::VectorXd& q, const Vec3& f, Eigen::VectorXd& F);

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

/// evaluateCable (cable.h) that also adds the cable's generalized force -T dl/dq into F (when not null).
CableState evaluateCable(const Model& model, const Cable& cable, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                         const ActuationValues& u, bool damping, Eigen::VectorXd* F);

/// The same at point slots with the points' motion from frames formed at (q, qd) and the forces summed into `sum`
/// and F (the caller flushes `sum` into F once all elements are added): a residual's force loop.
CableState evaluateCable(const Cable& cable, const PointSlot* points, const BodyFrames& frames,
                         const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const ActuationValues& u, bool damping,
                         PointForceSum& sum, Eigen::VectorXd& F);
}  // namespace active_tensegrity::core
