#include "active_tensegrity/core/natural.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <unsupported/Eigen/AutoDiff>

#include "active_tensegrity/core/cable.h"
#include "active_tensegrity/core/kinematics.h"
#include "active_tensegrity/core/rotation.h"

namespace active_tensegrity::core
{
namespace
{
using Vec12 = Eigen::Matrix<double, 12, 1>;
using Mat12 = Eigen::Matrix<double, 12, 12>;

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
    throw std::invalid_argument(what + ": a point of the ground is not a node of the natural coordinates");
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

// the constants of one pair's contact
struct PairConstants
{
  double radius[2] = { 0.0, 0.0 };
  double inv_length2[2] = { 0.0, 0.0 };  // 1 / L^2
  double stiffness90 = 0.0, core_stiffness90 = 0.0, core_gap = 0.0;
  double floor_sin = 0.0;
  double scale = 0.0;  // (L1 + L2) / 2
};

// One pair's contact on its four nodes (a, b of strut 1, then of strut 2), generic in the scalar so that the
// tangents are its forward-mode derivatives. Fills F (when `force`) and the pair's state (values).
template <typename T>
void pairKernel(const Model& model, const PairConstants& pc, const V3<T> r[4], const V3<T> v[4], double impact_speed,
                bool force, Eigen::Matrix<T, 12, 1>& F, ContactPairState& st)
{
  using std::sqrt;
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
  if (h > 1e-12 * pc.scale)
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
  const double r1 = pc.radius[0], r2 = pc.radius[1];
  const T zeta = r1 + r2 - h;
  const V3<T> vp1 = v[0] + s * (v[1] - v[0]), vp2 = v[2] + t * (v[3] - v[2]);
  const T rate = -n.dot(vp1 - vp2);
  st.normal = valueOf(n);
  st.gap = -valueOf(zeta);
  st.penetration = valueOf(zeta);
  st.active = st.penetration > 0.0;
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
    const bool above = sin2 > pc.floor_sin * pc.floor_sin;
    const T root = above ? T(sqrt(sqrt(sin2))) : T(sqrt(pc.floor_sin));
    const T k = pc.stiffness90 / root;
    st.stiffness = valueOf(k);
    T elastic = k * zeta * sqrt(zeta);
    const T zc = zeta - pc.core_gap;
    if (pc.core_stiffness90 > 0.0 && zc > 0.0)
    {
      const T kc = pc.core_stiffness90 / root;
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
  // friction at the contact points as material points of struts without spin: w = u x u_dot / L^2
  const V3<T> w1 = pc.inv_length2[0] * u1.cross(v[1] - v[0]), w2 = pc.inv_length2[1] * u2.cross(v[3] - v[2]);
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
  const V3<T> turn1 = (r1 * pc.inv_length2[0]) * m.cross(u1), turn2 = (r2 * pc.inv_length2[1]) * m.cross(u2);
  F.template segment<3>(0) += (1.0 - s) * fa + turn1;
  F.template segment<3>(3) += s * fa - turn1;
  F.template segment<3>(6) += -(1.0 - t) * fa + turn2;
  F.template segment<3>(9) += -t * fa - turn2;
}

PairConstants pairConstants(const NaturalModel& nm, int slot)
{
  const Model& model = *nm.model;
  const StrutPair p = model.strutPair(slot);
  PairConstants pc;
  const int bodies[2] = { p.body_a, p.body_b };
  for (int k = 0; k < 2; ++k)
  {
    const Body& b = model.bodies[bodies[k]];
    pc.radius[k] = b.radius();
    pc.inv_length2[k] = 1.0 / (b.length * b.length);
    pc.scale += 0.5 * b.length;
  }
  pc.stiffness90 = p.stiffness90;
  pc.core_stiffness90 = p.core_stiffness90;
  pc.core_gap = p.core_gap;
  pc.floor_sin = std::sin(model.contact.min_crossing_angle);
  return pc;
}

// the four nodes of a pair slot
std::array<int, 4> pairNodes(const NaturalModel& nm, int slot)
{
  const auto [body_a, body_b] = nm.model->pairBodies(slot);
  const NaturalStrut& a = nm.struts[nm.strut_of_body[body_a]];
  const NaturalStrut& b = nm.struts[nm.strut_of_body[body_b]];
  return { a.a, a.b, b.a, b.b };
}
}  // namespace

NaturalModel buildNaturalModel(const Model& model)
{
  NaturalModel nm;
  nm.model = &model;
  if (model.ground.enabled)
    throw std::invalid_argument("natural coordinates: ground contact is not covered");
  double size = 0.0;
  for (const Body& b : model.bodies)
    size = std::max(size, b.length);
  const double tol = 1e-9 * std::max(1.0, size);
  nm.strut_of_body.assign(model.bodies.size(), -1);
  nm.node_of_body.assign(model.bodies.size(), -1);
  std::vector<double> node_mass;
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
  for (NaturalNode& n : nm.nodes)
    if (n.kind == NaturalNode::Kind::kFree)
    {
      n.column = nm.coordinates;
      nm.coordinates += 3;
    }
  // the constant mass matrix and the weight
  const int n = nm.coordinates;
  nm.mass = Eigen::MatrixXd::Zero(n, n);
  nm.gravity = Eigen::VectorXd::Zero(n);
  const Vec3 g = model.gravity_enabled ? model.gravity : Vec3::Zero();
  for (const NaturalStrut& s : nm.struts)
  {
    const Body& b = model.bodies[s.body];
    const double jt = b.inertia.x(), l2 = s.length * s.length;
    const double diag = 0.25 * b.mass + jt / l2, off = 0.25 * b.mass - jt / l2;
    const int ca = nm.nodes[s.a].column, cb = nm.nodes[s.b].column;
    for (const int col : { ca, cb })
      if (col >= 0)
      {
        nm.mass.block<3, 3>(col, col).diagonal().array() += diag;
        nm.gravity.segment<3>(col) += 0.5 * b.mass * g;
      }
    if (ca >= 0 && cb >= 0)
    {
      nm.mass.block<3, 3>(ca, cb).diagonal().array() += off;
      nm.mass.block<3, 3>(cb, ca).diagonal().array() += off;
    }
  }
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const int node = nm.node_of_body[i];
    if (node < 0 || nm.nodes[node].column < 0)
      continue;
    const int col = nm.nodes[node].column;
    nm.mass.block<3, 3>(col, col).diagonal().array() += model.bodies[i].mass;
    nm.gravity.segment<3>(col) += model.bodies[i].mass * g;
  }
  if (model.contact.enabled)
    model.checkedPairList(&nm.pair_slots);
  return nm;
}

NaturalState naturalInitialState(const NaturalModel& nm)
{
  NaturalState s;
  s.x.resize(nm.coordinates);
  for (const NaturalNode& n : nm.nodes)
    if (n.column >= 0)
      s.x.segment<3>(n.column) = n.position0;
  s.v.setZero(nm.coordinates);
  s.a.setZero(nm.coordinates);
  s.lambda.setZero(static_cast<int>(nm.struts.size() + nm.rows.size()));
  s.contact_speed.assign(nm.pair_slots.size(), 0.0);
  return s;
}

Vec3 naturalNodePosition(const NaturalModel& nm, int i, const Eigen::VectorXd& x, const ActuationValues& u)
{
  const NaturalNode& n = nm.nodes[i];
  switch (n.kind)
  {
    case NaturalNode::Kind::kFree:
      return x.segment<3>(n.column);
    case NaturalNode::Kind::kFixed:
      return n.position0;
    case NaturalNode::Kind::kDriven:
      break;
  }
  return n.position0 + (u.empty() ? 0.0 : u[n.actuator].value) * n.direction;
}

Vec3 naturalNodeVelocity(const NaturalModel& nm, int i, const Eigen::VectorXd& v, const ActuationValues& u)
{
  const NaturalNode& n = nm.nodes[i];
  switch (n.kind)
  {
    case NaturalNode::Kind::kFree:
      return v.segment<3>(n.column);
    case NaturalNode::Kind::kFixed:
      return Vec3::Zero();
    case NaturalNode::Kind::kDriven:
      break;
  }
  return (u.empty() ? 0.0 : u[n.actuator].rate) * n.direction;
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

ContactPairState naturalPairContact(const NaturalModel& nm, int slot, const Vec3 r[4], const Vec3 v[4],
                                    double impact_speed, Vec12* force, Mat12* stiffness, Mat12* damping)
{
  const Model& model = *nm.model;
  const PairConstants pc = pairConstants(nm, slot);
  ContactPairState st;
  st.pair = slot;
  const auto [body_a, body_b] = model.pairBodies(slot);
  st.body_a = body_a;
  st.body_b = body_b;
  if (!stiffness && !damping)
  {
    Vec12 f;
    pairKernel<double>(model, pc, r, v, impact_speed, force != nullptr, f, st);
    if (force)
      *force = f;
    return st;
  }
  using Ad = Eigen::AutoDiffScalar<Eigen::Matrix<double, 24, 1>>;
  V3<Ad> ra[4], va[4];
  for (int i = 0; i < 4; ++i)
    for (int k = 0; k < 3; ++k)
    {
      ra[i](k) = Ad(r[i](k), 24, 3 * i + k);
      va[i](k) = Ad(v[i](k), 24, 12 + 3 * i + k);
    }
  Eigen::Matrix<Ad, 12, 1> f;
  pairKernel<Ad>(model, pc, ra, va, impact_speed, true, f, st);
  for (int i = 0; i < 12; ++i)
  {
    if (force)
      (*force)(i) = f(i).value();
    const Eigen::Matrix<double, 24, 1>& dfi = f(i).derivatives();
    if (stiffness)
      stiffness->row(i) = -dfi.head<12>().transpose();
    if (damping)
      damping->row(i) = -dfi.tail<12>().transpose();
  }
  return st;
}

std::vector<ContactPairState> naturalContacts(const NaturalModel& nm, const NaturalState& s, const ActuationValues& u)
{
  std::vector<ContactPairState> out;
  for (size_t k = 0; k < nm.pair_slots.size(); ++k)
  {
    const std::array<int, 4> nodes = pairNodes(nm, nm.pair_slots[k]);
    Vec3 r[4], v[4];
    for (int i = 0; i < 4; ++i)
    {
      r[i] = naturalNodePosition(nm, nodes[i], s.x, u);
      v[i] = naturalNodeVelocity(nm, nodes[i], s.v, u);
    }
    Vec12 f;
    const ContactPairState st =
        naturalPairContact(nm, nm.pair_slots[k], r, v, s.contact_speed[k], &f, nullptr, nullptr);
    if (st.active)
      out.push_back(st);
  }
  return out;
}

// ---- the solver ----------------------------------------------------------------------------------------

NaturalSolver::NaturalSolver(const NaturalModel& nm, const SolverOptions& options)
  : nm_(nm), model_(*nm.model), options_(options)
{
  if (options.integrator != Integrator::kNewmark)
    throw std::invalid_argument("natural coordinates: only the Newmark family is covered");
  beta_ = options.newmark_beta;
  gamma_ = options.newmark_gamma;
  step_speeds_.assign(nm.pair_slots.size(), model_.contact.min_impact_speed);
  h_next_ = options.dt;
}

void NaturalSolver::forces(const Eigen::VectorXd& x, const Eigen::VectorXd& v, bool tangents)
{
  const int n = nm_.coordinates;
  f_ = nm_.gravity;
  if (tangents)
  {
    k_.setZero(n, n);
    c_.setZero(n, n);
  }
  for (size_t ci = 0; ci < model_.cables.size(); ++ci)
  {
    const Cable& cable = model_.cables[ci];
    const std::vector<int>& nodes = nm_.cable_nodes[ci];
    const int count = static_cast<int>(nodes.size());
    Vec3 p[Cable::kMaxPoints], e[Cable::kMaxPoints];
    double len[Cable::kMaxPoints];
    double l = 0.0, rate = 0.0;
    for (int i = 0; i < count; ++i)
      p[i] = naturalNodePosition(nm_, nodes[i], x, u_);
    for (int i = 0; i + 1 < count; ++i)
    {
      const Vec3 d = p[i + 1] - p[i];
      len[i] = d.norm();
      e[i] = d / len[i];
      l += len[i];
      rate += e[i].dot(naturalNodeVelocity(nm_, nodes[i + 1], v, u_) - naturalNodeVelocity(nm_, nodes[i], v, u_));
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
    {
      const int col = nm_.nodes[nodes[i]].column;
      if (col >= 0)
        f_.segment<3>(col) -= tension * g[i];
    }
    if (!tangents)
      continue;
    const double damping = model_.damping_enabled ? cable.damping : 0.0;
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
        k_.block<3, 3>(ci2, cj).noalias() += cs.stiffness * g[i] * g[j].transpose();
        if (damping > 0.0)
          c_.block<3, 3>(ci2, cj).noalias() += damping * g[i] * g[j].transpose();
      }
    }
    for (int i = 0; i + 1 < count; ++i)
    {
      const Mat3 gs = tension / len[i] * (Mat3::Identity() - e[i] * e[i].transpose());
      const int c0 = nm_.nodes[nodes[i]].column, c1 = nm_.nodes[nodes[i + 1]].column;
      if (c0 >= 0)
        k_.block<3, 3>(c0, c0) += gs;
      if (c1 >= 0)
        k_.block<3, 3>(c1, c1) += gs;
      if (c0 >= 0 && c1 >= 0)
      {
        k_.block<3, 3>(c0, c1) -= gs;
        k_.block<3, 3>(c1, c0) -= gs;
      }
    }
  }
}

void NaturalSolver::contactForces(const Eigen::VectorXd& x, const Eigen::VectorXd& v, bool tangents)
{
  for (const int k : near_)
  {
    const int slot = nm_.pair_slots[k];
    const std::array<int, 4> nodes = pairNodes(nm_, slot);
    Vec3 r[4], rv[4];
    for (int i = 0; i < 4; ++i)
    {
      r[i] = naturalNodePosition(nm_, nodes[i], x, u_);
      rv[i] = naturalNodeVelocity(nm_, nodes[i], v, u_);
    }
    Vec12 f;
    Mat12 kk, cc;
    const ContactPairState st =
        naturalPairContact(nm_, slot, r, rv, step_speeds_[k], &f, tangents ? &kk : nullptr, tangents ? &cc : nullptr);
    if (!(st.normal_force > 0.0))
      continue;
    ++stats_.contact_evaluations;
    for (int i = 0; i < 4; ++i)
    {
      const int ci = nm_.nodes[nodes[i]].column;
      if (ci < 0)
        continue;
      f_.segment<3>(ci) += f.segment<3>(3 * i);
      if (!tangents)
        continue;
      for (int j = 0; j < 4; ++j)
      {
        const int cj = nm_.nodes[nodes[j]].column;
        if (cj < 0)
          continue;
        k_.block<3, 3>(ci, cj) += kk.block<3, 3>(3 * i, 3 * j);
        c_.block<3, 3>(ci, cj) += cc.block<3, 3>(3 * i, 3 * j);
      }
    }
  }
}
}  // namespace active_tensegrity::core

namespace active_tensegrity::core
{
namespace
{
constexpr double kNearFloor = 1e-4;  // m: the least motion the near pairs allow for
constexpr double kSafety = 0.9, kMaxGrowth = 2.0, kMinShrink = 0.1, kKeepBand = 1.2;
}  // namespace

double NaturalSolver::largestMotion(const Eigen::VectorXd& x0, const Eigen::VectorXd& x1) const
{
  double most = 0.0;
  for (int c = 0; c < nm_.coordinates; c += 3)
    most = std::max(most, (x1.segment<3>(c) - x0.segment<3>(c)).norm());
  return most;
}

void NaturalSolver::findNear(const NaturalState& s, double motion)
{
  near_.clear();
  near_motion_ = motion;
  if (nm_.pair_slots.empty())
    return;
  ActuationValues u = u_;  // (u_ holds the step's end; the start's driven nodes move by less than `motion`)
  for (size_t k = 0; k < nm_.pair_slots.size(); ++k)
  {
    const int slot = nm_.pair_slots[k];
    const std::array<int, 4> nodes = pairNodes(nm_, slot);
    Vec3 r[4], v[4];
    for (int i = 0; i < 4; ++i)
    {
      r[i] = naturalNodePosition(nm_, nodes[i], s.x, u);
      v[i] = naturalNodeVelocity(nm_, nodes[i], s.v, u);
    }
    const ContactPairState st = naturalPairContact(nm_, slot, r, v, 0.0, nullptr, nullptr, nullptr);
    if (st.gap > 2.0 * motion)
      continue;
    near_.push_back(static_cast<int>(k));
    const double memory = s.contact_speed[k];
    step_speeds_[k] = memory > 0.0 ? memory : std::max(st.penetration_rate, model_.contact.min_impact_speed);
  }
}

Summary NaturalSolver::initialize(NaturalState& s, const ActuationLaw& law)
{
  Summary out;
  const int n = nm_.coordinates, m = static_cast<int>(nm_.struts.size() + nm_.rows.size());
  law(s.t, u_);
  findNear(s, kNearFloor);
  forces(s.x, s.v, false);
  contactForces(s.x, s.v, false);
  // [M G^T; G 0] [a; lambda] = [F; -2 |u_dot|^2 - 2 u . (driven accelerations)]
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n + m, n + m);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(n + m);
  a.topLeftCorner(n, n) = nm_.mass;
  rhs.head(n) = f_;
  const int struts = static_cast<int>(nm_.struts.size());
  for (int k = struts; k < m; ++k)
  {
    const NaturalRow& row = nm_.rows[k - struts];
    const int col = nm_.nodes[row.node].column;
    a.block<3, 1>(col, n + k) = row.direction;
    a.block<1, 3>(n + k, col) = row.direction.transpose();
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
      {
        a.block<3, 1>(nd.column, n + k) = 2.0 * sign * d;
        a.block<1, 3>(n + k, nd.column) = 2.0 * sign * d.transpose();
      }
      else if (nd.kind == NaturalNode::Kind::kDriven)
        r -= 2.0 * sign * d.dot(u_[nd.actuator].accel * nd.direction);
    }
    rhs(n + k) = r;
  }
  const Eigen::VectorXd z = a.partialPivLu().solve(rhs);
  if (!z.allFinite())
  {
    out.status = SolveStatus::kNonFinite;
    out.message = "natural coordinates: no consistent accelerations at the start";
    return out;
  }
  s.a = z.head(n);
  s.lambda = z.tail(m);
  return out;
}

Summary NaturalSolver::tryStep(NaturalState& s, double h, const ActuationLaw& law)
{
  Summary out;
  const int n = nm_.coordinates, m = static_cast<int>(nm_.struts.size() + nm_.rows.size());
  const double t1 = s.t + h;
  law(t1, u_);
  // the pairs a node can reach in this step (from its speed and acceleration at the start), checked after
  double reach = 0.0;
  for (int c = 0; c < n; c += 3)
    reach = std::max(reach, s.v.segment<3>(c).norm() * h + s.a.segment<3>(c).norm() * h * h);
  for (const NaturalNode& nd : nm_.nodes)
    if (nd.kind == NaturalNode::Kind::kDriven)
      reach = std::max(reach, std::abs(u_[nd.actuator].rate) * h + std::abs(u_[nd.actuator].accel) * h * h);
  findNear(s, std::max(2.0 * reach, kNearFloor));
  const double bh2 = beta_ * h * h, gh = gamma_ * h;
  acc_ = s.a;
  lambda_ = s.lambda;
  residual_.resize(n + m);
  const Eigen::VectorXd x_pred = s.x + h * s.v + h * h * (0.5 - beta_) * s.a;
  const Eigen::VectorXd v_pred = s.v + h * (1.0 - gamma_) * s.a;
  bool rebuild = !have_lu_ || std::abs(h - lu_h_) > 0.25 * lu_h_;
  double last_norm = std::numeric_limits<double>::infinity();
  for (int it = 0; it < options_.max_iterations; ++it)
  {
    x_ = x_pred + bh2 * acc_;
    v_ = v_pred + gh * acc_;
    const bool build = rebuild || it >= 3 || !options_.reuse_jacobian;
    forces(x_, v_, build);
    contactForces(x_, v_, build);
    residual_.head(n).noalias() = nm_.mass * acc_ - f_;
    if (build)
    {
      jac_.setZero(n + m, n + m);
      jac_.topLeftCorner(n, n) = nm_.mass + bh2 * k_ + gh * c_;
    }
    const int struts = static_cast<int>(nm_.struts.size());
    for (int k = struts; k < m; ++k)
    {
      const NaturalRow& row = nm_.rows[k - struts];
      const int col = nm_.nodes[row.node].column;
      residual_(n + k) =
          (row.direction.dot(x_.segment<3>(col)) - row.offset - (row.actuator >= 0 ? u_[row.actuator].value : 0.0)) /
          bh2;
      residual_.segment<3>(col) += lambda_(k) * row.direction;
      if (build)
      {
        jac_.block<3, 1>(col, n + k) = row.direction;
        jac_.block<1, 3>(n + k, col) = row.direction.transpose();
      }
    }
    for (int k = 0; k < struts; ++k)
    {
      const NaturalStrut& st = nm_.struts[k];
      const Vec3 d = naturalNodePosition(nm_, st.b, x_, u_) - naturalNodePosition(nm_, st.a, x_, u_);
      residual_(n + k) = (d.squaredNorm() - st.length * st.length) / bh2;
      const int ca = nm_.nodes[st.a].column, cb = nm_.nodes[st.b].column;
      const double l2 = 2.0 * lambda_(k);
      if (cb >= 0)
        residual_.segment<3>(cb) += l2 * d;
      if (ca >= 0)
        residual_.segment<3>(ca) -= l2 * d;
      if (!build)
        continue;
      if (cb >= 0)
      {
        jac_.block<3, 1>(cb, n + k) = 2.0 * d;
        jac_.block<1, 3>(n + k, cb) = 2.0 * d.transpose();
        jac_.block<3, 3>(cb, cb).diagonal().array() += bh2 * l2;
      }
      if (ca >= 0)
      {
        jac_.block<3, 1>(ca, n + k) = -2.0 * d;
        jac_.block<1, 3>(n + k, ca) = -2.0 * d.transpose();
        jac_.block<3, 3>(ca, ca).diagonal().array() += bh2 * l2;
      }
      if (ca >= 0 && cb >= 0)
      {
        jac_.block<3, 3>(ca, cb).diagonal().array() -= bh2 * l2;
        jac_.block<3, 3>(cb, ca).diagonal().array() -= bh2 * l2;
      }
    }
    if (build)
    {
      lu_.compute(jac_);
      have_lu_ = true;
      lu_h_ = h;
      rebuild = false;
      ++stats_.factorizations;
    }
    correction_ = lu_.solve(-residual_);
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
    if (norm <= options_.newton_tolerance)
    {
      x_ = x_pred + bh2 * acc_;
      // a node went further than the near pairs allow for: again with the pairs it can reach
      if (largestMotion(s.x, x_) > near_motion_)
      {
        findNear(s, 2.0 * largestMotion(s.x, x_));
        continue;
      }
      // the local error and a new contact's depth
      error_ = 0.0;
      const double factor = h * h * (std::abs(beta_ - 1.0 / 6.0) + std::abs(gamma_ - 0.5));
      for (int c = 0; c < n; c += 3)
        error_ = std::max(error_, factor * (acc_.segment<3>(c) - s.a.segment<3>(c)).norm());
      v_ = v_pred + gh * acc_;
      onset_depth_ = 0.0;
      std::vector<double> speeds(nm_.pair_slots.size(), 0.0);
      for (const int k : near_)
      {
        const int slot = nm_.pair_slots[k];
        const std::array<int, 4> nodes = pairNodes(nm_, slot);
        Vec3 r[4], rv[4];
        for (int i = 0; i < 4; ++i)
        {
          r[i] = naturalNodePosition(nm_, nodes[i], x_, u_);
          rv[i] = naturalNodeVelocity(nm_, nodes[i], v_, u_);
        }
        const ContactPairState st = naturalPairContact(nm_, slot, r, rv, 0.0, nullptr, nullptr, nullptr);
        if (st.gap >= 0.0)
          continue;
        speeds[k] = step_speeds_[k];
        if (s.contact_speed[k] > 0.0 || -st.gap <= onset_depth_)
          continue;
        onset_depth_ = -st.gap;
      }
      s.x = x_;
      s.v = v_;
      s.a = acc_;
      s.lambda = lambda_;
      s.t = t1;
      s.contact_speed = std::move(speeds);
      ++stats_.steps;
      return out;
    }
    // slow convergence on an old matrix: a new one
    if (norm > 0.5 * last_norm)
      rebuild = true;
    last_norm = norm;
  }
  out.status = SolveStatus::kMaxIterations;
  out.message = "natural coordinates: Newton did not converge";
  have_lu_ = false;
  return out;
}

Summary NaturalSolver::stepOnce(NaturalState& s, double h, const ActuationLaw& law, int depth)
{
  Summary r = tryStep(s, h, law);
  if (r.ok() || depth >= options_.max_step_cuts)
    return r;
  ++stats_.rejected_solver;
  Summary half = stepOnce(s, 0.5 * h, law, depth + 1);
  half.step_cuts += 1;
  if (!half.ok())
    return half;
  Summary second = stepOnce(s, 0.5 * h, law, depth + 1);
  second.iterations += half.iterations + r.iterations;
  second.step_cuts += half.step_cuts;
  return second;
}

Summary NaturalSolver::advanceTo(NaturalState& s, double t_end, const ActuationLaw& law,
                                 const std::function<void(const NaturalState&)>& on_step)
{
  Summary total;
  const double eps = 1e-12 * std::max(1.0, std::abs(t_end));
  while (t_end - s.t > eps)
  {
    const double remaining = t_end - s.t;
    if (!options_.adaptive)
    {
      const double h = remaining <= 1.05 * options_.dt ? remaining : options_.dt;
      const double t1 = s.t + h;
      const Summary r = stepOnce(s, h, law, 0);
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
    double h = std::min(h_next_, options_.dt_max);
    bool clipped = false;
    if (remaining <= 1.05 * h)
    {
      clipped = remaining < h;
      h = remaining;
    }
    else if (remaining < 2.0 * h)
    {
      h = 0.5 * remaining;
      clipped = true;
    }
    const bool at_min = h <= options_.dt_min * (1.0 + 1e-9);
    NaturalState trial = s;
    const Summary r = tryStep(trial, h, law);
    total.iterations += r.iterations;
    if (!r.ok())
    {
      ++stats_.rejected_solver;
      ++total.step_cuts;
      if (at_min)
      {
        total.status = r.status;
        total.message = r.message;
        return total;
      }
      h_next_ = std::max(options_.dt_min, 0.5 * h);
      continue;
    }
    const double err = error_ / options_.error_tolerance;
    if (!at_min && onset_depth_ > options_.onset_depth)
    {
      // aim at half the allowed depth from the pair's gap at the start
      double gap_start = 0.0;
      for (const int k : near_)
        if (trial.contact_speed[k] > 0.0 && !(s.contact_speed[k] > 0.0))
        {
          const std::array<int, 4> nodes = pairNodes(nm_, nm_.pair_slots[k]);
          Vec3 r0[4], v0[4];
          ActuationValues u0;
          law(s.t, u0);
          for (int i = 0; i < 4; ++i)
          {
            r0[i] = naturalNodePosition(nm_, nodes[i], s.x, u0);
            v0[i] = Vec3::Zero();
          }
          gap_start = std::max(gap_start,
                               naturalPairContact(nm_, nm_.pair_slots[k], r0, v0, 0.0, nullptr, nullptr, nullptr).gap);
        }
      ++stats_.rejected_onset;
      const double fraction = (gap_start + 0.5 * options_.onset_depth) / (gap_start + onset_depth_);
      h_next_ = std::max(options_.dt_min, h * std::clamp(fraction, 0.02, 0.9));
      continue;
    }
    if (!at_min && err > 1.0)
    {
      ++stats_.rejected_error;
      h_next_ = std::max(options_.dt_min, h * std::clamp(kSafety * std::cbrt(1.0 / err), kMinShrink, kSafety));
      continue;
    }
    s = std::move(trial);
    if (on_step)
      on_step(s);
    double ratio = std::clamp(kSafety * std::cbrt(1.0 / std::max(err, 1e-12)), kMinShrink, kMaxGrowth);
    if (ratio >= 1.0 && ratio <= kKeepBand)
      ratio = 1.0;
    const double proposal = std::clamp(h * ratio, options_.dt_min, options_.dt_max);
    if (!clipped || proposal < h)
      h_next_ = proposal;
  }
  s.t = t_end;
  return total;
}

}  // namespace active_tensegrity::core
