/// Strut-strut contact (Kan et al. 2019, Sec. 3-4 and Appendix A; docs/physics.md, "Strut contact"), in stages:
/// broad phase (broad_phase.h) -> narrow phase (closest points of the two axis segments,
/// geometry.h) -> force law (this file) -> assembly (System::contactForce).
///
/// For struts 1 and 2 with axes P_i(s_i) = R_i + s_i A(Theta_i) z, s_i in [-L_i/2, L_i/2], and the
/// closest points P1, P2 (h = |P1 - P2|, n = (P1 - P2)/h):
///   penetration   zeta = r1 + r2 - h  (contact when zeta > 0),
///   rate          zeta_dot = -n . (v_P1 - v_P2)  (material points at fixed s_i),
///   normal force  F_N = K zeta^(3/2) (1 + D zeta_dot),  D = 3 (1 - c_e^2) / (4 v_0)   (dynamics)
///                 F_N = K zeta^(3/2)                                                  (statics)
///                 with F_N >= 0 (no adhesion), v_0 the penetration rate at contact onset;
///                 or, with the linear law (ContactLaw::kLinear), F_N = k zeta + c zeta_dot (c = 0 in statics),
///                 k and c the scene's, no crossing-angle factor and no cores;
///   stiffness     K = (4/3) E* sqrt(Re), Re = sqrt(r1 r2) / |sin theta| (Johnson, Eq. 30-35 closed),
///                 theta the crossing angle, |sin theta| floored at sin(min_crossing_angle);
///   layered       struts with a core (radius rc, its own material): once zeta exceeds the sleeves'
///                 thicknesses t = (r1 - rc1) + (r2 - rc2), the cores' Hertz contact adds K_c (zeta - t)^(3/2)
///                 (K_c from the cores' E* and radii, the same crossing-angle law) to K zeta^(3/2): force and
///                 tangent are continuous at the switch;
///   friction      F_T = mu c_d(|v_T|) F_N against the slip v_T = (I - n n^T)(v_PA - v_PB) of the
///                 contact points PA = P1 - r1 n, PB = P2 + r2 n (material points of each strut),
///                 c_d = 0 below v0, linear to 1 at v1, 1 above (Ambrosio's modified Coulomb law);
/// The law acts on the struts' axis segments, which are each strut's two end nodes: the forces on the nodes and
/// their exact tangents are the natural coordinates' (natural.h: naturalContact), derived from this law.
///
/// The ground (Model::ground) is a half-space z <= h touched by spheres (Model::ground_contacts: strut ends,
/// point masses with a radius), each a contact "slot" after the strut pairs: for a sphere of centre c and
/// radius r, zeta = h + r - c_z, n = +z (from the ground, "body b", towards the body), the same
/// Lankarani-Nikravesh normal force with K = (4/3) E* sqrt(r) and the ground's restitution, and the same
/// modified Coulomb friction (the ground's mu, v0 and v1) at the sphere's lowest point PA = c - r z as a material
/// point.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/base/geometry.h"
#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
/// How the normal force is evaluated: with Lankarani-Nikravesh damping and friction (dynamics), or
/// Hertz's law alone (statics: no velocities, no friction).
enum class ContactMode
{
  kDynamic,
  kStatic
};

/// (effectiveModulus and makeStrutPair: model.h)

/// Everything known about one checked pair after evaluation (world frame, SI units).
struct ContactPairState
{
  int pair = -1;                      // contact slot: a strut pair (Model::strutPair), then the ground contacts
  int body_a = -1;                    // strut a (or the body touching the ground)
  int body_b = -1;                    // strut b, -1 for the ground
  bool active = false;                // zeta > 0
  double gap = 0.0;                   // surface gap h - r1 - r2 (m), negative when overlapping
  double penetration = 0.0;           // zeta (m)
  double penetration_rate = 0.0;      // zeta_dot (m/s)
  double stiffness = 0.0;             // K (N/m^1.5) of the sleeves (the outer layers); k (N/m) under the linear law
  double core_penetration = 0.0;      // zeta - t: overlap of the cores of layered struts (m), 0 until they meet
  double core_stiffness = 0.0;        // K_c (N/m^1.5) of the cores, while they overlap
  double normal_force = 0.0;          // F_N (N)
  double slip_speed = 0.0;            // |v_T| (m/s)
  double friction_force = 0.0;        // F_T (N)
  Vec3 normal = Vec3::Zero();         // n, from strut b (or the ground) towards strut a
  Vec3 point_a = Vec3::Zero();        // PA, contact point on strut a's surface
  Vec3 point_b = Vec3::Zero();        // PB, contact point on strut b's surface (or the ground's, below PA)
  Vec3 force_on_a = Vec3::Zero();     // F_N n - F_T t: total contact force on strut a (b gets minus it)
  Vec3 friction_on_a = Vec3::Zero();  // -F_T t
  ClosestRegion region = ClosestRegion::kInterior;
};

/// Geometry of a contact slot at body poses q alone (narrow phase, no forces): gap, closest points, normal.
ContactPairState contactGeometry(const Model& model, int pair, const Eigen::VectorXd& q);

/// Evaluates contact slot `pair` (a strut pair or a ground contact) at body poses and rates (q, qd) with impact speed
/// v_0 (m/s, used in dynamics only): the struts' end nodes and spin rates from the poses, then the natural
/// coordinates' law (statics: at rest, so neither damping nor friction).
ContactPairState evaluateContact(const Model& model, int pair, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                 double impact_speed, ContactMode mode);

/// The elastic energy (J) stored in contact state `st` (from evaluateContact): Hertz's (2/5) K zeta^(5/2), plus the
/// cores', or (1/2) k zeta^2 under the linear law; 0 when not active.
double contactElasticEnergy(const Model& model, const ContactPairState& st);

/// Appends the ground slots whose sphere is within `margin` (m) of the ground at q (none when the ground is off).
void appendGroundCandidates(const Model& model, const Eigen::VectorXd& q, double margin, std::vector<int>& out);

/// "ground" for body -1, else the body's name (contacts' second body in outputs).
const std::string& contactBodyName(const Model& model, int body);

/// A strut axis at an instant: its centre and unit direction.
struct AxisPose
{
  Vec3 centre, axis;
};
/// True when two axes of half-lengths half_a and half_b, each moving linearly from (a0, b0) to (a1, b1), passed
/// through each other: the signed distance (c1 - c2) . (a1 x a2) of the axis lines changed sign while the lines'
/// closest points lie inside both segments. A common normal a1 x a2 that turned by more than 90 degrees (motion
/// through a parallel configuration) is not judged.
bool axesPassedThrough(const AxisPose& a0, const AxisPose& b0, const AxisPose& a1, const AxisPose& b1, double half_a,
                       double half_b);

}  // namespace active_tensegrity::core
