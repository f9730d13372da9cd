#include "active_tensegrity/core/analysis.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "active_tensegrity/core/adaptive.h"
#include "active_tensegrity/core/dynamics.h"
#include "active_tensegrity/core/broad_phase.h"
#include "active_tensegrity/core/contact.h"
#include "active_tensegrity/core/contact_search.h"
#include "active_tensegrity/core/geometry.h"
#include "active_tensegrity/core/kinematics.h"
#include "active_tensegrity/core/statics.h"
#include "active_tensegrity/core/structure_check.h"
#include "active_tensegrity/core/text.h"

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
  double force = 0.0;
  for (int c : model.actuators[actuator].constraints)
  {
    int row = 0;  // (a few constraints per actuator: summed here rather than kept in a table)
    for (int i = 0; i < c; ++i)
      row += model.constraints[i].rows();
    force -= state.lambda(row);
  }
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

namespace
{
/// Calls f(ramp, from, to) for each ramp of actuator a in the sequence, in time order.
template <class F>
void forEachRamp(const AnalysisSettings& an, int a, F&& f)
{
  double value = 0.0;
  for (const ActuationStep& step : an.sequence)
    for (size_t k = 0; k < step.actuators.size(); ++k)
      if (step.actuators[k] == a)
      {
        f(an.schedule.startingAt(step.time, std::abs(step.targets[k] - value)), value, step.targets[k]);
        value = step.targets[k];
      }
}
}  // namespace

ActuationValues scheduledActuation(const Model& model, double t)
{
  ActuationValues out;
  scheduledActuation(model, t, out);
  return out;
}

void scheduledActuation(const Model& model, double t, ActuationValues& out)
{
  const AnalysisSettings& an = model.analysis;
  if (an.sequence.empty())
  {
    out.assign(model.actuators.size(), an.schedule.evaluate(t));
    return;
  }
  out.assign(model.actuators.size(), ActuationValue{});
  for (size_t a = 0; a < model.actuators.size(); ++a)
    forEachRamp(an, static_cast<int>(a),
                [&](const RampSchedule& r, double from, double to)
                {
                  if (t < r.start_time)
                    return;
                  const ActuationValue v = r.evaluate(t);
                  const double sign = to >= from ? 1.0 : -1.0;
                  out[a] = ActuationValue{ from + sign * v.value, sign * v.rate, sign * v.accel };
                });
}

double actuationEndTime(const Model& model)
{
  const AnalysisSettings& an = model.analysis;
  if (an.sequence.empty())
    return an.schedule.endTime();
  double end = 0.0;
  for (size_t a = 0; a < model.actuators.size(); ++a)
    forEachRamp(an, static_cast<int>(a),
                [&](const RampSchedule& r, double, double) { end = std::max(end, r.endTime()); });
  return end;
}

std::vector<double> actuationBreakpoints(const Model& model)
{
  const AnalysisSettings& an = model.analysis;
  if (an.sequence.empty())
    return an.schedule.breakpoints();
  std::vector<double> out;
  for (size_t a = 0; a < model.actuators.size(); ++a)
    forEachRamp(an, static_cast<int>(a),
                [&](const RampSchedule& r, double, double)
                {
                  const std::vector<double> b = r.breakpoints();
                  out.insert(out.end(), b.begin(), b.end());
                });
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
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

bool hasLoadPath(const Model& model)
{
  return model.analysis.type == AnalysisType::kStatic &&
         model.analysis.load_factor_start != model.analysis.load_factor_end;
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
  Eigen::Index row = 0;
  for (const Constraint& c : model.constraints)
  {
    const Eigen::Index rows = c.rows();
    if (c.kind == Constraint::Kind::kPoints && row + rows <= state.lambda.size())
    {
      Vec3 w = Vec3::Zero();
      for (Eigen::Index k = 0; k < rows; ++k)
        w += state.lambda[row + k] * c.directions[static_cast<size_t>(k)];
      add(c.a, -w);
      add(c.b, w);
    }
    row += rows;
  }
  const double factor = loadFactor(model, state);
  for (const PointLoad& l : model.loads)
    add(l.point, factor * l.force);
  if (end_imbalance)
    *end_imbalance = net;
  return force;
}

std::vector<std::string> memberColumns(const Model& model)
{
  std::vector<std::string> cols = { "t" };
  for (const Cable& c : model.cables)
    for (const char* what : { "_tension", "_length", "_rest_length" })
      cols.push_back(c.name + what);
  for (const Body& b : model.bodies)
    if (b.kind == BodyKind::kStrut)
      cols.push_back(b.name + "_force");
  return cols;
}

std::vector<double> memberRow(const Model& model, const State& state)
{
  std::vector<double> row = { state.t };
  for (const CableState& c : cableStates(model, state))
  {
    row.push_back(c.tension);
    row.push_back(c.length);
    row.push_back(c.rest_length);
  }
  const std::vector<double> axial = strutAxialForces(model, state);
  for (size_t b = 0; b < model.bodies.size(); ++b)
    if (model.bodies[b].kind == BodyKind::kStrut)
      row.push_back(axial[b]);
  return row;
}

double loadFactor(const Model& model, const State& state)
{
  const AnalysisSettings& an = model.analysis;
  if (an.type != AnalysisType::kStatic)
    return 1.0;
  return an.load_factor_start + state.t * (an.load_factor_end - an.load_factor_start);
}

std::vector<std::string> csvColumns(const Model& model)
{
  std::vector<std::string> cols = { "t",
                                    "actuation",
                                    "actuation_force",
                                    "height",
                                    "active_contacts",
                                    "min_gap",
                                    "max_normal_force",
                                    "max_friction_force",
                                    "slack_cables",
                                    "max_strut_bending_stress",
                                    "max_cable_stress",
                                    "min_cable_strut_gap" };
  if (model.ground.enabled)
    for (const char* name : { "ground_contacts", "min_ground_gap", "ground_normal_force", "max_ground_friction_force" })
      cols.push_back(name);
  if (hasLoadPath(model))
    cols.push_back("load_factor");
  for (const OutputLayer& layer : model.layers)
    cols.push_back("height_" + layer.name);
  if (model.actuators.size() > 1)
    for (const Actuator& a : model.actuators)
    {
      cols.push_back("actuation_" + a.name);
      cols.push_back("actuation_force_" + a.name);
    }
  return cols;
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

PeakTracker::PeakTracker(const Model& model) : model_(model), contacts_(model), cable_stress_(model)
{
  for (const char* name :
       { "actuation_force", "max_normal_force", "max_friction_force", "max_strut_bending_stress", "max_cable_stress" })
    peaks_.push_back({ name, 0.0, 0.0 });
}

void PeakTracker::add(const State& state, const std::vector<ContactPairState>* given)
{
  // the five columns as csvRow computes them, and nothing else of the row (this runs at every step)
  double max_normal = 0.0, max_friction = 0.0;
  const std::vector<ContactPairState>& contacts = given ? *given : contacts_.active(state);
  for (const ContactPairState& c : contacts)
    if (c.body_b >= 0)
    {
      max_normal = std::max(max_normal, c.normal_force);
      max_friction = std::max(max_friction, c.friction_force);
    }
  const double values[] = { model_.actuators.empty() ? 0.0 : actuationForce(model_, state, 0), max_normal, max_friction,
                            maxStrutBendingStress(model_, state.q, contacts), cable_stress_.largest(state) };
  for (size_t k = 0; k < peaks_.size(); ++k)
    if (std::abs(values[k]) > std::abs(peaks_[k].value))
    {
      peaks_[k].value = values[k];
      peaks_[k].t = state.t;
    }
}

std::vector<double> csvRow(const Model& model, const State& state)
{
  const bool any = !model.actuators.empty();
  double max_normal = 0.0, max_friction = 0.0, ground_normal = 0.0, ground_friction = 0.0;
  int strut_contacts = 0, ground_contacts = 0;
  const std::vector<ContactPairState> contacts = activeContacts(model, state);
  for (const ContactPairState& c : contacts)
    if (c.body_b < 0)
    {
      ++ground_contacts;
      ground_normal += c.normal_force;
      ground_friction = std::max(ground_friction, c.friction_force);
    }
    else
    {
      ++strut_contacts;
      max_normal = std::max(max_normal, c.normal_force);
      max_friction = std::max(max_friction, c.friction_force);
    }
  std::vector<double> row = { state.t,
                              any ? state.u[0].value : 0.0,
                              any ? actuationForce(model, state, 0) : 0.0,
                              structureHeight(model, state.q),
                              static_cast<double>(strut_contacts),
                              minimumGap(model, state.q),
                              max_normal,
                              max_friction,
                              static_cast<double>(slackCables(model, state)),
                              maxStrutBendingStress(model, state.q, contacts),
                              maxCableStress(model, state),
                              minimumCableStrutGap(model, state.q).gap };
  if (model.ground.enabled)
    row.insert(row.end(), { static_cast<double>(ground_contacts), minimumGroundGap(model, state.q), ground_normal,
                            ground_friction });
  if (hasLoadPath(model))
    row.push_back(loadFactor(model, state));
  for (const OutputLayer& layer : model.layers)
    row.push_back(nodesHeight(model, layer.nodes, state.q));
  if (model.actuators.size() > 1)
    for (size_t i = 0; i < model.actuators.size(); ++i)
    {
      row.push_back(state.u[i].value);
      row.push_back(actuationForce(model, state, static_cast<int>(i)));
    }
  return row;
}

std::vector<std::pair<std::string, double>> timeBreakdown(const RunResult& result)
{
  const StepTimings& t = result.timings;
  const double parts = t.forces + t.contact + t.constraints + t.factorization + t.solve;
  return { { "forces", t.forces },
           { "contact", t.contact },
           { "constraints", t.constraints },
           { "factorization", t.factorization },
           { "solve", t.solve },
           { "solver_other", std::max(0.0, t.total - parts) },
           { "callbacks", result.callback_time },
           { "rest", std::max(0.0, result.wall_time - t.total - result.callback_time) } };
}

namespace
{
/// The dynamic loop with solver.adaptive: steps to every output time and every actuation breakpoint.
void runAdaptive(const Model& model, DynamicsSolver& solver, const ActuationLaw& law, State& state, RunResult& result,
                 const std::function<void(const State&)>& on_output, const std::function<void(double)>& on_progress,
                 const std::function<void(const State&)>& after_step, bool wants_steps)
{
  const AnalysisSettings& an = model.analysis;
  const double eps = 1e-12 * std::max(1.0, an.duration);
  const double interval = an.output_interval;  // 0 or at least dt_min (the loader sees to it)
  // no step is shorter than dt_min: a breakpoint closer than that to an output time, the end or the
  // breakpoint before is left to the step that lands there (the actuation law is evaluated exactly anyway)
  const double gap = model.solver.dt_min;
  std::vector<double> stops;
  for (double t : actuationBreakpoints(model))
  {
    const double to_output = interval > 0.0 ? std::abs(t - interval * std::round(t / interval)) : gap;
    if (t >= gap && t <= an.duration - gap && to_output >= gap && (stops.empty() || t - stops.back() >= gap))
      stops.push_back(t);
  }
  const int every = interval > 0.0 ? 0 : 1;  // no output interval: a row per accepted step
  // an output time closer than dt_min to the end is the end's
  const auto output_after = [&](double t) { return t > an.duration - gap ? an.duration : t; };
  double next_output = interval > 0.0 ? output_after(std::min(interval, an.duration)) : an.duration;
  size_t next_stop = 0;
  AdaptiveStepper stepper(solver, model.solver);
  long accepted = 0;
  const auto timed = [&](const auto& f)
  {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    result.callback_time += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  // (a std::function made once: advanceTo takes one, and a lambda of this size converted at each call allocates)
  double last_t = state.t;
  const std::function<void(const State&)> each_step = [&](const State& s)
  {
    // (the body poses and the actuators' forces for whoever reads this step: the caller's on_step, the yield watch or a
    // row)
    const bool row = every && s.t < an.duration - eps;
    if (wants_steps || row)
      solver.writePoses(state);  // (s is state)
    if (!model.actuators.empty() && (wants_steps || row))
      solver.formActuatorForces(state);
    result.energy.add(stepper.lastEnergy(), s.t - last_t, s.t, stepper.lastEnergyCheck());
    last_t = s.t;
    timed(
        [&]()
        {
          after_step(s);
          if (every && s.t < an.duration - eps)
          {
            on_output(s);
            ++result.steps;
          }
        });
    if (on_progress && ++accepted % 256 == 0)
      on_progress(s.t / an.duration);
  };
  while (state.t < an.duration - eps)
  {
    double stop = std::min(next_output, an.duration);
    if (next_stop < stops.size())
      stop = std::min(stop, stops[next_stop]);
    const Summary s = stepper.advanceTo(state, stop, law, each_step);
    result.summary.iterations += s.iterations;
    result.summary.step_cuts += s.step_cuts;
    result.summary.crossings_refused += s.crossings_refused;
    result.summary.residual = s.residual;
    if (!s.ok())
    {
      result.summary.status = s.status;
      result.summary.message = s.message;
      break;
    }
    if (next_stop < stops.size() && stop >= stops[next_stop] - eps)
      ++next_stop;
    if (stop >= next_output - eps || stop >= an.duration - eps)
    {
      solver.writePoses(state);
      if (!model.actuators.empty())
        solver.formActuatorForces(state);
      timed([&]() { on_output(state); });
      ++result.steps;
      next_output = output_after(next_output + (interval > 0.0 ? interval : an.duration));
    }
  }
  result.adaptive = stepper.stats();
  result.solver_steps = static_cast<int>(stepper.stats().accepted);
}
/// Both runAnalysis: `contacts_wanted` says whether on_step reads the step's contacts (the dynamics solver forms
/// their forces for it alone; the state-only callback never sees them).
RunResult run(const Model& model, const std::function<void(const State&)>& user_output,
              const std::function<void(double)>& on_progress, const StepCallback& on_step, bool contacts_wanted);
}  // namespace

RunResult runAnalysis(const Model& model, const std::function<void(const State&)>& on_output,
                      const std::function<void(double)>& on_progress, const std::function<void(const State&)>& on_step)
{
  StepCallback each;
  if (on_step)
    each = [&on_step](const State& s, const std::vector<ContactPairState>*) { on_step(s); };
  return run(model, on_output, on_progress, each, false);
}

RunResult runAnalysis(const Model& model, const std::function<void(const State&)>& on_output,
                      const std::function<void(double)>& on_progress, const StepCallback& on_step)
{
  return run(model, on_output, on_progress, on_step, static_cast<bool>(on_step));
}

namespace
{
RunResult run(const Model& model, const std::function<void(const State&)>& user_output,
              const std::function<void(double)>& on_progress, const StepCallback& on_step, bool contacts_wanted)
{
  // cables that run through a strut, at the output steps: once per cable and strut, at most kMaxCrossingWarnings
  constexpr size_t kMaxCrossingWarnings = 20;
  std::vector<std::pair<int, int>> crossed;
  std::vector<std::string> crossing_warnings;
  const std::function<void(const State&)> on_output = [&](const State& s)
  {
    for (const CableStrutGap& g : cableStrutCrossings(model, s.q))
    {
      if (std::find(crossed.begin(), crossed.end(), std::make_pair(g.cable, g.strut)) != crossed.end())
        continue;
      crossed.emplace_back(g.cable, g.strut);
      if (crossed.size() <= kMaxCrossingWarnings)
        crossing_warnings.push_back(
            "cable " + quoted(model.cables[g.cable].name) + " runs through strut " +
            quoted(model.bodies[g.strut].name) + " (its segment from point " + std::to_string(g.segment + 1) + ", " +
            roundedNumber(-g.gap * 1e3, 3) + " mm inside the strut's surface) first at " +
            (model.analysis.type == AnalysisType::kStatic ? "path parameter " + roundedNumber(s.t) :
                                                            "t = " + roundedNumber(s.t) + " s") +
            " (min_cable_strut_gap; cables do not touch struts in the model)");
    }
    user_output(s);
  };
  const auto with_crossing_warnings = [&](Summary& sum)
  {
    sum.warnings.insert(sum.warnings.end(), crossing_warnings.begin(), crossing_warnings.end());
    if (crossed.size() > kMaxCrossingWarnings)
      sum.warnings.push_back("and " + std::to_string(crossed.size() - kMaxCrossingWarnings) +
                             " more cable and strut pairs where the cable runs through the strut");
  };
  const auto start = std::chrono::steady_clock::now();
  RunResult result;
  State state = initialState(model);
  const AnalysisSettings& an = model.analysis;
  // what the start is: in equilibrium, slack elements, prestress stable (structure_check.h)
  std::vector<std::string> start_warnings = startWarnings(model, state);
  const double actuation_end = actuationEndTime(model);
  const bool ends_early = an.type == AnalysisType::kDynamic && !model.actuators.empty() &&
                          an.duration < actuation_end - 1e-9 * std::max(1.0, an.duration);
  if (ends_early && !an.sequence.empty())
    start_warnings.push_back("analysis.duration " + shortestNumber(an.duration) +
                             " s ends before actuation.sequence does (its last ramp ends at " +
                             roundedNumber(actuation_end) + " s)");
  else if (ends_early)
    start_warnings.push_back("analysis.duration " + shortestNumber(an.duration) +
                             " s ends before the actuators reach analysis.max_actuation " +
                             shortestNumber(an.max_actuation) + " m (the ramp ends at " +
                             roundedNumber(an.schedule.endTime()) + " s): the run stops at actuation " +
                             roundedNumber(an.schedule.evaluate(an.duration).value) + " m");
  const auto with_start_warnings = [&](Summary& s)
  { s.warnings.insert(s.warnings.begin(), start_warnings.begin(), start_warnings.end()); };
  // members above their material's yield strength: the first time each one is, over every step
  std::vector<size_t> watched;  // material cables with a yield strength not yet passed
  for (size_t i = 0; i < model.cables.size(); ++i)
    if (model.cables[i].yield_strength > 0.0 && model.cables[i].area > 0.0)
      watched.push_back(i);
  std::vector<std::string> yield_warnings;
  const auto watch = [&](const State& s)
  {
    for (auto it = watched.begin(); it != watched.end();)
    {
      const size_t i = *it;
      const Cable& c = model.cables[i];
      const CableState cable = evaluateCable(model, c, s.q, s.qd, s.u, model.damping_enabled);
      const double stress = cable.tension / c.area;
      if (!(stress > c.yield_strength))
      {
        ++it;
        continue;
      }
      it = watched.erase(it);
      yield_warnings.push_back("cable " + quoted(c.name) + " is above its material's yield_strength " +
                               shortestNumber(c.yield_strength) + " Pa: " + roundedNumber(stress, 6) + " Pa (tension " +
                               roundedNumber(cable.tension, 6) + " N) first at " +
                               (an.type == AnalysisType::kStatic ? "path parameter " + roundedNumber(s.t) :
                                                                   "t = " + roundedNumber(s.t) + " s"));
    }
  };
  const StepCallback step_hook = [&](const State& s, const std::vector<ContactPairState>* contacts)
  {
    watch(s);
    if (on_step)
      on_step(s, contacts);
  };
  const auto with_yield_warnings = [&](Summary& s)
  { s.warnings.insert(s.warnings.end(), yield_warnings.begin(), yield_warnings.end()); };

  if (an.type == AnalysisType::kStatic)
  {
    StaticSolver solver(model, model.solver);
    solver.setLoadPath(an.load_factor_start, an.load_factor_end);
    solver.setArcLength(an.arc_length);
    // the initial equilibrium (prestress, no actuation, the loads at their first factor)
    Summary first = solver.solve(state, state.u);
    result.summary.iterations += first.iterations;
    if (!first.ok())
    {
      result.summary = first;
      result.summary.message = "initial equilibrium: " + first.message;
      with_start_warnings(result.summary);
      result.final_state = state;
      return result;
    }
    watch(state);
    on_output(state);
    ++result.steps;
    ActuationValues u_end = state.u;
    for (auto& v : u_end)
      v.value = an.max_actuation;
    Summary path =
        solver.followPath(state, u_end, an.steps,
                          [&](const State& s, const Summary&)
                          {
                            const auto callbacks = std::chrono::steady_clock::now();
                            step_hook(s, nullptr);
                            on_output(s);
                            result.callback_time +=
                                std::chrono::duration<double>(std::chrono::steady_clock::now() - callbacks).count();
                            ++result.steps;
                            if (on_progress)
                              on_progress(s.t);
                          });
    path.iterations += first.iterations;
    result.summary = path;
    with_start_warnings(result.summary);
    with_yield_warnings(result.summary);
    result.solver_steps = an.arc_length ? result.steps - 1 : an.steps + path.step_cuts;
    result.timings = solver.timings();
  }
  else
  {
    DynamicsSolver solver(model, model.solver);
    const ActuationLaw law =
        ActuationLaw::writing([&model](double t, ActuationValues& u) { scheduledActuation(model, t, u); });
    result.summary = solver.initialize(state, law);
    with_start_warnings(result.summary);
    if (!result.summary.ok())
    {
      result.final_state = state;
      return result;
    }
    if (!model.actuators.empty())
      solver.formActuatorForces(state);  // (what the rows and callbacks read; a step leaves them unformed)
    solver.deferPoses(true);             // (written below for the steps that are read)
    watch(state);
    on_output(state);
    ++result.steps;
    result.energy.begin(solver.energyAt(state));
    // after each step: the yield watch, and the caller's on_step with the step's contacts (formed when asked)
    const auto after_step = [&](const State& s) { step_hook(s, contacts_wanted ? solver.contactsAt(s) : nullptr); };
    if (model.solver.adaptive)
      runAdaptive(model, solver, law, state, result, on_output, on_progress, after_step, on_step || !watched.empty());
    else
    {
      const double dt = model.solver.dt;
      long n_steps = std::lround(std::ceil(an.duration / dt - 1e-9));
      // a last step shorter than dt_min is merged into the one before
      if (n_steps > 1 && an.duration - static_cast<double>(n_steps - 1) * dt < model.solver.dt_min)
        --n_steps;
      // output rows: every step (output_interval 0), else the first step at or after each multiple of the interval
      // (counted, not summed: a sum of intervals drifts from the step times and skips or doubles rows)
      const bool every_step = !(an.output_interval > 0.0);
      const double interval = an.output_interval;
      long next_row = 1;
      double step_start = state.t;
      bool touched = false;  // contacts active at the last step's end
      for (long k = 1; k <= n_steps; ++k)
      {
        const double t_target = k == n_steps ? an.duration : std::min(an.duration, k * dt);
        const Summary s = solver.step(state, t_target - state.t, law);
        result.summary.iterations += s.iterations;
        result.summary.step_cuts += s.step_cuts;
        result.summary.crossings_refused += s.crossings_refused;
        result.summary.residual = s.residual;
        ++result.solver_steps;
        if (!s.ok())
        {
          result.summary.status = s.status;
          result.summary.message = s.message;
          break;
        }
        const double h = t_target - step_start;
        step_start = t_target;
        state.t = t_target;  // no drift from summing steps
        {
          const EnergyPoint end = solver.energyAt(state);
          const bool touching = !state.natural.touching.empty();
          result.energy.add(end, h, state.t,
                            checkStepEnergy(result.energy.now, end, h, model.solver.energy_tolerance,
                                            stepEnergyRoundoff(model, state.natural.x, h), touched || touching));
          touched = touching;
        }
        const auto callbacks = std::chrono::steady_clock::now();
        const bool row = every_step || k == n_steps || state.t >= static_cast<double>(next_row) * interval - 1e-9 * dt;
        // (the body poses and the actuators' forces for whoever reads this step: the caller's on_step, the yield watch
        // or a row)
        if (on_step || !watched.empty() || row)
          solver.writePoses(state);
        if (!model.actuators.empty() && (on_step || row))
          solver.formActuatorForces(state);
        after_step(state);
        if (row)
        {
          on_output(state);
          ++result.steps;
          if (!every_step)
            while (static_cast<double>(next_row) * interval - 1e-9 * dt <= state.t)
              ++next_row;
        }
        result.callback_time += std::chrono::duration<double>(std::chrono::steady_clock::now() - callbacks).count();
        if (on_progress && k % 256 == 0)
          on_progress(state.t / an.duration);
      }
    }
    result.timings = solver.timings();
    const EnergyAccount& e = result.energy;
    const std::string where =
        model.solver.adaptive ? " (at solver.dt_min; lower it)" : " at solver.dt (use solver.adaptive or a smaller dt)";
    const auto percent = [&e](double energy)
    { return roundedNumber(100.0 * energy / std::max(e.peak_mechanical, 1e-300), 3) + " %"; };
    if (e.gainedMaterially(model.solver.energy_tolerance))
      result.summary.warnings.push_back(
          "the integrator gained " + roundedNumber(-e.numerical_dissipation, 3) + " J over the run (" +
          percent(-e.numerical_dissipation) + " of the largest kinetic and elastic energy; " +
          std::to_string(e.gaining_steps) + " steps gained more than solver.energy_tolerance " +
          shortestNumber(model.solver.energy_tolerance) + ", the first at t = " + roundedNumber(e.first_unresolved_t) +
          " s): impacts, cables going slack and taut or an actuator starting without blend_time were under-resolved" +
          where + " (energy in the summary)");
    if (e.contactsUnresolved(model.solver.energy_tolerance))
      result.summary.warnings.push_back(
          "impacts under-resolved" + where + ": steps in contact changed the energy by " +
          roundedNumber(e.contact_unresolved_energy, 3) + " J (" + percent(e.contact_unresolved_energy) +
          " of the largest kinetic and elastic energy) that no force accounts for, each more than "
          "solver.energy_tolerance " +
          shortestNumber(model.solver.energy_tolerance) + " (" + std::to_string(e.gaining_steps) + " gained, " +
          std::to_string(e.contact_loss_steps) + " lost; the first at t = " + roundedNumber(e.first_unresolved_t) +
          " s): rebounds and contact forces are off by about as much (energy in the summary)");
    with_yield_warnings(result.summary);
    solver.writePoses(state);  // (a failed step's last good state included)
    if (!model.actuators.empty())
      solver.formActuatorForces(state);  // (the final state's, for whoever reads it)
  }
  with_crossing_warnings(result.summary);
  result.final_state = state;
  result.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}
}  // namespace

}  // namespace active_tensegrity::core
