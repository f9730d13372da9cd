#include "active_tensegrity/core/outputs/observables.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>

#include "active_tensegrity/core/base/geometry.h"
#include "active_tensegrity/core/contact/broad_phase.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/contact/contact_search.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/solvers/dynamics.h"

namespace active_tensegrity::core
{
double actuationForce(const Model& model, const State& state, int actuator)
{
  if (state.natural.x.size() > 0)
  {
    // (a dynamics state: its forces are what DynamicsSolver::formActuatorForces formed)
    if (state.natural.actuator_force.size() != model.actuators.size())
      throw std::logic_error("actuationForce: the dynamics state at t = " + std::to_string(state.t) +
                             " s has no actuator forces formed (DynamicsSolver::formActuatorForces)");
    return state.natural.actuator_force[static_cast<size_t>(actuator)];
  }
  // (a state without natural coordinates has no multipliers: a driven node's reaction is not known, its cables are)
  double force = 0.0;
  for (int c : model.actuators[actuator].cables)
    force += evaluateCable(model, model.cables[c], state.q, state.qd, state.u, model.damping_enabled).tension;
  return force;
}

double nodesHeight(const Model& model, const std::vector<int>& nodes, const Eigen::VectorXd& q)
{
  double top = -std::numeric_limits<double>::infinity();
  for (int n : nodes)
    top = std::max(top, pointPosition(model, model.nodes[n].point, q).z());
  return top - model.ground_level;
}

double structureHeight(const Model& model, const Eigen::VectorXd& q)
{
  return nodesHeight(model, model.height_nodes, q);
}

double maxStrutBendingStress(const Model& model, const Eigen::VectorXd& q, const std::vector<ContactPairState>& contacts)
{
  // loads on struts: (strut, position along the axis from the lower end, force across the axis), grouped by
  // strut (a per-thread buffer: this runs at every step of a run's peak tracking)
  struct Load
  {
    int body;
    int order;  // its place in the contact list (the sort keeps it within a strut)
    double s;
    Vec3 f;
  };
  thread_local std::vector<Load> loads;
  loads.clear();
  for (const ContactPairState& c : contacts)
  {
    const int bodies[2] = { c.body_a, c.body_b };
    const Vec3 points[2] = { c.point_a, c.point_b };
    for (int k = 0; k < 2; ++k)
    {
      if (bodies[k] < 0 || model.bodies[bodies[k]].kind != BodyKind::kStrut)
        continue;  // the ground, a point mass
      const Body& b = model.bodies[bodies[k]];
      const Vec3 axis = bodyZAxis(q.segment<4>(b.offset + 3));
      const double s = std::clamp(axis.dot(points[k] - q.segment<3>(b.offset)) + 0.5 * b.length, 0.0, b.length);
      const Vec3 f = k == 0 ? c.force_on_a : Vec3(-c.force_on_a);
      loads.push_back({ bodies[k], static_cast<int>(loads.size()), s, f - axis * axis.dot(f) });
    }
  }
  // (std::stable_sort took a heap buffer at every call)
  std::sort(loads.begin(), loads.end(),
            [](const Load& x, const Load& y) { return x.body < y.body || (x.body == y.body && x.order < y.order); });
  double sigma = 0.0;
  for (size_t first = 0, last = 0; first < loads.size(); first = last)
  {
    while (last < loads.size() && loads[last].body == loads[first].body)
      ++last;
    const Body& b = model.bodies[loads[first].body];
    const double len = b.length;
    Vec3 reaction = Vec3::Zero();  // at the lower end
    for (size_t i = first; i < last; ++i)
      reaction += loads[i].f * (len - loads[i].s) / len;
    // the moment is piecewise linear: its largest magnitude is at a load point (compared squared, one square root
    // and division per strut: the same number, as the square root is monotonic)
    double largest = 0.0;
    for (size_t j = first; j < last; ++j)
    {
      const double x = loads[j].s;
      Vec3 moment = reaction * x;
      for (size_t i = first; i < last; ++i)
        if (loads[i].s < x)
          moment -= loads[i].f * (x - loads[i].s);
      largest = std::max(largest, moment.squaredNorm());
    }
    const double r = b.layers.front().outer_radius;
    sigma = std::max(sigma, 4.0 * std::sqrt(largest) / (M_PI * r * r * r));
  }
  return sigma;
}

std::vector<CableState> cableStates(const Model& model, const State& state)
{
  std::vector<CableState> out;
  out.reserve(model.cables.size());
  for (const Cable& c : model.cables)
    out.push_back(evaluateCable(model, c, state.q, state.qd, state.u, model.damping_enabled));
  return out;
}

double maxCableStress(const Model& model, const State& state)
{
  return CableStressScan(model).largest(state);
}

CableStressScan::CableStressScan(const Model& model) : model_(model)
{
  for (size_t c = 0; c < model.cables.size(); ++c)
  {
    if (!(model.cables[c].area > 0.0))
      continue;
    cables_.push_back(static_cast<int>(c));
    first_.push_back(static_cast<int>(slots_.size()));
    for (const PointRef& p : model.cables[c].points)
      slots_.push_back(pointSlot(model, p));
  }
}

double CableStressScan::largest(const State& state)
{
  frames_.update(model_, state.q, state.qd);
  double sigma = 0.0;
  for (size_t k = 0; k < cables_.size(); ++k)
  {
    const Cable& c = model_.cables[cables_[k]];
    const CableState s =
        evaluateCable(c, slots_.data() + first_[k], frames_, state.q, state.qd, state.u, model_.damping_enabled);
    sigma = std::max(sigma, s.tension / c.area);
  }
  return sigma;
}

double minimumGroundGap(const Model& model, const Eigen::VectorXd& q)
{
  double gap = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < model.ground_contacts.size(); ++i)
    gap = std::min(gap, contactGeometry(model, model.pairSlots() + static_cast<int>(i), q).gap);
  return gap;
}

double minimumGap(const Model& model, const Eigen::VectorXd& q)
{
  // (a scene of up to about 90 struts: every pair, no broad phase to build)
  constexpr int kDirectMostSlots = 4096;
  if (model.pairSlots() > kDirectMostSlots)
    return minimumGapNear(model, BroadPhase(model), q);
  double gap = std::numeric_limits<double>::infinity();
  for (int i = 0; i < model.pairSlots(); ++i)
    if (model.isCheckedPair(i))
      gap = std::min(gap, contactGeometry(model, i, q).gap);
  return gap;
}

double minimumGapNear(const Model& model, const BroadPhase& broad, const Eigen::VectorXd& q)
{
  if (model.checkedPairCount() == 0)
    return std::numeric_limits<double>::infinity();
  if (!q.allFinite())
    return std::numeric_limits<double>::quiet_NaN();
  double margin = 0.0;  // the struts' mean radius to start with
  for (int b : model.all_strut_pairs ? model.pair_struts : std::vector<int>{})
    margin += model.bodies[b].radius() / static_cast<double>(model.pair_struts.size());
  if (!(margin > 0.0))
    margin = 1e-3;
  std::vector<int> near;
  for (;;)
  {
    broad.candidates(q, margin, near);
    double gap = std::numeric_limits<double>::infinity();
    for (int i : near)
      gap = std::min(gap, contactGeometry(model, i, q).gap);
    // every pair left out is more than 2 margin apart; all pairs in: the minimum of them all
    if (gap <= 2.0 * margin || static_cast<long>(near.size()) == model.checkedPairCount())
      return gap;
    margin *= 4.0;
  }
}

namespace
{
/// Calls visit(gap) for every checked pair of a cable segment and a strut whose boxes overlap, the strut's grown
/// by the mean strut length (`grown`; the minimum's search) or by nothing (the crossings': a segment that runs
/// through a strut meets its box).
void forEachCableStrutGap(const Model& model, const Eigen::VectorXd& q, bool grown,
                          const std::function<void(const CableStrutGap&)>& visit)
{
  struct Box
  {
    int strut;
    Vec3 a, b;    // axis ends
    Vec3 lo, hi;  // the capsule's box, grown by the margin
  };
  // (kept from call to call: the run checks the crossings at every output, with no allocation once it has its size;
  // the visitors do not call back in here)
  thread_local std::vector<Box> boxes;
  boxes.clear();
  double length_sum = 0.0, widest = 0.0;
  int struts = 0;
  for (const Body& b : model.bodies)
    if (b.kind == BodyKind::kStrut)
    {
      length_sum += b.length;
      ++struts;
    }
  if (struts == 0 || model.cables.empty())
    return;
  const double margin = grown ? length_sum / struts : 0.0;
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const Body& b = model.bodies[i];
    if (b.kind != BodyKind::kStrut)
      continue;
    Box box;
    box.strut = static_cast<int>(i);
    box.a = pointPosition(model, PointRef{ box.strut, Vec3(0.0, 0.0, -0.5 * b.length) }, q);
    box.b = pointPosition(model, PointRef{ box.strut, Vec3(0.0, 0.0, 0.5 * b.length) }, q);
    const Vec3 grow = Vec3::Constant(b.radius() + margin);
    box.lo = box.a.cwiseMin(box.b) - grow;
    box.hi = box.a.cwiseMax(box.b) + grow;
    widest = std::max(widest, box.hi.x() - box.lo.x());
    boxes.push_back(box);
  }
  std::sort(boxes.begin(), boxes.end(), [](const Box& x, const Box& y) { return x.lo.x() < y.lo.x(); });
  for (size_t c = 0; c < model.cables.size(); ++c)
  {
    const Cable& cable = model.cables[c];
    Vec3 p = pointPosition(model, cable.points[0], q);
    for (size_t k = 0; k + 1 < cable.points.size(); ++k)
    {
      const Vec3 next = pointPosition(model, cable.points[k + 1], q);
      const Vec3 lo = p.cwiseMin(next), hi = p.cwiseMax(next);
      // boxes whose lower x lies in [lo.x - widest, hi.x] can overlap the segment's
      auto it = std::lower_bound(boxes.begin(), boxes.end(), lo.x() - widest,
                                 [](const Box& b, double x) { return b.lo.x() < x; });
      for (; it != boxes.end() && it->lo.x() <= hi.x(); ++it)
      {
        if ((it->hi.array() < lo.array()).any() || (it->lo.array() > hi.array()).any())
          continue;
        const auto meets = [&](size_t point)
        {
          if (point < cable.point_struts.size())
            return std::find(cable.point_struts[point].begin(), cable.point_struts[point].end(), it->strut) !=
                   cable.point_struts[point].end();
          return cable.points[point].body == it->strut;
        };
        if (meets(k) || meets(k + 1))
          continue;
        visit({ closestPointsSegments(p, next, it->a, it->b).distance - model.bodies[it->strut].radius(),
                static_cast<int>(c), static_cast<int>(k), it->strut });
      }
      p = next;
    }
  }
}
}  // namespace

CableStrutGap minimumCableStrutGap(const Model& model, const Eigen::VectorXd& q)
{
  CableStrutGap best;
  forEachCableStrutGap(model, q, true,
                       [&](const CableStrutGap& g)
                       {
                         if (g.gap < best.gap)
                           best = g;
                       });
  return best;
}

std::vector<CableStrutGap> cableStrutCrossings(const Model& model, const Eigen::VectorXd& q)
{
  std::vector<CableStrutGap> out;
  forEachCableStrutGap(model, q, false,
                       [&](const CableStrutGap& g)
                       {
                         if (!(g.gap < 0.0))
                           return;
                         for (CableStrutGap& o : out)
                           if (o.cable == g.cable && o.strut == g.strut)
                           {
                             if (g.gap < o.gap)
                               o = g;
                             return;
                           }
                         out.push_back(g);
                       });
  return out;
}

namespace
{
/// Appends the states of the listed slots that touch in `state`, evaluated as the analysis does (with the
/// state's impact speeds in dynamics).
void appendActiveContacts(const Model& model, const std::vector<int>& slots, const State& state,
                          std::vector<ContactPairState>& out)
{
  const ContactMode mode = model.analysis.type == AnalysisType::kStatic ? ContactMode::kStatic : ContactMode::kDynamic;
  for (int i : slots)
  {
    const double v0 = state.contactSpeed(i);
    const ContactPairState st = evaluateContact(model, i, state.q, state.qd, v0, mode);
    if (st.active)
      out.push_back(st);
  }
}
}  // namespace

std::vector<ContactPairState> activeContacts(const Model& model, const State& state)
{
  std::vector<ContactPairState> out;
  if (!model.anyContact())
    return out;
  if (state.natural.x.size() > 0)
    return state.natural.contacts;  // (the dynamics solver's, as its step formed them)
  std::vector<int> candidates;
  contactCandidates(model, BroadPhase(model), state.q, 0.0, candidates);
  appendActiveContacts(model, candidates, state, out);
  return out;
}

int slackCables(const Model& model, const State& state)
{
  int n = 0;
  for (const CableState& c : cableStates(model, state))
    n += c.slack ? 1 : 0;
  return n;
}

std::vector<double> strutAxialForces(const Model& model, const State& state, std::vector<double>* end_imbalance)
{
  const size_t n_bodies = model.bodies.size();
  std::vector<double> force(n_bodies, 0.0), net(n_bodies, 0.0);
  if (state.natural.x.size() > 0)
  {
    // the dynamics' natural coordinates: the strut's length row carries its axial force, 2 L lambda, and nothing else
    // acts along it at its ends
    Eigen::Index k = 0;
    for (size_t b = 0; b < n_bodies; ++b)
      if (model.bodies[b].kind == BodyKind::kStrut && k < state.natural.lambda.size())
        force[b] = 2.0 * model.bodies[b].length * state.natural.lambda(k++);
    if (end_imbalance)
      *end_imbalance = net;
    return force;
  }
  std::vector<Vec3> axis(n_bodies, Vec3::Zero());
  for (size_t b = 0; b < n_bodies; ++b)
    if (model.bodies[b].kind == BodyKind::kStrut)
    {
      const double half = 0.5 * model.bodies[b].length;
      const int body = static_cast<int>(b);
      axis[b] = (pointPosition(model, { body, Vec3(0.0, 0.0, half) }, state.q) -
                 pointPosition(model, { body, Vec3(0.0, 0.0, -half) }, state.q))
                    .normalized();
    }
  // +1: the top end (local +z), -1: the bottom end, 0: not a strut end
  const auto end = [&](const PointRef& p)
  {
    if (p.body < 0 || model.bodies[p.body].kind != BodyKind::kStrut)
      return 0;
    const double half = 0.5 * model.bodies[p.body].length;
    if (p.local.head<2>().norm() > 1e-9 * half)
      return 0;
    return std::abs(p.local.z() - half) <= 1e-9 * half ? 1 : std::abs(p.local.z() + half) <= 1e-9 * half ? -1 : 0;
  };
  // half of (F_top - F_bottom) . u, and (F_top + F_bottom) . u
  const auto add = [&](const PointRef& p, const Vec3& f)
  {
    if (const int e = end(p))
    {
      force[p.body] += 0.5 * e * f.dot(axis[p.body]);
      net[p.body] += f.dot(axis[p.body]);
    }
  };
  const std::vector<CableState> cables = cableStates(model, state);
  for (size_t c = 0; c < model.cables.size(); ++c)
  {
    const std::vector<PointRef>& pts = model.cables[c].points;
    if (cables[c].tension == 0.0)
      continue;
    for (size_t k = 0; k + 1 < pts.size(); ++k)
    {
      const Vec3 d = pointPosition(model, pts[k + 1], state.q) - pointPosition(model, pts[k], state.q);
      const double l = d.norm();
      if (!(l > 0.0))
        continue;
      const Vec3 f = cables[c].tension * d / l;  // pulls point k towards k + 1 and k + 1 back
      add(pts[k], f);
      add(pts[k + 1], -f);
    }
  }
  const double factor = loadFactor(model, state);
  for (const PointLoad& l : model.loads)
    add(l.point, factor * l.force);
  if (end_imbalance)
    *end_imbalance = net;
  return force;
}

double loadFactor(const Model& model, const State& state)
{
  const AnalysisSettings& an = model.analysis;
  if (an.type != AnalysisType::kStatic)
    return 1.0;
  return an.load_factor_start + state.t * (an.load_factor_end - an.load_factor_start);
}

ContactScan::ContactScan(const Model& model) : model_(model), broad_(model)
{
  double smallest = std::numeric_limits<double>::infinity();
  for (const Body& b : model.bodies)
    if (b.kind == BodyKind::kStrut)
      smallest = std::min(smallest, b.radius());
  for (const GroundContact& g : model.ground_contacts)
    smallest = std::min(smallest, g.radius);
  reach_ = std::isfinite(smallest) && smallest > 0.0 ? 0.1 * smallest : 1e-4;
}

const std::vector<ContactPairState>& ContactScan::active(const State& state)
{
  contacts_.clear();
  if (!model_.anyContact())
    return contacts_;
  if (state.natural.x.size() > 0)
  {
    contacts_ = state.natural.contacts;  // (the dynamics solver's, as its step formed them)
    return contacts_;
  }
  const bool near_reference = have_reference_ && reference_q_.size() == state.q.size() &&
                              largestMotion(model_, reference_q_, state.q) <= reach_;
  if (!near_reference)
  {
    reference_q_ = state.q;
    have_reference_ = true;
    nearContactSlots(model_, broad_, state.q, reach_, candidates_, near_);
  }
  appendActiveContacts(model_, near_, state, contacts_);
  return contacts_;
}

}  // namespace active_tensegrity::core
