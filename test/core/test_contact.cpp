// Strut contact (core/contact, and the oracle's body coordinates): the exact tangents of the normal and friction forces
// against central differences in all 14 coordinates and 14 velocities of a pair (Theta off the unit sphere too), per
// regime and for random crossings away from the kinks; the stiffness law; special configurations (parallel, end to end,
// end to side) stay finite and point the right way; friction never adds energy.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "active_tensegrity/oracle/body_contact.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/oracle/mechanics.h"
#include "fd_check.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
constexpr double kTol = 2e-6;

// two free struts checked against each other (rubber-like outer layers keep forces moderate)
Model twoStruts(double mu, double restitution, double ra = 0.04, double rb = 0.05)
{
  Model m;
  m.name = "pair";
  m.bodies.push_back(makeStrut("A", 1.2, ra, 2000.0));
  m.bodies.push_back(makeStrut("B", 1.0, rb, 2000.0));
  for (Body& b : m.bodies)
  {
    b.layers.back().youngs_modulus = 2.0e7;
    b.layers.back().poisson_ratio = 0.45;
  }
  finalizeModel(m);
  m.contact.enabled = true;
  m.contact.friction = mu;
  m.contact.restitution = restitution;
  m.contact.stick_velocity = 0.01;
  m.contact.slip_velocity = 0.1;
  m.listed_pairs.push_back(makeStrutPair(m, 0, 1));
  m.q0.setZero(m.nq);
  return m;
}

Vec3 randomUnit(std::mt19937& rng)
{
  std::normal_distribution<double> n(0.0, 1.0);
  return Vec3(n(rng), n(rng), n(rng)).normalized();
}

// a crossing: strut A through the origin along a random axis, B's axis at a random angle (above
// 25 degrees), the closest points at random interior stations, the surfaces overlapping by `overlap`
// (negative: apart). Each Theta is then scaled by (1 + 1e-3 * random) off the unit sphere.
Eigen::VectorXd crossing(const Model& m, double overlap, std::mt19937& rng, bool off_sphere = true)
{
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Body& a = m.bodies[0];
  const Body& b = m.bodies[1];
  const Vec3 ax = randomUnit(rng);
  Vec3 bx;
  do
    bx = randomUnit(rng);
  while (std::abs(ax.dot(bx)) > std::cos(25.0 * M_PI / 180.0));
  const Vec3 n = ax.cross(bx).normalized();
  const double s1 = 0.3 * a.length * u(rng), s2 = 0.3 * b.length * u(rng);
  const Vec3 p1 = Vec3(0.1, -0.2, 0.3) + s1 * ax;
  const Vec3 p2 = p1 - (a.radius() + b.radius() - overlap) * n;
  Eigen::VectorXd q(m.nq);
  q.segment<3>(0) = p1 - s1 * ax;
  q.segment<4>(3) = thetaFromZAxis(ax);
  q.segment<3>(7) = p2 - s2 * bx;
  q.segment<4>(10) = thetaFromZAxis(bx);
  if (off_sphere)
  {
    q.segment<4>(3) *= 1.0 + 1e-3 * u(rng);
    q.segment<4>(10) *= 1.0 + 1e-3 * u(rng);
  }
  return q;
}

Eigen::VectorXd contactForceOf(const Model& m, const Eigen::VectorXd& q, const Eigen::VectorXd& qd, double v0,
                               ContactMode mode)
{
  ContactContribution c;
  evaluateContact(m, 0, q, qd, v0, mode, &c);
  return c.force;
}

// checks K = -dQ/dq and C = -dQ/dqd at (q, qd)
void expectExactTangents(const Model& m, const Eigen::VectorXd& q, const Eigen::VectorXd& qd, double v0,
                         ContactMode mode, const std::string& what)
{
  ContactContribution c;
  evaluateContact(m, 0, q, qd, v0, mode, &c);
  const auto fq = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return -contactForceOf(m, x, qd, v0, mode); };
  const auto fqd = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd { return -contactForceOf(m, q, x, v0, mode); };
  const double scale = std::max(1.0, c.force.lpNorm<Eigen::Infinity>());
  const FdComparison ck = compareJacobians(c.stiffness, fdJacobian(fq, q, 1e-7), kTol, scale);
  EXPECT_TRUE(ck.ok) << what << ", K: " << ck.message;
  const FdComparison cc = compareJacobians(c.damping, fdJacobian(fqd, qd, 1e-7), kTol, scale);
  EXPECT_TRUE(cc.ok) << what << ", C: " << cc.message;
}

// velocities whose slip speed is `slip` (m/s) at q: random, then scaled (the slip is linear in qd);
// drawn again until the hysteresis factor 1 + D zeta_dot (D for impact speed v0) is in [0.5, 1.5]
Eigen::VectorXd velocitiesWithSlip(const Model& m, const Eigen::VectorXd& q, double slip, double v0, std::mt19937& rng)
{
  Model with_friction = m;
  with_friction.contact.friction = 1.0;
  const double d = 3.0 * (1.0 - m.contact.restitution * m.contact.restitution) / (4.0 * v0);
  for (;;)
  {
    Eigen::VectorXd qd = randomVector(m.nq, 1.0, rng);
    const ContactPairState st = evaluateContact(with_friction, 0, q, qd, 1e9, ContactMode::kDynamic, nullptr);
    qd *= slip / st.slip_speed;
    if (std::abs(d * st.penetration_rate * slip / st.slip_speed) <= 0.5)
      return qd;
  }
}
}  // namespace

TEST(ContactStiffness, RightCrossingIsJohnsonsAndGrowsAsTheStrutsAlign)
{
  const Model m = twoStruts(0.0, 1.0);
  const double estar = 1.0 / (2.0 * (1.0 - 0.45 * 0.45) / 2.0e7);
  const double k90 = 4.0 / 3.0 * estar * std::sqrt(std::sqrt(0.04 * 0.05));
  EXPECT_NEAR(m.checkedPairList()[0].stiffness90, k90, 1e-9 * k90);
  // Re = sqrt(r1 r2) / |sin theta| (Eq. 31-32 with R' = inf): K = k90 / sqrt(sin theta)
  for (double deg : { 90.0, 60.0, 30.0, 15.0 })
  {
    const double c = std::cos(deg * M_PI / 180.0);
    const StiffnessValue v = contactStiffness(k90, c * c, 10.0 * M_PI / 180.0);
    EXPECT_NEAR(v.k, k90 / std::sqrt(std::sin(deg * M_PI / 180.0)), 1e-9 * k90) << deg;
    const double d = 1e-7;
    const double fd =
        (contactStiffness(k90, c * c + d, 0.1745).k - contactStiffness(k90, c * c - d, 0.1745).k) / (2 * d);
    EXPECT_NEAR(v.dk_dc2, fd, 1e-5 * std::abs(fd) + 1e-9) << deg;
  }
  // below the floor angle K is capped at its value there
  const double c5 = std::cos(5.0 * M_PI / 180.0);
  const StiffnessValue capped = contactStiffness(k90, c5 * c5, 10.0 * M_PI / 180.0);
  EXPECT_NEAR(capped.k, k90 / std::sqrt(std::sin(10.0 * M_PI / 180.0)), 1e-9 * k90);
  EXPECT_EQ(capped.dk_dc2, 0.0);
  EXPECT_TRUE(std::isfinite(contactStiffness(k90, 1.0, 10.0 * M_PI / 180.0).k));
}

TEST(ContactTangent, NoContactNoForceNoTangent)
{
  std::mt19937 rng(1);
  const Model m = twoStruts(0.3, 0.5);
  const Eigen::VectorXd q = crossing(m, -1e-3, rng);
  const Eigen::VectorXd qd = randomVector(m.nq, 1.0, rng);
  ContactContribution c;
  const ContactPairState st = evaluateContact(m, 0, q, qd, 0.1, ContactMode::kDynamic, &c);
  EXPECT_FALSE(st.active);
  EXPECT_NEAR(st.gap, 1e-3, 1e-9);
  EXPECT_EQ(c.force.norm(), 0.0);
  EXPECT_EQ(c.stiffness.norm(), 0.0);
  EXPECT_EQ(c.damping.norm(), 0.0);
}

TEST(ContactTangent, HertzStaticsIsExactForRandomCrossings)
{
  std::mt19937 rng(2);
  const Model m = twoStruts(0.3, 0.5);
  for (int k = 0; k < 20; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 2e-3, rng);
    const ContactPairState st =
        evaluateContact(m, 0, q, Eigen::VectorXd::Zero(m.nq), 0.0, ContactMode::kStatic, nullptr);
    ASSERT_TRUE(st.active);
    ASSERT_EQ(st.region, ClosestRegion::kInterior);
    expectExactTangents(m, q, Eigen::VectorXd::Zero(m.nq), 0.0, ContactMode::kStatic, "static " + std::to_string(k));
  }
}

TEST(ContactTangent, DampedNormalForceBelowTheStickVelocityIsExact)
{
  std::mt19937 rng(3);
  const Model m = twoStruts(0.3, 0.5);
  for (int k = 0; k < 20; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 2e-3, rng);
    const Eigen::VectorXd qd = velocitiesWithSlip(m, q, 0.5 * m.contact.stick_velocity, 0.05, rng);
    const ContactPairState st = evaluateContact(m, 0, q, qd, 0.05, ContactMode::kDynamic, nullptr);
    ASSERT_GT(st.normal_force, 0.0);
    ASSERT_EQ(st.friction_force, 0.0);
    expectExactTangents(m, q, qd, 0.05, ContactMode::kDynamic, "below v0, " + std::to_string(k));
  }
}

TEST(ContactTangent, FrictionBetweenTheToleranceVelocitiesIsExact)
{
  std::mt19937 rng(4);
  const Model m = twoStruts(0.3, 0.5);
  for (int k = 0; k < 20; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 2e-3, rng);
    const Eigen::VectorXd qd = velocitiesWithSlip(m, q, 0.05, 0.05, rng);  // v0 = 0.01, v1 = 0.1
    const ContactPairState st = evaluateContact(m, 0, q, qd, 0.05, ContactMode::kDynamic, nullptr);
    ASSERT_GT(st.friction_force, 0.0);
    ASSERT_LT(st.friction_force, 0.3 * st.normal_force);
    expectExactTangents(m, q, qd, 0.05, ContactMode::kDynamic, "between v0 and v1, " + std::to_string(k));
  }
}

TEST(ContactTangent, FullFrictionAboveTheSlipVelocityIsExact)
{
  std::mt19937 rng(5);
  const Model m = twoStruts(0.3, 0.5);
  for (int k = 0; k < 20; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 2e-3, rng);
    const Eigen::VectorXd qd = velocitiesWithSlip(m, q, 0.4, 0.5, rng);
    const ContactPairState st = evaluateContact(m, 0, q, qd, 0.5, ContactMode::kDynamic, nullptr);
    ASSERT_GT(st.normal_force, 0.0);
    ASSERT_NEAR(st.friction_force, 0.3 * st.normal_force, 1e-9 * st.normal_force);
    expectExactTangents(m, q, qd, 0.5, ContactMode::kDynamic, "above v1, " + std::to_string(k));
  }
}

TEST(ContactTangent, EndAgainstSideIsExact)
{
  // strut B's end presses on A's side: s2 is clamped, s1 moves
  const Model m = twoStruts(0.3, 0.5);
  std::mt19937 rng(6);
  for (int k = 0; k < 10; ++k)
  {
    const Vec3 ax = Vec3(1.0, 0.2, -0.1).normalized();
    const Vec3 bx = (Vec3(0.1, 0.3, 1.0) + 0.2 * randomUnit(rng)).normalized();
    Eigen::VectorXd q(m.nq);
    q.segment<3>(0) = Vec3::Zero();
    q.segment<4>(3) = thetaFromZAxis(ax);
    // B's lower end (its axis point) sits 2 mm closer to A's axis than r_A + r_B, near A's middle, in
    // the direction n of bx normal to ax: B leans away from A, so its end is its closest point
    const Vec3 n = (bx - bx.dot(ax) * ax).normalized();
    const Vec3 end = 0.1 * ax + (m.bodies[0].radius() + m.bodies[1].radius() - 2e-3) * n;
    q.segment<3>(7) = end + 0.5 * m.bodies[1].length * bx;
    q.segment<4>(10) = thetaFromZAxis(bx);
    const ContactPairState st0 = contactGeometry(m, 0, q);
    ASSERT_EQ(st0.region, ClosestRegion::kEnd);
    EXPECT_NEAR(st0.penetration, 2e-3, 1e-12);
    const Eigen::VectorXd qd = velocitiesWithSlip(m, q, 0.4, 0.5, rng);
    const ContactPairState st = evaluateContact(m, 0, q, qd, 0.5, ContactMode::kDynamic, nullptr);
    ASSERT_TRUE(st.active);
    ASSERT_GT(st.normal_force, 0.0);
    // the normal runs from B's end to A's axis: A is pushed away from B's end
    EXPECT_NEAR(st.normal.dot(-n), 1.0, 1e-9);
    EXPECT_GT((st.force_on_a - st.friction_on_a).dot(-n), 0.0);
    expectExactTangents(m, q, qd, 0.5, ContactMode::kDynamic, "end against side, " + std::to_string(k));
  }
}

TEST(ContactTangent, CombinedIntoTheSystemTangent)
{
  // System::contactForce places the pair's blocks where the global matrix expects them
  std::mt19937 rng(7);
  const Model m = twoStruts(0.3, 0.5);
  const System sys(m);
  const Eigen::VectorXd q = crossing(m, 2e-3, rng);
  const Eigen::VectorXd qd = velocitiesWithSlip(m, q, 0.4, 0.5, rng);
  const SlotValues v0(1, 0.5);
  BlockSparseMatrix jac = sys.makeMatrix();
  Eigen::VectorXd F = Eigen::VectorXd::Zero(m.nq);
  sys.contactForce(q, qd, v0, ContactMode::kDynamic, F, &jac, 2.0, 3.0);
  ContactContribution c;
  evaluateContact(m, 0, q, qd, 0.5, ContactMode::kDynamic, &c);
  EXPECT_TRUE(F.isApprox(Eigen::VectorXd(c.force)));
  EXPECT_TRUE(denseBlock(jac, 14, 14).isApprox(2.0 * c.stiffness + 3.0 * c.damping));
}

TEST(ContactForce, ActionEqualsReactionAndActsAtTheContactPoints)
{
  std::mt19937 rng(8);
  const Model m = twoStruts(0.3, 0.5);
  for (int k = 0; k < 10; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 2e-3, rng, false);
    const Eigen::VectorXd qd = velocitiesWithSlip(m, q, 0.4, 0.5, rng);
    ContactContribution c;
    const ContactPairState st = evaluateContact(m, 0, q, qd, 0.5, ContactMode::kDynamic, &c);
    // translational parts: the force on A and its opposite on B
    EXPECT_TRUE(c.force.head<3>().isApprox(st.force_on_a, 1e-12));
    EXPECT_TRUE(c.force.segment<3>(7).isApprox(-st.force_on_a, 1e-12));
    // the normal force pushes A away from B, along n, at the right magnitude
    EXPECT_GT(st.force_on_a.dot(st.normal), 0.0);
    EXPECT_NEAR((st.force_on_a - st.friction_on_a).dot(st.normal), st.normal_force, 1e-9 * st.normal_force);
    // the contact points lie on each surface, penetration apart along n
    EXPECT_NEAR((st.point_a - st.point_b).dot(st.normal), -st.penetration, 1e-12);
  }
}

TEST(ContactForce, FrictionNeverAddsEnergy)
{
  // on the unit sphere with consistent velocities, the friction power -F_T |v_T| is never positive
  std::mt19937 rng(9);
  const Model m = twoStruts(0.3, 1.0);
  Model frictionless = m;
  frictionless.contact.friction = 0.0;
  for (int k = 0; k < 50; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 2e-3, rng, false);
    Eigen::VectorXd qd = randomVector(m.nq, 1.0, rng);
    for (int b = 0; b < 2; ++b)
    {
      const Vec4 th = q.segment<4>(7 * b + 3);
      qd.segment<4>(7 * b + 3) -= th.dot(qd.segment<4>(7 * b + 3)) * th;  // Theta . Theta_dot = 0
    }
    const double p_all = contactForceOf(m, q, qd, 0.5, ContactMode::kDynamic).dot(qd);
    const double p_normal = contactForceOf(frictionless, q, qd, 0.5, ContactMode::kDynamic).dot(qd);
    const ContactPairState st = evaluateContact(m, 0, q, qd, 0.5, ContactMode::kDynamic, nullptr);
    EXPECT_LE(p_all - p_normal, 1e-9 * std::max(1.0, std::abs(p_normal))) << k;
    if (st.slip_speed > m.contact.stick_velocity)
    {
      EXPECT_NEAR(p_all - p_normal, -st.friction_force * st.slip_speed,
                  1e-6 * st.friction_force * st.slip_speed + 1e-12);
    }
  }
}

TEST(ContactForce, ZeroFrictionCoefficientSkipsFriction)
{
  std::mt19937 rng(10);
  const Model m = twoStruts(0.0, 0.5);
  const Eigen::VectorXd q = crossing(m, 2e-3, rng);
  const Eigen::VectorXd qd = velocitiesWithSlip(m, q, 0.4, 0.5, rng);
  const ContactPairState st = evaluateContact(m, 0, q, qd, 0.5, ContactMode::kDynamic, nullptr);
  EXPECT_GT(st.normal_force, 0.0);
  EXPECT_EQ(st.friction_force, 0.0);
  EXPECT_EQ(st.slip_speed, 0.0);  // not even computed
}

TEST(ContactForce, SeparatingFastNeverPulls)
{
  // 1 + D zeta_dot < 0: the Lankarani-Nikravesh force would pull; it is cut at zero, with no tangent
  std::mt19937 rng(11);
  const Model m = twoStruts(0.3, 0.0);
  const Eigen::VectorXd q = crossing(m, 2e-3, rng, false);
  Eigen::VectorXd qd = Eigen::VectorXd::Zero(m.nq);
  const ContactPairState g = contactGeometry(m, 0, q);
  qd.segment<3>(0) = 1.0 * g.normal;  // A leaves B at 1 m/s; D = 0.75 / v0
  ContactContribution c;
  const ContactPairState st = evaluateContact(m, 0, q, qd, 0.1, ContactMode::kDynamic, &c);
  EXPECT_TRUE(st.active);
  EXPECT_LT(st.penetration_rate, -0.9);
  EXPECT_EQ(st.normal_force, 0.0);
  EXPECT_EQ(c.force.norm(), 0.0);
  EXPECT_EQ(c.stiffness.norm(), 0.0);
}

TEST(ContactSpecialCases, ParallelStrutsPressedTogetherPushApart)
{
  const Model m = twoStruts(0.3, 0.5);
  for (double tilt : { 0.0, 1e-9, 1e-6, 1e-3 })
  {
    Eigen::VectorXd q(m.nq);
    q.segment<3>(0) = Vec3::Zero();
    q.segment<4>(3) = thetaFromZAxis(Vec3::UnitZ());
    q.segment<3>(7) = Vec3(0.088, 0.0, 0.1);  // overlap 2 mm
    q.segment<4>(10) = thetaFromZAxis(Vec3(tilt, 0.0, 1.0));
    const Eigen::VectorXd qd = Eigen::VectorXd::Zero(m.nq);
    ContactContribution c;
    const ContactPairState st = evaluateContact(m, 0, q, qd, 0.1, ContactMode::kDynamic, &c);
    ASSERT_TRUE(st.active) << tilt;
    EXPECT_TRUE(c.force.allFinite() && c.stiffness.allFinite() && c.damping.allFinite()) << tilt;
    EXPECT_NEAR(st.penetration, 2e-3 + 0.5 * tilt, 1e-6) << tilt;  // B's lower end leans towards A
    EXPECT_NEAR(st.normal.x(), -1.0, 1e-3) << tilt;                // A is pushed to -x, away from B
    EXPECT_LT(c.force(0), 0.0) << tilt;
    EXPECT_GT(c.force(7), 0.0) << tilt;
    // the capped stiffness: never above K at the floor angle
    EXPECT_LE(st.stiffness,
              m.checkedPairList()[0].stiffness90 / std::sqrt(std::sin(m.contact.min_crossing_angle)) * (1 + 1e-12));
  }
}

TEST(ContactSpecialCases, StrutsMeetingEndToEndPushAlongTheirAxes)
{
  const Model m = twoStruts(0.3, 0.5);
  Eigen::VectorXd q(m.nq);
  const Vec3 axis = Vec3(0.3, -0.2, 1.0).normalized();
  q.segment<3>(0) = Vec3::Zero();
  q.segment<4>(3) = thetaFromZAxis(axis);
  // B collinear above A, its lower end 2 mm past A's upper end... then shifted sideways less than the radii
  q.segment<3>(7) = (0.6 + 0.5 + 0.085) * axis;
  q.segment<4>(10) = thetaFromZAxis(axis);
  const Eigen::VectorXd qd = Eigen::VectorXd::Zero(m.nq);
  ContactContribution c;
  const ContactPairState st = evaluateContact(m, 0, q, qd, 0.1, ContactMode::kDynamic, &c);
  ASSERT_TRUE(st.active);
  EXPECT_TRUE(c.force.allFinite() && c.stiffness.allFinite() && c.damping.allFinite());
  EXPECT_NEAR(st.normal.dot(axis), -1.0, 1e-9);  // A is pushed down its axis, B up
  EXPECT_NEAR(st.penetration, 0.005, 1e-9);
  EXPECT_LT(c.force.head<3>().dot(axis), 0.0);
}

TEST(ContactSpecialCases, AxesThroughEachOtherStayFinite)
{
  // a deep, unphysical overlap (axes intersecting): finite forces along the common normal
  const Model m = twoStruts(0.3, 0.5);
  Eigen::VectorXd q(m.nq);
  q.segment<3>(0) = Vec3::Zero();
  q.segment<4>(3) = thetaFromZAxis(Vec3::UnitX());
  q.segment<3>(7) = Vec3(0.0, 0.0, 0.0);
  q.segment<4>(10) = thetaFromZAxis(Vec3::UnitY());
  std::mt19937 rng(12);
  ContactContribution c;
  const ContactPairState st = evaluateContact(m, 0, q, randomVector(m.nq, 1.0, rng), 0.1, ContactMode::kDynamic, &c);
  EXPECT_TRUE(st.active);
  EXPECT_NEAR(std::abs(st.normal.z()), 1.0, 1e-12);
  EXPECT_TRUE(c.force.allFinite() && c.stiffness.allFinite() && c.damping.allFinite());
}

TEST(ContactForce, ForceWithoutTangentsIsTheSameForce)
{
  // the residual-only path (modified Newton) must give the force the full evaluation gives, in every
  // friction regime and in statics
  std::mt19937 rng(12);
  const Model m = twoStruts(0.3, 0.5);
  int with_friction = 0;
  for (int k = 0; k < 30; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 2e-3, rng);
    const double slip = k % 3 == 0 ? 0.005 : (k % 3 == 1 ? 0.05 : 0.5);
    const Eigen::VectorXd qd = velocitiesWithSlip(m, q, slip, 0.05, rng);
    for (ContactMode mode : { ContactMode::kDynamic, ContactMode::kStatic })
    {
      ContactContribution full, alone;
      alone.tangents = false;
      const ContactPairState a = evaluateContact(m, 0, q, qd, 0.05, mode, &full);
      const ContactPairState b = evaluateContact(m, 0, q, qd, 0.05, mode, &alone);
      ASSERT_TRUE(a.active);
      EXPECT_EQ(a.normal_force, b.normal_force);
      EXPECT_LE((full.force - alone.force).norm(), 1e-12 * full.force.norm()) << k;
      with_friction += a.friction_force > 0.0 ? 1 : 0;
    }
  }
  EXPECT_GT(with_friction, 10);
}

namespace
{
// twoStruts with steel cores (radius 1.5 cm, E = 210 GPa) inside the rubber-like sleeves: both struts, or strut
// A alone
Model layeredStruts(double mu, double restitution, bool both = true)
{
  Model m = twoStruts(mu, restitution);
  for (size_t i = 0; i < (both ? 2u : 1u); ++i)
    addSteelCore(m.bodies[i], 0.015);
  m.listed_pairs[0] = makeStrutPair(m, 0, 1);
  return m;
}

// the same crossing (seed) at another overlap
Eigen::VectorXd crossingAt(const Model& m, double overlap, unsigned seed)
{
  std::mt19937 rng(seed);
  return crossing(m, overlap, rng);
}
}  // namespace

TEST(LayeredContact, CoresMeetAtTheSleevesThicknessWithTheirOwnHertzStiffness)
{
  const Model plain = twoStruts(0.0, 1.0);
  const Model both = layeredStruts(0.0, 1.0), one = layeredStruts(0.0, 1.0, false);
  EXPECT_EQ(plain.checkedPairList()[0].core_stiffness90, 0.0);
  const double steel = 1.0 / (2.0 * (1.0 - 0.09) / 210e9);
  EXPECT_NEAR(both.checkedPairList()[0].core_gap, (0.04 - 0.015) + (0.05 - 0.015), 1e-15);
  EXPECT_NEAR(both.checkedPairList()[0].core_stiffness90, 4.0 / 3.0 * steel * std::sqrt(0.015), 1e-6);
  // a strut without a core meets the other's core with its one layer
  const double mixed = 1.0 / ((1.0 - 0.09) / 210e9 + (1.0 - 0.45 * 0.45) / 2.0e7);
  EXPECT_NEAR(one.checkedPairList()[0].core_gap, 0.04 - 0.015, 1e-15);
  EXPECT_NEAR(one.checkedPairList()[0].core_stiffness90, 4.0 / 3.0 * mixed * std::pow(0.015 * 0.05, 0.25), 1e-6);
  // the sleeves' stiffness is the plain struts'
  EXPECT_EQ(both.checkedPairList()[0].stiffness90, plain.checkedPairList()[0].stiffness90);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(plain.nq);
  for (const Model* m : { &both, &one })
  {
    const double t = m->checkedPairList()[0].core_gap;
    for (double overlap : { 0.5 * t, t - 1e-6, t + 1e-6, t + 2e-3 })
    {
      const Eigen::VectorXd q = crossingAt(*m, overlap, 21);
      const ContactPairState s = evaluateContact(*m, 0, q, zero, 0.0, ContactMode::kStatic, nullptr);
      const ContactPairState p = evaluateContact(plain, 0, q, zero, 0.0, ContactMode::kStatic, nullptr);
      ASSERT_TRUE(s.active);
      EXPECT_NEAR(s.penetration, overlap, 1e-12);
      if (overlap < t)
      {
        // below the thickness: the sleeves' law alone, as without cores
        EXPECT_EQ(s.normal_force, p.normal_force) << overlap;
        EXPECT_EQ(s.core_penetration, 0.0);
      }
      else
      {
        const double zc = overlap - t;
        EXPECT_NEAR(s.core_penetration, zc, 1e-12);
        // K_c follows the crossing angle as K does: K_c / K = core_stiffness90 / stiffness90
        EXPECT_NEAR(s.core_stiffness / s.stiffness,
                    m->checkedPairList()[0].core_stiffness90 / m->checkedPairList()[0].stiffness90,
                    1e-12 * s.core_stiffness);
        EXPECT_NEAR(s.normal_force, p.normal_force + s.core_stiffness * zc * std::sqrt(zc), 1e-9 * s.normal_force)
            << overlap;
      }
    }
  }
}

TEST(LayeredContact, TangentsAreExactOnBothSidesOfTheSwitch)
{
  std::mt19937 rng(22);
  for (bool both : { true, false })
  {
    const Model m = layeredStruts(0.3, 0.5, both);
    const double t = m.checkedPairList()[0].core_gap;
    for (int k = 0; k < 8; ++k)
    {
      const double overlap = t + (k % 4 == 0 ? -1e-3 : k % 4 == 1 ? -1e-4 : k % 4 == 2 ? 1e-4 : 1e-3);
      const Eigen::VectorXd q = crossing(m, overlap, rng);
      const std::string what = std::string(both ? "two cores" : "one core") + ", overlap " + std::to_string(overlap);
      expectExactTangents(m, q, Eigen::VectorXd::Zero(m.nq), 0.0, ContactMode::kStatic, "static, " + what);
      const Eigen::VectorXd qd = velocitiesWithSlip(m, q, 0.05, 0.05, rng);
      expectExactTangents(m, q, qd, 0.05, ContactMode::kDynamic, "dynamic, " + what);
      EXPECT_EQ(evaluateContact(m, 0, q, qd, 0.05, ContactMode::kDynamic, nullptr).core_penetration > 0.0, overlap > t);
    }
  }
}

TEST(LayeredContact, ForceAndTangentAreContinuousAtTheSwitch)
{
  // F = K zeta^1.5 + K_c (zeta - t)^1.5: the core's term and its derivative 1.5 K_c (zeta - t)^0.5 start at zero,
  // so force and tangent just below and just above the switch differ by O(delta) and O(K_c sqrt(delta))
  const Model m = layeredStruts(0.0, 1.0);
  const double t = m.checkedPairList()[0].core_gap;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.nq);
  double previous = INFINITY;
  for (double delta : { 1e-6, 1e-8, 1e-10 })
  {
    ContactContribution below, above;
    evaluateContact(m, 0, crossingAt(m, t - delta, 23), zero, 0.0, ContactMode::kStatic, &below);
    evaluateContact(m, 0, crossingAt(m, t + delta, 23), zero, 0.0, ContactMode::kStatic, &above);
    const double scale = below.stiffness.cwiseAbs().maxCoeff();
    const double jump = (above.stiffness - below.stiffness).cwiseAbs().maxCoeff() / scale;
    const double kc = m.checkedPairList()[0].core_stiffness90;
    // the core's tangent at delta is about 1.5 K_c sqrt(delta) (times the crossing angle's factor, <= 1.4)
    EXPECT_LT(jump, 3.0 * kc * std::sqrt(delta) / scale + 1e-9) << delta;
    // no step: a hundredth of delta, a tenth of the difference (sqrt), not a floor
    if (std::isfinite(previous))
    {
      EXPECT_GT(jump, 0.05 * previous) << delta;
      EXPECT_LT(jump, 0.2 * previous) << delta;
    }
    previous = jump;
    EXPECT_LT((above.force - below.force).cwiseAbs().maxCoeff(), 1e-3 * below.force.cwiseAbs().maxCoeff());
  }
}

TEST(ContactTunnelling, OnlyAxisSegmentsThatCrossArePassages)
{
  // strut A (length 1.2, radius 4 cm) along x about the origin; strut B (radius 5 cm) along y, moved down
  // through z = 0 at x = x_b. Through A's axis (|x_b| < 0.6): a passage. Beyond A's end but within B's radius
  // of it (0.6 < |x_b| < 0.65): B's axis passes A's end cap, the closest points run round the end and the
  // normal turns continuously: not a passage. Far beyond: no contact at all.
  const Model m = twoStruts(0.0, 1.0);
  const auto state = [&](double x_b, double z_b)
  {
    Eigen::VectorXd q(m.nq);
    q.segment<3>(0) = Vec3::Zero();
    q.segment<4>(3) = thetaFromZAxis(Vec3::UnitX());
    q.segment<3>(7) = Vec3(x_b, 0.0, z_b);
    q.segment<4>(10) = thetaFromZAxis(Vec3::UnitY());
    return q;
  };
  for (double x_b : { 0.0, 0.3, 0.59 })
    EXPECT_TRUE(passedThrough(m, 0, state(x_b, 0.01), state(x_b, -0.01))) << x_b;
  for (double x_b : { 0.61, 0.64, 0.7 })
    EXPECT_FALSE(passedThrough(m, 0, state(x_b, 0.01), state(x_b, -0.01))) << x_b;
  // moving apart or staying on one side: no passage
  EXPECT_FALSE(passedThrough(m, 0, state(0.3, 0.01), state(0.3, 0.02)));
}

namespace
{
// the pair of twoStruts() on the linear law: k = 2e5 N/m, c = 40 N s/m
Model twoStrutsLinear(double mu)
{
  Model m = twoStruts(mu, 1.0);
  m.contact.law = ContactLaw::kLinear;
  m.contact.linear_stiffness = 2e5;
  m.contact.linear_damping = 40.0;
  return m;
}
}  // namespace

TEST(LinearLaw, NormalForceIsTheSpringDashpotAtEveryCrossingAngle)
{
  std::mt19937 rng(21);
  const Model m = twoStrutsLinear(0.0);
  for (int k = 0; k < 10; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 1e-3 * (1 + k), rng, false);
    const Eigen::VectorXd qd = randomVector(m.nq, 0.05, rng);
    const ContactPairState st = evaluateContact(m, 0, q, qd, 0.0, ContactMode::kDynamic, nullptr);
    ASSERT_TRUE(st.active);
    // no crossing-angle factor, no restitution: k zeta + c zeta_dot
    EXPECT_NEAR(st.normal_force, std::max(0.0, 2e5 * st.penetration + 40.0 * st.penetration_rate), 1e-9);
    EXPECT_EQ(st.stiffness, 2e5);
    // statics: the spring alone; the stored energy is k zeta^2 / 2
    const ContactPairState s0 = evaluateContact(m, 0, q, qd, 0.0, ContactMode::kStatic, nullptr);
    EXPECT_NEAR(s0.normal_force, 2e5 * s0.penetration, 1e-9);
    EXPECT_NEAR(contactElasticEnergy(m, s0), 0.5 * 2e5 * s0.penetration * s0.penetration, 1e-12);
  }
}

TEST(LinearLaw, TangentsAreExactStaticDampedAndWithFriction)
{
  std::mt19937 rng(22);
  const Model m = twoStrutsLinear(0.3);
  Model frictionless = m;
  frictionless.contact.friction = 0.0;
  for (int k = 0; k < 10; ++k)
  {
    const Eigen::VectorXd q = crossing(m, 2e-3, rng);
    const std::string what = "linear " + std::to_string(k);
    expectExactTangents(m, q, Eigen::VectorXd::Zero(m.nq), 0.0, ContactMode::kStatic, what + " static");
    // slips below v0, between v0 and v1 and above v1, the damper within half the spring's force
    for (double slip : { 0.005, 0.05, 0.4 })
    {
      Eigen::VectorXd qd;
      ContactPairState st;
      do
      {
        qd = velocitiesWithSlip(frictionless, q, slip, 1e9, rng);
        st = evaluateContact(m, 0, q, qd, 0.0, ContactMode::kDynamic, nullptr);
      } while (std::abs(40.0 * st.penetration_rate) > 0.5 * 2e5 * st.penetration);
      ASSERT_GT(st.normal_force, 0.0);
      expectExactTangents(m, q, qd, 0.0, ContactMode::kDynamic, what + " slip " + std::to_string(slip));
      expectExactTangents(frictionless, q, qd, 0.0, ContactMode::kDynamic, what + " frictionless");
    }
  }
}

TEST(LinearLaw, SeparatingFasterThanTheSpringHoldsNeverPulls)
{
  // k zeta + c zeta_dot < 0 while the surfaces still overlap: no force and no tangent
  std::mt19937 rng(23);
  const Model m = twoStrutsLinear(0.3);
  const Eigen::VectorXd q = crossing(m, 2e-3, rng, false);
  Eigen::VectorXd qd = Eigen::VectorXd::Zero(m.nq);
  qd.segment<3>(0) = 20.0 * contactGeometry(m, 0, q).normal;  // c zeta_dot = -800 N against k zeta = 400 N
  ContactContribution c;
  const ContactPairState st = evaluateContact(m, 0, q, qd, 0.0, ContactMode::kDynamic, &c);
  EXPECT_TRUE(st.active);
  EXPECT_EQ(st.normal_force, 0.0);
  EXPECT_EQ(c.force.norm(), 0.0);
  EXPECT_EQ(c.stiffness.norm(), 0.0);
  EXPECT_EQ(c.damping.norm(), 0.0);
}

namespace
{
// the core's evaluation at body poses (the natural coordinates' law on the struts' end nodes and spin rates) against
// the body coordinates' law: the same state and force
// rates of unit Euler parameters: each strut's Theta_dot with its part along Theta taken out (poses carry no scaling)
Eigen::VectorXd onTheUnitSphere(const Model& m, const Eigen::VectorXd& q, Eigen::VectorXd qd)
{
  for (const Body& b : m.bodies)
    if (b.kind == BodyKind::kStrut)
    {
      const Vec4 theta = q.segment<4>(b.offset + 3);
      qd.segment<4>(b.offset + 3) -= theta.dot(qd.segment<4>(b.offset + 3)) * theta;
    }
  return qd;
}

void expectSameContact(const Model& m, int slot, const Eigen::VectorXd& q, const Eigen::VectorXd& qd_any, double v0,
                       ContactMode mode, const std::string& what)
{
  const Eigen::VectorXd qd = onTheUnitSphere(m, q, qd_any);
  const ContactPairState a = evaluateContact(m, slot, q, qd, v0, mode);
  const ContactPairState b = evaluateContact(m, slot, q, qd, v0, mode, nullptr);
  ASSERT_TRUE(b.active) << what;
  ASSERT_EQ(a.active, b.active) << what;
  const double scale = std::max(1.0, b.normal_force);
  EXPECT_NEAR(a.penetration, b.penetration, 1e-12) << what;
  EXPECT_NEAR(a.penetration_rate, b.penetration_rate, 1e-10) << what;
  EXPECT_NEAR(a.normal_force, b.normal_force, 1e-9 * scale) << what;
  EXPECT_NEAR(a.friction_force, b.friction_force, 1e-9 * scale) << what;
  EXPECT_NEAR(a.slip_speed, b.slip_speed, 1e-10) << what;
  EXPECT_LT((a.force_on_a - b.force_on_a).norm(), 1e-9 * scale) << what;
  EXPECT_LT((a.point_a - b.point_a).norm(), 1e-12) << what;
  EXPECT_EQ(a.body_a, b.body_a) << what;
  EXPECT_EQ(a.body_b, b.body_b) << what;
}
}  // namespace

TEST(ContactAtPoses, AgreesWithTheBodyCoordinatesLawInEveryRegime)
{
  std::mt19937 rng(23);
  const double v0 = 0.5;
  for (const Model& m : { twoStruts(0.4, 0.6), layeredStruts(0.4, 0.6) })
    for (int trial = 0; trial < 8; ++trial)
    {
      // unit Theta (poses, not Newton iterates); overlaps past the layered struts' sleeves too
      const Eigen::VectorXd q = crossing(m, 1e-3 * (1 + 4 * trial), rng, false);
      const std::string what = m.bodies[0].layers.size() > 1 ? "layered " : "plain ";
      expectSameContact(m, 0, q, Eigen::VectorXd::Zero(m.nq), 0.0, ContactMode::kStatic,
                        what + std::to_string(trial) + " static");
      // about held (below v0 = 0.01 m/s), on the ramp and sliding (the rates made tangent to the unit sphere then)
      for (double slip : { 0.005, 0.05, 0.5 })
        expectSameContact(m, 0, q, velocitiesWithSlip(m, q, slip, v0, rng), v0, ContactMode::kDynamic,
                          what + std::to_string(trial) + " slip " + std::to_string(slip));
    }
}
