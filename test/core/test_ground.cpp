// The ground (core/contact, Model::ground): the exact tangents of a sphere's normal and friction forces
// against central differences (strut ends at random tilts, Theta off the unit sphere, each friction
// regime; point masses), a strut dropped flat rebounding as the 1-D Lankarani-Nikravesh model and c_e say,
// a strut sliding on its side slowing at mu g, the six-bar robot at rest carrying its weight, and the
// loader's refusals.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "active_tensegrity/oracle/body_contact.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "contact_checks.h"
#include "fd_check.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
constexpr double kTol = 2e-6;

// one free steel strut (1 m, radius 2 cm) along x at height z, above a concrete ground at 0
std::string strutScene(double z, double restitution, double friction, const std::string& extra = "")
{
  return "name: strut\n"
         "materials:\n"
         "  steel: {youngs_modulus: 2.0e11, poisson_ratio: 0.3, density: 7800.0}\n"
         "  concrete: {youngs_modulus: 3.0e10, poisson_ratio: 0.2, density: 2400.0}\n"
         "nodes:\n"
         "  A: {position: [-0.5, 0.0, " +
         std::to_string(z) +
         "]}\n"
         "  B: {position: [0.5, 0.0, " +
         std::to_string(z) +
         "]}\n"
         "struts: {radius: 0.02, material: steel, members: {S: [A, B]}}\n"
         "ground: {enabled: true, height: 0.0, material: concrete, restitution: " +
         std::to_string(restitution) + ", friction: " + std::to_string(friction) +
         ", stick_velocity: 0.01, slip_velocity: 0.1}\n"
         "analysis: {type: dynamic, duration: 1.0}\n" +
         extra;
}

Eigen::VectorXd groundForceOf(const Model& m, int slot, const Eigen::VectorXd& q, const Eigen::VectorXd& qd, double v0,
                              ContactMode mode)
{
  ContactContribution c;
  evaluateContact(m, slot, q, qd, v0, mode, &c);
  return c.force.head(m.nq);
}

void expectExactTangents(const Model& m, int slot, const Eigen::VectorXd& q, const Eigen::VectorXd& qd, double v0,
                         ContactMode mode, const std::string& what)
{
  ContactContribution c;
  const ContactPairState st = evaluateContact(m, slot, q, qd, v0, mode, &c);
  ASSERT_GT(st.normal_force, 0.0) << what;
  const auto fq = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return -groundForceOf(m, slot, x, qd, v0, mode); };
  const auto fqd = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return -groundForceOf(m, slot, q, x, v0, mode); };
  const double scale = std::max(1.0, c.force.lpNorm<Eigen::Infinity>());
  const FdComparison ck = compareJacobians(c.stiffness.topLeftCorner(m.nq, m.nq), fdJacobian(fq, q, 1e-7), kTol, scale);
  EXPECT_TRUE(ck.ok) << what << ", K: " << ck.message;
  const FdComparison cc = compareJacobians(c.damping.topLeftCorner(m.nq, m.nq), fdJacobian(fqd, qd, 1e-7), kTol, scale);
  EXPECT_TRUE(cc.ok) << what << ", C: " << cc.message;
}

// the strut tilted along a random axis pointing down, its lower end's sphere `depth` into the ground, Theta off
// the unit sphere by up to 1e-3; returns the lower end's slot
int tiltedIntoTheGround(const Model& m, double depth, std::mt19937& rng, Eigen::VectorXd& q)
{
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Body& b = m.bodies[0];
  Vec3 axis;
  do
    axis = Vec3(u(rng), u(rng), u(rng));
  while (axis.norm() < 0.3 || axis.normalized().z() > -0.2);
  axis.normalize();
  q = m.q0;
  // the body z axis points from A (local -L/2) to B (local +L/2): B is the lower end (placed after Theta is
  // scaled, which moves the ends)
  q.segment<4>(3) = thetaFromZAxis(axis) * (1.0 + 1e-3 * u(rng));
  q.segment<3>(0).setZero();
  const Vec3 end = pointPosition(m, PointRef{ 0, Vec3(0.0, 0.0, 0.5 * b.length) }, q);
  q.segment<3>(0) = Vec3(0.3 * u(rng), 0.3 * u(rng), b.radius() - depth) - end;
  for (int slot = 0; slot < m.contactSlots(); ++slot)
    if (contactGeometry(m, slot, q).active)
      return slot;
  return -1;
}

// random velocities scaled so that the lower end's slip speed is `slip` (m/s), drawn again until the hysteresis
// factor 1 + D zeta_dot stays within [0.5, 1.5]
Eigen::VectorXd velocitiesWithSlip(const Model& m, int slot, const Eigen::VectorXd& q, double slip, double v0,
                                   std::mt19937& rng)
{
  Model with_friction = m;
  with_friction.ground.friction = 1.0;
  const double d = 3.0 * (1.0 - m.ground.restitution * m.ground.restitution) / (4.0 * v0);
  for (;;)
  {
    Eigen::VectorXd qd = randomVector(m.nq, 1.0, rng);
    const ContactPairState st = evaluateContact(with_friction, slot, q, qd, 1e9, ContactMode::kDynamic, nullptr);
    qd *= slip / st.slip_speed;
    if (std::abs(d * st.penetration_rate * slip / st.slip_speed) <= 0.5)
      return qd;
  }
}

SolverOptions fineOptions(double dt)
{
  return trapezoidalOptions(dt, 1e-12);
}

ActuationLaw noActuation()
{
  return [](double) { return ActuationValues(); };
}
}  // namespace

namespace
{
// the loader's message for a scene text, or "accepted"
std::string refusalOf(const std::string& text)
{
  try
  {
    loadSceneFromString(text, "bad");
  }
  catch (const SceneError& e)
  {
    return std::string(e.what());
  }
  return std::string("accepted");
}
}  // namespace

TEST(GroundContact, SpheresOfStrutEndsAndTheirStiffness)
{
  const Model m = loadSceneFromString(strutScene(0.5, 0.8, 0.0), "strut");
  ASSERT_EQ(m.ground_contacts.size(), 2u);
  EXPECT_EQ(m.contactSlots(), 2);
  const double estar = 1.0 / ((1.0 - 0.09) / 2.0e11 + (1.0 - 0.04) / 3.0e10);
  for (const GroundContact& g : m.ground_contacts)
  {
    EXPECT_EQ(g.body, 0);
    EXPECT_DOUBLE_EQ(g.radius, 0.02);
    EXPECT_NEAR(g.stiffness, 4.0 / 3.0 * estar * std::sqrt(0.02), 1e-9 * g.stiffness);
    EXPECT_DOUBLE_EQ(std::abs(g.local.z()), 0.5);
  }
  EXPECT_EQ(m.ground_contacts[0].node, "A");
  EXPECT_EQ(m.ground_contacts[1].node, "B");
  // 0.48 m above the ground: no contact, the gap from the sphere's surface
  const State s = initialState(m);
  EXPECT_NEAR(minimumGroundGap(m, s.q), 0.48, 1e-12);
  EXPECT_TRUE(activeContacts(m, s).empty());
}

TEST(GroundContact, TangentsAreExactForStrutEndsInEveryRegime)
{
  std::mt19937 rng(11);
  const Model base = loadSceneFromString(strutScene(0.5, 0.7, 0.6), "strut");
  const double v0 = 0.8;
  for (int trial = 0; trial < 6; ++trial)
  {
    Eigen::VectorXd q;
    const int slot = tiltedIntoTheGround(base, 1e-4 * (1.0 + trial), rng, q);
    ASSERT_GE(slot, 0);
    const std::string what = "trial " + std::to_string(trial);
    expectExactTangents(base, slot, q, Eigen::VectorXd::Zero(base.nq), 0.0, ContactMode::kStatic, what + " static");
    Model frictionless = base;
    frictionless.ground.friction = 0.0;
    const Eigen::VectorXd qd = randomVector(base.nq, 0.1, rng);
    expectExactTangents(frictionless, slot, q, qd, v0, ContactMode::kDynamic, what + " frictionless");
    // the ramp of the modified Coulomb law (between v0 = 0.01 and v1 = 0.1 m/s) and full sliding
    for (double slip : { 0.04, 0.3 })
      expectExactTangents(base, slot, q, velocitiesWithSlip(base, slot, q, slip, v0, rng), v0, ContactMode::kDynamic,
                          what + " slip " + std::to_string(slip));
    // the ground's default law (v0 = 0, v1 = 0.01 m/s): linear in the slip from zero
    Model linear = base;
    linear.ground.stick_velocity = 0.0;
    linear.ground.slip_velocity = 0.01;
    for (double slip : { 1e-4, 0.004 })
      expectExactTangents(linear, slot, q, velocitiesWithSlip(linear, slot, q, slip, v0, rng), v0,
                          ContactMode::kDynamic, what + " default law, slip " + std::to_string(slip));
  }
}

TEST(GroundContact, TangentsAreExactForPointMasses)
{
  const std::string scene = "name: ball\n"
                            "materials:\n"
                            "  rubber: {youngs_modulus: 2.0e7, poisson_ratio: 0.45}\n"
                            "  concrete: {youngs_modulus: 3.0e10, poisson_ratio: 0.2}\n"
                            "nodes:\n"
                            "  P: {position: [0.0, 0.0, 0.1], mass: 2.0, radius: 0.05, material: rubber}\n"
                            "ground: {enabled: true, material: concrete, restitution: 0.6, friction: 0.5,\n"
                            "         stick_velocity: 0.01, slip_velocity: 0.1}\n"
                            "analysis: {type: dynamic, duration: 1.0}\n";
  const Model m = loadSceneFromString(scene, "ball");
  ASSERT_EQ(m.ground_contacts.size(), 1u);
  const double estar = 1.0 / ((1.0 - 0.45 * 0.45) / 2.0e7 + (1.0 - 0.04) / 3.0e10);
  EXPECT_NEAR(m.ground_contacts[0].stiffness, 4.0 / 3.0 * estar * std::sqrt(0.05), 1e-6);
  std::mt19937 rng(5);
  Eigen::VectorXd q = m.q0;
  q.z() = 0.05 - 2e-3;
  expectExactTangents(m, 0, q, Eigen::VectorXd::Zero(3), 0.0, ContactMode::kStatic, "static");
  for (double slip : { 0.05, 0.5 })
    expectExactTangents(m, 0, q, velocitiesWithSlip(m, 0, q, slip, 0.5, rng), 0.5, ContactMode::kDynamic,
                        "slip " + std::to_string(slip));
}

class GroundRestitution : public ::testing::TestWithParam<double>
{
};

TEST_P(GroundRestitution, AStrutDroppedFlatReboundsAsTheOneDegreeOfFreedomModel)
{
  // flat, both end spheres 0.5 mm above the ground, falling at 1 m/s without gravity: each end is a 1-D
  // impact of half the strut's mass on its sphere's stiffness
  const double ce = GetParam(), v = 1.0;
  const Model m = loadSceneFromString(strutScene(0.0205, ce, 0.0), "strut");
  DynamicsSolver solver(m, fineOptions(2e-6));
  State s = initialState(m);
  s.qd.z() = -v;
  ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
  double max_force = 0.0;
  for (int k = 0; k < 2500; ++k)
  {
    ASSERT_TRUE(solver.step(s, 2e-6, noActuation()).ok()) << k;
    for (const ContactPairState& c : activeContacts(m, s))
    {
      EXPECT_EQ(c.body_b, -1);
      max_force = std::max(max_force, c.normal_force);
    }
  }
  ASSERT_GT(max_force, 0.0);
  ASSERT_GT(minimumGroundGap(m, s.q), 0.0) << "still in contact";
  const double rebound = s.qd.z() / v;
  const double exact = reboundOfOneDegreeOfFreedom(0.5 * m.bodies[0].mass, m.ground_contacts[0].stiffness, v, ce);
  std::printf("[ measured ] c_e %.2f: rebound %.5f, 1-D model %.5f, peak force per end %.1f N\n", ce, rebound, exact,
              max_force);
  EXPECT_NEAR(rebound, exact, 2e-3);
  EXPECT_NEAR(rebound, ce, ce >= 0.9 ? 0.02 : 0.06);
  // it falls flat and leaves flat: no spin
  EXPECT_LT(s.qd.segment<4>(3).norm(), 1e-9);
}

INSTANTIATE_TEST_SUITE_P(Ground, GroundRestitution, ::testing::Values(1.0, 0.9, 0.8));

TEST(GroundFriction, AStrutSlidingOnItsSideSlowsAtMuG)
{
  // resting on the ground under gravity (first settled without friction), then pushed along its axis at 2 m/s
  const double mu = 0.4, g = 9.81;
  const std::string gravity = "gravity: {enabled: true}\n";
  Model m = loadSceneFromString(strutScene(0.02, 0.3, mu, gravity), "strut");
  SolverOptions o = fineOptions(2e-4);
  o.newmark_gamma = 0.6;
  o.newmark_beta = 0.3025;
  DynamicsSolver solver(m, o);
  State s = initialState(m);
  ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
  for (int k = 0; k < 1000; ++k)
    ASSERT_TRUE(solver.step(s, 2e-4, noActuation()).ok());
  s.qd.x() = 2.0;
  std::vector<std::pair<double, double>> samples;  // (t, vx)
  for (int k = 0; k < 3000; ++k)
  {
    ASSERT_TRUE(solver.step(s, 2e-4, noActuation()).ok());
    samples.emplace_back(s.t, s.qd.x());
  }
  // the speed falls linearly at mu g until it reaches the modified law's ramp (0.1 m/s)
  const auto at = [&](double t)
  {
    for (const auto& [ts, vx] : samples)
      if (ts >= t)
        return vx;
    return samples.back().second;
  };
  const double t0 = samples.front().first;
  const double decel = (at(t0 + 0.05) - at(t0 + 0.35)) / 0.3;
  std::printf("[ measured ] deceleration %.5f m/s^2 (mu g = %.5f)\n", decel, mu * g);
  EXPECT_NEAR(decel, mu * g, 2e-3 * mu * g);
  // and it stops (below the stick speed) rather than reversing
  EXPECT_LT(std::abs(samples.back().second), 0.011);
}

TEST(GroundSupport, TheSixBarRobotAtRestCarriesItsWeightOnThreeEnds)
{
  // the shipped robot standing on a cable triangle, its cables damped harder to come to rest sooner: once at
  // rest, the ground's normal forces on the triangle's three strut ends add up to the robot's weight
  const Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/six_bar.yaml",
                            { { "springs.cables.damping", "100" } });
  EXPECT_EQ(m.ground_contacts.size(), 12u);
  double weight = 0.0;
  for (const Body& b : m.bodies)
    weight += b.mass * 9.81;
  DynamicsSolver solver(m, m.solver);
  State s = initialState(m);
  ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
  // 20 s: the slowest motion, a rocking on the three ends, has decayed below 1e-7 of the weight by 18 s
  for (int k = 0; k < 20000; ++k)
    ASSERT_TRUE(solver.step(s, 1e-3, noActuation()).ok()) << k;
  double sum = 0.0;
  std::vector<std::string> touching;
  for (const ContactPairState& c : activeContacts(m, s))
  {
    ASSERT_EQ(c.body_b, -1);
    sum += c.normal_force;
    EXPECT_DOUBLE_EQ(c.point_b.z(), 0.0);
    touching.push_back(m.ground_contacts[c.pair - m.pairSlots()].node);
  }
  std::printf("[ measured ] ground contacts at %s carry %.9f N of a weight of %.9f N\n",
              (touching.size() == 3 ? touching[0] + ", " + touching[1] + ", " + touching[2] : std::string("?")).c_str(),
              sum, weight);
  EXPECT_EQ(touching, (std::vector<std::string>{ "N4", "N8", "N12" }));
  EXPECT_NEAR(sum, weight, 1e-6 * weight);
}

TEST(GroundSupport, TheContactsARunHandsItsStepCallbackAreThoseOfAFullSearch)
{
  // runAnalysis hands on_step the contacts the solver formed from its near list at each step's end; on the six-bar
  // robot's roll (ground contact with friction, strut ends landing and lifting) they must be, at every step, what an
  // evaluation of every ground contact gives
  const Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/six_bar.yaml",
                            { { "analysis.duration", "4" } });
  int steps = 0, given = 0, sliding = 0;
  std::vector<bool> touched(m.ground_contacts.size(), false);
  const RunResult result = runAnalysis(
      m, [](const State&) {}, {},
      [&](const State& s, const std::vector<ContactPairState>* contacts)
      {
        ++steps;
        if (!contacts)
          return;
        ++given;
        const std::vector<ContactPairState> full = searchEverySlot(m, s);
        expectSameContacts(*contacts, full, s.t);
        for (const ContactPairState& c : full)
        {
          touched[c.pair - m.pairSlots()] = true;
          sliding += c.friction_force > 0.0 ? 1 : 0;
        }
      });
  ASSERT_TRUE(result.summary.ok()) << result.summary.message;
  EXPECT_EQ(given, steps) << "every step's contacts come from the solver";
  EXPECT_GT(std::count(touched.begin(), touched.end(), true), 3) << "the roll must change the ends on the ground";
  EXPECT_GT(sliding, 0) << "friction must act for the comparison to cover it";
}

TEST(GroundScene, RefusesAStartInTheGroundAnUnknownMaterialAndARadiusWithoutAMass)
{
  // nodes on the ground plane itself: the spheres start a radius deep
  const std::string deep = refusalOf(strutScene(0.0, 0.5, 0.0));
  EXPECT_NE(deep.find("nodes.A"), std::string::npos) << deep;
  EXPECT_NE(deep.find("deep in the ground"), std::string::npos) << deep;
  EXPECT_NE(deep.find("z >= 0.02"), std::string::npos) << deep;
  std::string text = strutScene(0.5, 0.5, 0.0);
  text.replace(text.find("material: concrete"), 18, "material: granite");
  const std::string unknown = refusalOf(text);
  EXPECT_NE(unknown.find("ground.material"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("granite"), std::string::npos) << unknown;
  text = strutScene(0.5, 0.5, 0.0);
  text.replace(text.find("restitution: 0.5"), 16, "restitution: 1.5");
  const std::string restitution = refusalOf(text);
  EXPECT_NE(restitution.find("ground.restitution"), std::string::npos) << restitution;
  text = strutScene(0.5, 0.5, 0.0);
  text.replace(text.find("  B: {position"), 0, "  C: {position: [0, 0, 1], fixed: true, radius: 0.1}\n");
  const std::string radius = refusalOf(text);
  EXPECT_NE(radius.find("nodes.C.radius"), std::string::npos) << radius;
  // the ground off (the default): no spheres
  text = strutScene(0.5, 0.5, 0.0);
  text.replace(text.find("enabled: true"), 13, "enabled: false");
  EXPECT_TRUE(loadSceneFromString(text, "off").ground_contacts.empty());
}

TEST(GroundScene, AFreePointMassWithoutARadiusIsWarnedAbout)
{
  const std::string scene = "name: hanging\n"
                            "materials:\n"
                            "  concrete: {youngs_modulus: 3.0e10, poisson_ratio: 0.2}\n"
                            "nodes:\n"
                            "  A: {position: [0, 0, 1], fixed: true}\n"
                            "  P: {position: [0, 0, 0.5], mass: 1.0}\n"
                            "  Q: {position: [0.1, 0, 0.5], mass: 1.0, radius: 0.05}\n"
                            "springs:\n"
                            "  s: {stiffness: 100, members: {K: [A, P], L: [A, Q]}}\n"
                            "ground: {enabled: true, material: concrete}\n"
                            "analysis: {type: dynamic, duration: 0.1}\n";
  const Model m = loadSceneFromString(scene, "hanging");
  ASSERT_EQ(m.ground_contacts.size(), 1u);  // Q only
  const std::vector<std::string> w = startWarnings(m, initialState(m));
  const auto about = [&](const std::string& node)
  {
    return std::count_if(w.begin(), w.end(),
                         [&](const std::string& x)
                         { return x.find("'" + node + "' has no radius") != std::string::npos; });
  };
  EXPECT_EQ(about("P"), 1);
  EXPECT_EQ(about("Q"), 0);
}

namespace
{
// strutScene's strut on a ground with the linear law (k N/m, c N s/m at each end sphere)
std::string linearGroundScene(double z, double k, double c, double friction)
{
  std::string text = strutScene(z, 0.5, friction);
  const size_t at = text.find("material: concrete, restitution: ");
  const size_t end = text.find(',', at + 20);
  text.replace(at, end - at, "law: linear, stiffness: " + std::to_string(k) + ", damping: " + std::to_string(c));
  return text;
}
}  // namespace

TEST(GroundLinearLaw, TangentsAreExactForStrutEndsAndPointMasses)
{
  std::mt19937 rng(31);
  const Model base = loadSceneFromString(linearGroundScene(0.5, 3e5, 200.0, 0.6), "strut");
  ASSERT_EQ(base.ground.law, ContactLaw::kLinear);
  ASSERT_EQ(base.ground_contacts.size(), 2u);
  EXPECT_EQ(base.ground_contacts[0].stiffness, 3e5);
  for (int trial = 0; trial < 4; ++trial)
  {
    Eigen::VectorXd q;
    const int slot = tiltedIntoTheGround(base, 1e-3 * (1.0 + trial), rng, q);
    ASSERT_GE(slot, 0);
    const std::string what = "trial " + std::to_string(trial);
    expectExactTangents(base, slot, q, Eigen::VectorXd::Zero(base.nq), 0.0, ContactMode::kStatic, what + " static");
    for (double slip : { 0.005, 0.04, 0.3 })
    {
      // the damper within half the spring's force
      Eigen::VectorXd qd;
      ContactPairState st;
      do
      {
        qd = velocitiesWithSlip(base, slot, q, slip, 1e9, rng);
        st = evaluateContact(base, slot, q, qd, 0.0, ContactMode::kDynamic, nullptr);
      } while (std::abs(200.0 * st.penetration_rate) > 0.5 * 3e5 * st.penetration);
      EXPECT_NEAR(st.normal_force, 3e5 * st.penetration + 200.0 * st.penetration_rate, 1e-9 * st.normal_force);
      expectExactTangents(base, slot, q, qd, 0.0, ContactMode::kDynamic, what + " slip " + std::to_string(slip));
    }
  }
  const std::string ball = "name: ball\n"
                           "nodes:\n"
                           "  P: {position: [0.0, 0.0, 0.1], mass: 2.0, radius: 0.05}\n"
                           "ground: {enabled: true, law: linear, stiffness: 1e4, damping: 20, friction: 0.5,\n"
                           "         stick_velocity: 0.01, slip_velocity: 0.1}\n"
                           "analysis: {type: dynamic, duration: 1.0}\n";
  const Model m = loadSceneFromString(ball, "ball");
  ASSERT_EQ(m.ground_contacts.size(), 1u);
  Eigen::VectorXd q = m.q0;
  q.z() = 0.05 - 2e-3;
  expectExactTangents(m, 0, q, Eigen::VectorXd::Zero(3), 0.0, ContactMode::kStatic, "point mass static");
  expectExactTangents(m, 0, q, Eigen::VectorXd((Eigen::VectorXd(3) << 0.3, -0.1, -0.2).finished()), 0.0,
                      ContactMode::kDynamic, "point mass sliding");
}

TEST(GroundLinearLaw, AStrutDroppedFlatReboundsAsTheClosedFormSpringDashpot)
{
  // each end: half the strut's mass on k, c (damping ratio 0.2), no gravity, 1 m/s
  const double v = 1.0, k = 2e6;
  const Model probe = loadSceneFromString(linearGroundScene(0.0205, k, 0.0, 0.0), "strut");
  const double mstar = 0.5 * probe.bodies[0].mass, c = 2.0 * 0.2 * std::sqrt(k * mstar);
  const Model m = loadSceneFromString(linearGroundScene(0.0205, k, c, 0.0), "strut");
  DynamicsSolver solver(m, fineOptions(2e-6));
  State s = initialState(m);
  s.qd.z() = -v;
  ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
  double max_force = 0.0, max_depth = 0.0;
  for (int k_step = 0; k_step < 6000; ++k_step)
  {
    ASSERT_TRUE(solver.step(s, 2e-6, noActuation()).ok()) << k_step;
    for (const ContactPairState& st : activeContacts(m, s))
      max_force = std::max(max_force, st.normal_force);
    max_depth = std::max(max_depth, -minimumGroundGap(m, s.q));
  }
  ASSERT_GT(minimumGroundGap(m, s.q), 0.0) << "still in contact";
  const LinearImpact exact = linearImpact(mstar, k, c, v);
  std::printf("[ measured ] rebound %.5f (closed form %.5f), depth %.6g m (%.6g), force per end %.2f N (%.2f)\n",
              s.qd.z() / v, exact.rebound, max_depth, exact.max_penetration, max_force, exact.max_force);
  EXPECT_NEAR(s.qd.z() / v, exact.rebound, 2e-3);
  EXPECT_NEAR(max_depth, exact.max_penetration, 2e-3 * exact.max_penetration);
  EXPECT_NEAR(max_force, exact.max_force, 2e-3 * exact.max_force);
  EXPECT_LT(s.qd.segment<4>(3).norm(), 1e-9);
}

TEST(GroundLinearLaw, TheLoaderRefusesKeysOfTheOtherLawAndAMissingStiffness)
{
  const auto expectRefused = [&](const std::string& text, const std::string& key, const std::string& words)
  {
    const std::string e = refusalOf(text);
    EXPECT_NE(e.find(key), std::string::npos) << e;
    EXPECT_NE(e.find(words), std::string::npos) << e;
  };
  const std::string good = linearGroundScene(0.5, 1e5, 10.0, 0.2);
  EXPECT_EQ(refusalOf(good), "accepted");
  std::string t = good;
  t.replace(t.find("law: linear"), 11, "law: kelvin");
  expectRefused(t, "ground.law", "'kelvin'");
  t = good;
  t.replace(t.find("stiffness: "), 11, "stiff: ");
  expectRefused(t, "ground.stiffness", "required by law 'linear'");
  t = good;
  t.replace(t.find("law: linear, "), 13, "");  // stiffness and damping under the hertz law (and no material)
  expectRefused(t, "ground.stiffness", "applies to law 'linear' only");
  t = good;
  t.replace(t.find("law: linear"), 11, "law: linear, restitution: 0.5");
  expectRefused(t, "ground.restitution", "applies to law 'hertz' only");
  t = good;
  t.replace(t.find("law: linear"), 11, "law: linear, material: concrete");
  expectRefused(t, "ground.material", "applies to law 'hertz' only");
  t = good;
  t.replace(t.find("damping: "), 9, "damping: -");
  expectRefused(t, "ground.damping", "must not be negative");
  t = good;
  t.replace(t.find("stiffness: 100000.000000"), 24, "stiffness: .nan");
  expectRefused(t, "ground.stiffness", "nan");
}

TEST(GroundContact, ForceWithoutTangentsIsTheSameForce)
{
  // the residual-only evaluation (no point Jacobians) gives the force of the full one, for strut ends with and
  // without friction and for both laws
  std::mt19937 rng(41);
  for (const std::string& text : { strutScene(0.5, 0.7, 0.6), linearGroundScene(0.5, 3e5, 200.0, 0.6) })
  {
    const Model m = loadSceneFromString(text, "strut");
    for (int trial = 0; trial < 6; ++trial)
    {
      Eigen::VectorXd q;
      const int slot = tiltedIntoTheGround(m, 1e-3 * (1.0 + trial), rng, q);
      ASSERT_GE(slot, 0);
      const Eigen::VectorXd qd = randomVector(m.nq, 0.3, rng);
      ContactContribution full, alone;
      alone.tangents = false;
      const ContactPairState a = evaluateContact(m, slot, q, qd, 0.8, ContactMode::kDynamic, &full);
      const ContactPairState b = evaluateContact(m, slot, q, qd, 0.8, ContactMode::kDynamic, &alone);
      ASSERT_GT(a.normal_force, 0.0);
      EXPECT_NEAR(a.normal_force, b.normal_force, 1e-12 * a.normal_force);
      EXPECT_NEAR(a.friction_force, b.friction_force, 1e-12 * a.normal_force);
      EXPECT_LT((full.force - alone.force).norm(), 1e-12 * full.force.norm()) << trial;
    }
  }
}

TEST(GroundSupport, ModifiedNewtonSettlesTheSixBarAsFullNewtonDoes)
{
  // the six-bar robot settling on its triangle: Lankarani-Nikravesh damping with the impact speed at its floor
  // stiffens the contacts' damping from step to step; modified Newton keeps a matrix while it contracts and builds a
  // new one where it does not, and the motion is full Newton's
  const Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/six_bar.yaml");
  const auto settle = [&](bool reuse, std::vector<Eigen::VectorXd>* path, StepTimings& timings)
  {
    SolverOptions o = m.solver;
    o.reuse_jacobian = reuse;
    o.newton_tolerance = 1e-9;
    DynamicsSolver solver(m, o);
    State s = initialState(m);
    EXPECT_TRUE(solver.initialize(s, noActuation()).ok());
    for (int k = 0; k < 400; ++k)
    {
      EXPECT_TRUE(solver.step(s, 1e-3, noActuation()).ok()) << k;
      if (path)
        path->push_back(s.q);
    }
    timings = solver.timings();
    return s.q;
  };
  StepTimings modified, full;
  std::vector<Eigen::VectorXd> path;
  settle(true, &path, modified);
  std::vector<Eigen::VectorXd> reference;
  settle(false, &reference, full);
  double distance = 0.0;
  for (size_t k = 0; k < path.size(); ++k)
    distance = std::max(distance, (path[k] - reference[k]).lpNorm<Eigen::Infinity>());
  std::printf("[ measured ] 400 steps: %ld iterations, %ld factorizations (full Newton: %ld iterations); largest "
              "distance to full Newton %.2e\n",
              modified.newton_iterations, modified.factorizations, full.newton_iterations, distance);
  EXPECT_EQ(full.factorizations, full.newton_iterations);
  EXPECT_LT(modified.factorizations, 400 / 4);
  EXPECT_LT(modified.newton_iterations, 3 * 400);
  EXPECT_LT(distance, 1e-6);
}

TEST(GroundContact, AtPosesAgreesWithTheBodyCoordinatesLaw)
{
  // the core's evaluation at body poses (the natural coordinates' law on the strut's end nodes and spin rate)
  // against the body coordinates' law, about held, on the ramp and sliding, and in statics
  std::mt19937 rng(29);
  const Model m = loadSceneFromString(strutScene(0.5, 0.7, 0.6), "strut");
  const double v0 = 0.8;
  for (int trial = 0; trial < 6; ++trial)
  {
    Eigen::VectorXd q;
    const int slot = tiltedIntoTheGround(m, 2e-3 * (1.0 + trial), rng, q);
    ASSERT_GE(slot, 0);
    q.segment<4>(3).normalize();  // poses: unit Theta
    for (double slip : { 0.0, 0.005, 0.04, 0.3 })
    {
      // (the rates of unit Theta: the part along Theta taken out)
      Eigen::VectorXd qd = slip > 0.0 ? velocitiesWithSlip(m, slot, q, slip, v0, rng) : Eigen::VectorXd::Zero(m.nq);
      qd.segment<4>(3) -= q.segment<4>(3).dot(qd.segment<4>(3)) * q.segment<4>(3);
      for (ContactMode mode : { ContactMode::kStatic, ContactMode::kDynamic })
      {
        const std::string what = "trial " + std::to_string(trial) + " slip " + std::to_string(slip) +
                                 (mode == ContactMode::kStatic ? " static" : " dynamic");
        const ContactPairState a = evaluateContact(m, slot, q, qd, v0, mode);
        const ContactPairState b = evaluateContact(m, slot, q, qd, v0, mode, nullptr);
        ASSERT_TRUE(a.active && b.active) << what;
        const double scale = std::max(1.0, b.normal_force);
        EXPECT_NEAR(a.penetration, b.penetration, 1e-12) << what;
        EXPECT_NEAR(a.normal_force, b.normal_force, 1e-9 * scale) << what;
        EXPECT_NEAR(a.friction_force, b.friction_force, 1e-9 * scale) << what;
        EXPECT_LT((a.force_on_a - b.force_on_a).norm(), 1e-9 * scale) << what;
        EXPECT_EQ(a.body_a, b.body_a) << what;
        EXPECT_EQ(a.body_b, -1) << what;
      }
    }
  }
}
