#include "active_tensegrity/oracle/body_kinematics.h"
#include "active_tensegrity/oracle/body_rotation.h"
#include "active_tensegrity/oracle/body_contact.h"

#include <cmath>

#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
namespace
{
using Row14 = Eigen::Matrix<double, 1, 14>;
using Mat3x14 = Eigen::Matrix<double, 3, 14>;
using Mat4x14 = Eigen::Matrix<double, 4, 14>;
using Mat14 = Eigen::Matrix<double, 14, 14>;
using Vec14 = Eigen::Matrix<double, 14, 1>;

const Vec3 kAxis = Vec3::UnitZ();
const Vec4 kConjugate(1.0, -1.0, -1.0, -1.0);

// one strut seen by the contact code: centre, Euler parameters, axis a = A(Theta) z, its rate and Jacobian
struct StrutAxis
{
  Vec3 centre, centre_rate;
  Vec4 theta, theta_rate;
  Vec3 axis;       // A(Theta) z (unit on the unit sphere)
  Vec3 axis_rate;  // B_Theta(Theta, z) Theta_dot (zero for a geometry-only axis)
  Mat34 axis_jac;  // B_Theta(Theta, z) = d axis / d Theta (only when asked for: the tangents alone read it)
  double half_length = 0.0;
  double radius = 0.0;
};

StrutAxis strutAxis(const Body& b, const Eigen::VectorXd& q, const Eigen::VectorXd* qd, bool jacobian = false)
{
  StrutAxis s;
  s.centre = q.segment<3>(b.offset);
  s.theta = q.segment<4>(b.offset + 3);
  s.axis = bodyZAxis(s.theta);
  if (jacobian)  // (not filled otherwise: filling it with NaN cost 1.5 % of the tower's dynamic step)
    s.axis_jac = pointJacobianTheta(s.theta, kAxis);
  s.half_length = 0.5 * b.length;
  s.radius = b.radius();
  if (qd)
  {
    s.centre_rate = qd->segment<3>(b.offset);
    s.theta_rate = qd->segment<4>(b.offset + 3);
    s.axis_rate = bodyZAxisRate(s.theta, s.theta_rate);
  }
  else
  {
    s.centre_rate.setZero();
    s.theta_rate.setZero();
    s.axis_rate.setZero();
  }
  return s;
}

// the narrow phase of one pair: closest points on the axes, s in metres from each centre
struct Closest
{
  double s1 = 0.0, s2 = 0.0;
  bool free1 = true, free2 = true;  // closest point strictly inside its segment (s moves with q)
  Vec3 p1, p2, d;                   // d = p1 - p2
  double h = 0.0;
  Vec3 n;  // d / h
  ClosestRegion region = ClosestRegion::kInterior;
};

Closest closest(const StrutAxis& a, const StrutAxis& b)
{
  const Vec3 ha = a.half_length * a.axis, hb = b.half_length * b.axis;
  const SegmentClosest c = closestPointsSegments(a.centre - ha, a.centre + ha, b.centre - hb, b.centre + hb);
  Closest out;
  out.s1 = (2.0 * c.s1 - 1.0) * a.half_length;
  out.s2 = (2.0 * c.s2 - 1.0) * b.half_length;
  out.free1 = c.region != ClosestRegion::kParallel && c.s1 > 0.0 && c.s1 < 1.0;
  out.free2 = c.region != ClosestRegion::kParallel && c.s2 > 0.0 && c.s2 < 1.0;
  out.region = c.region;
  out.p1 = c.p1;
  out.p2 = c.p2;
  out.d = c.p1 - c.p2;
  out.h = out.d.norm();
  const double scale = a.half_length + b.half_length;
  if (out.h > 1e-12 * scale)
    out.n = out.d / out.h;
  else
  {
    // the axes intersect: no direction from the points; take the common normal of the axes,
    // pointing from b's centre towards a's (a deep, unphysical overlap: the tangent is not exact here)
    Vec3 n = a.axis.cross(b.axis);
    if (n.squaredNorm() < 1e-24)
      n = a.axis.unitOrthogonal();
    n.normalize();
    if (n.dot(a.centre - b.centre) < 0.0)
      n = -n;
    out.n = n;
  }
  return out;
}

// N_f(Theta) with N_f u = B_Theta(Theta, u)^T f for every u (4x3)
Eigen::Matrix<double, 4, 3> transposedPointJacobianTimes(const Vec4& theta, const Vec3& f)
{
  Eigen::Matrix<double, 4, 3> m;
  for (int j = 0; j < 3; ++j)
    m.col(j) = pointJacobianTheta(theta, Vec3::Unit(j)).transpose() * f;
  return m;
}

// The modified Coulomb law's factor c_d at slip speed `slip` and its slope: 0 up to v0, linear to 1 at v1, then 1.
struct CoulombFactor
{
  double cd = 0.0;
  double dcd = 0.0;
};
CoulombFactor coulombFactor(double slip, double v0, double v1)
{
  if (slip <= v0)
    return {};
  if (slip >= v1)
    return { 1.0, 0.0 };
  const double slope = 1.0 / (v1 - v0);
  return { (slip - v0) * slope, slope };
}

// The friction force on body a from the slip velocity vt (tangential): t = vt / |vt|, F_T = mu c_d F_N, f = -F_T t.
// Fills the state's slip speed and friction; all zero below v0.
struct FrictionValue
{
  Vec3 t = Vec3::Zero(), f = Vec3::Zero();
  double cd = 0.0, dcd = 0.0, ft = 0.0;
};
FrictionValue frictionForce(ContactPairState& st, const Vec3& vt, double mu, double fn, double v0, double v1)
{
  FrictionValue out;
  st.slip_speed = vt.norm();
  const CoulombFactor law = coulombFactor(st.slip_speed, v0, v1);
  if (law.cd <= 0.0)
    return out;
  out.t = vt / st.slip_speed;
  out.cd = law.cd;
  out.dcd = law.dcd;
  out.ft = mu * out.cd * fn;
  out.f = -out.ft * out.t;
  st.friction_force = out.ft;
  st.friction_on_a = out.f;
  st.force_on_a += out.f;
  return out;
}

// A normal force law at one penetration: F_N = E (1 + D zeta_dot) + c zeta_dot (E the elastic force, Hertz: D from
// the restitution, c = 0; linear: E = k zeta, D = 0) with dF_N/dE = elastic_factor, dE/dzeta = de_dzeta and
// dF_N/dzeta_dot = rate_coefficient. No force unless fn > 0 (contact never pulls).
struct NormalLaw
{
  double fn = 0.0;
  double de_dzeta = 0.0;
  double elastic_factor = 0.0;
  double rate_coefficient = 0.0;
};

// Lankarani-Nikravesh: D = 3 (1 - c_e^2) / (4 v_0), v_0 floored at min_speed
double lankaraniNikravesh(double restitution, double impact_speed, double min_speed)
{
  return 3.0 * (1.0 - restitution * restitution) / (4.0 * std::max(impact_speed, min_speed));
}

NormalLaw hertzLaw(double elastic, double de_dzeta, double damping, double rate)
{
  const double hysteresis = 1.0 + damping * rate;
  return { elastic * hysteresis, de_dzeta, hysteresis, elastic * damping };
}

NormalLaw linearLaw(double stiffness, double damping, double zeta, double rate)
{
  return { stiffness * zeta + damping * rate, stiffness, 1.0, damping };
}

ContactPairState baseState(int pair, const Closest& c, const StrutAxis& a, const StrutAxis& b)
{
  ContactPairState st;
  st.pair = pair;
  st.region = c.region;
  st.normal = c.n;
  st.gap = c.h - a.radius - b.radius;
  st.penetration = -st.gap;
  st.active = st.penetration > 0.0;
  st.point_a = c.p1 - a.radius * c.n;
  st.point_b = c.p2 + b.radius * c.n;
  return st;
}

// ---- the ground --------------------------------------------------------------------------------------

const GroundContact& groundContact(const Model& model, int slot)
{
  return model.groundContactOf(slot);
}

// the state of a ground slot whose sphere's centre is at c
ContactPairState groundGeometry(const Model& model, int slot, const Vec3& c)
{
  const GroundContact& g = groundContact(model, slot);
  ContactPairState st;
  st.pair = slot;
  st.body_a = g.body;
  st.body_b = -1;
  st.normal = Vec3::UnitZ();
  st.gap = c.z() - g.radius - model.ground.height;
  st.penetration = -st.gap;
  st.active = st.penetration > 0.0;
  st.point_a = c - g.radius * Vec3::UnitZ();
  st.point_b = Vec3(c.x(), c.y(), model.ground.height);
  st.region = ClosestRegion::kInterior;
  return st;
}

using Row7 = Eigen::Matrix<double, 1, 7>;
using Mat3x7 = Eigen::Matrix<double, 3, 7>;
using Mat4x7 = Eigen::Matrix<double, 4, 7>;
using Mat7 = Eigen::Matrix<double, 7, 7>;
using Vec7 = Eigen::Matrix<double, 7, 1>;

/// A ground contact's point and state without forces, with the penetration rate.
ContactPairState groundMotion(const Model& model, int slot, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                              bool tangents, PointKinematics& k)
{
  const GroundContact& g = groundContact(model, slot);
  // the point's Jacobians only for the tangents; a force or a state needs its position and velocity alone
  if (tangents)
    pointKinematics(model, PointRef{ g.body, g.local }, q, qd, true, k);
  else
    pointMotion(model, PointRef{ g.body, g.local }, q, qd, k.p, k.v);
  ContactPairState st = groundGeometry(model, slot, k.p);
  st.penetration_rate = -k.v.z();
  return st;
}

// A sphere (centre c = R + A(Theta) u, radius r) on the plane z = h: zeta = h + r - c_z, n = z. The normal
// force acts along z through c; friction acts at the lowest point PA as a material point,
// u_A = u - r A^T z (moving over the body as it turns), against the slip v_T = P (R_dot + B(Theta, u_A)
// Theta_dot), P = I - z z^T. The tangents are exact (the point mass is the strut without Theta).
ContactPairState evaluateGroundContact(const Model& model, int slot, const Eigen::VectorXd& q,
                                       const Eigen::VectorXd& qd, double impact_speed, ContactMode mode,
                                       ContactContribution* out)
{
  const GroundContact& g = groundContact(model, slot);
  const GroundSettings& ground = model.ground;
  const double min_impact_speed = model.contact.min_impact_speed;
  const Body& body = model.bodies[g.body];
  const bool strut = body.kind == BodyKind::kStrut;
  const bool dynamic = mode == ContactMode::kDynamic;
  const bool tangents = out && out->tangents;
  PointKinematics k;
  ContactPairState st = groundMotion(model, slot, q, qd, tangents, k);
  if (out)
  {
    out->force.setZero();
    if (tangents)
    {
      out->stiffness.setZero();
      out->damping.setZero();
    }
  }
  if (!st.active)
    return st;
  const double zeta = st.penetration;
  // (g.stiffness is the sphere's K, or the ground's k under the linear law)
  st.stiffness = g.stiffness;
  NormalLaw law;
  if (ground.law == ContactLaw::kLinear)
    law = linearLaw(g.stiffness, dynamic ? ground.linear_damping : 0.0, zeta, st.penetration_rate);
  else
  {
    law = hertzLaw(g.stiffness * zeta * std::sqrt(zeta), 1.5 * g.stiffness * std::sqrt(zeta),
                   dynamic ? lankaraniNikravesh(ground.restitution, impact_speed, min_impact_speed) : 0.0,
                   st.penetration_rate);
  }
  if (!(law.fn > 0.0))
    return st;
  const double fn = law.fn;
  st.normal_force = fn;
  st.force_on_a = fn * Vec3::UnitZ();

  // friction at the lowest point of the sphere
  const bool friction = dynamic && ground.friction > 0.0;
  Vec4 theta = Vec4::Zero(), theta_rate = Vec4::Zero(), conj = Vec4::Zero();
  Vec3 ua = Vec3::Zero(), vtol = Vec3::Zero(), t = Vec3::Zero(), f = Vec3::Zero();
  Mat34 bua = Mat34::Zero();
  double cd = 0.0, dcd = 0.0, ft = 0.0;
  if (friction)
  {
    vtol = k.v;
    if (strut)
    {
      theta = thetaOf(q, body);
      theta_rate = thetaOf(qd, body);
      conj = kConjugate.cwiseProduct(theta);
      ua = g.local - g.radius * rotate(conj, Vec3::UnitZ());
      if (tangents)
        bua = pointJacobianTheta(theta, ua);
      vtol = qd.segment<3>(body.offset) + pointJacobianThetaTimes(theta, ua, theta_rate);
    }
    const FrictionValue fv = frictionForce(st, Vec3(vtol.x(), vtol.y(), 0.0), ground.friction, fn,
                                           ground.stick_velocity, ground.slip_velocity);
    t = fv.t;
    f = fv.f;
    cd = fv.cd;
    dcd = fv.dcd;
    ft = fv.ft;
  }
  if (!out)
    return st;
  // g = dc_z/dq^T = [z; B_u^T z] (the normal force's generalized direction)
  Vec7 gvec = Vec7::Zero();
  gvec.head<3>() = Vec3::UnitZ();
  if (strut)
    gvec.tail<4>() = pointJacobianThetaTransposeTimes(thetaOf(q, body), g.local, Vec3::UnitZ());
  Vec7 force = fn * gvec;
  if (ft > 0.0)
  {
    force.head<3>() += f;
    if (strut)
      force.tail<4>() += pointJacobianThetaTransposeTimes(theta, ua, f);
  }
  // (fixed sizes: a run-time sized block of a 7-vector lets GCC see 8-wide loads past its end)
  if (strut)
    out->force.head<7>() = force;
  else
    out->force.head<3>() = force.head<3>();
  if (!out->tangents)
    return st;

  // normal force F_N = E(zeta) (1 + D zeta_dot) + c zeta_dot, zeta = h + r - c_z, zeta_dot = -v_z
  const Row7 jzeta = -gvec.transpose();
  const Row7 jq_rate = -k.dv_dq.row(2);
  const Row7 jqd_rate = -gvec.transpose();
  const Row7 jq_fn = law.elastic_factor * law.de_dzeta * jzeta + law.rate_coefficient * jq_rate;
  const Row7 jqd_fn = law.rate_coefficient * jqd_rate;
  Mat7 jq_force = gvec * jq_fn;
  if (strut)
    jq_force.block<4, 4>(3, 3) += fn * pointHessianTheta(g.local, Vec3::UnitZ());
  Mat7 jqd_force = gvec * jqd_fn;

  if (ft > 0.0)
  {
    Mat3x7 jua = Mat3x7::Zero();  // d u_A / dq
    Mat3x7 jq_vtol = Mat3x7::Zero(), jqd_vtol = Mat3x7::Zero();
    jqd_vtol.block<3, 3>(0, 0).setIdentity();
    if (strut)
    {
      jua.block<3, 4>(0, 3) = -g.radius * pointJacobianTheta(conj, Vec3::UnitZ()) * kConjugate.asDiagonal();
      jq_vtol = rotationMatrixRate(theta, theta_rate) * jua;
      jq_vtol.block<3, 4>(0, 3) += pointJacobianTheta(theta_rate, ua);
      jqd_vtol.block<3, 4>(0, 3) = bua;
    }
    Mat3x7 jq_vt = jq_vtol, jqd_vt = jqd_vtol;
    jq_vt.row(2).setZero();
    jqd_vt.row(2).setZero();
    const Mat3 tproj = (Mat3::Identity() - t * t.transpose()) / st.slip_speed;
    const Row7 jq_ft = ground.friction * (fn * dcd * t.transpose() * jq_vt + cd * jq_fn);
    const Row7 jqd_ft = ground.friction * (fn * dcd * t.transpose() * jqd_vt + cd * jqd_fn);
    const Mat3x7 jq_f = -(t * jq_ft + ft * tproj * jq_vt);
    const Mat3x7 jqd_f = -(t * jqd_ft + ft * tproj * jqd_vt);
    jq_force.topRows<3>() += jq_f;
    jqd_force.topRows<3>() += jqd_f;
    if (strut)
    {
      Mat4x7 jq_rot = bua.transpose() * jq_f + transposedPointJacobianTimes(theta, f) * jua;
      jq_rot.block<4, 4>(0, 3) += pointHessianTheta(ua, f);
      jq_force.bottomRows<4>() += jq_rot;
      jqd_force.bottomRows<4>() += bua.transpose() * jqd_f;
    }
  }
  if (strut)
  {
    out->stiffness.topLeftCorner<7, 7>() = -jq_force;
    out->damping.topLeftCorner<7, 7>() = -jqd_force;
  }
  else
  {
    out->stiffness.topLeftCorner<3, 3>() = -jq_force.topLeftCorner<3, 3>();
    out->damping.topLeftCorner<3, 3>() = -jqd_force.topLeftCorner<3, 3>();
  }
  return st;
}
}  // namespace

namespace
{
// sin(min_crossing_angle), remembered for the last angle asked (a sine per pair evaluation cost 0.6 % of the
// tower's dynamic step)
double crossingFloorSine(double angle)
{
  thread_local double last_angle = 0.0, last_sine = 0.0;
  if (angle != last_angle)
  {
    last_sine = std::sin(angle);
    last_angle = angle;
  }
  return last_sine;
}

// K and dK/dcos2 with the floor sin(min_crossing_angle) given
StiffnessValue stiffnessAbove(double k90, double cos2, double floor_sin)
{
  // Re = sqrt(r1 r2) / |sin theta|, so K = k90 (sin^2 theta)^(-1/4)
  StiffnessValue v;
  const double sin2 = 1.0 - cos2;
  if (sin2 > floor_sin * floor_sin)
  {
    v.k = k90 / std::sqrt(std::sqrt(sin2));  // (sin^2)^(-1/4), without pow
    v.dk_dc2 = 0.25 * v.k / sin2;
  }
  else
    v.k = k90 / std::sqrt(floor_sin);
  return v;
}
}  // namespace

StiffnessValue contactStiffness(double k90, double cos2, double min_crossing_angle)
{
  return stiffnessAbove(k90, cos2, std::sin(min_crossing_angle));
}

namespace
{
/// A strut pair's axes, closest points and state without forces, with the penetration rate (the velocities of the
/// axis points at fixed s; also outside contact: the dynamics solver takes the impact speed from it).
struct PairMotion
{
  StrutAxis a, b;
  Closest c;
  Vec3 dv;  // velocity of a's closest axis point relative to b's
  ContactPairState st;
};

PairMotion pairMotion(const Model& model, int pair, const Eigen::VectorXd& q, const Eigen::VectorXd& qd, bool tangents)
{
  const auto [body_a, body_b] = model.pairBodies(pair);
  PairMotion m;
  m.a = strutAxis(model.bodies[body_a], q, &qd, tangents);
  m.b = strutAxis(model.bodies[body_b], q, &qd, tangents);
  m.c = closest(m.a, m.b);
  m.st = baseState(pair, m.c, m.a, m.b);
  m.st.body_a = body_a;
  m.st.body_b = body_b;
  m.dv = (m.a.centre_rate + m.c.s1 * m.a.axis_rate) - (m.b.centre_rate + m.c.s2 * m.b.axis_rate);
  m.st.penetration_rate = -m.c.n.dot(m.dv);
  return m;
}

}  // namespace

ContactPairState contactMotion(const Model& model, int pair, const Eigen::VectorXd& q, const Eigen::VectorXd& qd)
{
  PointKinematics k;
  return model.isGroundSlot(pair) ? groundMotion(model, pair, q, qd, false, k) :
                                    pairMotion(model, pair, q, qd, false).st;
}

ContactPairState evaluateContact(const Model& model, int pair, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                 double impact_speed, ContactMode mode, ContactContribution* out)
{
  if (model.isGroundSlot(pair))
    return evaluateGroundContact(model, pair, q, qd, impact_speed, mode, out);
  const StrutPair p = model.strutPair(pair);
  const ContactSettings& set = model.contact;
  const bool dynamic = mode == ContactMode::kDynamic;
  const bool tangents = out && out->tangents;
  PairMotion motion = pairMotion(model, pair, q, qd, tangents);
  const StrutAxis& a = motion.a;
  const StrutAxis& b = motion.b;
  const Closest& c = motion.c;
  ContactPairState& st = motion.st;
  if (out)
  {
    out->force.setZero();
    if (out->tangents)
    {
      out->stiffness.setZero();
      out->damping.setZero();
    }
  }
  if (!st.active)
    return st;
  const Vec3& axis_rate1 = a.axis_rate;
  const Vec3& axis_rate2 = b.axis_rate;
  const Vec3& dv = motion.dv;

  // the forces: stiffness from the crossing angle, then Lankarani-Nikravesh (dynamics) or Hertz
  // (statics), or the linear spring-dashpot; never pulling
  const double dot = a.axis.dot(b.axis), m1 = a.axis.squaredNorm(), m2 = b.axis.squaredNorm();
  const double cos2 = dot * dot / (m1 * m2);
  const double zeta = st.penetration;
  NormalLaw law;
  double de_dc2 = 0.0;
  if (set.law == ContactLaw::kLinear)
  {
    st.stiffness = set.linear_stiffness;
    law = linearLaw(set.linear_stiffness, dynamic ? set.linear_damping : 0.0, zeta, st.penetration_rate);
  }
  else
  {
    const double floor_sin = crossingFloorSine(set.min_crossing_angle);
    const StiffnessValue kv = stiffnessAbove(p.stiffness90, cos2, floor_sin);
    st.stiffness = kv.k;
    // the elastic force E(zeta, cos2): the sleeves' Hertz law, plus the cores' once they overlap
    double elastic = kv.k * zeta * std::sqrt(zeta);
    double de_dzeta = 1.5 * kv.k * std::sqrt(zeta);
    de_dc2 = kv.dk_dc2 * zeta * std::sqrt(zeta);
    const double zc = zeta - p.core_gap;
    if (p.core_stiffness90 > 0.0 && zc > 0.0)
    {
      const StiffnessValue kc = stiffnessAbove(p.core_stiffness90, cos2, floor_sin);
      st.core_penetration = zc;
      st.core_stiffness = kc.k;
      elastic += kc.k * zc * std::sqrt(zc);
      de_dzeta += 1.5 * kc.k * std::sqrt(zc);
      de_dc2 += kc.dk_dc2 * zc * std::sqrt(zc);
    }
    law = hertzLaw(elastic, de_dzeta,
                   dynamic ? lankaraniNikravesh(set.restitution, impact_speed, set.min_impact_speed) : 0.0,
                   st.penetration_rate);
  }
  if (!(law.fn > 0.0))
    return st;
  const double fn = law.fn;
  st.normal_force = fn;
  st.force_on_a = fn * c.n;

  // friction (dynamics only, and only when mu > 0): slip of the contact points as material points,
  // u_A = s1 z - r1 A1^T n, u_B = s2 z + r2 A2^T n
  const bool friction = dynamic && set.friction > 0.0;
  const Vec4 conj1 = kConjugate.cwiseProduct(a.theta), conj2 = kConjugate.cwiseProduct(b.theta);
  Mat3 at1, at2;  // A^T
  Vec3 ua, ub;
  Mat34 bua, bub;
  Vec3 vtol = Vec3::Zero(), vt = Vec3::Zero(), t = Vec3::Zero(), f = Vec3::Zero();
  double cd = 0.0, dcd = 0.0, ft = 0.0;
  if (friction)
  {
    ua = c.s1 * kAxis - a.radius * rotate(conj1, c.n);
    ub = c.s2 * kAxis + b.radius * rotate(conj2, c.n);
    if (tangents)  // (the matrices only the tangents below use)
    {
      at1 = rotationMatrix(conj1);
      at2 = rotationMatrix(conj2);
      bua = pointJacobianTheta(a.theta, ua);
      bub = pointJacobianTheta(b.theta, ub);
    }
    vtol = a.centre_rate + pointJacobianThetaTimes(a.theta, ua, a.theta_rate) - b.centre_rate -
           pointJacobianThetaTimes(b.theta, ub, b.theta_rate);
    vt = vtol - c.n.dot(vtol) * c.n;
    const FrictionValue fv = frictionForce(st, vt, set.friction, fn, set.stick_velocity, set.slip_velocity);
    t = fv.t;
    f = fv.f;  // on strut a at PA
    cd = fv.cd;
    dcd = fv.dcd;
    ft = fv.ft;
  }
  if (!out)
    return st;
  if (!out->tangents)
  {
    // the generalized force alone: g F_N (g below) and the friction's [f; B_A^T f; -f; -B_B^T f]
    out->force << fn * c.n, (fn * c.s1) * bodyZAxisTransposeTimes(a.theta, c.n), -fn * c.n,
        (-fn * c.s2) * bodyZAxisTransposeTimes(b.theta, c.n);
    if (ft > 0.0)
    {
      out->force.segment<3>(0) += f;
      out->force.segment<4>(3) += pointJacobianThetaTransposeTimes(a.theta, ua, f);
      out->force.segment<3>(7) -= f;
      out->force.segment<4>(10) -= pointJacobianThetaTransposeTimes(b.theta, ub, f);
    }
    return st;
  }

  // Jacobians over x = [q_a; q_b] (14 columns): axis points at fixed s, axes
  Mat3x14 jp1 = Mat3x14::Zero(), jp2 = Mat3x14::Zero(), ja1 = Mat3x14::Zero(), ja2 = Mat3x14::Zero();
  jp1.block<3, 3>(0, 0).setIdentity();
  jp1.block<3, 4>(0, 3) = c.s1 * a.axis_jac;
  jp2.block<3, 3>(0, 7).setIdentity();
  jp2.block<3, 4>(0, 10) = c.s2 * b.axis_jac;
  ja1.block<3, 4>(0, 3) = a.axis_jac;
  ja2.block<3, 4>(0, 10) = b.axis_jac;

  // closest points move along the axes: stationarity a_i . d = 0 for each free s_i
  Row14 ds1 = Row14::Zero(), ds2 = Row14::Zero();
  {
    const Mat3x14 jd_fixed = jp1 - jp2;
    const Row14 g1 = c.d.transpose() * ja1 + a.axis.transpose() * jd_fixed;
    const Row14 g2 = c.d.transpose() * ja2 + b.axis.transpose() * jd_fixed;
    const double h11 = a.axis.squaredNorm(), h12 = -a.axis.dot(b.axis), h22 = -b.axis.squaredNorm();
    if (c.free1 && c.free2)
    {
      const double det = h11 * h22 + h12 * h12;  // H = [h11 h12; -h12 h22]
      ds1 = -(h22 * g1 - h12 * g2) / det;
      ds2 = -(h11 * g2 + h12 * g1) / det;
    }
    else if (c.free1)
      ds1 = -g1 / h11;
    else if (c.free2)
      ds2 = -g2 / h22;
  }
  const Mat3x14 jd = jp1 - jp2 + a.axis * ds1 - b.axis * ds2;
  const Mat3 proj = Mat3::Identity() - c.n * c.n.transpose();
  const Mat3x14 jn = c.h > 0.0 ? Mat3x14(proj * jd / c.h) : Mat3x14::Zero();
  const Row14 jzeta = -c.n.transpose() * jd;

  // penetration rate
  Mat3x14 jqv1 = axis_rate1 * ds1, jqv2 = axis_rate2 * ds2;
  jqv1.block<3, 4>(0, 3) += c.s1 * pointJacobianTheta(a.theta_rate, kAxis);
  jqv2.block<3, 4>(0, 10) += c.s2 * pointJacobianTheta(b.theta_rate, kAxis);
  const Row14 jq_rate = -dv.transpose() * jn - c.n.transpose() * (jqv1 - jqv2);
  const Row14 jqd_rate = -c.n.transpose() * (jp1 - jp2);

  // the elastic force through the crossing angle (the stiffnesses' dependence on cos2)
  Row14 je_angle = Row14::Zero();
  if (de_dc2 != 0.0)
  {
    const Row14 jdot = b.axis.transpose() * ja1 + a.axis.transpose() * ja2;
    const Row14 jm1 = 2.0 * a.axis.transpose() * ja1, jm2 = 2.0 * b.axis.transpose() * ja2;
    je_angle = de_dc2 * (2.0 * dot * jdot - cos2 * (m2 * jm1 + m1 * jm2)) / (m1 * m2);
  }

  // normal force F_N = E (1 + D zeta_dot) + c zeta_dot and the generalized normal force g F_N with
  // g = [n; s1 B1^T n; -n; -s2 B2^T n]
  const Row14 jq_fn = law.elastic_factor * (je_angle + law.de_dzeta * jzeta) + law.rate_coefficient * jq_rate;
  const Row14 jqd_fn = law.rate_coefficient * jqd_rate;
  Vec14 g;
  g << c.n, c.s1 * a.axis_jac.transpose() * c.n, -c.n, -c.s2 * b.axis_jac.transpose() * c.n;
  Mat14 jg = Mat14::Zero();
  jg.block<3, 14>(0, 0) = jn;
  jg.block<4, 14>(3, 0) = c.s1 * a.axis_jac.transpose() * jn + (a.axis_jac.transpose() * c.n) * ds1;
  jg.block<4, 4>(3, 3) += pointHessianTheta(c.s1 * kAxis, c.n);
  jg.block<3, 14>(7, 0) = -jn;
  jg.block<4, 14>(10, 0) = -(c.s2 * b.axis_jac.transpose() * jn + (b.axis_jac.transpose() * c.n) * ds2);
  jg.block<4, 4>(10, 10) -= pointHessianTheta(c.s2 * kAxis, c.n);
  out->force = fn * g;
  Mat14 jq_force = g * jq_fn + fn * jg;
  Mat14 jqd_force = g * jqd_fn;

  if (ft > 0.0)
  {
    // friction: Q_T = [f; B_A^T f; -f; -B_B^T f] with f = -F_T t
    Mat3x14 jua = kAxis * ds1 - a.radius * (at1 * jn);
    jua.block<3, 4>(0, 3) -= a.radius * pointJacobianTheta(conj1, c.n) * kConjugate.asDiagonal();
    Mat3x14 jub = kAxis * ds2 + b.radius * (at2 * jn);
    jub.block<3, 4>(0, 10) += b.radius * pointJacobianTheta(conj2, c.n) * kConjugate.asDiagonal();
    Mat3x14 jq_vtol = rotationMatrixRate(a.theta, a.theta_rate) * jua - rotationMatrixRate(b.theta, b.theta_rate) * jub;
    jq_vtol.block<3, 4>(0, 3) += pointJacobianTheta(a.theta_rate, ua);
    jq_vtol.block<3, 4>(0, 10) -= pointJacobianTheta(b.theta_rate, ub);
    Mat3x14 jqd_vtol = Mat3x14::Zero();
    jqd_vtol.block<3, 3>(0, 0).setIdentity();
    jqd_vtol.block<3, 4>(0, 3) = bua;
    jqd_vtol.block<3, 3>(0, 7) = -Mat3::Identity();
    jqd_vtol.block<3, 4>(0, 10) = -bub;

    const double vn = c.n.dot(vtol);
    const Mat3x14 jq_vt = proj * jq_vtol - vn * jn - c.n * (vtol.transpose() * jn);
    const Mat3x14 jqd_vt = proj * jqd_vtol;
    const Mat3 tproj = (Mat3::Identity() - t * t.transpose()) / st.slip_speed;
    const Row14 jq_ft = set.friction * (fn * dcd * t.transpose() * jq_vt + cd * jq_fn);
    const Row14 jqd_ft = set.friction * (fn * dcd * t.transpose() * jqd_vt + cd * jqd_fn);
    const Mat3x14 jq_f = -(t * jq_ft + ft * tproj * jq_vt);
    const Mat3x14 jqd_f = -(t * jqd_ft + ft * tproj * jqd_vt);

    Vec14 qt;
    qt << f, bua.transpose() * f, -f, -bub.transpose() * f;
    out->force += qt;
    Mat4x14 jq_rot_a = bua.transpose() * jq_f + transposedPointJacobianTimes(a.theta, f) * jua;
    jq_rot_a.block<4, 4>(0, 3) += pointHessianTheta(ua, f);
    Mat4x14 jq_rot_b = bub.transpose() * jq_f + transposedPointJacobianTimes(b.theta, f) * jub;
    jq_rot_b.block<4, 4>(0, 10) += pointHessianTheta(ub, f);
    jq_force.block<3, 14>(0, 0) += jq_f;
    jq_force.block<4, 14>(3, 0) += jq_rot_a;
    jq_force.block<3, 14>(7, 0) -= jq_f;
    jq_force.block<4, 14>(10, 0) -= jq_rot_b;
    jqd_force.block<3, 14>(0, 0) += jqd_f;
    jqd_force.block<4, 14>(3, 0) += bua.transpose() * jqd_f;
    jqd_force.block<3, 14>(7, 0) -= jqd_f;
    jqd_force.block<4, 14>(10, 0) -= bub.transpose() * jqd_f;
  }
  out->stiffness = -jq_force;
  out->damping = -jqd_force;
  return st;
}

bool passedThrough(const Model& model, int pair, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1)
{
  const auto [body_a, body_b] = model.pairBodies(pair);
  const Body& ba = model.bodies[body_a];
  const Body& bb = model.bodies[body_b];
  const StrutAxis a0 = strutAxis(ba, q0, nullptr), b0 = strutAxis(bb, q0, nullptr);
  const StrutAxis a1 = strutAxis(ba, q1, nullptr), b1 = strutAxis(bb, q1, nullptr);
  return axesPassedThrough({ a0.centre, a0.axis }, { b0.centre, b0.axis }, { a1.centre, a1.axis },
                           { b1.centre, b1.axis }, a0.half_length, b0.half_length);
}
}  // namespace active_tensegrity::core
