// The cable law of core/cable: energy and power consistent with the force. The conservative power is
// -dV/dt (central differences along a motion) and -F . qd of the undamped force; the two powers add up
// to F . qd; the non-conservative power never is positive while the actuator holds still; at rest
// length and when slack there is no force, no energy and no power. (The force's tangents against
// finite differences: test_mechanics, test_sliding_cable.) The law along the cable against closed forms.
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/oracle/body_kinematics.h"
#include "active_tensegrity/core/elements/cable.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
/// mixedModel's cables (two points each, damped and undamped, strut-strut, strut-ground, strut-mass),
/// a sliding cable ground -> strut A -> strut B -> mass M, a material cable pulled in by actuator 0 and a
/// soft, strongly damped cable.
Model cableModel()
{
  Model m = mixedModel();
  Cable slide;
  slide.name = "slide";
  slide.points = { PointRef{ -1, Vec3(-0.8, 0.1, 0.0) }, PointRef{ 0, Vec3(0.0, 0.0, 0.2) },
                   PointRef{ 1, Vec3(0.01, 0.0, -0.1) }, PointRef{ 2, Vec3::Zero() } };
  slide.stiffness = 4000.0;
  slide.rest_length = 1.0;
  slide.damping = 6.0;
  m.cables.push_back(slide);
  Cable winch =
      makeCable("winch", PointRef{ 1, Vec3(0.0, 0.0, 0.5) }, PointRef{ -1, Vec3(0.4, -0.6, 0.0) }, 2500.0, 0.4, 10.0);
  winch.area = 1e-5;
  winch.actuator = 0;
  m.cables.push_back(winch);
  // soft and strongly damped, stretched 0.2 m at q0: fast shortening clamps it slack
  Cable soft = makeCable("soft", PointRef{ 0, Vec3(0.0, 0.0, -0.6) }, PointRef{ 2, Vec3::Zero() }, 50.0, 0.0, 40.0);
  soft.rest_length = evaluateCable(m, soft, m.q0, Eigen::VectorXd::Zero(m.nq), {}, false).length - 0.2;
  m.cables.push_back(soft);
  return m;
}

CableState evaluate(const Model& m, const Cable& c, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                    const ActuationValues& u, bool damping, Eigen::VectorXd* F = nullptr)
{
  return evaluateCable(m, c, q, qd, u, damping, F);
}

double energy(const Model& m, const Cable& c, const Eigen::VectorXd& q, const ActuationValues& u)
{
  return cablePotentialEnergy(c, evaluate(m, c, q, Eigen::VectorXd::Zero(m.nq), u, false));
}

/// The generalized force of one cable alone.
Eigen::VectorXd force(const Model& m, const Cable& c, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                      const ActuationValues& u, bool damping)
{
  Eigen::VectorXd F = Eigen::VectorXd::Zero(m.nq);
  evaluate(m, c, q, qd, u, damping, &F);
  return F;
}

/// No generalized force F, no energy, no power.
void expectNothing(const Cable& c, const CableState& s, const Eigen::VectorXd& F)
{
  EXPECT_EQ(F.norm(), 0.0) << c.name;
  EXPECT_EQ(cablePotentialEnergy(c, s), 0.0) << c.name;
  EXPECT_EQ(cableConservativePower(c, s), 0.0) << c.name;
  EXPECT_EQ(cableNonConservativePower(c, s), 0.0) << c.name;
}

const ActuationValues kHeld = { ActuationValue{ 0.05, 0.0, 0.0 } };
}  // namespace

TEST(CableEnergy, ConservativePowerIsMinusTheEnergyRateAlongAMotion)
{
  const Model m = cableModel();
  std::mt19937 rng(7);
  const double h = 1e-6;
  for (int trial = 0; trial < 5; ++trial)
  {
    const Eigen::VectorXd q = perturbed(m.q0, 0.05, rng);
    const Eigen::VectorXd qd = randomVector(m.nq, 0.8, rng);
    for (const Cable& c : m.cables)
    {
      const CableState s = evaluate(m, c, q, qd, kHeld, true);
      ASSERT_GT(s.length - s.rest_length, 0.01) << c.name << " should be taut in this configuration";
      // q(t) = q + t qd: V's rate by central differences against -P_c
      const double rate = (energy(m, c, q + h * qd, kHeld) - energy(m, c, q - h * qd, kHeld)) / (2.0 * h);
      const double p_c = cableConservativePower(c, s);
      EXPECT_NEAR(rate, -p_c, 1e-6 * std::max(1.0, std::abs(p_c))) << c.name;
      // and P_c is the power of the undamped force
      EXPECT_NEAR(force(m, c, q, qd, kHeld, false).dot(qd), p_c, 1e-9 * std::max(1.0, std::abs(p_c))) << c.name;
    }
  }
}

TEST(CableEnergy, PowersAddUpToThePowerOfTheForce)
{
  const Model m = cableModel();
  std::mt19937 rng(11);
  for (int trial = 0; trial < 20; ++trial)
  {
    const Eigen::VectorXd q = perturbed(m.q0, 0.05, rng);
    const Eigen::VectorXd qd = randomVector(m.nq, 3.0, rng);
    const ActuationValues u = { ActuationValue{ 0.05, trial % 2 ? 0.3 : -0.2, 0.0 } };
    for (const Cable& c : m.cables)
    {
      const CableState s = evaluate(m, c, q, qd, u, true);
      const double total = force(m, c, q, qd, u, true).dot(qd);
      EXPECT_NEAR(cableConservativePower(c, s) + cableNonConservativePower(c, s), total,
                  1e-9 * std::max(1.0, std::abs(total)))
          << c.name;
      EXPECT_NEAR(total, -s.tension * s.rate, 1e-9 * std::max(1.0, std::abs(total))) << c.name;
    }
  }
}

TEST(CableEnergy, DampingNeverDeliversPowerWhileTheActuatorHoldsStill)
{
  const Model m = cableModel();
  std::mt19937 rng(3);
  int taut = 0, clamped = 0;
  for (int trial = 0; trial < 200; ++trial)
  {
    const Eigen::VectorXd q = perturbed(m.q0, 0.05, rng);
    const Eigen::VectorXd qd = randomVector(m.nq, 20.0, rng);  // fast enough for damping to clamp some
    for (const Cable& c : m.cables)
    {
      const CableState s = evaluate(m, c, q, qd, kHeld, true);
      EXPECT_LE(cableNonConservativePower(c, s), 0.0) << c.name;
      (s.slack ? clamped : taut) += 1;
    }
  }
  EXPECT_GT(taut, 0);
  EXPECT_GT(clamped, 0);  // the clamp case was met
  // without damping the force is conservative
  const Eigen::VectorXd qd = randomVector(m.nq, 1.0, rng);
  for (const Cable& c : m.cables)
    EXPECT_EQ(cableNonConservativePower(c, evaluate(m, c, m.q0, qd, kHeld, false)), 0.0) << c.name;
}

TEST(CableEnergy, NoForceNoEnergyNoPowerAtRestLength)
{
  Model m = mixedModel();
  m.cables = { makeCable("c", PointRef{ -1, Vec3::Zero() }, PointRef{ 2, Vec3::Zero() }, 100.0, 1.0, 5.0) };
  m.q0.segment<3>(14) = Vec3(0.6, 0.0, 0.8);  // |p| = 1 = l0
  const Cable& c = m.cables[0];
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.nq);
  Eigen::VectorXd F = zero;
  const CableState s = evaluate(m, c, m.q0, zero, {}, true, &F);
  EXPECT_NEAR(s.length, 1.0, 1e-15);
  EXPECT_EQ(s.tension, 0.0);
  expectNothing(c, s, F);
  // moving, without damping: still no force there, and V is stationary (V = 1/2 k (l - l0)^2)
  Eigen::VectorXd qd = zero;
  qd.segment<3>(14) = Vec3(0.3, 0.2, 0.4);
  F.setZero();
  const CableState moving = evaluate(m, c, m.q0, qd, {}, false, &F);
  EXPECT_EQ(F.norm(), 0.0);
  EXPECT_EQ(cableConservativePower(c, moving), 0.0);
}

TEST(CableEnergy, SlackCableHasNoForceNoEnergyNoPower)
{
  Model m = mixedModel();
  m.cables = { makeCable("c", PointRef{ -1, Vec3::Zero() }, PointRef{ 2, Vec3::Zero() }, 100.0, 1.5, 5.0) };
  m.q0.segment<3>(14) = Vec3(0.6, 0.0, 0.8);  // l = 1 < l0
  Eigen::VectorXd qd = Eigen::VectorXd::Zero(m.nq);
  qd.segment<3>(14) = Vec3(0.3, -0.2, 0.4);
  const Cable& c = m.cables[0];
  Eigen::VectorXd F = Eigen::VectorXd::Zero(m.nq);
  const CableState s = evaluate(m, c, m.q0, qd, {}, true, &F);
  EXPECT_TRUE(s.slack);
  expectNothing(c, s, F);
  // a spring that also pushes stores energy when compressed and its power is still -dV/dt
  m.cables[0].tension_only = false;
  const CableState spring = evaluate(m, m.cables[0], m.q0, qd, {}, false);
  EXPECT_NEAR(cablePotentialEnergy(m.cables[0], spring), 0.5 * 100.0 * 0.25, 1e-12);
  EXPECT_NEAR(cableConservativePower(m.cables[0], spring), -100.0 * (-0.5) * spring.rate, 1e-12);
}

TEST(CableEnergy, EnergyGradientIsMinusTheUndampedForce)
{
  const Model m = cableModel();
  std::mt19937 rng(5);
  const Eigen::VectorXd q = perturbed(m.q0, 0.05, rng);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(m.nq);
  const double h = 1e-6;
  for (const Cable& c : m.cables)
  {
    const Eigen::VectorXd F = force(m, c, q, zero, kHeld, false);
    for (int j = 0; j < m.nq; ++j)
    {
      Eigen::VectorXd qp = q, qm = q;
      qp(j) += h;
      qm(j) -= h;
      const double grad = (energy(m, c, qp, kHeld) - energy(m, c, qm, kHeld)) / (2.0 * h);
      EXPECT_NEAR(grad, -F(j), 1e-6 * std::max(1.0, F.lpNorm<Eigen::Infinity>())) << c.name << " q" << j;
    }
  }
}

TEST(CableLaw, TensionAlongTheCableMatchesClosedForms)
{
  Cable spring = makeCable("s", PointRef{}, PointRef{}, 100.0, 1.0, 5.0);
  CableState s = cableLaw(spring, 1.2, 0.5, {}, true);
  EXPECT_FALSE(s.slack);
  EXPECT_NEAR(s.tension, 100.0 * 0.2 + 5.0 * 0.5, 1e-12);
  EXPECT_NEAR(s.damping_tension, 5.0 * 0.5, 1e-15);
  EXPECT_NEAR(cableLaw(spring, 1.2, 0.5, {}, false).tension, 20.0, 1e-12);
  // pulled in by 0.1 at 0.2 m/s: a spring keeps k, a material cable keeps EA (k = EA / l0)
  spring.actuator = 0;
  const ActuationValues u = { ActuationValue{ 0.1, 0.2, 0.0 } };
  s = cableLaw(spring, 1.2, 0.5, u, true);
  EXPECT_NEAR(s.rest_length, 0.9, 1e-15);
  EXPECT_NEAR(s.tension, 100.0 * 0.3 + 5.0 * 0.7, 1e-12);
  Cable material = spring;
  material.area = 1e-5;
  s = cableLaw(material, 1.2, 0.5, u, true);
  EXPECT_NEAR(s.stiffness, 100.0 / 0.9, 1e-12);
  EXPECT_NEAR(s.tension, 100.0 / 0.9 * 0.3 + 5.0 * 0.7, 1e-12);
  // shortening fast enough that damping would push: slack; a two-sided spring pushes
  s = cableLaw(spring, 1.2, -10.0, u, true);
  EXPECT_TRUE(s.slack);
  EXPECT_EQ(s.tension, 0.0);
  spring.tension_only = false;
  EXPECT_NEAR(cableLaw(spring, 0.8, 0.0, u, true).tension, 100.0 * (0.8 - 0.9) + 5.0 * 0.2, 1e-12);
}

TEST(CableLaw, IsWhatEvaluateCableAppliesToItsLengthAndRate)
{
  const Model m = cableModel();
  std::mt19937 rng(23);
  const Eigen::VectorXd q = perturbed(m.q0, 0.05, rng);
  const Eigen::VectorXd qd = randomVector(m.nq, 5.0, rng);
  for (const Cable& c : m.cables)
  {
    const CableState s = evaluate(m, c, q, qd, kHeld, true);
    const CableState law = cableLaw(c, s.length, s.rate, kHeld, true);
    EXPECT_EQ(law.tension, s.tension) << c.name;
    EXPECT_EQ(law.slack, s.slack) << c.name;
    EXPECT_EQ(law.rest_length, s.rest_length) << c.name;
    EXPECT_EQ(law.stiffness, s.stiffness) << c.name;
  }
}

TEST(CableFrames, ResidualLoopEqualsThePointwiseForms)
{
  // the residual's loop (frames once per strut, moments summed per strut) against evaluateCable point by point,
  // off the unit sphere too (Newton iterates), for cables on struts, the ground and a point mass
  const Model m = cableModel();
  std::mt19937 rng(29);
  BodyFrames frames;
  PointForceSum sum;
  for (int trial = 0; trial < 5; ++trial)
  {
    const Eigen::VectorXd q = perturbed(m.q0, 0.2, rng);
    const Eigen::VectorXd qd = randomVector(m.nq, 5.0, rng);
    frames.update(m, q, qd);
    sum.reset(m);
    Eigen::VectorXd F = Eigen::VectorXd::Zero(m.nq), F_each = Eigen::VectorXd::Zero(m.nq);
    int taut = 0;
    for (const Cable& c : m.cables)
    {
      std::vector<PointSlot> slots;
      for (const PointRef& p : c.points)
        slots.push_back(pointSlot(m, p));
      const CableState s = evaluateCable(c, slots.data(), frames, q, qd, kHeld, true, sum, F);
      const CableState each = evaluate(m, c, q, qd, kHeld, true, &F_each);
      EXPECT_NEAR(s.length, each.length, 1e-14 * each.length) << c.name;
      EXPECT_NEAR(s.rate, each.rate, 1e-12 * (1.0 + std::abs(each.rate))) << c.name;
      EXPECT_EQ(s.slack, each.slack) << c.name;
      taut += s.slack ? 0 : 1;
      for (const PointRef& p : c.points)
      {
        Vec3 pf, vf, pe, ve;
        frames.motion(pointSlot(m, p), q, qd, pf, vf);
        pointMotion(m, p, q, qd, pe, ve);
        EXPECT_LT((pf - pe).norm(), 1e-14 * (1.0 + pe.norm())) << c.name;
        EXPECT_LT((vf - ve).norm(), 1e-13 * (1.0 + ve.norm())) << c.name;
      }
    }
    EXPECT_GE(taut, 3);
    // before the flush only the translations are in
    for (const Body& b : m.bodies)
    {
      if (b.kind == BodyKind::kStrut)
      {
        EXPECT_EQ(F.segment<4>(b.offset + 3).norm(), 0.0);
      }
    }
    sum.flush(m, q, F);
    EXPECT_LT((F - F_each).norm(), 1e-12 * F_each.norm()) << F.transpose() << "\n" << F_each.transpose();
    EXPECT_GT(F_each.norm(), 1.0);
    // a flush leaves nothing behind
    const Eigen::VectorXd kept = F;
    sum.flush(m, q, F);
    EXPECT_EQ(F, kept);
  }
}
