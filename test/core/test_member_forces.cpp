// Member forces (observables.h, csv.h: strutAxialForces, memberColumns, memberRow): the quadruplex's strut force of
// Table 1, the tower's struts through their ball joints in static equilibrium (both ends agree, and the natural
// coordinates' forces are the body coordinates'), a
// form-found prism at rest in a dynamic run; the struts' bending stress under contact loads (maxStrutBendingStress).
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/csv.h"
#include "active_tensegrity/core/outputs/peaks.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/oracle/body_statics.h"
#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/design/form_finding.h"
#include "active_tensegrity/design/generators.h"
#include "active_tensegrity/core/scene/scene.h"

namespace at = active_tensegrity::core;
namespace design = active_tensegrity::design;

namespace
{
std::string scene(const std::string& name)
{
  return std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name;
}

std::vector<at::Override> overrides(const std::vector<std::string>& texts)
{
  std::vector<at::Override> out;
  for (const std::string& t : texts)
    out.push_back(at::parseOverride(t));
  return out;
}

/// The states a run writes.
std::vector<at::State> run(const at::Model& model)
{
  std::vector<at::State> states;
  const at::RunResult r = at::runAnalysis(model, [&](const at::State& s) { states.push_back(s); });
  EXPECT_TRUE(r.summary.ok()) << r.summary.message;
  return states;
}

/// The struts' axial forces and end imbalances (strutAxialForces); with `body`, a state of the body coordinates'
/// statics, also the reactions of the constraints at the struts' ends, -Phi_q^T lambda (ball joints, pins, drives).
std::vector<double> strutForces(const at::Model& model, const at::State& s, std::vector<double>& imbalance,
                                const at::BodyState* body = nullptr)
{
  std::vector<double> all = at::strutAxialForces(model, s, &imbalance);
  // a force f at p, when p is a strut's end (+1 its top, local +z; -1 its bottom): half of (F_top - F_bottom) . u
  // and (F_top + F_bottom) . u
  const auto add = [&](const at::PointRef& p, const at::Vec3& f)
  {
    if (p.body < 0 || model.bodies[p.body].kind != at::BodyKind::kStrut)
      return;
    const double half = 0.5 * model.bodies[p.body].length;
    const int end = p.local.head<2>().norm() > 1e-9 * half      ? 0 :
                    std::abs(p.local.z() - half) <= 1e-9 * half ? 1 :
                    std::abs(p.local.z() + half) <= 1e-9 * half ? -1 :
                                                                  0;
    const at::Vec3 u = (at::pointPosition(model, { p.body, at::Vec3(0.0, 0.0, half) }, s.q) -
                        at::pointPosition(model, { p.body, at::Vec3(0.0, 0.0, -half) }, s.q))
                           .normalized();
    all[p.body] += 0.5 * end * f.dot(u);
    imbalance[p.body] += end == 0 ? 0.0 : f.dot(u);
  };
  Eigen::Index row = 0;
  for (const at::Constraint& c : body ? model.constraints : std::vector<at::Constraint>())
  {
    const Eigen::Index rows = c.rows();
    if (c.kind == at::Constraint::Kind::kPoints)
    {
      at::Vec3 w = at::Vec3::Zero();
      for (Eigen::Index k = 0; k < rows; ++k)
        w += body->lambda[row + k] * c.directions[static_cast<size_t>(k)];
      add(c.a, -w);
      add(c.b, w);
    }
    row += rows;
  }
  std::vector<double> out, net;
  for (size_t b = 0; b < model.bodies.size(); ++b)
    if (model.bodies[b].kind == at::BodyKind::kStrut)
    {
      out.push_back(all[b]);
      net.push_back(imbalance[b]);
    }
  imbalance = net;
  return out;
}
}  // namespace

// The quadruplex at its start (the static path's first state, pins and drives solved): Table 1's lower
// cables at 200 N, upper and bracing at 282.84 N, struts at -200 sqrt(6) N (to the rounding of 282.84)
TEST(MemberForces, QuadruplexStrutsCarryTable1)
{
  const at::Model model =
      at::loadScene(scene("quadruplex.yaml"), overrides({ "analysis.max_actuation=0.1", "analysis.steps=2" }));
  const std::vector<at::State> states = run(model);
  ASSERT_FALSE(states.empty());
  std::vector<double> imbalance;
  for (double f : strutForces(model, states.front(), imbalance))
    EXPECT_NEAR(f, -200.0 * std::sqrt(6.0), 0.01);
  for (double n : imbalance)
    EXPECT_LT(std::abs(n), 1e-6);
  const std::vector<std::string> cols = at::memberColumns(model);
  const std::vector<double> row = at::memberRow(model, states.front());
  ASSERT_EQ(cols.size(), row.size());
  EXPECT_EQ(cols.front(), "t");
  EXPECT_EQ(cols[1], model.cables[0].name + "_tension");
  EXPECT_EQ(cols.back(), model.bodies.back().name + "_force");
  EXPECT_NEAR(row[1], 200.0, 1e-6);  // C1, lower
}

// The tower folded quasi-statically by 0.6 m without contact: its struts meet at ball joints, the sliding cables run
// over the joints. A strut's axial force in natural coordinates is its length row's 2 L lambda; in the body
// coordinates (BodyStaticSolver) it is what the cables and the joints' reactions give at each end. Both ends agree
// there, every strut is in compression, and the two formulations give the same forces.
TEST(MemberForces, TowerStrutsBalanceThroughTheirJoints)
{
  const at::Model model = at::loadScene(
      scene("tower.yaml"), overrides({ "contact.enabled=false", "analysis.max_actuation=0.6", "analysis.steps=60" }));
  const std::vector<at::State> states = run(model);
  ASSERT_FALSE(states.empty());
  std::vector<double> imbalance;
  const std::vector<double> forces = strutForces(model, states.back(), imbalance);
  ASSERT_EQ(forces.size(), 16u);

  // the same equilibrium in the body coordinates: Newton from the natural one (the unprestressed tower starts as a
  // mechanism, so its paths from the start need not meet)
  at::BodyStaticSolver body(model, model.solver);
  at::BodyState b(states.back());
  b.natural = at::NaturalState();
  ASSERT_TRUE(body.solve(b, b.u).ok());
  double moved = 0.0;
  for (const at::Node& n : model.nodes)
    moved = std::max(
        moved, (at::pointPosition(model, n.point, b.q) - at::pointPosition(model, n.point, states.back().q)).norm());
  EXPECT_LT(moved, 1e-6);
  const std::vector<double> body_forces = strutForces(model, b, imbalance, &b);
  for (size_t k = 0; k < forces.size(); ++k)
  {
    EXPECT_LT(forces[k], -10.0) << k;
    EXPECT_LT(std::abs(imbalance[k]), 1e-6 * std::abs(body_forces[k])) << k;
    EXPECT_NEAR(forces[k], body_forces[k], 1e-5 * std::abs(body_forces[k])) << k;
  }
  // without the joints' reactions the ends would not agree: a strut's cables alone leave a net force
  strutForces(model, b, imbalance);
  double largest = 0.0;
  for (double n : imbalance)
    largest = std::max(largest, std::abs(n));
  EXPECT_GT(largest, 1.0);
}

// A free-standing prism in its form, in a dynamic run: at rest, each strut carries the form's force at both
// ends
TEST(MemberForces, FormFoundPrismAtRest)
{
  design::FormFindingOptions o;
  o.tension["rings"] = 60.0;
  const design::FormFindingResult form = design::findForm(design::prismScene({ 5 }), "prism", o);
  const at::Model model = at::loadSceneFromString(form.scene, "prism", overrides({ "analysis.duration=0.05" }));
  const std::vector<at::State> states = run(model);
  ASSERT_GE(states.size(), 2u);
  std::vector<double> imbalance;
  const std::vector<double> forces = strutForces(model, states.back(), imbalance);
  for (size_t k = 0; k < forces.size(); ++k)
  {
    EXPECT_NEAR(forces[k], form.members[k].tension, 1e-6 * std::abs(form.members[k].tension)) << k;
    EXPECT_LT(std::abs(imbalance[k]), 1e-6 * std::abs(forces[k])) << k;
  }
}

// maxStrutBendingStress: each strut a simply supported beam under the contact forces across its axis, the
// stress M / (pi r^3 / 4) at the largest moment. One load P at a from the lower end: M = P a (L - a) / L (the
// axial part of the force bends nothing); two equal loads at a and L - a (four-point bending): M = P a between
// them, in either order of the contact list; a load on the ground's side is not a strut's.
TEST(MemberForces, StrutBendingIsThatOfASimplySupportedBeam)
{
  const at::Model model = at::loadScene(scene("quadruplex.yaml"));
  const at::State s = at::initialState(model);
  ASSERT_EQ(model.bodies[0].kind, at::BodyKind::kStrut);
  const at::Body& b = model.bodies[0];
  const double length = b.length, r = b.layers.front().outer_radius;
  const at::Vec3 centre = s.q.segment<3>(b.offset);
  const at::Vec3 axis = at::bodyZAxis(s.q.segment<4>(b.offset + 3));
  const at::Vec3 across = axis.unitOrthogonal();
  const auto load = [&](double x, double p, double axial)
  {
    at::ContactPairState c;
    c.body_a = 0;
    c.body_b = -1;  // the ground: only strut 0 is loaded
    c.active = true;
    c.point_a = centre + (x - 0.5 * length) * axis;
    c.force_on_a = p * across + axial * axis;
    return c;
  };
  const double section = M_PI * r * r * r / 4.0;
  const double one = at::maxStrutBendingStress(model, s.q, { load(0.3 * length, 100.0, 50.0) });
  const double expected_one = 100.0 * 0.3 * length * 0.7 * length / length / section;
  EXPECT_NEAR(one, expected_one, 1e-9 * expected_one);
  const double expected_four = 100.0 * 0.2 * length / section;
  const double forward =
      at::maxStrutBendingStress(model, s.q, { load(0.2 * length, 100.0, 0.0), load(0.8 * length, 100.0, 0.0) });
  const double backward =
      at::maxStrutBendingStress(model, s.q, { load(0.8 * length, 100.0, 0.0), load(0.2 * length, 100.0, 0.0) });
  EXPECT_NEAR(forward, expected_four, 1e-9 * expected_four);
  EXPECT_NEAR(backward, expected_four, 1e-9 * expected_four);
  // opposite loads at a and L - a: the moment changes sign at mid-span, M = P a (L - 2a) / L at the loads
  const double opposite =
      at::maxStrutBendingStress(model, s.q, { load(0.2 * length, 100.0, 0.0), load(0.8 * length, -100.0, 0.0) });
  const double expected_opposite = 100.0 * 0.2 * length * 0.6 * length / length / section;
  EXPECT_NEAR(opposite, expected_opposite, 1e-9 * expected_opposite);
  EXPECT_EQ(at::maxStrutBendingStress(model, s.q, {}), 0.0);
}

// PeakTracker (a run's `peaks`, fed every step) gives, for each of its five columns, the largest magnitude over the
// steps of what the row functions give at each step (actuationForce, the contacts' largest forces,
// maxStrutBendingStress, maxCableStress), the same bits and the same step, though it keeps its cable scan
// (CableStressScan) from step to step; and the cable stress of each step is the cables' own (evaluateCable from each
// point's motion) to its round-off. (maxStrutBendingStress's values are checked in closed form above.)
namespace
{
void expectPeaksOfEveryStep(const at::Model& model)
{
  at::PeakTracker tracker(model);
  std::vector<at::Peak> expected = { { "actuation_force", 0.0, 0.0 },
                                     { "max_normal_force", 0.0, 0.0 },
                                     { "max_friction_force", 0.0, 0.0 },
                                     { "max_strut_bending_stress", 0.0, 0.0 },
                                     { "max_cable_stress", 0.0, 0.0 } };
  int steps = 0;
  const auto on_step = [&](const at::State& s, const std::vector<at::ContactPairState>* given)
  {
    tracker.add(s, given);
    const std::vector<at::ContactPairState> contacts = at::activeContacts(model, s);
    double normal = 0.0, friction = 0.0;
    for (const at::ContactPairState& c : contacts)
      if (c.body_b >= 0)
      {
        normal = std::max(normal, c.normal_force);
        friction = std::max(friction, c.friction_force);
      }
    const double values[] = { model.actuators.empty() ? 0.0 : at::actuationForce(model, s, 0), normal, friction,
                              at::maxStrutBendingStress(model, s.q, contacts), at::maxCableStress(model, s) };
    // the cable stress as evaluateCable gives it from each point's own motion (not from frames and slots)
    double stress = 0.0;
    for (const at::Cable& c : model.cables)
      if (c.area > 0.0)
        stress = std::max(stress, at::evaluateCable(model, c, s.q, s.qd, s.u, model.damping_enabled).tension / c.area);
    EXPECT_NEAR(values[4], stress, 1e-9 * stress) << "t = " << s.t;  // (T = k (l - l0): l's round-off, magnified)
    for (size_t k = 0; k < expected.size(); ++k)
      if (std::abs(values[k]) > std::abs(expected[k].value))
        expected[k] = { expected[k].name, values[k], s.t };
    ++steps;
  };
  const at::RunResult r = at::runAnalysis(
      model, [](const at::State&) {}, {}, on_step);
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  ASSERT_GT(steps, 100);
  ASSERT_EQ(tracker.peaks().size(), expected.size());
  for (size_t k = 0; k < expected.size(); ++k)
  {
    EXPECT_EQ(tracker.peaks()[k].name, expected[k].name);
    EXPECT_EQ(tracker.peaks()[k].value, expected[k].value) << expected[k].name;
    EXPECT_EQ(tracker.peaks()[k].t, expected[k].t) << expected[k].name;
  }
  // every column met something to track
  EXPECT_GT(expected[1].value, 0.0);
  EXPECT_GT(expected[3].value, 0.0);
  EXPECT_GT(expected[4].value, 0.0);
}
}  // namespace

TEST(MemberForces, PeaksAreTheLargestOfEveryStepsRowValues)
{
  // the quadruplex pressed into strut contact (two-point cables, several loads on a strut)
  expectPeaksOfEveryStep(at::loadScene(scene("quadruplex_linear_contact.yaml"),
                                       overrides({ "analysis.duration=0.7", "analysis.output_interval=0.1" })));
  // the tower's fast fold into contact with friction (sliding cables over several points)
  expectPeaksOfEveryStep(
      at::loadScene(scene("tower.yaml"), overrides({ "analysis.type=dynamic", "actuation.speed=5",
                                                     "analysis.duration=0.6", "analysis.output_interval=0.1" })));
}
