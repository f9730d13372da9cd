#include "active_tensegrity/core/solvers/natural.h"

#include <algorithm>
#include <sstream>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include <unsupported/Eigen/AutoDiff>

#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
namespace
{
using Vec14 = Eigen::Matrix<double, 14, 1>;
using Mat14 = Eigen::Matrix<double, 14, 14>;

// ---- the model -----------------------------------------------------------------------------------------

// the node at position p (within `tolerance`), added when there is none
int nodeAt(NaturalModel& nm, const Vec3& p, double tolerance)
{
  for (size_t i = 0; i < nm.nodes.size(); ++i)
    if ((nm.nodes[i].position0 - p).norm() <= tolerance)
      return static_cast<int>(i);
  NaturalNode n;
  n.position0 = p;
  nm.nodes.push_back(n);
  return static_cast<int>(nm.nodes.size()) - 1;
}

// the node of a point of the scene: a strut end or a point mass
int pointNode(NaturalModel& nm, const Model& model, const PointRef& p, double tolerance, const std::string& what)
{
  if (p.body < 0)
  {
    // a point of the ground: a fixed node of its own (never merged with a body's node that starts there)
    NaturalNode n;
    n.kind = NaturalNode::Kind::kFixed;
    n.position0 = p.local;
    nm.nodes.push_back(n);
    return static_cast<int>(nm.nodes.size()) - 1;
  }
  const Body& b = model.bodies[p.body];
  if (b.kind == BodyKind::kStrut)
  {
    const double half = 0.5 * b.length;
    if (!(std::abs(std::abs(p.local.z()) - half) <= tolerance && p.local.head<2>().norm() <= tolerance))
      throw std::invalid_argument(what + ": a point of strut " + b.name +
                                  " away from its ends is not a node of the natural coordinates");
  }
  else if (p.local.norm() > tolerance)
    throw std::invalid_argument(what + ": a point away from point mass " + b.name);
  return nodeAt(nm, pointPosition(model, p, model.q0), tolerance);
}

// ---- the contact kernel --------------------------------------------------------------------------------

template <typename T>
using V3 = Eigen::Matrix<T, 3, 1>;

template <typename T>
T clamp01(const T& x)
{
  if (x < 0.0)
    return T(0.0);
  if (x > 1.0)
    return T(1.0);
  return x;
}

// a scalar's value, and a vector's
double valueOf(double x)
{
  return x;
}
template <typename D>
double valueOf(const Eigen::AutoDiffScalar<D>& x)
{
  return x.value();
}
template <typename T>
Vec3 valueOf(const V3<T>& x)
{
  return Vec3(valueOf(x(0)), valueOf(x(1)), valueOf(x(2)));
}

// the penetration below which a contact is not touching, relative to the struts' size or the sphere's height
constexpr double kPenetrationRoundoff = 64.0 * std::numeric_limits<double>::epsilon();

// One pair's contact on its four nodes (a, b of strut 1, then of strut 2), generic in the scalar so that the
// tangents are its forward-mode derivatives. Fills F (when `force`) and the pair's state (values).
template <typename T>
void pairKernel(const Model& model, const NaturalContactSlot& cs, double floor_sin, const V3<T> r[4], const V3<T> v[4],
                const T spin[2], double impact_speed, bool force, Eigen::Matrix<T, 14, 1>& F, ContactPairState& st)
{
  using std::sqrt;
  const double inv_length2[2] = { cs.inv_length[0] * cs.inv_length[0], cs.inv_length[1] * cs.inv_length[1] };
  const double scale = 0.5 / cs.inv_length[0] + 0.5 / cs.inv_length[1];  // (L1 + L2) / 2
  const ContactSettings& set = model.contact;
  F.setZero();
  const V3<T> u1 = r[1] - r[0], u2 = r[3] - r[2], w = r[0] - r[2];
  const T a = u1.squaredNorm(), e = u2.squaredNorm(), f = u2.dot(w), c = u1.dot(w), b = u1.dot(u2);
  const T den = a * e - b * b;
  T s, t;
  bool parallel = false;
  if (den > 1e-12 * a * e)
    s = clamp01(T((b * f - c * e) / den));
  else
  {
    parallel = true;
    s = 0.5 * (clamp01(T(-c / a)) + clamp01(T((b - c) / a)));
  }
  t = (b * s + f) / e;
  if (t < 0.0)
  {
    t = T(0.0);
    s = clamp01(T(-c / a));
  }
  else if (t > 1.0)
  {
    t = T(1.0);
    s = clamp01(T((b - c) / a));
  }
  const V3<T> p1 = r[0] + s * u1, p2 = r[2] + t * u2, d = p1 - p2;
  const T h = d.norm();
  V3<T> n;
  if (h > 1e-12 * scale)
    n = d / h;
  else
  {
    n = u1.cross(u2);
    if (n.squaredNorm() < 1e-24)
    {
      const Vec3 o = valueOf(u1).unitOrthogonal();
      n = V3<T>(T(o.x()), T(o.y()), T(o.z()));
    }
    n.normalize();
    if (n.dot(r[0] + r[1] - r[2] - r[3]) < 0.0)
      n = -n;
  }
  const double r1 = cs.radius[0], r2 = cs.radius[1];
  const T zeta = r1 + r2 - h;
  const V3<T> vp1 = v[0] + s * (v[1] - v[0]), vp2 = v[2] + t * (v[3] - v[2]);
  const T rate = -n.dot(vp1 - vp2);
  st.normal = valueOf(n);
  st.gap = -valueOf(zeta);
  st.penetration = valueOf(zeta);
  // (a penetration within the round-off of the axes' distance is none: a contact that begins exactly where a step
  // ends would otherwise switch on and off between Newton's iterates)
  st.active = st.penetration > kPenetrationRoundoff * scale;
  st.point_a = valueOf(V3<T>(p1 - r1 * n));
  st.point_b = valueOf(V3<T>(p2 + r2 * n));
  st.penetration_rate = valueOf(rate);
  st.region = parallel                                       ? ClosestRegion::kParallel :
              (s <= 0.0 || s >= 1.0 || t <= 0.0 || t >= 1.0) ? ClosestRegion::kEnd :
                                                               ClosestRegion::kInterior;
  if (!st.active || !force)
    return;
  // the normal force: Hertz with the crossing-angle stiffness (and the cores beyond the sleeves) and
  // Lankarani-Nikravesh damping, or the linear law
  T fn;
  if (set.law == ContactLaw::kLinear)
  {
    st.stiffness = set.linear_stiffness;
    fn = set.linear_stiffness * zeta + set.linear_damping * rate;
  }
  else
  {
    const T sin2 = 1.0 - b * b / (a * e);
    const bool above = sin2 > floor_sin * floor_sin;
    const T root = above ? T(sqrt(sqrt(sin2))) : T(sqrt(floor_sin));
    const T k = cs.stiffness90 / root;
    st.stiffness = valueOf(k);
    T elastic = k * zeta * sqrt(zeta);
    const T zc = zeta - cs.core_gap;
    if (cs.core_stiffness90 > 0.0 && zc > 0.0)
    {
      const T kc = cs.core_stiffness90 / root;
      st.core_penetration = valueOf(zc);
      st.core_stiffness = valueOf(kc);
      elastic += kc * zc * sqrt(zc);
    }
    const double damping =
        3.0 * (1.0 - set.restitution * set.restitution) / (4.0 * std::max(impact_speed, set.min_impact_speed));
    fn = elastic * (1.0 + damping * rate);
  }
  if (!(fn > 0.0))
    return;
  st.normal_force = valueOf(fn);
  st.force_on_a = valueOf(V3<T>(fn * n));
  F.template segment<3>(0) = (1.0 - s) * fn * n;
  F.template segment<3>(3) = s * fn * n;
  F.template segment<3>(6) = -(1.0 - t) * fn * n;
  F.template segment<3>(9) = -t * fn * n;
  if (!(set.friction > 0.0))
    return;
  // friction at the contact points as material points: w = u x u_dot / L^2 + w_s e (e = u / L, w_s the spin rate)
  const V3<T> e1 = cs.inv_length[0] * u1, e2 = cs.inv_length[1] * u2;
  const V3<T> w1 = inv_length2[0] * u1.cross(v[1] - v[0]) + spin[0] * e1;
  const V3<T> w2 = inv_length2[1] * u2.cross(v[3] - v[2]) + spin[1] * e2;
  const V3<T> vtol = (vp1 - r1 * w1.cross(n)) - (vp2 + r2 * w2.cross(n));
  const V3<T> vt = vtol - n.dot(vtol) * n;
  const T slip = vt.norm();
  st.slip_speed = valueOf(slip);
  if (!(slip > set.stick_velocity))
    return;
  const T cd =
      slip >= set.slip_velocity ? T(1.0) : T((slip - set.stick_velocity) / (set.slip_velocity - set.stick_velocity));
  const T ft = set.friction * cd * fn;
  const V3<T> fa = -(ft / slip) * vt;  // on strut 1 at its contact point
  st.friction_force = valueOf(ft);
  st.friction_on_a = valueOf(fa);
  st.force_on_a += st.friction_on_a;
  // f at PA = P1 - r1 n: the power f . (v_P1 - r1 w1 x n) = f . v_P1 - (r1 / L1^2) u1_dot . ((n x f) x u1)
  const V3<T> m = n.cross(fa);
  const V3<T> turn1 = (r1 * inv_length2[0]) * m.cross(u1), turn2 = (r2 * inv_length2[1]) * m.cross(u2);
  F.template segment<3>(0) += (1.0 - s) * fa + turn1;
  F.template segment<3>(3) += s * fa - turn1;
  F.template segment<3>(6) += -(1.0 - t) * fa + turn2;
  F.template segment<3>(9) += -t * fa - turn2;
  // and about the axes: -r1 e1 . m on strut 1's spin, -r2 e2 . m on strut 2's
  F(12) = -r1 * e1.dot(m);
  F(13) = -r2 * e2.dot(m);
}

// One ground contact (contact.h: Hertz or linear normal force, Lankarani-Nikravesh damping, modified Coulomb friction
// at the sphere's lowest point as a material point), generic in the scalar. Nodes: r[0], r[1] the strut's a and b
// (the sphere's centre at r[sphere_end]), or r[0] the point mass; F: 3 per node (a, b), then the spin at F(12).
template <typename T>
void groundKernel(const Model& model, const NaturalContactSlot& cs, const V3<T> r[4], const V3<T> v[4], const T spin[2],
                  double impact_speed, bool force, Eigen::Matrix<T, 14, 1>& F, ContactPairState& st)
{
  using std::sqrt;
  // a sphere of radius cs.radius[0] and stiffness cs.stiffness90 at a node: of a strut (its nodes a and b, the sphere
  // at cs.sphere_end) or of a point mass
  const double radius = cs.radius[0], stiffness = cs.stiffness90;
  const bool strut = cs.struts[0] >= 0;
  const double inv_length = cs.inv_length[0], inv_length2 = inv_length * inv_length;
  const GroundSettings& ground = model.ground;
  F.setZero();
  const int at = strut ? cs.sphere_end : 0;
  const V3<T>& c = r[at];
  const T zeta = ground.height + radius - c.z();
  const T rate = -v[at].z();
  st.normal = Vec3::UnitZ();
  st.gap = -valueOf(zeta);
  st.penetration = valueOf(zeta);
  st.active = st.penetration > kPenetrationRoundoff * (radius + std::abs(valueOf(c.z())));
  st.point_a = valueOf(c) - radius * Vec3::UnitZ();
  st.point_b = Vec3(valueOf(c.x()), valueOf(c.y()), ground.height);
  st.penetration_rate = valueOf(rate);
  st.region = ClosestRegion::kInterior;
  if (!st.active || !force)
    return;
  st.stiffness = stiffness;
  T fn;
  if (ground.law == ContactLaw::kLinear)
    fn = stiffness * zeta + ground.linear_damping * rate;
  else
  {
    const double damping = 3.0 * (1.0 - ground.restitution * ground.restitution) /
                           (4.0 * std::max(impact_speed, model.contact.min_impact_speed));
    fn = stiffness * zeta * sqrt(zeta) * (1.0 + damping * rate);
  }
  if (!(fn > 0.0))
    return;
  st.normal_force = valueOf(fn);
  st.force_on_a = Vec3(0.0, 0.0, st.normal_force);
  F(3 * at + 2) += fn;
  if (!(ground.friction > 0.0))
    return;
  // the lowest point PA = c + rho, rho = -R z, moving with the strut's w = u x u_dot / L^2 + w_s e
  const V3<T> rho(T(0.0), T(0.0), T(-radius));
  V3<T> vpa = v[at];
  V3<T> u = V3<T>::Zero(), e = V3<T>::Zero();
  if (strut)
  {
    u = r[1] - r[0];
    e = inv_length * u;
    const V3<T> w = inv_length2 * u.cross(v[1] - v[0]) + spin[0] * e;
    vpa += w.cross(rho);
  }
  const V3<T> vt(vpa.x(), vpa.y(), T(0.0));
  const T slip = vt.norm();
  st.slip_speed = valueOf(slip);
  if (!(slip > ground.stick_velocity))
    return;
  const T cd = slip >= ground.slip_velocity ?
                   T(1.0) :
                   T((slip - ground.stick_velocity) / (ground.slip_velocity - ground.stick_velocity));
  const T ft = ground.friction * cd * fn;
  const V3<T> f = -(ft / slip) * vt;
  st.friction_force = valueOf(ft);
  st.friction_on_a = valueOf(f);
  st.force_on_a += st.friction_on_a;
  F.template segment<3>(3 * at) += f;
  if (!strut)
    return;
  // the moment m = rho x f: w . m = u_dot . (m x u) / L^2 + w_s e . m
  const V3<T> m = rho.cross(f);
  const V3<T> turn = inv_length2 * m.cross(u);
  F.template segment<3>(0) -= turn;
  F.template segment<3>(3) += turn;
  F(12) = e.dot(m);
}

}  // namespace

NaturalModel buildNaturalModel(const Model& model, bool spin)
{
  NaturalModel nm;
  nm.model = &model;
  double size = 0.0;
  for (const Body& b : model.bodies)
    size = std::max(size, b.length);
  const double tol = 1e-9 * std::max(1.0, size);
  nm.strut_of_body.assign(model.bodies.size(), -1);
  nm.node_of_body.assign(model.bodies.size(), -1);
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const Body& b = model.bodies[i];
    const int body = static_cast<int>(i);
    if (b.kind == BodyKind::kPointMass)
    {
      nm.node_of_body[i] = nodeAt(nm, pointPosition(model, PointRef{ body, Vec3::Zero() }, model.q0), tol);
      continue;
    }
    NaturalStrut s;
    s.body = body;
    s.length = b.length;
    s.radius = b.radius();
    s.a = nodeAt(nm, pointPosition(model, PointRef{ body, Vec3(0.0, 0.0, -0.5 * b.length) }, model.q0), tol);
    s.b = nodeAt(nm, pointPosition(model, PointRef{ body, Vec3(0.0, 0.0, 0.5 * b.length) }, model.q0), tol);
    if (s.a == s.b)
      throw std::invalid_argument("natural coordinates: strut " + b.name + " has both ends at one node");
    nm.strut_of_body[i] = static_cast<int>(nm.struts.size());
    nm.struts.push_back(s);
  }
  // pins, drives and guides (rows against the ground); joints between bodies are the shared nodes
  std::vector<std::vector<NaturalRow>> ground_rows;
  for (const Constraint& c : model.constraints)
  {
    if (c.kind != Constraint::Kind::kPoints)
      continue;
    const int na = pointNode(nm, model, c.a, tol, "constraint " + c.name);
    if (c.b.body >= 0)
    {
      const int nb = pointNode(nm, model, c.b, tol, "constraint " + c.name);
      if (na != nb || c.directions.size() != 3)
        throw std::invalid_argument("natural coordinates: constraint " + c.name + " is not a ball joint at a node");
      continue;
    }
    ground_rows.resize(nm.nodes.size());
    for (size_t k = 0; k < c.directions.size(); ++k)
      ground_rows[na].push_back({ na, c.directions[k], c.offsets[k], c.actuator });
  }
  ground_rows.resize(nm.nodes.size());
  for (size_t i = 0; i < nm.nodes.size(); ++i)
  {
    const std::vector<NaturalRow>& rows = ground_rows[i];
    if (rows.empty())
      continue;
    // three orthonormal rows, at most one driven, hold the node: pinned, or moved along the driven row's direction
    int driven = -1;
    bool holds = rows.size() == 3;
    for (size_t k = 0; k < rows.size() && holds; ++k)
    {
      if (rows[k].actuator >= 0)
      {
        holds = driven < 0;
        driven = static_cast<int>(k);
      }
      for (size_t l = 0; l < rows.size(); ++l)
        holds = holds && std::abs(rows[k].direction.dot(rows[l].direction) - (k == l ? 1.0 : 0.0)) <= 1e-9;
    }
    if (!holds)
    {
      nm.rows.insert(nm.rows.end(), rows.begin(), rows.end());
      continue;
    }
    NaturalNode& node = nm.nodes[i];
    node.kind = driven >= 0 ? NaturalNode::Kind::kDriven : NaturalNode::Kind::kFixed;
    if (driven >= 0)
    {
      node.actuator = rows[driven].actuator;
      node.direction = rows[driven].direction;
    }
  }
  nm.cable_nodes.resize(model.cables.size());
  for (size_t k = 0; k < model.cables.size(); ++k)
    for (const PointRef& p : model.cables[k].points)
      nm.cable_nodes[k].push_back(pointNode(nm, model, p, tol, "cable " + model.cables[k].name));
  nm.floor_sin = std::sin(model.contact.min_crossing_angle);
  for (const PointLoad& l : model.loads)
    nm.loads.push_back(naturalLoad(nm, l));
  // the ground's spheres, each at a node (the strut pairs' contacts are made when asked: naturalContactSlot)
  for (size_t i = 0; i < model.ground_contacts.size(); ++i)
  {
    const GroundContact& g = model.ground_contacts[i];
    NaturalContactSlot cs;
    cs.slot = model.pairSlots() + static_cast<int>(i);
    cs.ground = true;
    const int node = pointNode(nm, model, PointRef{ g.body, g.local }, tol, "ground contact at " + g.node);
    const int strut = nm.strut_of_body[g.body];
    if (strut >= 0)
    {
      cs.struts[0] = strut;
      cs.nodes[0] = nm.struts[strut].a;
      cs.nodes[1] = nm.struts[strut].b;
      cs.sphere_end = node == nm.struts[strut].a ? 0 : 1;
    }
    else
      cs.nodes[0] = node;
    cs.radius[0] = g.radius;
    cs.stiffness90 = g.stiffness;
    if (strut >= 0)
      cs.inv_length[0] = 1.0 / nm.struts[strut].length;
    nm.ground_contacts.push_back(cs);
  }
  for (NaturalNode& n : nm.nodes)
    if (n.kind == NaturalNode::Kind::kFree)
    {
      n.column = nm.coordinates;
      nm.coordinates += 3;
    }
  nm.positions = nm.coordinates;
  // a spin rate per strut when friction can turn struts about their axes
  const bool friction =
      (model.contact.enabled && model.contact.friction > 0.0) || (model.ground.enabled && model.ground.friction > 0.0);
  if (spin && friction)
    for (NaturalStrut& st : nm.struts)
      st.spin = nm.coordinates++;
  // the constant mass matrix and the weight
  const int n = nm.coordinates;
  std::vector<Eigen::Triplet<double>> mass;
  nm.gravity = Eigen::VectorXd::Zero(n);
  const Vec3 g = model.gravity_enabled ? model.gravity : Vec3::Zero();
  const auto diagonal3 = [&mass](int r, int c, double value)
  {
    for (int k = 0; k < 3; ++k)
      mass.emplace_back(r + k, c + k, value);
  };
  for (const NaturalStrut& s : nm.struts)
  {
    const Body& b = model.bodies[s.body];
    const double jt = b.inertia.x(), l2 = s.length * s.length;
    const double diag = 0.25 * b.mass + jt / l2, off = 0.25 * b.mass - jt / l2;
    const int ca = nm.nodes[s.a].column, cb = nm.nodes[s.b].column;
    for (const int col : { ca, cb })
      if (col >= 0)
      {
        diagonal3(col, col, diag);
        nm.gravity.segment<3>(col) += 0.5 * b.mass * g;
      }
    if (ca >= 0 && cb >= 0)
    {
      diagonal3(ca, cb, off);
      diagonal3(cb, ca, off);
    }
    if (s.spin >= 0)
      mass.emplace_back(s.spin, s.spin, b.inertia.z());
  }
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const int node = nm.node_of_body[i];
    if (node < 0 || nm.nodes[node].column < 0)
      continue;
    const int col = nm.nodes[node].column;
    diagonal3(col, col, model.bodies[i].mass);
    nm.gravity.segment<3>(col) += model.bodies[i].mass * g;
  }
  nm.mass.resize(n, n);
  nm.mass.setFromTriplets(mass.begin(), mass.end());
  return nm;
}

NaturalState naturalInitialState(const NaturalModel& nm)
{
  NaturalState s;
  s.x.setZero(nm.coordinates);  // (a spin rate's entry integrates to the strut's spin angle, 0 at the start)
  for (const NaturalNode& n : nm.nodes)
    if (n.column >= 0)
      s.x.segment<3>(n.column) = n.position0;
  s.v.setZero(nm.coordinates);
  s.a.setZero(nm.coordinates);
  s.qdd.setZero(nm.coordinates);
  s.lambda.setZero(static_cast<int>(nm.struts.size() + nm.rows.size()));
  s.frame_spin.setZero(static_cast<Eigen::Index>(nm.struts.size()));
  return s;
}

NaturalLoad naturalLoad(const NaturalModel& nm, const PointLoad& load)
{
  const Model& model = *nm.model;
  NaturalLoad out;
  out.force = load.force;
  const int body = load.point.body;
  if (body < 0)
    return out;
  if (body >= static_cast<int>(model.bodies.size()))
    throw std::invalid_argument("load " + load.name + ": no body " + std::to_string(body));
  const Body& b = model.bodies[static_cast<size_t>(body)];
  const Vec3& p = load.point.local;
  const double tolerance = 1e-9 * std::max(1.0, b.length);
  if (b.kind != BodyKind::kStrut)
  {
    if (p.norm() > tolerance)
      throw std::invalid_argument("load " + load.name + ": a point away from point mass " + b.name);
    out.nodes[0] = nm.node_of_body[static_cast<size_t>(body)];
    out.weights[0] = 1.0;
    return out;
  }
  if (p.head<2>().norm() > tolerance)
    throw std::invalid_argument("load " + load.name + ": a point " + std::to_string(p.head<2>().norm()) +
                                " m off the axis of strut " + b.name +
                                " (the natural coordinates take forces on strut axes)");
  const NaturalStrut& st = nm.struts[static_cast<size_t>(nm.strut_of_body[static_cast<size_t>(body)])];
  const double along = p.z() / b.length + 0.5;  // from node a (at -L/2) to node b
  out.nodes[0] = st.a;
  out.nodes[1] = st.b;
  out.weights[0] = 1.0 - along;
  out.weights[1] = along;
  return out;
}

double NaturalState::contactSpeed(int slot) const
{
  const auto at =
      std::lower_bound(touching.begin(), touching.end(), slot, [](const NaturalTouch& c, int x) { return c.slot < x; });
  return at != touching.end() && at->slot == slot ? at->speed : 0.0;
}

NaturalContactSlot naturalContactSlot(const NaturalModel& nm, int slot)
{
  const Model& model = *nm.model;
  if (model.isGroundSlot(slot))
    return nm.ground_contacts[static_cast<size_t>(slot - model.pairSlots())];
  const auto [body_a, body_b] = model.pairBodies(slot);
  const int sa = nm.strut_of_body[body_a], sb = nm.strut_of_body[body_b];
  NaturalContactSlot cs;
  cs.slot = slot;
  cs.nodes[0] = nm.struts[sa].a;
  cs.nodes[1] = nm.struts[sa].b;
  cs.nodes[2] = nm.struts[sb].a;
  cs.nodes[3] = nm.struts[sb].b;
  cs.struts[0] = sa;
  cs.struts[1] = sb;
  for (int k = 0; k < 2; ++k)
  {
    const NaturalStrut& st = nm.struts[k == 0 ? sa : sb];
    cs.radius[k] = st.radius;
    cs.inv_length[k] = 1.0 / st.length;
  }
  const StrutPair p = model.strutPair(slot);
  cs.stiffness90 = p.stiffness90;
  cs.core_stiffness90 = p.core_stiffness90;
  cs.core_gap = p.core_gap;
  return cs;
}

Eigen::VectorXd naturalToBodyCoordinates(const NaturalModel& nm, const Eigen::VectorXd& x, const ActuationValues& u)
{
  const Model& model = *nm.model;
  Eigen::VectorXd q = model.q0;
  for (const NaturalStrut& s : nm.struts)
  {
    const Vec3 ra = naturalNodePosition(nm, s.a, x, u), rb = naturalNodePosition(nm, s.b, x, u);
    const int off = model.bodies[s.body].offset;
    q.segment<3>(off) = 0.5 * (ra + rb);
    q.segment<4>(off + 3) = thetaFromZAxis((rb - ra).normalized());
  }
  for (size_t i = 0; i < model.bodies.size(); ++i)
    if (nm.node_of_body[i] >= 0)
      q.segment<3>(model.bodies[i].offset) = naturalNodePosition(nm, nm.node_of_body[i], x, u);
  return q;
}

// ---- body poses ----------------------------------------------------------------------------------------

namespace
{
/// The unit quaternion (scalar first) that takes the unit vector a onto the unit vector b along the shortest arc:
/// (1 + a.b, a x b) normalized, or a half turn about an axis normal to a when b is -a.
Vec4 shortestArc(const Vec3& a, const Vec3& b)
{
  const double c = 1.0 + a.dot(b);
  if (c < 1e-8)
    return fromEigenQuaternion(Eigen::Quaterniond::FromTwoVectors(a, b));
  Vec4 r;
  r(0) = c;
  r.tail<3>() = a.cross(b);
  return r / r.norm();
}

Vec4 multiply(const Vec4& p, const Vec4& q)
{
  Vec4 r;
  r(0) = p(0) * q(0) - p.tail<3>().dot(q.tail<3>());
  r.tail<3>() = p(0) * q.tail<3>() + q(0) * p.tail<3>() + p.tail<3>().cross(q.tail<3>());
  return r;
}
}  // namespace

bool carriesNaturalOf(const NaturalModel& nm, const State& s)
{
  const Model& model = *nm.model;
  if (s.natural.x.size() != nm.coordinates || s.natural.v.size() != nm.coordinates || s.q.size() != model.nq ||
      s.qd.size() != model.nq)
    return false;
  // the strut centres and point masses as writeBodyPoses forms them, bit for bit
  for (const NaturalStrut& st : nm.struts)
  {
    const int off = model.bodies[st.body].offset;
    const Vec3 c =
        0.5 * (naturalNodePosition(nm, st.a, s.natural.x, s.u) + naturalNodePosition(nm, st.b, s.natural.x, s.u));
    const Vec3 cd =
        0.5 * (naturalNodeVelocity(nm, st.a, s.natural.v, s.u) + naturalNodeVelocity(nm, st.b, s.natural.v, s.u));
    if (c != s.q.segment<3>(off) || cd != s.qd.segment<3>(off))
      return false;
  }
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const int node = nm.node_of_body[i];
    if (node < 0)
      continue;
    const int off = model.bodies[i].offset;
    if (naturalNodePosition(nm, node, s.natural.x, s.u) != s.q.segment<3>(off) ||
        naturalNodeVelocity(nm, node, s.natural.v, s.u) != s.qd.segment<3>(off))
      return false;
  }
  return true;
}

void naturalFromBody(const NaturalModel& nm, State& s)
{
  const Model& model = *nm.model;
  NaturalState& n = s.natural;
  n.t = s.t;
  n.x.setZero(nm.coordinates);
  n.v.setZero(nm.coordinates);
  n.a.setZero(nm.coordinates);
  n.qdd.setZero(nm.coordinates);
  n.lambda.setZero(static_cast<Eigen::Index>(nm.struts.size() + nm.rows.size()));
  n.touching.clear();
  n.contacts.clear();
  n.actuator_force.clear();
  n.equilibrium = false;
  n.frame_spin.setZero(static_cast<Eigen::Index>(nm.struts.size()));
  const auto set = [&](int node, const Vec3& r, const Vec3& v)
  {
    const int col = nm.nodes[static_cast<size_t>(node)].column;
    if (col < 0)
      return;
    n.x.segment<3>(col) = r;
    n.v.segment<3>(col) = v;
  };
  for (const NaturalStrut& st : nm.struts)
  {
    const int off = model.bodies[st.body].offset;
    const Vec3 c = s.q.segment<3>(off), cd = s.qd.segment<3>(off);
    const Vec4 theta = s.q.segment<4>(off + 3).normalized();
    const Vec3 e = bodyZAxis(theta);
    // world angular velocity: A(Theta) 2 L(Theta) Theta_dot
    const Vec3 w = rotate(theta, 2.0 * lTimes(theta, s.qd.segment<4>(off + 3)));
    const Vec3 e_dot = w.cross(e);
    set(st.a, c - 0.5 * st.length * e, cd - 0.5 * st.length * e_dot);
    set(st.b, c + 0.5 * st.length * e, cd + 0.5 * st.length * e_dot);
    if (st.spin >= 0)
      n.v(st.spin) = w.dot(e);
  }
  for (size_t i = 0; i < model.bodies.size(); ++i)
    if (nm.node_of_body[i] >= 0)
    {
      const int off = model.bodies[i].offset;
      set(nm.node_of_body[i], s.q.segment<3>(off), s.qd.segment<3>(off));
    }
}

void carryBodyFrames(const NaturalModel& nm, State& s)
{
  const Model& model = *nm.model;
  const NaturalState& n = s.natural;
  if (s.q.size() != model.nq)
    s.q = model.q0;
  for (size_t k = 0; k < nm.struts.size(); ++k)
  {
    const NaturalStrut& st = nm.struts[k];
    const int off = model.bodies[st.body].offset;
    const Vec3 e = naturalNodePosition(nm, st.b, n.x, s.u) - naturalNodePosition(nm, st.a, n.x, s.u);
    // the frame (unit: as the last carry left it, else normalized)
    Vec4 theta = s.q.segment<4>(off + 3);
    const double norm2 = theta.squaredNorm();
    if (!(norm2 > 0.0))
      theta = thetaFromZAxis(e);
    else if (std::abs(norm2 - 1.0) > 1e-12)
      theta /= std::sqrt(norm2);
    // turned about its axis by the spin angle integrated since: Theta (cos(phi/2), 0, 0, sin(phi/2)), the turn about
    // the body's own z axis (a small angle, a step's, by its series to round-off)
    if (st.spin >= 0)
    {
      const double half = 0.5 * (n.x(st.spin) - n.frame_spin(static_cast<Eigen::Index>(k)));
      if (half != 0.0)
      {
        double sin_half, cos_half;
        if (std::abs(half) < 0.05)
        {
          const double h2 = half * half;
          sin_half = half * (1.0 - h2 / 6.0 * (1.0 - h2 / 20.0 * (1.0 - h2 / 42.0 * (1.0 - h2 / 72.0))));
          cos_half = 1.0 - h2 / 2.0 * (1.0 - h2 / 12.0 * (1.0 - h2 / 30.0 * (1.0 - h2 / 56.0)));
        }
        else
          sincos(half, &sin_half, &cos_half);
        const Vec4 t = theta;
        theta(0) = t(0) * cos_half - t(3) * sin_half;
        theta(1) = t(1) * cos_half + t(2) * sin_half;
        theta(2) = t(2) * cos_half - t(1) * sin_half;
        theta(3) = t(3) * cos_half + t(0) * sin_half;
      }
      s.natural.frame_spin(static_cast<Eigen::Index>(k)) = n.x(st.spin);
    }
    // then carried along the shortest arc from its z axis onto the new axis: (1 + z.e, z x e) for unit z and e, times
    // Theta, normalized once
    const Vec3 z = bodyZAxis(theta);
    const Vec3 u = e / e.norm();
    const double c = 1.0 + z.dot(u);
    Vec4 arc;
    if (c < 1e-8)
      arc = shortestArc(z.normalized(), u);
    else
    {
      arc(0) = c;
      arc.tail<3>() = z.cross(u);
    }
    theta = multiply(arc, theta);
    s.q.segment<4>(off + 3) = theta / theta.norm();
  }
}

void writeBodyMotion(const NaturalModel& nm, State& s)
{
  const Model& model = *nm.model;
  const NaturalState& n = s.natural;
  if (s.q.size() != model.nq)
    s.q = model.q0;
  s.qd.setZero(model.nq);
  s.t = n.t;
  for (const NaturalStrut& st : nm.struts)
  {
    const int off = model.bodies[st.body].offset;
    const Vec3 ra = naturalNodePosition(nm, st.a, n.x, s.u), rb = naturalNodePosition(nm, st.b, n.x, s.u);
    const Vec3 va = naturalNodeVelocity(nm, st.a, n.v, s.u), vb = naturalNodeVelocity(nm, st.b, n.v, s.u);
    const Vec3 e = (rb - ra).normalized();
    s.q.segment<3>(off) = 0.5 * (ra + rb);
    s.qd.segment<3>(off) = 0.5 * (va + vb);
    // Theta_dot = 1/2 L(Theta)^T omega_bar, omega_bar = A(Theta)^T omega, omega = e x e_dot + spin e
    const Vec4 theta = s.q.segment<4>(off + 3);
    const Vec3 e_dot = (vb - va) / st.length;
    const Vec3 w = e.cross(e_dot) + (st.spin >= 0 ? n.v(st.spin) : 0.0) * e;
    const Vec4 conj(theta(0), -theta(1), -theta(2), -theta(3));
    s.qd.segment<4>(off + 3) = 0.5 * lMatrixTransposeTimes(theta, rotate(conj, w));
  }
  for (size_t i = 0; i < model.bodies.size(); ++i)
    if (nm.node_of_body[i] >= 0)
    {
      const int off = model.bodies[i].offset;
      s.q.segment<3>(off) = naturalNodePosition(nm, nm.node_of_body[i], n.x, s.u);
      s.qd.segment<3>(off) = naturalNodeVelocity(nm, nm.node_of_body[i], n.v, s.u);
    }
}

void writeBodyPoses(const NaturalModel& nm, State& s)
{
  carryBodyFrames(nm, s);
  writeBodyMotion(nm, s);
}

NaturalContactInput naturalContactInput(const NaturalModel& nm, const NaturalContactSlot& cs, const Eigen::VectorXd& x,
                                        const Eigen::VectorXd& v, const ActuationValues& u)
{
  NaturalContactInput in;
  for (int i = 0; i < 4; ++i)
  {
    if (cs.nodes[i] < 0)
      continue;
    in.r[i] = naturalNodePosition(nm, cs.nodes[i], x, u);
    in.v[i] = naturalNodeVelocity(nm, cs.nodes[i], v, u);
  }
  for (int i = 0; i < 2; ++i)
    if (cs.struts[i] >= 0 && nm.struts[cs.struts[i]].spin >= 0)
      in.spin[i] = v(nm.struts[cs.struts[i]].spin);
  return in;
}

ContactPairState naturalContact(const NaturalModel& nm, const NaturalContactSlot& cs, const NaturalContactInput& in,
                                double impact_speed, Vec14* force, Mat14* stiffness, Mat14* damping)
{
  const Model& model = *nm.model;
  ContactPairState st;
  st.pair = cs.slot;
  if (cs.ground)
  {
    st.body_a = model.groundContactOf(cs.slot).body;
    st.body_b = -1;
  }
  else
  {
    const auto [body_a, body_b] = model.pairBodies(cs.slot);
    st.body_a = body_a;
    st.body_b = body_b;
  }
  const auto kernel = [&](auto r, auto v, auto spin, bool with_force, auto& f)
  {
    if (cs.ground)
      groundKernel(model, cs, r, v, spin, impact_speed, with_force, f, st);
    else
      pairKernel(model, cs, nm.floor_sin, r, v, spin, impact_speed, with_force, f, st);
  };
  {
    // (apart: no force, no tangents, and no derivatives to carry through the closest points)
    Vec14 f;
    kernel(in.r, in.v, in.spin, force != nullptr, f);
    if (force)
      *force = f;
    if ((!stiffness && !damping) || !st.active)
    {
      if (stiffness)
        stiffness->setZero();
      if (damping)
        damping->setZero();
      return st;
    }
  }
  using Ad = Eigen::AutoDiffScalar<Eigen::Matrix<double, 26, 1>>;
  V3<Ad> ra[4], va[4];
  Ad spin[2];
  for (int i = 0; i < 4; ++i)
    for (int c = 0; c < 3; ++c)
    {
      ra[i](c) = Ad(in.r[i](c), 26, 3 * i + c);
      va[i](c) = Ad(in.v[i](c), 26, 12 + 3 * i + c);
    }
  for (int i = 0; i < 2; ++i)
    spin[i] = Ad(in.spin[i], 26, 24 + i);
  Eigen::Matrix<Ad, 14, 1> f;
  kernel(static_cast<const V3<Ad>*>(ra), static_cast<const V3<Ad>*>(va), static_cast<const Ad*>(spin), true, f);
  for (int i = 0; i < 14; ++i)
  {
    if (force)
      (*force)(i) = f(i).value();
    // (an entry the kernel never wrote carries no derivatives)
    Eigen::Matrix<double, 26, 1> dfi = f(i).derivatives();
    if (dfi.size() != 26)
      dfi.setZero();
    if (stiffness)
    {
      stiffness->row(i).head<12>() = -dfi.head<12>().transpose();
      stiffness->row(i).tail<2>().setZero();
    }
    if (damping)
    {
      damping->row(i).head<12>() = -dfi.segment<12>(12).transpose();
      damping->row(i).tail<2>() = -dfi.tail<2>().transpose();
    }
  }
  return st;
}

// ---- contacts at body poses ----------------------------------------------------------------------------

namespace
{
// A strut's end nodes a and b (centre -/+ L/2 e), their velocities and its spin rate about e at body poses q and
// rates qd (none: at rest). omega = A(Theta) 2 L(Theta) Theta_dot, so the spin e . omega is the body-frame z part.
void strutEnds(const Body& b, const Eigen::VectorXd& q, const Eigen::VectorXd* qd, Vec3* r, Vec3* v, double& spin)
{
  const Vec4 theta = q.segment<4>(b.offset + 3);
  const Vec3 e = bodyZAxis(theta), c = q.segment<3>(b.offset);
  const double half = 0.5 * b.length;
  r[0] = c - half * e;
  r[1] = c + half * e;
  if (!qd)
    return;
  const Vec3 w_body = 2.0 * lTimes(theta, qd->segment<4>(b.offset + 3));
  const Vec3 e_dot = rotate(theta, w_body).cross(e);
  v[0] = qd->segment<3>(b.offset) - half * e_dot;
  v[1] = qd->segment<3>(b.offset) + half * e_dot;
  spin = w_body.z();
}

// the natural coordinates' law on the nodes of contact slot `slot` at body poses; qd null: at rest; no force unless
// `force`
ContactPairState contactAtPoses(const Model& model, int slot, const Eigen::VectorXd& q, const Eigen::VectorXd* qd,
                                double impact_speed, bool force)
{
  Vec3 r[4], v[4];
  for (int i = 0; i < 4; ++i)
    r[i] = v[i] = Vec3::Zero();
  double spin[2] = { 0.0, 0.0 };
  ContactPairState st;
  st.pair = slot;
  Vec14 f;
  // the slot's constants as a NaturalContactSlot holds them (naturalContactSlot), from the model's bodies
  NaturalContactSlot cs;
  if (model.isGroundSlot(slot))
  {
    const GroundContact& g = model.groundContactOf(slot);
    const Body& b = model.bodies[g.body];
    st.body_a = g.body;
    st.body_b = -1;
    cs.radius[0] = g.radius;
    cs.stiffness90 = g.stiffness;
    if (b.kind == BodyKind::kStrut)
    {
      cs.struts[0] = 0;  // (a strut: its spin turns the sphere's lowest point)
      cs.sphere_end = g.local.z() > 0.0 ? 1 : 0;
      cs.inv_length[0] = 1.0 / b.length;
      strutEnds(b, q, qd, r, v, spin[0]);
    }
    else if (qd)
      pointMotion(model, PointRef{ g.body, g.local }, q, *qd, r[0], v[0]);
    else
      r[0] = pointPosition(model, PointRef{ g.body, g.local }, q);
    groundKernel(model, cs, r, v, spin, impact_speed, force, f, st);
    return st;
  }
  const auto [body_a, body_b] = model.pairBodies(slot);
  st.body_a = body_a;
  st.body_b = body_b;
  const int bodies[2] = { body_a, body_b };
  for (int k = 0; k < 2; ++k)
  {
    const Body& b = model.bodies[bodies[k]];
    cs.radius[k] = b.radius();
    cs.inv_length[k] = 1.0 / b.length;
    strutEnds(b, q, qd, r + 2 * k, v + 2 * k, spin[k]);
  }
  const StrutPair p = model.strutPair(slot);
  cs.stiffness90 = p.stiffness90;
  cs.core_stiffness90 = p.core_stiffness90;
  cs.core_gap = p.core_gap;
  pairKernel(model, cs, std::sin(model.contact.min_crossing_angle), r, v, spin, impact_speed, force, f, st);
  return st;
}
}  // namespace

ContactPairState contactGeometry(const Model& model, int pair, const Eigen::VectorXd& q)
{
  return contactAtPoses(model, pair, q, nullptr, 0.0, false);
}

ContactPairState evaluateContact(const Model& model, int pair, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                 double impact_speed, ContactMode mode)
{
  return contactAtPoses(model, pair, q, mode == ContactMode::kDynamic ? &qd : nullptr, impact_speed, true);
}

namespace
{
constexpr double kNearFloor = 1e-4;        // m: the least motion the near pairs allow for
constexpr int kDirectPairsMost = 64;       // up to this many strut pairs are checked without the broad phase
constexpr double kListMarginLeast = 2e-3;  // m: the least margin of the listed contacts
constexpr double kListMarginSteps = 8.0;   // the margin in steps' motions

// The length and lengthening rate of cable k (Model::cables) at s under u.
void cableLengthRate(const NaturalModel& nm, int k, const NaturalState& s, const ActuationValues& u, double& l,
                     double& rate)
{
  const std::vector<int>& nodes = nm.cable_nodes[static_cast<size_t>(k)];
  l = rate = 0.0;
  for (size_t i = 0; i + 1 < nodes.size(); ++i)
  {
    const Vec3 d = naturalNodePosition(nm, nodes[i + 1], s.x, u) - naturalNodePosition(nm, nodes[i], s.x, u);
    const double li = d.norm();
    l += li;
    if (li > 0.0)
      rate += d.dot(naturalNodeVelocity(nm, nodes[i + 1], s.v, u) - naturalNodeVelocity(nm, nodes[i], s.v, u)) / li;
  }
}

// Whether the axes of strut pair c passed through each other while its nodes moved in straight lines from from(i) to
// to(i).
template <class From, class To>
bool pairPassedThrough(const NaturalModel& nm, const NaturalContactSlot& c, const From& from, const To& to)
{
  AxisPose start[2], end[2];
  for (int i = 0; i < 2; ++i)
  {
    const int a = c.nodes[2 * i], b = c.nodes[2 * i + 1];
    const Vec3 a0 = from(a), b0 = from(b), a1 = to(a), b1 = to(b);
    start[i] = { 0.5 * (a0 + b0), (b0 - a0).normalized() };
    end[i] = { 0.5 * (a1 + b1), (b1 - a1).normalized() };
  }
  return axesPassedThrough(start[0], start[1], end[0], end[1], 0.5 * nm.struts[static_cast<size_t>(c.struts[0])].length,
                           0.5 * nm.struts[static_cast<size_t>(c.struts[1])].length);
}
}  // namespace

// ---- the solver ----------------------------------------------------------------------------------------

NaturalSolver::NaturalSolver(const NaturalModel& nm, const SolverOptions& options)
  : nm_(nm), model_(*nm.model), options_(options), broad_phase_(*nm.model), control_(options)
{
  // a few pairs are cheaper to check directly than to box
  if (model_.contact.enabled)
  {
    use_broad_phase_ = model_.checkedPairCount() > kDirectPairsMost;
    if (!use_broad_phase_)
      model_.checkedPairList(&direct_pairs_);
  }
  if (options.integrator == Integrator::kGeneralizedAlpha)
  {
    // Chung and Hulbert's parameters from the spectral radius at infinite frequency (as the body solver's)
    const double rho = options.rho_infinity;
    alpha_m_ = (2.0 * rho - 1.0) / (rho + 1.0);
    alpha_f_ = rho / (rho + 1.0);
    gamma_ = 0.5 + alpha_f_ - alpha_m_;
    beta_ = 0.25 * (gamma_ + 0.5) * (gamma_ + 0.5);
  }
  else
  {
    beta_ = options.newmark_beta;
    gamma_ = options.newmark_gamma;
  }
  mass_scale_ = nm.mass.coeffs().size() > 0 ? nm.mass.coeffs().cwiseAbs().maxCoeff() : 1.0;
  for (const std::vector<int>& nodes : nm.cable_nodes)
    cable_driven_.push_back(
        std::any_of(nodes.begin(), nodes.end(),
                    [&](int n) { return nm.nodes[static_cast<size_t>(n)].kind == NaturalNode::Kind::kDriven; }));
}

void NaturalSolver::forces(const Eigen::VectorXd& x, const Eigen::VectorXd& v, bool tangents)
{
  f_ = nm_.gravity;
  if (held_ && model_.gravity_enabled)
  {
    // (the weight at the fixed and driven nodes: half a strut's at each end, a point mass's at its node)
    for (const NaturalStrut& st : nm_.struts)
      for (const int node : { st.a, st.b })
        if (nm_.nodes[static_cast<size_t>(node)].column < 0)
          (*held_)[static_cast<size_t>(node)] +=
              0.5 * model_.bodies[static_cast<size_t>(st.body)].mass * model_.gravity;
    for (size_t b = 0; b < model_.bodies.size(); ++b)
    {
      const int node = nm_.node_of_body[b];
      if (node >= 0 && nm_.nodes[static_cast<size_t>(node)].column < 0)
        (*held_)[static_cast<size_t>(node)] += model_.bodies[b].mass * model_.gravity;
    }
  }
  // point loads: linear in the nodes' positions, constant forces (no tangent)
  for (const std::vector<NaturalLoad>* loads : { &nm_.loads, static_cast<const std::vector<NaturalLoad>*>(&external_) })
  {
    const double factor = loads == &nm_.loads ? load_factor_ : 1.0;
    for (const NaturalLoad& l : *loads)
      for (int i = 0; i < 2; ++i)
        if (l.nodes[i] >= 0)
          addNodeForce(l.nodes[i], factor * l.weights[i] * l.force);
  }
  // every node's position and velocity at this iterate, read below and by contactForces and the rows
  pos_.resize(nm_.nodes.size());
  vel_.resize(nm_.nodes.size());
  for (size_t i = 0; i < nm_.nodes.size(); ++i)
  {
    pos_[i] = naturalNodePosition(nm_, static_cast<int>(i), x, u_);
    vel_[i] = naturalNodeVelocity(nm_, static_cast<int>(i), v, u_);
  }
  // a spinning strut's gyroscopic moment -J_a w_s e_dot on its transverse motion, as the couple
  // F_b = -F_a = (J_a / L^3) w_s u x u_dot at its nodes (no work)
  const auto driven = [&](int node) { return nm_.nodes[static_cast<size_t>(node)].kind == NaturalNode::Kind::kDriven; };
  for (const NaturalStrut& st : nm_.struts)
  {
    if (st.spin < 0 || v(st.spin) == 0.0 || (driven_only_ && !driven(st.a) && !driven(st.b)))
      continue;
    const double c = model_.bodies[st.body].inertia.z() / (st.length * st.length * st.length), ws = v(st.spin);
    const Vec3 u = pos_[st.b] - pos_[st.a];
    const Vec3 ud = vel_[st.b] - vel_[st.a];
    const Vec3 fb = c * ws * u.cross(ud);
    const int ca = nm_.nodes[st.a].column, cb = nm_.nodes[st.b].column;
    addNodeForce(st.b, fb);
    addNodeForce(st.a, -fb);
    if (!tangents)
      continue;
    // dF_b/du = -c w_s [u_dot]x, dF_b/du_dot = c w_s [u]x, dF_b/dw_s = c u x u_dot; u = r_b - r_a
    const Mat3 du = -c * ws * skew(ud), dud = c * ws * skew(u);
    const int cols[2] = { ca, cb };
    const double sign[2] = { -1.0, 1.0 };
    for (int i = 0; i < 2; ++i)
    {
      if (cols[i] < 0)
        continue;
      for (int r = 0; r < 3; ++r)
        entries_.add(cols[i] + r, st.spin, -entries_.c_weight * sign[i] * fb(r) / ws);
      for (int j = 0; j < 2; ++j)
        if (cols[j] >= 0)
        {
          entries_.block(cols[i], cols[j], -sign[i] * sign[j] * du, entries_.k_weight);
          entries_.block(cols[i], cols[j], -sign[i] * sign[j] * dud, entries_.c_weight);
        }
    }
  }
  for (size_t ci = 0; ci < model_.cables.size(); ++ci)
  {
    if (driven_only_ && !cable_driven_[ci])
      continue;
    const Cable& cable = model_.cables[ci];
    const std::vector<int>& nodes = nm_.cable_nodes[ci];
    const int count = static_cast<int>(nodes.size());
    Vec3 p[Cable::kMaxPoints], e[Cable::kMaxPoints];
    double len[Cable::kMaxPoints];
    double l = 0.0, rate = 0.0;
    for (int i = 0; i < count; ++i)
      p[i] = pos_[nodes[i]];
    for (int i = 0; i + 1 < count; ++i)
    {
      const Vec3 d = p[i + 1] - p[i];
      len[i] = d.norm();
      e[i] = d / len[i];
      l += len[i];
      rate += e[i].dot(vel_[nodes[i + 1]] - vel_[nodes[i]]);
    }
    const CableState cs = cableLaw(cable, l, rate, u_, model_.damping_enabled);
    if (cs.slack)
      continue;
    const double tension = cs.tension;
    // dl/dr of each point: the unit vectors of its two segments
    Vec3 g[Cable::kMaxPoints];
    for (int i = 0; i < count; ++i)
      g[i] = (i > 0 ? e[i - 1] : Vec3::Zero()) - (i + 1 < count ? e[i] : Vec3::Zero());
    for (int i = 0; i < count; ++i)
      addNodeForce(nodes[i], -tension * g[i]);
    if (!tangents)
      continue;
    const double damping = model_.damping_enabled ? cable.damping : 0.0;
    // the damping's rate moves with the positions too: dl_dot/dr of each point, from de_i/dr = (I - e_i e_i^T) / l_i
    Vec3 w[Cable::kMaxPoints];
    for (int i = 0; i < count; ++i)
      w[i].setZero();
    if (damping > 0.0)
      for (int i = 0; i + 1 < count; ++i)
      {
        const Vec3 dv = vel_[nodes[i + 1]] - vel_[nodes[i]];
        const Vec3 turn = (dv - e[i].dot(dv) * e[i]) / len[i];
        w[i + 1] += turn;
        w[i] -= turn;
      }
    for (int i = 0; i < count; ++i)
    {
      const int ci2 = nm_.nodes[nodes[i]].column;
      if (ci2 < 0)
        continue;
      for (int j = 0; j < count; ++j)
      {
        const int cj = nm_.nodes[nodes[j]].column;
        if (cj < 0)
          continue;
        const Mat3 gg = g[i] * g[j].transpose();
        entries_.block(ci2, cj, gg, cs.stiffness * entries_.k_weight + damping * entries_.c_weight);
        if (damping > 0.0)
          entries_.block(ci2, cj, g[i] * w[j].transpose(), damping * entries_.k_weight);
      }
    }
    for (int i = 0; i + 1 < count; ++i)
    {
      const Mat3 gs = tension / len[i] * (Mat3::Identity() - e[i] * e[i].transpose());
      const int c0 = nm_.nodes[nodes[i]].column, c1 = nm_.nodes[nodes[i + 1]].column;
      if (c0 >= 0)
        entries_.block(c0, c0, gs, entries_.k_weight);
      if (c1 >= 0)
        entries_.block(c1, c1, gs, entries_.k_weight);
      if (c0 >= 0 && c1 >= 0)
      {
        entries_.block(c0, c1, gs, -entries_.k_weight);
        entries_.block(c1, c0, gs, -entries_.k_weight);
      }
    }
  }
}

void NaturalSolver::contactForces(const Eigen::VectorXd& /*x: forces() cached the nodes*/, const Eigen::VectorXd& v,
                                  bool tangents)
{
  for (const int k : near_)
  {
    const NaturalContactSlot& cs = listed_[k].c;
    Vec14 f;
    Mat14 kk, cc;
    // (the nodes as forces() left them at this iterate)
    NaturalContactInput in;
    for (int i = 0; i < 4; ++i)
      if (cs.nodes[i] >= 0)
      {
        in.r[i] = pos_[cs.nodes[i]];
        in.v[i] = vel_[cs.nodes[i]];
      }
    for (int i = 0; i < 2; ++i)
      if (cs.struts[i] >= 0 && nm_.struts[cs.struts[i]].spin >= 0)
        in.spin[i] = v(nm_.struts[cs.struts[i]].spin);
    const ContactPairState st =
        naturalContact(nm_, cs, in, listed_[k].step_speed, &f, tangents ? &kk : nullptr, tangents ? &cc : nullptr);
    if (!(st.normal_force > 0.0))
      continue;
    ++stats_.contact_evaluations;
    // the local entries' columns: 3 per node, then the two spins
    int cols[14];
    for (int i = 0; i < 14; ++i)
    {
      if (i < 12)
        cols[i] = cs.nodes[i / 3] >= 0 && nm_.nodes[cs.nodes[i / 3]].column >= 0 ?
                      nm_.nodes[cs.nodes[i / 3]].column + i % 3 :
                      -1;
      else
        cols[i] = cs.struts[i - 12] >= 0 ? nm_.struts[cs.struts[i - 12]].spin : -1;
    }
    if (held_)
      for (int i = 0; i < 12; i += 3)
        if (cs.nodes[i / 3] >= 0 && cols[i] < 0)
          (*held_)[static_cast<size_t>(cs.nodes[i / 3])] += f.segment<3>(i);
    for (int i = 0; i < 14; ++i)
    {
      if (cols[i] < 0)
        continue;
      f_(cols[i]) += f(i);
      if (!tangents)
        continue;
      for (int j = 0; j < 14; ++j)
        if (cols[j] >= 0)
        {
          entries_.add(cols[i], cols[j], entries_.k_weight * kk(i, j) + entries_.c_weight * cc(i, j));
        }
    }
  }
}

void NaturalSolver::actuationForces(const NaturalState& s, const ActuationValues& u, std::vector<double>& out)
{
  out.assign(model_.actuators.size(), 0.0);
  // driven rows: the force on the node is -lambda along the row
  const int struts = static_cast<int>(nm_.struts.size());
  for (size_t k = 0; k < nm_.rows.size(); ++k)
    if (nm_.rows[k].actuator >= 0)
      out[static_cast<size_t>(nm_.rows[k].actuator)] -= s.lambda(struts + static_cast<int>(k));
  // the cables each pulls in: their tension
  for (size_t a = 0; a < model_.actuators.size(); ++a)
    for (const int c : model_.actuators[a].cables)
    {
      double l, rate;
      cableLengthRate(nm_, c, s, u, l, rate);
      out[a] += cableLaw(model_.cables[static_cast<size_t>(c)], l, rate, u, model_.damping_enabled).tension;
    }
  // the nodes each drives: the reaction that prescribes each one's motion, along the direction
  bool drives = false;
  for (const NaturalNode& nd : nm_.nodes)
    drives = drives || nd.kind == NaturalNode::Kind::kDriven;
  if (!drives)
    return;
  drivenReactions(s, u);
  for (size_t i = 0; i < nm_.nodes.size(); ++i)
    if (nm_.nodes[i].kind == NaturalNode::Kind::kDriven)
      out[static_cast<size_t>(nm_.nodes[i].actuator)] += reaction_along_[i];
}

void NaturalSolver::drivenReactions(const NaturalState& s, const ActuationValues& u)
{
  // (the same state as the last call, the same step and actuation: its reactions stand)
  const auto same_u = [&]()
  {
    if (reactions_u_.size() != u.size())
      return false;
    for (size_t i = 0; i < u.size(); ++i)
      if (reactions_u_[i].value != u[i].value || reactions_u_[i].rate != u[i].rate ||
          reactions_u_[i].accel != u[i].accel)
        return false;
    return true;
  };
  if (reactions_valid_ && reactions_t_ == s.t && reactions_steps_ == stats_.steps && reactions_x_ == s.x &&
      reactions_v_ == s.v && same_u())
    return;
  // R = M_D qdd - F_D + (G^T lambda)_D at each driven node D: what it takes, beyond the forces on it, to give it the
  // prescribed motion
  reactions_valid_ = true;
  reactions_t_ = s.t;
  reactions_steps_ = stats_.steps;
  reactions_x_ = s.x;
  reactions_v_ = s.v;
  reactions_u_ = u;
  held_force_.assign(nm_.nodes.size(), Vec3::Zero());
  reaction_along_.assign(nm_.nodes.size(), 0.0);
  held_ = &held_force_;
  driven_only_ = true;  // (f_ is left partial: the next forces() forms it whole)
  u_ = u;
  forces(s.x, s.v, false);
  held_ = nullptr;
  driven_only_ = false;
  // (the contacts at driven nodes: only their reactions are formed here)
  const auto driven = [&](int node) { return node >= 0 && nm_.nodes[node].kind == NaturalNode::Kind::kDriven; };
  for (const Listed& l : listed_)
  {
    if (!driven(l.c.nodes[0]) && !driven(l.c.nodes[1]) && !driven(l.c.nodes[2]) && !driven(l.c.nodes[3]))
      continue;
    const NaturalContactInput in = naturalContactInput(nm_, l.c, s.x, s.v, u);
    Vec14 f;
    naturalContact(nm_, l.c, in, s.contactSpeed(l.c.slot), &f, nullptr, nullptr);
    for (int i = 0; i < 4; ++i)
      if (driven(l.c.nodes[i]))
        held_force_[static_cast<size_t>(l.c.nodes[i])] += f.segment<3>(3 * i);
  }
  const auto accel = [&](int node)
  {
    const NaturalNode& nd = nm_.nodes[static_cast<size_t>(node)];
    if (nd.column >= 0)
      return Vec3(s.qdd.segment<3>(nd.column));
    return nd.kind == NaturalNode::Kind::kDriven ? Vec3(u[nd.actuator].accel * nd.direction) : Vec3(Vec3::Zero());
  };
  for (size_t i = 0; i < nm_.nodes.size(); ++i)
  {
    const NaturalNode& nd = nm_.nodes[i];
    if (nd.kind != NaturalNode::Kind::kDriven)
      continue;
    Vec3 r = -held_force_[i];
    for (size_t k = 0; k < nm_.struts.size(); ++k)
    {
      const NaturalStrut& st = nm_.struts[k];
      if (st.a != static_cast<int>(i) && st.b != static_cast<int>(i))
        continue;
      const Body& b = model_.bodies[static_cast<size_t>(st.body)];
      const double jt = b.inertia.x(), l2 = st.length * st.length;
      const double diag = 0.25 * b.mass + jt / l2, off = 0.25 * b.mass - jt / l2;
      const int other = st.a == static_cast<int>(i) ? st.b : st.a;
      r += diag * accel(static_cast<int>(i)) + off * accel(other);
      const Vec3 d = naturalNodePosition(nm_, st.b, s.x, u) - naturalNodePosition(nm_, st.a, s.x, u);
      r += (st.b == static_cast<int>(i) ? 2.0 : -2.0) * s.lambda(static_cast<int>(k)) * d;
    }
    for (size_t b = 0; b < model_.bodies.size(); ++b)
      if (nm_.node_of_body[b] == static_cast<int>(i))
        r += model_.bodies[b].mass * accel(static_cast<int>(i));
    reaction_along_[i] = nd.direction.dot(r);
  }
}

EnergyPoint NaturalSolver::energyAt(const NaturalState& s, const ActuationValues& u)
{
  u_ = u;
  EnergyPoint e;
  const Vec3 g = model_.gravity_enabled ? model_.gravity : Vec3::Zero();
  const auto position = [&](int node) { return naturalNodePosition(nm_, node, s.x, u); };
  const auto velocity = [&](int node) { return naturalNodeVelocity(nm_, node, s.v, u); };
  for (const NaturalStrut& st : nm_.struts)
  {
    const Body& b = model_.bodies[static_cast<size_t>(st.body)];
    const Vec3 vc = 0.5 * (velocity(st.a) + velocity(st.b)), ud = velocity(st.b) - velocity(st.a);
    e.kinetic += 0.5 * b.mass * vc.squaredNorm() + 0.5 * b.inertia.x() / (st.length * st.length) * ud.squaredNorm();
    if (st.spin >= 0)
      e.kinetic += 0.5 * b.inertia.z() * s.v(st.spin) * s.v(st.spin);
    const Vec3 c = 0.5 * (position(st.a) + position(st.b));
    const Vec3 c0 =
        0.5 * (nm_.nodes[static_cast<size_t>(st.a)].position0 + nm_.nodes[static_cast<size_t>(st.b)].position0);
    e.gravity -= b.mass * g.dot(c - c0);
  }
  for (size_t b = 0; b < model_.bodies.size(); ++b)
  {
    const int node = nm_.node_of_body[b];
    if (node < 0)
      continue;
    const double m = model_.bodies[b].mass;
    e.kinetic += 0.5 * m * velocity(node).squaredNorm();
    e.gravity -= m * g.dot(position(node) - nm_.nodes[static_cast<size_t>(node)].position0);
  }
  for (const std::vector<NaturalLoad>* loads : { &nm_.loads, static_cast<const std::vector<NaturalLoad>*>(&external_) })
    for (const NaturalLoad& l : *loads)
      for (int i = 0; i < 2; ++i)
        if (l.nodes[i] >= 0)
          e.gravity -= (loads == &nm_.loads ? load_factor_ : 1.0) * l.weights[i] *
                       l.force.dot(position(l.nodes[i]) - nm_.nodes[static_cast<size_t>(l.nodes[i])].position0);
  for (size_t k = 0; k < model_.cables.size(); ++k)
  {
    const Cable& c = model_.cables[k];
    double l, rate;
    cableLengthRate(nm_, static_cast<int>(k), s, u, l, rate);
    const CableState cs = cableLaw(c, l, rate, u, true);
    e.elastic += cablePotentialEnergy(c, cs);
    if (c.damping > 0.0 && !cs.slack)
      e.damping_power += cs.damping_tension * cs.damping_tension / c.damping;
    if (c.actuator >= 0 && c.actuator < static_cast<int>(u.size()))
      e.actuator_power += (cablePullInForce(c, cs) + (cs.slack ? 0.0 : cs.damping_tension)) * u[c.actuator].rate;
  }
  for (const ContactPairState& st : s.contacts)  // (as the step that made s formed them)
  {
    e.elastic += contactElasticEnergy(model_, st);
    e.contact_power += (st.normal_force - contactElasticNormalForce(model_, st)) * st.penetration_rate +
                       st.friction_force * st.slip_speed;
  }
  // the drives: a driven row's force -lambda along its direction at the rate s_dot; a driven node's reaction
  const int struts = static_cast<int>(nm_.struts.size());
  for (size_t k = 0; k < nm_.rows.size(); ++k)
    if (nm_.rows[k].actuator >= 0)
      e.actuator_power -= s.lambda(struts + static_cast<int>(k)) * u[nm_.rows[k].actuator].rate;
  bool driven = false;
  for (const NaturalNode& nd : nm_.nodes)
    driven = driven || (nd.kind == NaturalNode::Kind::kDriven && u[nd.actuator].rate != 0.0);
  if (driven)
  {
    drivenReactions(s, u);
    for (size_t i = 0; i < nm_.nodes.size(); ++i)
      if (nm_.nodes[i].kind == NaturalNode::Kind::kDriven)
        e.actuator_power += reaction_along_[i] * u[nm_.nodes[i].actuator].rate;
  }
  return e;
}

void NaturalSolver::appliedForces(const Eigen::VectorXd& x, const Eigen::VectorXd& v, const ActuationValues& u,
                                  Eigen::VectorXd& force, Eigen::MatrixXd* stiffness, Eigen::MatrixXd* damping)
{
  u_ = u;
  const int n = nm_.coordinates;
  for (int pass = 0; pass < 2; ++pass)
  {
    Eigen::MatrixXd* out = pass == 0 ? stiffness : damping;
    entries_.clear(n, true);
    entries_.k_weight = pass == 0 ? 1.0 : 0.0;
    entries_.c_weight = pass == 0 ? 0.0 : 1.0;
    forces(x, v, out != nullptr);
    if (out)
      *out = entries_.dense;
  }
  force = f_;
}

std::vector<ContactPairState> NaturalSolver::contactsAt(const NaturalState& s) const
{
  std::vector<ContactPairState> out;
  contactsAt(s, out);
  return out;
}

void NaturalSolver::contactsAt(const NaturalState& s, std::vector<ContactPairState>& out) const
{
  out.clear();
  for (const Listed& l : listed_)
  {
    Vec14 f;
    const ContactPairState st = naturalContact(nm_, l.c, naturalContactInput(nm_, l.c, s.x, s.v, u_),
                                               s.contactSpeed(l.c.slot), &f, nullptr, nullptr);
    if (st.active)
      out.push_back(st);
  }
}

bool NaturalSolver::factorize(int size, Pivots pivots)
{
  scaled_ = false;
  static_mode_ = false;
  use_inverse_ = false;
  solves_per_factor_ = policy_.solves_average * static_cast<double>(solves_since_factor_) +
                       (1.0 - policy_.solves_average) * solves_per_factor_;
  solves_since_factor_ = 0;
  dense_mode_ = entries_.to_dense;
  if (dense_mode_)
  {
    dense_lu_.compute(entries_.dense);
    // modified Newton's: inverted when the factorizations have been serving more solves than the inverse costs (about
    // size / 2); full Newton's keep the LU's more accurate solves. In place: the inverse's own expression allocates
    if (pivots == Pivots::kStatic && solves_per_factor_ >= policy_.inverse_solves * size)
    {
      // P (P A = L U), then L and U solved in place (the row of P I holding column i's one is P's index of i)
      dense_inverse_.setZero(size, size);
      const auto& p = dense_lu_.permutationP().indices();
      for (int i = 0; i < size; ++i)
        dense_inverse_(p(i), i) = 1.0;
      dense_lu_.matrixLU().triangularView<Eigen::UnitLower>().solveInPlace(dense_inverse_);
      dense_lu_.matrixLU().triangularView<Eigen::Upper>().solveInPlace(dense_inverse_);
      use_inverse_ = true;
    }
    return true;
  }
  sparse_.resize(size, size);
  sparse_.setFromTriplets(entries_.triplets.begin(), entries_.triplets.end());
  // the ordering and symbolic analysis serve while the pattern stays (the same taut cables and touching contacts)
  const Eigen::Index nnz = sparse_.nonZeros();
  const bool same = pattern_ready_ && static_cast<Eigen::Index>(pattern_outer_.size()) == sparse_.outerSize() + 1 &&
                    static_cast<Eigen::Index>(pattern_inner_.size()) == nnz &&
                    std::equal(pattern_outer_.begin(), pattern_outer_.end(), sparse_.outerIndexPtr()) &&
                    std::equal(pattern_inner_.begin(), pattern_inner_.end(), sparse_.innerIndexPtr());
  if (!same)
  {
    pattern_outer_.assign(sparse_.outerIndexPtr(), sparse_.outerIndexPtr() + sparse_.outerSize() + 1);
    pattern_inner_.assign(sparse_.innerIndexPtr(), sparse_.innerIndexPtr() + nnz);
    pattern_ready_ = true;
    lu_analysed_ = false;
    const Eigen::SparseMatrix<double> t = sparse_.transpose();
    pattern_symmetric_ = t.nonZeros() == nnz &&
                         std::equal(pattern_outer_.begin(), pattern_outer_.end(), t.outerIndexPtr()) &&
                         std::equal(pattern_inner_.begin(), pattern_inner_.end(), t.innerIndexPtr());
    ++stats_.analyses;
  }
  if (pivots != Pivots::kPartial)
  {
    if (static_skip_ > 0)
      --static_skip_;
    else if (factorizeStaticPivot(pivots == Pivots::kStaticRefined))
    {
      ++stats_.static_pivots;
      return true;
    }
    else
    {
      // refused: the sparse LU for this and the next policy_.static_pivot_skip factorizations
      ++stats_.static_pivot_refusals;
      static_skip_ = policy_.static_pivot_skip;
    }
  }
  if (!lu_analysed_)
  {
    sparse_lu_.analyzePattern(sparse_);
    lu_analysed_ = true;
  }
  sparse_lu_.factorize(sparse_);
  if (sparse_lu_.info() != Eigen::Success)
  {
    pattern_ready_ = false;
    return false;
  }
  return true;
}

bool NaturalSolver::factorizeStaticPivot(bool refined)
{
  // static pivots need a symmetric pattern: where the values leave it unsymmetric (a friction tangent's one-sided
  // entries), the union with the transpose's pattern, the added entries zero
  if (!pattern_symmetric_)
    symmetric_ = sparse_ + 0.0 * Eigen::SparseMatrix<double>(sparse_.transpose());
  const Eigen::SparseMatrix<double>& a = pattern_symmetric_ ? sparse_ : symmetric_;
  const int n = nm_.coordinates;
  const Eigen::Index size = a.rows();
  shifted_rows_.clear();
  for (int r = n; r < size; ++r)
    shifted_rows_.push_back(r);
  // delta = static_shift phi^2 / d, phi the constraint rows' largest entry and d the largest diagonal entry: the
  // constraint block's Schur complement is about phi^2 / d at its smallest
  const double diag = a.diagonal().head(n).cwiseAbs().maxCoeff();
  double phi = 0.0;
  for (const int r : shifted_rows_)  // (column r holds row r's entries: the pattern is symmetric)
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, r); it; ++it)
      phi = std::max(phi, std::abs(it.value()));
  if (!(diag > 0.0) || !(phi > 0.0) || !std::isfinite(diag) || !std::isfinite(phi))
    return false;
  if (!static_lu_.factorize(a, shifted_rows_, -policy_.static_shift * phi * phi / diag))
    return false;
  static_mode_ = true;
  static_refined_ = refined;
  // the check: A 1 solved comes back near 1 (within what modified Newton keeps a matrix for; refined, to round-off)
  check_b_ = a * Eigen::VectorXd::Ones(size);
  bool ok = false;
  if (refined)
    ok = solveRefined(check_b_, check_x_) && (check_x_.array() - 1.0).abs().maxCoeff() <= policy_.static_refined_check;
  else
  {
    static_lu_.solve(check_b_, check_x_);
    ok = check_x_.allFinite() && (check_x_.array() - 1.0).abs().maxCoeff() <= policy_.static_check;
  }
  static_mode_ = ok;
  return ok;
}

bool NaturalSolver::solveRefined(const Eigen::VectorXd& rhs, Eigen::VectorXd& out)
{
  return static_lu_.solveRefined(pattern_symmetric_ ? sparse_ : symmetric_, rhs, out, refine_r_, refine_d_);
}

Eigen::VectorXd NaturalSolver::solve(const Eigen::VectorXd& rhs)
{
  Eigen::VectorXd out;
  solve(rhs, out);
  return out;
}

void NaturalSolver::solve(const Eigen::VectorXd& rhs, Eigen::VectorXd& out)
{
  if (scaled_)
  {
    out = col_scale_.cwiseProduct(dense_lu_.solve(row_scale_.cwiseProduct(rhs)));
    return;
  }
  ++solves_since_factor_;
  if (use_inverse_)
    out.noalias() = dense_inverse_ * rhs;
  else if (dense_mode_)
    out = dense_lu_.solve(rhs);
  else if (!static_mode_)
    out = sparse_lu_.solve(rhs);
  else if (!static_refined_)
    static_lu_.solve(rhs, out);
  else if (!solveRefined(rhs, out))
    out.setConstant(std::numeric_limits<double>::quiet_NaN());  // (a non-finite correction: the step is cut)
}

int NaturalSolver::firstPassedThrough() const
{
  // the near strut pairs' axes from the step's start (node_now_, as findNear left them) to the iterate x_
  const auto from = [&](int i) { return node_now_[static_cast<size_t>(i)]; };
  const auto to = [&](int i) { return naturalNodePosition(nm_, i, x_, u_); };
  for (const int k : near_)
    if (!listed_[k].c.ground && pairPassedThrough(nm_, listed_[k].c, from, to))
      return listed_[k].c.slot;
  return -1;
}

double NaturalSolver::largestMotion(const Eigen::VectorXd& x0, const Eigen::VectorXd& x1) const
{
  double most = 0.0;
  for (int c = 0; c < nm_.positions; c += 3)
    most = std::max(most, (x1.segment<3>(c) - x0.segment<3>(c)).norm());
  return most;
}

void NaturalSolver::findNear(const NaturalState& s, double motion)
{
  static_listed_ = false;  // (listStatic marks its own)
  near_.clear();
  near_motion_ = motion;
  if (!model_.contact.enabled && nm_.ground_contacts.empty())
    return;
  const ActuationValues& u = u_;  // (the step's end: the start's driven nodes move by less than `motion`)
  // The contacts within a margin V, kept while no node has moved by D since they were listed with 2 D + 2 motion < V:
  // a pair's gap falls by at most the largest motion of each strut's nodes, so a contact left out (gap > V then) is
  // still more than 2 motion apart.
  node_now_.resize(nm_.nodes.size());
  double moved = 0.0;
  for (size_t i = 0; i < nm_.nodes.size(); ++i)
  {
    node_now_[i] = naturalNodePosition(nm_, static_cast<int>(i), s.x, u);
    if (have_list_)
      moved = std::max(moved, (node_now_[i] - listed_nodes_[i]).norm());
  }
  if (!have_list_ || 2.0 * moved + 2.0 * motion >= list_margin_)
  {
    list_margin_ = std::max(kListMarginLeast, kListMarginSteps * motion);
    // the strut pairs whose boxes, grown by half the margin, overlap (broad_phase.h), or the few checked pairs, then
    // the ground's spheres
    candidates_.clear();
    if (use_broad_phase_)
    {
      broad_q_ = naturalToBodyCoordinates(nm_, s.x, u);
      broad_phase_.candidates(broad_q_, 0.5 * list_margin_, candidates_);
      std::sort(candidates_.begin(), candidates_.end());
    }
    else
      candidates_ = direct_pairs_;
    for (size_t i = 0; i < nm_.ground_contacts.size(); ++i)
      candidates_.push_back(model_.pairSlots() + static_cast<int>(i));
    listed_.clear();
    for (const int slot : candidates_)
    {
      Listed l;
      l.c = naturalContactSlot(nm_, slot);
      const ContactPairState st =
          naturalContact(nm_, l.c, naturalContactInput(nm_, l.c, s.x, s.v, u), 0.0, nullptr, nullptr, nullptr);
      if (!(st.gap <= list_margin_))
        continue;
      l.end_gap = st.gap;
      l.end_rate = st.penetration_rate;
      listed_.push_back(l);
    }
    listed_nodes_ = node_now_;
    have_list_ = true;
    ++list_version_;
    end_list_version_ = list_version_;  // (the gaps and rates just formed are this start's)
    end_t_ = s.t;
  }
  // (the gaps and rates the last accepted step left at its end, which is this start, when the list is the same)
  const bool cached = s.t == end_t_ && list_version_ == end_list_version_;
  // the contact memory: s.touching and listed_ both ascend by slot
  auto memory = s.touching.begin();
  for (size_t k = 0; k < listed_.size(); ++k)
  {
    Listed& l = listed_[k];
    if (!cached)
    {
      const ContactPairState st =
          naturalContact(nm_, l.c, naturalContactInput(nm_, l.c, s.x, s.v, u), 0.0, nullptr, nullptr, nullptr);
      l.end_gap = st.gap;
      l.end_rate = st.penetration_rate;
    }
    if (l.end_gap > 2.0 * motion)
      continue;
    near_.push_back(static_cast<int>(k));
    while (memory != s.touching.end() && memory->slot < l.c.slot)
      ++memory;
    const double speed = memory != s.touching.end() && memory->slot == l.c.slot ? memory->speed : 0.0;
    l.step_speed = speed > 0.0 ? speed : std::max(l.end_rate, model_.contact.min_impact_speed);
  }
}

double NaturalSolver::errorLeft(double scaled, bool kept, bool fresh, double& previous)
{
  // A Newton step's increment (a matrix built for it) is its error; with an older matrix the error left is about
  // theta / (1 - theta) times the increment, theta the largest contraction rate seen with that matrix (floored), and
  // the iteration must contract (contracting()).
  if (kept && previous > 0.0 && scaled > 1e-3)
  {
    theta_ = std::max(theta_, scaled / previous);
    theta_known_ = true;
  }
  previous = scaled;
  const double rate = std::max(theta_, policy_.rate_floor);
  return fresh ? scaled : (theta_known_ ? rate / (1.0 - rate) : 1.0) * scaled;
}

void NaturalSolver::freshMatrix(double& previous)
{
  theta_ = 0.0;
  theta_known_ = false;
  previous = 0.0;
  ++stats_.factorizations;
}

// ---- statics ----------------------------------------------------------------------------------------------

void NaturalSolver::listStatic(const Eigen::VectorXd& x)
{
  if (!model_.contact.enabled && nm_.ground_contacts.empty())
    return;
  // a contact left out of the near ones was more than 2 D apart at the listing (D = near_motion_); no node has moved by
  // more than D since, so it is still apart
  double moved = 0.0;
  if (static_listed_)
    for (size_t i = 0; i < nm_.nodes.size() && moved <= near_motion_; ++i)
      moved = std::max(moved, (naturalNodePosition(nm_, static_cast<int>(i), x, u_) - static_nodes_[i]).norm());
  if (static_listed_ && moved <= near_motion_)
    return;
  static_state_.x = x;
  static_state_.v = zero_v_;
  static_state_.t = std::numeric_limits<double>::quiet_NaN();
  static_state_.touching.clear();
  findNear(static_state_, std::max({ kNearFloor, 2.0 * moved, static_listed_ ? near_motion_ : 0.0 }));
  static_nodes_ = node_now_;
  static_listed_ = true;
}

void NaturalSolver::assembleStatic(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, const ActuationValues& u,
                                   bool tangent)
{
  const int n = nm_.coordinates, m = static_cast<int>(nm_.struts.size() + nm_.rows.size());
  u_ = u;
  for (ActuationValue& a : u_)
    a.rate = a.accel = 0.0;
  if (zero_v_.size() != n)
    zero_v_.setZero(n);
  reactions_valid_ = false;
  have_lu_ = false;  // (the dynamics' factorization, if any, is replaced)
  {
    const ScopeTimer timer(stats_.contact_time);
    listStatic(x);
  }
  residual_.resize(n + m);
  if (tangent)
  {
    entries_.clear(n + m, n + m <= policy_.dense_most);
    entries_.k_weight = 1.0;
    entries_.c_weight = 0.0;
  }
  {
    const ScopeTimer timer(stats_.forces_time);
    forces(x, zero_v_, tangent);
  }
  {
    const ScopeTimer timer(stats_.contact_time);
    contactForces(x, zero_v_, tangent);
  }
  const ScopeTimer timer(stats_.constraints_time);
  residual_.head(n) = -f_;
  constraintRows(x, lambda, 1.0, 1.0, tangent);
  // (no spin in statics: its rows hold the spin entries still)
  for (const NaturalStrut& st : nm_.struts)
    if (st.spin >= 0)
    {
      residual_(st.spin) = 0.0;
      if (tangent)
        entries_.add(st.spin, st.spin, mass_scale_);
    }
}

void NaturalSolver::addStaticMass(double mu)
{
  entries_.addMatrix(nm_.mass, mu);
}

bool NaturalSolver::factorizeStatic()
{
  const int size = static_cast<int>(residual_.size());
  const ScopeTimer timer(stats_.factorization_time);
  ++stats_.factorizations;
  if (entries_.to_dense && !entries_.dense.allFinite())
    return false;
  if (!entries_.to_dense)
    return factorize(size);
  // equilibrated: a stiffness of 1e5 N/m beside the rows' 2 L, near a mechanism, leaves partial pivoting's tangents to
  // round-off otherwise
  equilibrate(entries_.dense, row_scale_, col_scale_, equilibrated_);
  dense_mode_ = true;
  use_inverse_ = false;
  dense_lu_.compute(equilibrated_);
  scaled_ = true;
  return regular(dense_lu_);
}

int NaturalSolver::determinantSign()
{
  if (dense_mode_)
    return core::determinantSign(dense_lu_);
  return static_mode_ ? static_lu_.determinantSign() : static_cast<int>(sparse_lu_.signDeterminant());
}

Eigen::MatrixXd NaturalSolver::assembledMatrix() const
{
  if (entries_.to_dense)
    return entries_.dense;
  const Eigen::Index size = residual_.size();
  Eigen::SparseMatrix<double> m(size, size);
  m.setFromTriplets(entries_.triplets.begin(), entries_.triplets.end());
  return Eigen::MatrixXd(m);
}

Eigen::VectorXd NaturalSolver::assembledDiagonal() const
{
  if (entries_.to_dense)
    return entries_.dense.diagonal();
  Eigen::VectorXd d = Eigen::VectorXd::Zero(residual_.size());
  for (const Eigen::Triplet<double>& t : entries_.triplets)
    if (t.row() == t.col())
      d(t.row()) += t.value();
  return d;
}

Eigen::SparseMatrix<double> NaturalSolver::assembledRows() const
{
  const int n = nm_.coordinates, m = static_cast<int>(residual_.size()) - n;
  std::vector<Eigen::Triplet<double>> g;
  if (entries_.to_dense)
  {
    for (int c = 0; c < n; ++c)
      for (int r = 0; r < m; ++r)
        if (entries_.dense(n + r, c) != 0.0)
          g.emplace_back(r, c, entries_.dense(n + r, c));
  }
  else
    for (const Eigen::Triplet<double>& t : entries_.triplets)
      if (t.row() >= n && t.col() < n)
        g.emplace_back(t.row() - n, t.col(), t.value());
  Eigen::SparseMatrix<double> out(m, n);
  out.setFromTriplets(g.begin(), g.end());
  return out;
}

int NaturalSolver::passedThrough(const Eigen::VectorXd& x0, const ActuationValues& u0, const Eigen::VectorXd& x1,
                                 const ActuationValues& u1)
{
  if (!model_.contact.enabled)
    return -1;
  // the pairs that can meet on the way: a pair's gap changes by at most the motions of its two struts' nodes, so one
  // that met on the way is within twice the largest motion at either end
  double motion = 0.0;
  node_now_.resize(nm_.nodes.size());
  points_.resize(nm_.nodes.size());
  double from_listing = 0.0;  // how far x1's nodes are from the static listing's
  for (size_t i = 0; i < nm_.nodes.size(); ++i)
  {
    node_now_[i] = naturalNodePosition(nm_, static_cast<int>(i), x0, u0);
    points_[i] = naturalNodePosition(nm_, static_cast<int>(i), x1, u1);
    motion = std::max(motion, (points_[i] - node_now_[i]).norm());
    if (static_listed_)
      from_listing = std::max(from_listing, (points_[i] - static_nodes_[i]).norm());
  }
  candidates_.clear();
  if (static_listed_ && 2.0 * (motion + from_listing) < list_margin_)
  {
    // the listing holds every pair within its margin of where it was made: those are all
    for (const Listed& l : listed_)
      if (!l.c.ground)
        candidates_.push_back(l.c.slot);
  }
  else if (use_broad_phase_)
  {
    broad_q_ = naturalToBodyCoordinates(nm_, x0, u0);
    broad_phase_.candidates(broad_q_, motion, candidates_);
    std::sort(candidates_.begin(), candidates_.end());
  }
  else
    candidates_ = direct_pairs_;
  const auto from = [&](int i) { return node_now_[static_cast<size_t>(i)]; };
  const auto to = [&](int i) { return points_[static_cast<size_t>(i)]; };
  for (const int slot : candidates_)
    if (pairPassedThrough(nm_, naturalContactSlot(nm_, slot), from, to))
      return slot;
  return -1;
}

void NaturalSolver::staticContacts(const Eigen::VectorXd& x, const ActuationValues& u,
                                   std::vector<ContactPairState>& out)
{
  out.clear();
  u_ = u;
  for (ActuationValue& a : u_)
    a.rate = a.accel = 0.0;
  if (zero_v_.size() != nm_.coordinates)
    zero_v_.setZero(nm_.coordinates);
  listStatic(x);
  for (const Listed& l : listed_)
  {
    Vec14 f;
    const ContactPairState st =
        naturalContact(nm_, l.c, naturalContactInput(nm_, l.c, x, zero_v_, u_), 0.0, &f, nullptr, nullptr);
    if (st.active)
      out.push_back(st);
  }
}

Summary NaturalSolver::initialize(NaturalState& s, const ActuationLaw& law)
{
  Summary out;
  const int n = nm_.coordinates, m = static_cast<int>(nm_.struts.size() + nm_.rows.size());
  law(s.t, u_);
  reactions_valid_ = false;  // (the multipliers and accelerations are made anew)
  findNear(s, kNearFloor);
  forces(s.x, s.v, false);
  contactForces(s.x, s.v, false);
  contactsAt(s, s.contacts);
  // [M G^T; G 0] [a; lambda] = [F; -2 |u_dot|^2 - 2 u . (driven accelerations)]
  entries_.clear(n + m, n + m <= policy_.dense_most);
  entries_.addMatrix(nm_.mass);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n + m);
  rhs.head(n) = f_;
  const int struts = static_cast<int>(nm_.struts.size());
  for (int k = struts; k < m; ++k)
  {
    const NaturalRow& row = nm_.rows[k - struts];
    const int col = nm_.nodes[row.node].column;
    entries_.column(col, n + k, row.direction);
    rhs(n + k) = row.actuator >= 0 ? u_[row.actuator].accel : 0.0;
  }
  for (int k = 0; k < struts; ++k)
  {
    const NaturalStrut& st = nm_.struts[k];
    const Vec3 d = naturalNodePosition(nm_, st.b, s.x, u_) - naturalNodePosition(nm_, st.a, s.x, u_);
    const Vec3 dv = naturalNodeVelocity(nm_, st.b, s.v, u_) - naturalNodeVelocity(nm_, st.a, s.v, u_);
    double r = -2.0 * dv.squaredNorm();
    for (const auto& [node, sign] : { std::pair{ st.a, -1.0 }, std::pair{ st.b, 1.0 } })
    {
      const NaturalNode& nd = nm_.nodes[node];
      if (nd.column >= 0)
        entries_.column(nd.column, n + k, 2.0 * sign * d);
      else if (nd.kind == NaturalNode::Kind::kDriven)
        r -= 2.0 * sign * d.dot(u_[nd.actuator].accel * nd.direction);
    }
    rhs(n + k) = r;
  }
  factorize(n + m);
  have_lu_ = false;  // (not a Newton matrix)
  const Eigen::VectorXd z = solve(rhs);
  if (!z.allFinite())
  {
    out.status = SolveStatus::kNonFinite;
    out.message = "natural coordinates: no consistent accelerations at the start";
    return out;
  }
  s.a = z.head(n);
  s.qdd = s.a;
  s.lambda = z.tail(m);
  return out;
}

Summary NaturalSolver::project(NaturalState& s, const ActuationValues& u)
{
  Summary out;
  const int n = nm_.coordinates, m = static_cast<int>(nm_.struts.size() + nm_.rows.size());
  const int struts = static_cast<int>(nm_.struts.size());
  u_ = u;
  pos_.resize(nm_.nodes.size());
  const Eigen::VectorXd no_lambda = Eigen::VectorXd::Zero(m);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n + m);
  const auto build = [&]()
  {
    for (size_t i = 0; i < nm_.nodes.size(); ++i)
      pos_[i] = naturalNodePosition(nm_, static_cast<int>(i), s.x, u_);
    residual_.setZero(n + m);
    entries_.clear(n + m, n + m <= policy_.dense_most);
    entries_.addMatrix(nm_.mass);
    constraintRows(s.x, no_lambda, 1.0, 0.0, true);
    return factorize(n + m);
  };
  // [M G^T; G 0] [dx; mu] = [0; -Phi]: the least change of x in the mass metric that zeroes Phi to first order
  const double tolerance = 1e-12 * (1.0 + s.x.head(nm_.positions).lpNorm<Eigen::Infinity>());
  for (int it = 0;; ++it)
  {
    if (!build())
    {
      out.status = SolveStatus::kSingular;
      out.message = "natural coordinates: the constraint rows are singular at the state to project";
      return out;
    }
    rhs.head(n).setZero();
    rhs.tail(m) = -residual_.tail(m);
    const Eigen::VectorXd z = solve(rhs);
    if (!z.allFinite())
    {
      out.status = SolveStatus::kNonFinite;
      out.message = "natural coordinates: the projection onto the constraints is not finite";
      return out;
    }
    s.x.head(nm_.positions) += z.head(nm_.positions);
    ++out.iterations;
    out.residual = z.head(nm_.positions).lpNorm<Eigen::Infinity>();
    if (out.residual <= tolerance)
      break;
    if (it + 1 >= options_.max_iterations)
    {
      out.status = SolveStatus::kMaxIterations;
      out.message = "natural coordinates: the positions do not meet the constraints within " +
                    std::to_string(options_.max_iterations) + " iterations (last correction " +
                    std::to_string(out.residual) + " m)";
      return out;
    }
  }
  // the velocity rows at the projected positions: d/dt Phi = G v + (the driven nodes' and rows' rates) = 0
  if (!build())
  {
    out.status = SolveStatus::kSingular;
    out.message = "natural coordinates: the constraint rows are singular at the projected state";
    return out;
  }
  rhs.setZero();
  for (int k = 0; k < struts; ++k)
  {
    const NaturalStrut& st = nm_.struts[k];
    const Vec3 d = pos_[st.b] - pos_[st.a];
    rhs(n + k) = -2.0 * d.dot(naturalNodeVelocity(nm_, st.b, s.v, u_) - naturalNodeVelocity(nm_, st.a, s.v, u_));
  }
  for (int k = struts; k < m; ++k)
  {
    const NaturalRow& row = nm_.rows[k - struts];
    rhs(n + k) = -(row.direction.dot(s.v.segment<3>(nm_.nodes[row.node].column)) -
                   (row.actuator >= 0 ? u_[row.actuator].rate : 0.0));
  }
  const Eigen::VectorXd z = solve(rhs);
  if (!z.allFinite())
  {
    out.status = SolveStatus::kNonFinite;
    out.message = "natural coordinates: the projection of the velocities is not finite";
    return out;
  }
  s.v.head(nm_.positions) += z.head(nm_.positions);
  have_lu_ = false;  // (not a Newton matrix)
  return out;
}

void NaturalSolver::constraintRows(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, double phi_divisor,
                                   double hessian_weight, bool build)
{
  // rows n.. of residual_ get Phi / phi_divisor, its first n entries G^T lambda; with build, entries_ gets G, G^T and
  // hessian_weight times the rows' second derivatives weighted by lambda (pos_ holds the nodes at x)
  const int n = nm_.coordinates, m = static_cast<int>(nm_.struts.size() + nm_.rows.size());
  const int struts = static_cast<int>(nm_.struts.size());
  for (int k = struts; k < m; ++k)
  {
    const NaturalRow& row = nm_.rows[k - struts];
    const int col = nm_.nodes[row.node].column;
    residual_(n + k) =
        (row.direction.dot(x.segment<3>(col)) - row.offset - (row.actuator >= 0 ? u_[row.actuator].value : 0.0)) /
        phi_divisor;
    residual_.segment<3>(col) += lambda(k) * row.direction;
    if (build)
      entries_.column(col, n + k, row.direction);
  }
  for (int k = 0; k < struts; ++k)
  {
    const NaturalStrut& st = nm_.struts[k];
    const Vec3 d = pos_[st.b] - pos_[st.a];
    residual_(n + k) = (d.squaredNorm() - st.length * st.length) / phi_divisor;
    const int ca = nm_.nodes[st.a].column, cb = nm_.nodes[st.b].column;
    const double l2 = 2.0 * lambda(k);
    if (cb >= 0)
      residual_.segment<3>(cb) += l2 * d;
    if (ca >= 0)
      residual_.segment<3>(ca) -= l2 * d;
    if (!build)
      continue;
    if (cb >= 0)
    {
      entries_.column(cb, n + k, 2.0 * d);
      entries_.diagonal(cb, cb, hessian_weight * l2);
    }
    if (ca >= 0)
    {
      entries_.column(ca, n + k, -2.0 * d);
      entries_.diagonal(ca, ca, hessian_weight * l2);
    }
    if (ca >= 0 && cb >= 0)
    {
      entries_.diagonal(ca, cb, -hessian_weight * l2);
      entries_.diagonal(cb, ca, -hessian_weight * l2);
    }
  }
}

Summary NaturalSolver::setExternalLoads(const std::vector<PointLoad>& loads, NaturalState& s, const ActuationLaw& law)
{
  std::vector<NaturalLoad> converted;
  converted.reserve(loads.size());
  for (const PointLoad& l : loads)
    converted.push_back(naturalLoad(nm_, l));
  external_ = std::move(converted);
  reactions_valid_ = false;
  start_energy_valid_ = false;
  history_count_ = 0;
  last_end_t_ = -1.0;
  return initialize(s, law);
}

void NaturalSolver::startStep(const NaturalState& s, double h)
{
  // the pairs a node can reach in this step (from its speed and acceleration at the start), checked after
  double reach = 0.0;
  for (int c = 0; c < nm_.positions; c += 3)
    reach = std::max(reach, s.v.segment<3>(c).norm() * h + s.a.segment<3>(c).norm() * h * h);
  for (const NaturalNode& nd : nm_.nodes)
    if (nd.kind == NaturalNode::Kind::kDriven)
      reach = std::max(reach, std::abs(u_[nd.actuator].rate) * h + std::abs(u_[nd.actuator].accel) * h * h);
  {
    const ScopeTimer timer(stats_.contact_time);
    findNear(s, std::max(2.0 * reach, kNearFloor));
  }
  // (members, kept between steps: no allocation in the step loop once they have their size)
  c0_ = (alpha_f_ * s.qdd - alpha_m_ * s.a) / (1.0 - alpha_m_);
  acc_ = s.qdd;
  lambda_ = s.lambda;
  const int known = s.t == last_end_t_ ? history_count_ : 0;
  if (known == 1)
  {
    const double r = h / (s.t - history_[0].t);
    acc_ += r * (s.qdd - history_[0].a);
    lambda_ += r * (s.lambda - history_[0].lambda);
  }
  else if (known == 2)
  {
    const double t = s.t + h, t2 = s.t, t1 = history_[0].t, t0 = history_[1].t;
    const double w2 = (t - t0) * (t - t1) / ((t2 - t0) * (t2 - t1));
    const double w1 = (t - t0) * (t - t2) / ((t1 - t0) * (t1 - t2));
    const double w0 = (t - t1) * (t - t2) / ((t0 - t1) * (t0 - t2));
    acc_ = w2 * s.qdd + w1 * history_[0].a + w0 * history_[1].a;
    lambda_ = w2 * s.lambda + w1 * history_[0].lambda + w0 * history_[1].lambda;
  }
  x_pred_ = s.x + h * s.v + h * h * ((0.5 - beta_) * s.a + beta_ * c0_);
  v_pred_ = s.v + h * ((1.0 - gamma_) * s.a + gamma_ * c0_);
  touching_.clear();
  for (const NaturalTouch& c : s.touching)
    touching_.push_back(c.slot);
}

Summary NaturalSolver::tryStep(NaturalState& s, double h, const ActuationLaw& law)
{
  // The unknowns are the accelerations qdd at the step's end; the algorithmic accelerations are
  // a = c1 qdd + c0 (generalized-alpha: (1 - alpha_m) a + alpha_m a_n = (1 - alpha_f) qdd + alpha_f qdd_n; Newmark:
  // a = qdd), and x = x_n + h v_n + h^2 ((1/2 - beta) a_n + beta a), v = v_n + h ((1 - gamma) a_n + gamma a).
  Summary out;
  const int n = nm_.coordinates, m = static_cast<int>(nm_.struts.size() + nm_.rows.size());
  law(s.t + h, u_);
  startStep(s, h);
  const double c1 = (1.0 - alpha_f_) / (1.0 - alpha_m_);
  const double bh2 = beta_ * h * h * c1, gh = gamma_ * h * c1;
  residual_.resize(n + m);
  // modified Newton keeps the factorization while it serves (NewtonPolicy)
  bool rebuild =
      policy_.rebuildAtStart(have_lu_, h, lu_h_, factor_age_, options_.max_jacobian_age, touching_ != factor_contacts_);
  bool built_this_step = false;
  double previous = 0.0;  // the last increment over the tolerance
  for (int it = 0; it < options_.max_iterations; ++it)
  {
    x_ = x_pred_ + bh2 * acc_;
    v_ = v_pred_ + gh * acc_;
    const bool full = policy_.fullNewton(it, options_.reuse_jacobian);
    const bool build = rebuild || full;
    if (build)
    {
      entries_.clear(n + m, n + m <= policy_.dense_most);
      entries_.addMatrix(nm_.mass);
      entries_.k_weight = bh2;
      entries_.c_weight = gh;
    }
    // (the parts timed one after the other, one clock reading between each two)
    LapTimer laps;
    forces(x_, v_, build);
    laps.lap(stats_.forces_time);
    contactForces(x_, v_, build);
    laps.lap(stats_.contact_time);
    residual_.head(n) = -f_;
    residual_.head(n).noalias() += nm_.mass * acc_;  // (no temporary for the product)
    constraintRows(x_, lambda_, bh2, bh2, build);
    laps.lap(stats_.constraints_time);
    if (build)
    {
      // (modified Newton's matrix may be an approximation; full Newton's is refined to round-off at every solve)
      const bool factorized = factorize(n + m, full ? Pivots::kStaticRefined : Pivots::kStatic);
      laps.lap(stats_.factorization_time);
      if (!factorized)
      {
        out.status = SolveStatus::kSingular;
        out.message = "natural coordinates: a singular Newton matrix";
        have_lu_ = false;
        return out;
      }
      have_lu_ = true;
      lu_h_ = h;
      rebuild = false;
      built_this_step = true;
      factor_age_ = 0;
      factor_contacts_ = touching_;
      freshMatrix(previous);
    }
    rhs_ = -residual_;
    solve(rhs_, correction_);
    laps.lap(stats_.solve_time);
    ++out.iterations;
    ++stats_.iterations;
    if (!correction_.allFinite())
    {
      out.status = SolveStatus::kNonFinite;
      out.message = "natural coordinates: a non-finite Newton correction";
      have_lu_ = false;
      return out;
    }
    acc_ += correction_.head(n);
    lambda_ += correction_.tail(m);
    const double norm = bh2 * correction_.head(n).lpNorm<Eigen::Infinity>();
    out.residual = norm;
    // (the multipliers to the tolerance relative to their size, above the round-off of phi / (beta h^2))
    const double lambda_floor = 10.0 * std::numeric_limits<double>::epsilon() *
                                (1.0 + s.x.head(nm_.positions).lpNorm<Eigen::Infinity>()) * mass_scale_ / bh2;
    const double lambda_part =
        m > 0 ? correction_.tail(m).lpNorm<Eigen::Infinity>() /
                    (options_.newton_tolerance * (1.0 + lambda_.lpNorm<Eigen::Infinity>()) + lambda_floor) :
                0.0;
    const double scaled = std::max(norm / options_.newton_tolerance, lambda_part);
    if (errorLeft(scaled, !build, built_this_step, previous) <= 1.0 && contracting())
    {
      x_ = x_pred_ + bh2 * acc_;
      // a node went further than the near pairs allow for: again with the pairs it can reach
      if (largestMotion(s.x, x_) > near_motion_)
      {
        findNear(s, 2.0 * largestMotion(s.x, x_));
        continue;
      }
      const Summary end = endStep(s, h, c1);
      out.status = end.status;
      out.message = end.message;
      return out;
    }
    // an old matrix that does not contract: a new one
    if (!contracting())
      rebuild = true;
  }
  out.status = SolveStatus::kMaxIterations;
  out.message = "natural coordinates: Newton did not converge";
  have_lu_ = false;
  return out;
}

Summary NaturalSolver::endStep(NaturalState& s, double h, double c1)
{
  Summary out;
  const double t1 = s.t + h;
  // a step that jumps a strut through another is refused (and cut), never accepted silently
  const ScopeTimer timer(stats_.contact_time);  // (the pass-through check and the end's contacts)
  const int crossed = firstPassedThrough();
  if (crossed >= 0)
  {
    const auto [body_a, body_b] = model_.pairBodies(crossed);
    out.status = SolveStatus::kPassedThrough;
    out.message = "struts '" + model_.bodies[body_a].name + "' and '" + model_.bodies[body_b].name +
                  "' passed through each other";
    return out;
  }
  // the local error and a new contact's depth
  error_ = 0.0;
  const double factor = h * h * (std::abs(beta_ - 1.0 / 6.0) + std::abs(gamma_ - 0.5));
  a_end_ = c1 * acc_ + c0_;
  for (int c = 0; c < nm_.positions; c += 3)
    error_ = std::max(error_, factor * (a_end_.segment<3>(c) - s.a.segment<3>(c)).norm());
  v_ = v_pred_ + gamma_ * h * c1 * acc_;
  onset_depth_ = 0.0;
  // the listed contacts at the end (the next step's start reads them), a new contact's depth, and the contact
  // memory: the contacts touching at the end keep (or take) this step's impact speed, the others forget it; a near
  // pair's forces at its impact speed, in the same pass (near_ ascends, as listed_ does by slot)
  s.touching.clear();
  s.contacts.clear();
  auto next_near = near_.begin();
  for (size_t k = 0; k < listed_.size(); ++k)
  {
    Listed& l = listed_[k];
    const bool near = next_near != near_.end() && *next_near == static_cast<int>(k);
    if (near)
      ++next_near;
    Vec14 f;
    const ContactPairState st = naturalContact(nm_, l.c, naturalContactInput(nm_, l.c, x_, v_, u_),
                                               near ? l.step_speed : 0.0, near ? &f : nullptr, nullptr, nullptr);
    l.end_gap = st.gap;
    l.end_rate = st.penetration_rate;
    if (!near || !st.active)
      continue;
    s.touching.push_back({ l.c.slot, l.step_speed });
    s.contacts.push_back(st);
    if (-l.end_gap > onset_depth_ && !std::binary_search(touching_.begin(), touching_.end(), l.c.slot))
      onset_depth_ = -l.end_gap;
  }
  end_t_ = t1;
  end_list_version_ = list_version_;
  // the history of Newton's first guess
  if (s.t == last_end_t_ && history_count_ > 0)
    std::swap(history_[0], history_[1]);
  history_count_ = s.t == last_end_t_ ? std::min(history_count_ + 1, 2) : 1;
  history_[0].t = s.t;
  history_[0].a = s.qdd;
  history_[0].lambda = s.lambda;
  last_end_t_ = t1;
  s.x = x_;
  s.v = v_;
  s.a = a_end_;
  s.qdd = acc_;
  s.lambda = lambda_;
  s.t = t1;
  ++stats_.steps;
  ++factor_age_;
  return out;
}

Summary NaturalSolver::step(NaturalState& s, double h, const ActuationLaw& law)
{
  const double t_end = s.t + h;
  Summary total = stepInPieces(
      h, options_,
      [&](double piece)
      {
        Summary r = tryStep(s, piece, law);  // (changes s only when it succeeds)
        if (!r.ok())
          ++stats_.rejected_solver;
        return r;
      },
      [&]() { return s.t; });
  if (total.ok())
    s.t = t_end;
  return total;
}

void NaturalSolver::setAdaptiveOptions(const SolverOptions& o)
{
  options_.dt = o.dt;
  options_.dt_min = o.dt_min;
  options_.dt_max = o.dt_max;
  options_.error_tolerance = o.error_tolerance;
  options_.onset_depth = o.onset_depth;
  options_.energy_tolerance = o.energy_tolerance;
  control_ = StepSizeControl(options_);
}

Summary NaturalSolver::advance(NaturalState& s, double t_end, const ActuationLaw& law,
                               const std::function<void(const NaturalState&)>& on_step, bool adaptive)
{
  Summary total;
  const double eps = 1e-12 * std::max(1.0, std::abs(t_end));
  while (t_end - s.t > eps)
  {
    const double remaining = t_end - s.t;
    if (!adaptive)
    {
      const double h = remaining <= 1.05 * options_.dt ? remaining : options_.dt;
      const double t1 = s.t + h;
      const Summary r = step(s, h, law);
      total.iterations += r.iterations;
      total.step_cuts += r.step_cuts;
      if (!r.ok())
      {
        total.status = r.status;
        total.message = r.message;
        return total;
      }
      s.t = t1;
      if (on_step)
        on_step(s);
      continue;
    }
    const StepSizeControl::Trial step = control_.next(remaining);
    const double h = step.h;
    const bool at_min = step.at_min;
    trial_ = s;  // (a member: assigned into its buffers, no allocation once they have their size)
    const Summary r = tryStep(trial_, h, law);
    total.iterations += r.iterations;
    total.residual = r.residual;
    if (!r.ok())
    {
      ++stats_.rejected_solver;
      ++total.step_cuts;
      if (r.status == SolveStatus::kPassedThrough)
        ++total.crossings_refused;
      if (at_min)
      {
        total.status = r.status;
        total.message = r.message + " at t = " + std::to_string(s.t) + " s with the step at its minimum " +
                        std::to_string(h) + " s";
        return total;
      }
      control_.failed(h);
      continue;
    }
    const double err = error_ / options_.error_tolerance;
    if (!at_min && onset_depth_ > options_.onset_depth)
    {
      // the new contact's gap at the start
      double gap_start = 0.0;
      for (const NaturalTouch& c : trial_.touching)
        if (!(s.contactSpeed(c.slot) > 0.0))
        {
          ActuationValues& u0 = u_onset_;
          law(s.t, u0);
          const NaturalContactSlot cs = naturalContactSlot(nm_, c.slot);
          gap_start = std::max(
              gap_start,
              naturalContact(nm_, cs, naturalContactInput(nm_, cs, s.x, s.v, u0), 0.0, nullptr, nullptr, nullptr).gap);
        }
      ++stats_.rejected_onset;
      control_.tooDeep(h, gap_start, onset_depth_);
      continue;
    }
    if (!at_min && err > 1.0)
    {
      ++stats_.rejected_error;
      control_.tooLarge(h, err);
      continue;
    }
    // a step that gained energy no force accounts for did not resolve a stiff event (a contact or a cable going taut
    // within it), one that lost it in contact damped an impact numerically: halved, as a failed step
    u_end_ = u_;  // (tryStep left the trial's end in u_)
    const ActuationValues& u_end = u_end_;
    if (!start_energy_valid_ || start_energy_t_ != s.t)
    {
      law(s.t, u_start_);
      start_energy_ = energyAt(s, u_start_);
      start_energy_t_ = s.t;
      start_energy_valid_ = true;
    }
    const EnergyPoint end_energy = energyAt(trial_, u_end);
    u_ = u_end;
    double mass = 0.0;
    for (const Body& b : model_.bodies)
      mass += b.mass;
    const double v_round =
        2.0 * std::numeric_limits<double>::epsilon() * (1.0 + s.x.head(nm_.positions).lpNorm<Eigen::Infinity>()) / h;
    const StepEnergyCheck energy =
        checkStepEnergy(start_energy_, end_energy, h, options_.energy_tolerance, 0.5 * mass * v_round * v_round,
                        in_contact_ || !trial_.touching.empty());
    if (!at_min && !energy.ok())
    {
      ++stats_.rejected_energy;
      control_.energyRefused(h);
      continue;
    }
    last_check_ = energy;
    ++stats_.accepted;
    if (at_min && (err > 1.0 || onset_depth_ > options_.onset_depth || !energy.ok()))
      ++stats_.at_min_step;
    stats_.h_min = stats_.accepted == 1 ? h : std::min(stats_.h_min, h);
    stats_.h_max = std::max(stats_.h_max, h);
    std::swap(s, trial_);
    start_energy_ = end_energy;
    start_energy_t_ = s.t;
    in_contact_ = !s.touching.empty();
    if (on_step)
      on_step(s);
    control_.accepted(step, err);
  }
  s.t = t_end;
  return total;
}

}  // namespace active_tensegrity::core
