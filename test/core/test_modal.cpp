// Modal analysis (core/modal): a pendulum and a guyed mast against their closed forms, the pinned and the free
// prism's lowest frequency against the period of a free vibration integrated in time, and runModal on scenes.
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/modal.h"
#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
std::string scenePath(const std::string& name)
{
  return std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name;
}

// a 1 m steel strut (radius 1 cm) hanging from a ground pin at P under gravity
const std::string kPendulum = R"(name: pendulum
materials:
  steel: {youngs_modulus: 210.0e9, density: 7850.0}
nodes:
  P: {position: [0.0, 0.0, 1.0], fixed: true}
  Q: {position: [0.0, 0.0, 0.0]}
struts: {radius: 0.01, material: steel, members: {S: [P, Q]}}
gravity: {enabled: true}
analysis: {type: modal}
)";

// the same strut standing on a ground pin at P, its top Q held by two horizontal springs along x to ground
// points a = 0.5 m away, k = 2000 N/m, prestress T = 100 N each, under gravity
const std::string kGuyedMast = R"(name: guyed_mast
materials:
  steel: {youngs_modulus: 210.0e9, density: 7850.0}
nodes:
  P: {position: [0.0, 0.0, 0.0], fixed: true}
  Q: {position: [0.0, 0.0, 1.0]}
  A: {position: [-0.5, 0.0, 1.0], fixed: true}
  B: {position: [0.5, 0.0, 1.0], fixed: true}
struts: {radius: 0.01, material: steel, members: {S: [P, Q]}}
springs:
  guys: {stiffness: 2000.0, prestress: 100.0, members: {K1: [Q, A], K2: [Q, B]}}
gravity: {enabled: true}
analysis: {type: modal}
)";

/// The largest node displacement of a mode (1 by the normalization).
double largestDisplacement(const NaturalMode& m)
{
  double top = 0.0;
  for (const Vec3& d : m.node_displacements)
    top = std::max(top, d.norm());
  return top;
}

/// The period of the free vibration that starts at rest from `eq` moved by `amplitude` along `mode`: the mean
/// spacing of the zero crossings of the node displacements projected on the mode's, over `periods` periods of
/// the expected `period`, integrated by the trapezoidal rule (Newmark 1/2, 1/4: no numerical damping, a
/// period error of (omega h)^2 / 12, 2e-5 at 400 steps per period). Measured: 1.8e-5 (pinned prism), 4e-6 (free
/// prism) relative to the modal period.
double measuredPeriod(const Model& model, const State& eq, const NaturalMode& mode, double amplitude, double period,
                      int periods)
{
  SolverOptions o = model.solver;
  o.integrator = Integrator::kNewmark;
  o.newmark_gamma = 0.5;
  o.newmark_beta = 0.25;
  o.newton_tolerance = 1e-12;
  const double h = period / 400.0;
  DynamicsSolver solver(model, o);
  const ActuationValues held = eq.u;
  const ActuationLaw law = [held](double) { return held; };
  // moved along the mode in natural coordinates (the statics' layout: the free nodes' positions), as body poses
  const NaturalModel nm = buildNaturalModel(model, false);
  State s = eq;
  if (!(s.natural.x.size() == nm.coordinates && carriesNaturalOf(nm, s)))
    naturalFromBody(nm, s);
  const Eigen::VectorXd x = s.natural.x + amplitude * mode.shape;
  s = State();
  s.u = eq.u;
  s.q = naturalToBodyCoordinates(nm, x, s.u);
  s.qd.setZero(model.nq);
  EXPECT_TRUE(solver.initialize(s, law).ok());
  std::vector<Vec3> rest;
  for (const Node& n : model.nodes)
    rest.push_back(pointPosition(model, n.point, eq.q));
  const auto along = [&](const Eigen::VectorXd& q)
  {
    double y = 0.0;
    for (size_t i = 0; i < model.nodes.size(); ++i)
      y += (pointPosition(model, model.nodes[i].point, q) - rest[i]).dot(mode.node_displacements[i]);
    return y;
  };
  std::vector<double> crossings;
  double t = 0.0, y = along(s.q);
  const int steps = static_cast<int>(std::ceil(periods * period / h));
  for (int k = 0; k < steps; ++k)
  {
    EXPECT_TRUE(solver.step(s, h, law).ok());
    const double y_new = along(s.q);
    if ((y > 0.0) != (y_new > 0.0))
      crossings.push_back(t + h * y / (y - y_new));
    t += h;
    y = y_new;
  }
  EXPECT_GE(crossings.size(), 2u * periods - 1);
  return 2.0 * (crossings.back() - crossings.front()) / static_cast<double>(crossings.size() - 1);
}
}  // namespace

TEST(Modal, PendulumSwingsAtItsClosedFormFrequency)
{
  // a rigid body swinging about a fixed point: omega^2 = m g d / (J + m d^2), d = L/2 the distance to the
  // centre of mass, J the transverse inertia about it (the model's, radius included): 3 g / (2 L) for a
  // slender rod. Two swings (about x and y), nothing else: the spin is locked.
  const Model m = loadSceneFromString(kPendulum, "pendulum.yaml");
  const Body& b = m.bodies[0];
  const double d = 0.5 * b.length;
  const double expected = b.mass * 9.81 * d / (b.inertia.x() + b.mass * d * d);
  EXPECT_NEAR(expected, 1.5 * 9.81 / b.length, 1e-4 * expected);  // slender: the radius changes it by 1e-4
  const ModalAnalysis modal = naturalModes(m, initialState(m), 10);
  EXPECT_EQ(modal.free_coordinates, 2);
  ASSERT_EQ(modal.modes.size(), 2u);
  for (const NaturalMode& mode : modal.modes)
  {
    EXPECT_NEAR(mode.eigenvalue, expected, 1e-9 * expected);
    EXPECT_NEAR(mode.frequency_hz, std::sqrt(expected) / (2.0 * M_PI), 1e-9);
    // the free end swings horizontally with the largest displacement, 1; the pinned end stays
    const Vec3& free_end = mode.node_displacements[m.findNode("Q")];
    EXPECT_NEAR(free_end.norm(), 1.0, 1e-12);
    EXPECT_NEAR(free_end.z(), 0.0, 1e-12);
    EXPECT_LT(mode.node_displacements[m.findNode("P")].norm(), 1e-12);
  }
  // both swings are rigid motions the pin allows: no mechanism, no member
  const StructureReport r = checkStructure(m, initialState(m));
  EXPECT_EQ(r.rigid_body_modes, 2);
  EXPECT_EQ(r.mechanisms, 0);
}

TEST(Modal, GuyedMastHasTheMaterialAndTheGeometricStiffnessOfItsSprings)
{
  // rotation theta about the pin moves the top by L theta. Along the springs (x) they resist with their
  // stiffness, 2 k; across them (y) only by turning, with their tension: 2 T / a. Gravity takes m g (L/2) theta^2/2
  // off the energy. With I_P = J + m (L/2)^2: omega_x^2 = (2 k L^2 - m g L/2) / I_P,
  // omega_y^2 = (2 (T / a) L^2 - m g L/2) / I_P.
  const Model m = loadSceneFromString(kGuyedMast, "guyed_mast.yaml");
  const Body& b = m.bodies[0];
  const double len = b.length, k = 2000.0, t = 100.0, a = 0.5, g = 9.81;
  const double ip = b.inertia.x() + b.mass * 0.25 * len * len;
  const double wx2 = (2.0 * k * len * len - b.mass * g * 0.5 * len) / ip;
  const double wy2 = (2.0 * t / a * len * len - b.mass * g * 0.5 * len) / ip;
  const ModalRun run = runModal(m);
  ASSERT_TRUE(run.summary.ok()) << run.summary.message;
  ASSERT_EQ(run.modal.modes.size(), 2u);
  const NaturalMode& across = run.modal.modes[0];
  const NaturalMode& along = run.modal.modes[1];
  EXPECT_NEAR(across.eigenvalue, wy2, 1e-9 * wy2);
  EXPECT_NEAR(along.eigenvalue, wx2, 1e-9 * wx2);
  const int top = m.findNode("Q");
  EXPECT_NEAR(std::abs(across.node_displacements[top].y()), 1.0, 1e-12);
  EXPECT_NEAR(std::abs(along.node_displacements[top].x()), 1.0, 1e-12);
  // the springs' self-stress and their stiffness along x: one mechanism left (y), stiffened by the tension
  // but softened by gravity; stable, as omega_y^2 > 0
  EXPECT_EQ(run.structure.self_stress_states, 1);
  EXPECT_TRUE(run.structure.prestress_stable);
  EXPECT_EQ(run.summary.warnings.size(), 1u);  // fewer modes than the 10 asked for

  // without the tension the across-swing is the inverted pendulum alone: a negative eigenvalue, and a warning
  const Model slack = loadSceneFromString(kGuyedMast, "guyed_mast.yaml", { parseOverride("springs.guys.prestress=1") });
  const ModalRun unstable = runModal(slack);
  ASSERT_TRUE(unstable.summary.ok()) << unstable.summary.message;
  const double wy2_slack = (2.0 * 1.0 / a * len * len - b.mass * g * 0.5 * len) / ip;
  ASSERT_LT(wy2_slack, 0.0);
  EXPECT_NEAR(unstable.modal.modes[0].eigenvalue, wy2_slack, 1e-9 * std::abs(wy2_slack));
  EXPECT_LT(unstable.modal.modes[0].frequency_hz, 0.0);
  // the swing across is a rigid motion of the whole mast (the pin allows it, no member resists it): not a
  // mechanism, but its negative stiffness makes the state unstable all the same
  EXPECT_EQ(unstable.structure.rigid_body_modes, 1);
  EXPECT_EQ(unstable.structure.mechanisms, 0);
  EXPECT_NEAR(unstable.structure.smallest_rigid_mode_eigenvalue, wy2_slack * ip / (len * len),
              1e-9 * std::abs(wy2_slack * ip / (len * len)));
  EXPECT_FALSE(unstable.structure.prestress_stable);
  bool warned = false;
  for (const std::string& w : unstable.summary.warnings)
    warned = warned || w.find("mode 1 has a negative eigenvalue") != std::string::npos;
  EXPECT_TRUE(warned);
}

TEST(Modal, PinnedPrismLowestFrequencyIsThatOfItsFreeVibration)
{
  const Model m = loadScene(scenePath("prism_pinned.yaml"));
  const ModalRun run = runModal(m);  // about the equilibrium with the verticals pulled in by 1 mm
  ASSERT_TRUE(run.summary.ok()) << run.summary.message;
  ASSERT_EQ(run.modal.free_coordinates, 6);
  const NaturalMode& first = run.modal.modes[0];
  ASSERT_GT(first.eigenvalue, 0.0);
  const double period = 2.0 * M_PI / first.omega;
  const double measured = measuredPeriod(m, run.equilibrium, first, 1e-4, period, 4);
  EXPECT_NEAR(measured, period, 1e-4 * period) << "modal " << period << " s, integrated " << measured << " s";
  std::printf("[ measured ] modal period %.6f s, integrated %.6f s\n", period, measured);
}

TEST(Modal, FreePrismHasSixRigidModesAtZeroAndItsMechanismAtTheIntegratedFrequency)
{
  const Model m = loadScene(scenePath("prism.yaml"), { parseOverride("actuators={}") });
  const State start = initialState(m);
  const ModalAnalysis modal = naturalModes(m, start, 8);
  ASSERT_EQ(modal.modes.size(), 8u);
  for (int k = 0; k < 6; ++k)
    EXPECT_EQ(modal.modes[k].frequency_hz, 0.0) << "mode " << k + 1;
  const NaturalMode& mechanism = modal.modes[6];
  ASSERT_GT(mechanism.eigenvalue, 0.0);
  // the stretching modes are two orders of magnitude stiffer than the prestress-stiffened mechanism
  EXPECT_GT(modal.modes[7].eigenvalue, 100.0 * mechanism.eigenvalue);
  const double period = 2.0 * M_PI / mechanism.omega;
  const double measured = measuredPeriod(m, start, mechanism, 1e-4, period, 4);
  EXPECT_NEAR(measured, period, 1e-4 * period) << "modal " << period << " s, integrated " << measured << " s";
  std::printf("[ measured ] modal period %.6f s, integrated %.6f s\n", period, measured);
}

TEST(Modal, RunModalFollowsThePathAndNormalizesTheShapes)
{
  const Model m = loadScene(scenePath("quadruplex.yaml"),
                            { parseOverride("analysis.type=modal"), parseOverride("analysis.max_actuation=0.5"),
                              parseOverride("analysis.steps=50") });
  const ModalRun run = runModal(m);
  ASSERT_TRUE(run.summary.ok()) << run.summary.message;
  EXPECT_EQ(run.equilibrium.u[0].value, 0.5);
  // four struts pinned at their feet (2 coordinates each), the four top heights held: 4 modes
  ASSERT_EQ(run.modal.free_coordinates, 4);
  ASSERT_EQ(run.modal.modes.size(), 4u);
  for (size_t k = 0; k < run.modal.modes.size(); ++k)
  {
    EXPECT_NEAR(largestDisplacement(run.modal.modes[k]), 1.0, 1e-12);
    if (k > 0)
    {
      EXPECT_GE(run.modal.modes[k].eigenvalue, run.modal.modes[k - 1].eigenvalue);
    }
  }
  // the same modes from the equilibrium the static path gives
  State eq = initialState(m);
  StaticSolver solver(m, m.solver);
  ASSERT_TRUE(solver.solve(eq, eq.u).ok());
  ASSERT_TRUE(solver.followPath(eq, { ActuationValue{ 0.5, 0.0, 0.0 } }, 50, [](const State&, const Summary&) {}).ok());
  const ModalAnalysis direct = naturalModes(m, eq, 4);
  for (size_t k = 0; k < 4; ++k)
    EXPECT_NEAR(direct.modes[k].eigenvalue, run.modal.modes[k].eigenvalue, 1e-9 * run.modal.modes[k].eigenvalue);
}

TEST(Modal, AFailedEquilibriumGivesAStatusAndNoModes)
{
  const Model m = loadScene(scenePath("quadruplex.yaml"),
                            { parseOverride("analysis.type=modal"), parseOverride("analysis.max_actuation=0.5"),
                              parseOverride("analysis.steps=1"), parseOverride("solver.max_iterations=1"),
                              parseOverride("solver.max_step_cuts=0") });
  const ModalRun run = runModal(m);
  EXPECT_FALSE(run.summary.ok());
  EXPECT_EQ(run.summary.message.rfind("equilibrium at ", 0), 0u) << run.summary.message;
  EXPECT_TRUE(run.modal.modes.empty());
}
