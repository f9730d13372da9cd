/// The cable and spring law: everything about one tension element in one place (its force and exact
/// tangents, its potential energy and the power it delivers).
///
/// A cable runs through points p_0 .. p_{m-1} (two for a classical cable or spring, more for a clustered
/// cable sliding frictionlessly through the inner points; model.h, struct Cable). With
///   l = sum_k |p_{k+1} - p_k|                   length,   l_dot its rate,
///   l0(t) = l0 - s(t)                           rest length pulled in by the actuator's value s,
///   k(t) = EA / l0(t) (material cable) or k     stiffness (a material cable keeps EA when pulled in),
/// it carries one tension along every segment
///   T = k (l - l0(t)) + c (l_dot + s_dot)       while taut,
/// and none when slack: under tension_only, when l <= l0(t) or T <= 0 (damping never pushes).
/// The generalized force on the bodies is F = -T dl/dq; K = -dF/dq and C = -dF/dqd are exact.
///
/// Energy and power (at a fixed actuation value s):
///   V = 1/2 k (l - l0)^2                        when l > l0 or not tension_only, else 0;
///   conservative power     P_c  = -dV/dt = -k (l - l0) l_dot  (0 where V is 0);
///   non-conservative power P_nc = -(T - k (l - l0)) l_dot, the rest of the power F . qd = -T l_dot:
///   the damper's -c (l_dot + s_dot) l_dot while taut, and k (l - l0) l_dot while the damping holds the
///   cable slack although stretched. P_nc <= 0 whenever the actuator holds still (s_dot = 0).
#pragma once

#include <Eigen/Core>

#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
/// The state of a cable after evaluation.
struct CableState
{
  double length = 0.0;           // m (sum over segments)
  double rate = 0.0;             // m/s
  double rest_length = 0.0;      // m, after pull-in
  double stiffness = 0.0;        // k after pull-in, N/m (EA / l0 for a material cable)
  double tension = 0.0;          // N (>= 0 for tension-only elements)
  double damping_tension = 0.0;  // N, c (l_dot + s_dot): the damping part of the tension (0 when slack)
  bool slack = false;
};

/// The law along the cable: rest length l0(t), stiffness k(t), tension T (and its damping part) and slack
/// of a cable of length l (m) and rate l_dot (m/s) under actuation u (empty: no pull-in); no damping
/// unless `damping`. What evaluateCable applies once it has l and l_dot from the points.
CableState cableLaw(const Cable& cable, double length, double rate, const ActuationValues& u, bool damping);

/// Evaluates one cable (two points or sliding through several) at body poses and rates (q, qd) under actuation u
/// (empty: no pull-in).
CableState evaluateCable(const Model& model, const Cable& cable, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                         const ActuationValues& u, bool damping);
/// The cable's state alone at its point slots (`points`, as many as the cable has), the points' motion from frames
/// formed at (q, qd).
CableState evaluateCable(const Cable& cable, const PointSlot* points, const BodyFrames& frames,
                         const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const ActuationValues& u, bool damping);
/// V = 1/2 k (l - l0)^2 of a cable in state s (from evaluateCable), J; 0 when slack under tension_only
/// (l <= l0).
double cablePotentialEnergy(const Cable& cable, const CableState& s);
/// P_c = -dV/dt = -k (l - l0) l_dot at a fixed actuation value, W: the power the elastic part of the
/// tension delivers to the bodies.
double cableConservativePower(const Cable& cable, const CableState& s);
/// P_nc, W: the power of the rest of the tension, so that F . qd = P_c + P_nc: -c (l_dot + s_dot) l_dot while
/// taut, and k (l - l0) l_dot (the elastic part the tension-only clamp drops) while slack.
double cableNonConservativePower(const Cable& cable, const CableState& s);

}  // namespace active_tensegrity::core
