/// Strut contact in the body coordinates (centre and Euler parameters per strut), with its exact tangents: the test
/// oracle the natural coordinates' contact (natural.h) is checked against. The law is the core's (contact.h); here
/// the generalized forces are
///   Q_1 = F_N B_P1^T n - F_T B_PA^T t,  Q_2 = -F_N B_P2^T n + F_T B_PB^T t,  t = v_T/|v_T|,
/// and the tangents K = -dQ/dq and C = -dQ/dqd include the motion of the closest points along the axes (ds/dq from
/// the stationarity conditions), the turning of n, the change of K with the crossing angle and every term of the
/// friction force. A ground contact's friction acts at the sphere's lowest point as a material point.
#pragma once

#include <Eigen/Core>

#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
/// Contact stiffness K (N/m^1.5) for a squared cosine c2 of the crossing angle, and dK/dc2.
struct StiffnessValue
{
  double k = 0.0;
  double dk_dc2 = 0.0;
};
StiffnessValue contactStiffness(double k90, double cos2, double min_crossing_angle);

/// Local contributions of one pair: Q (14: body a's 7 then body b's 7) and its tangents
/// K = -dQ/dq, C = -dQ/dqd over [q_a; q_b]. A ground contact fills the first nq entries (its body's) only.
struct ContactContribution
{
  /// false: only `force` is filled (stiffness and damping are left as they were): for residual-only
  /// Newton iterations (modified Newton)
  bool tangents = true;
  Eigen::Matrix<double, 14, 1> force = Eigen::Matrix<double, 14, 1>::Zero();
  Eigen::Matrix<double, 14, 14> stiffness = Eigen::Matrix<double, 14, 14>::Zero();
  Eigen::Matrix<double, 14, 14> damping = Eigen::Matrix<double, 14, 14>::Zero();
};

/// Geometry of a contact slot at q and its penetration rate at qd, no forces.
ContactPairState contactMotion(const Model& model, int pair, const Eigen::VectorXd& q, const Eigen::VectorXd& qd);

/// Evaluates contact slot `pair` (a strut pair or a ground contact) at (q, qd) with impact speed v_0 (m/s,
/// used in dynamics only). Fills `out` (when not null) with its force and exact tangents; returns its state.
ContactPairState evaluateContact(const Model& model, int pair, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                 double impact_speed, ContactMode mode, ContactContribution* out);

/// True when the axes of strut pair `pair` passed through each other between q0 and q1 (axesPassedThrough on the
/// struts' body poses).
bool passedThrough(const Model& model, int pair, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1);
}  // namespace active_tensegrity::core
