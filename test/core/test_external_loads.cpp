// Forces from outside the scene (System::setExternalLoads: the node's pushes): a free strut pushed at one end
// gains exactly the momentum of the impulse; a mass between two springs pushed along them swings to twice the
// static shift and back; switching the loads on and off between adaptive steps never reads as energy the step
// control refuses (the start's energy is formed again with the loads in force); the tangent with an external
// load on a strut matches finite differences.
#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/state.h"
#include "fd_check.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
ActuationLaw noActuation()
{
  return [](double) { return ActuationValues(); };
}

// a free strut along x, no gravity
Model freeStrut()
{
  Model m = freeStrutModel("A", 1.0, 0.02, 7800.0, Vec3::UnitX());
  m.solver = trapezoidalOptions(1e-3, 1e-12);
  return m;
}

// a 2 kg point mass at (0, 0, -1) between springs to (0, 0, 0) and (0, 0, -2), each 1000 N/m stretched 0.1 m:
// 2000 N/m along z, no gravity, no damping
Model massBetweenSprings()
{
  Model m;
  m.name = "mass between springs";
  m.bodies.push_back(makePointMass("M", 2.0));
  m.cables.push_back(
      makeCable("up", PointRef{ -1, Vec3(0.0, 0.0, 0.0) }, PointRef{ 0, Vec3::Zero() }, 1000.0, 0.9, 0.0));
  m.cables.push_back(
      makeCable("down", PointRef{ 0, Vec3::Zero() }, PointRef{ -1, Vec3(0.0, 0.0, -2.0) }, 1000.0, 0.9, 0.0));
  finalizeModel(m);
  m.q0 = Vec3(0.0, 0.0, -1.0);
  m.solver = trapezoidalOptions(1e-3, 1e-12);
  m.solver.adaptive = true;
  m.solver.error_tolerance = 1e-7;
  return m;
}
}  // namespace

TEST(ExternalLoads, AFreeStrutPushedAtOneEndGainsTheImpulse)
{
  const Model m = freeStrut();
  DynamicsSolver solver(m, m.solver);
  State s = initialState(m);
  ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
  const Vec3 force(3.0, -2.0, 5.0);
  ASSERT_TRUE(solver.setExternalLoads({ PointLoad{ "push", PointRef{ 0, Vec3(0.0, 0.0, 0.5) }, force } }, s).ok());
  const double h = 1e-3;
  for (int k = 0; k < 300; ++k)
    ASSERT_TRUE(solver.step(s, h, noActuation()).ok());  // (step advances s.t)
  ASSERT_NEAR(s.t, 0.3, 1e-12);
  const double mass = m.bodies[0].mass;
  const Vec3 momentum = mass * s.qd.head<3>();
  EXPECT_LT((momentum - force * s.t).norm(), 1e-9 * force.norm() * s.t) << momentum.transpose();
  // (the constant net force moves the centre as a particle: x = F t^2 / (2 m), exact for the trapezoidal rule)
  EXPECT_LT((s.q.head<3>() - 0.5 * force / mass * s.t * s.t).norm(), 1e-9);
  // it also turned it: the end's force has a moment about the centre
  EXPECT_GT(s.qd.segment<4>(3).norm(), 1e-3);
  // off again: the velocity stays
  ASSERT_TRUE(solver.setExternalLoads({}, s).ok());
  const Vec3 v = s.qd.head<3>();
  for (int k = 0; k < 50; ++k)
    ASSERT_TRUE(solver.step(s, h, noActuation()).ok());
  EXPECT_LT((s.qd.head<3>() - v).norm(), 1e-12);
}

TEST(ExternalLoads, PushesSwitchedBetweenAdaptiveStepsSwingTheMassAndAreNeverRefusedAsEnergy)
{
  const Model m = massBetweenSprings();
  DynamicsSolver solver(m, m.solver);
  State s = initialState(m);
  ASSERT_TRUE(solver.initialize(s, noActuation()).ok());
  AdaptiveStepper stepper(solver, m.solver);
  ASSERT_TRUE(stepper.advanceTo(s, 0.1, noActuation()).ok());
  EXPECT_NEAR(s.q.z(), -1.0, 1e-12);  // at rest until pushed
  // 50 N down from t = 0.1 s: the static shift is 0.025 m, the undamped swing twice that
  const double shift = 50.0 / 2000.0, period = 2.0 * M_PI * std::sqrt(2.0 / 2000.0);
  ASSERT_TRUE(
      solver.setExternalLoads({ PointLoad{ "push", PointRef{ 0, Vec3::Zero() }, Vec3(0.0, 0.0, -50.0) } }, s).ok());
  double lowest = 0.0;
  const auto track = [&](const State& x) { lowest = std::min(lowest, x.q.z() + 1.0); };
  ASSERT_TRUE(stepper.advanceTo(s, 0.1 + 3.0 * period, noActuation(), track).ok());
  EXPECT_NEAR(lowest, -2.0 * shift, 2e-3 * shift);
  // released at the bottom of a swing, at rest there: it swings between -2 shift and 0 again, about 0
  ASSERT_TRUE(stepper.advanceTo(s, 0.1 + 3.5 * period, noActuation()).ok());
  EXPECT_NEAR(s.q.z() + 1.0, -2.0 * shift, 2e-3 * shift);
  ASSERT_TRUE(solver.setExternalLoads({}, s).ok());
  double highest = -1.0;
  const auto track_high = [&](const State& x) { highest = std::max(highest, x.q.z() + 1.0); };
  ASSERT_TRUE(stepper.advanceTo(s, 0.1 + 6.0 * period, noActuation(), track_high).ok());
  EXPECT_NEAR(highest, 2.0 * shift, 4e-3 * shift);
  std::printf("[ measured ] pushed mass: lowest %.6f m (exact %.6f), highest after release %.6f m (exact %.6f); "
              "%ld steps, %ld refused for energy\n",
              lowest, -2.0 * shift, highest, 2.0 * shift, stepper.stats().accepted, stepper.stats().rejected_energy);
  EXPECT_EQ(stepper.stats().rejected_energy, 0);
}

TEST(ExternalLoads, TheirTangentOnAStrutMatchesFiniteDifferences)
{
  // a force off the centre of a strut turns with it: B^T f depends on the orientation (K = -d(B^T f)/dq)
  Model m = freeStrut();
  System sys(m);
  sys.setExternalLoads({ PointLoad{ "push", PointRef{ 0, Vec3(0.01, -0.02, 0.4) }, Vec3(30.0, -20.0, 50.0) } });
  std::mt19937 rng(41);
  const Eigen::VectorXd q = perturbed(m.q0, 0.05, rng), qd = Eigen::VectorXd::Zero(m.nq);
  BlockSparseMatrix jac = sys.makeMatrix();
  Eigen::VectorXd F;
  sys.appliedForce(q, qd, {}, F, &jac, 1.0, 0.0);
  ASSERT_GT(F.norm(), 10.0);
  const auto minus_force = [&](const Eigen::VectorXd& x) -> Eigen::VectorXd
  {
    Eigen::VectorXd G;
    sys.appliedForce(x, qd, {}, G, nullptr, 0.0, 0.0);
    return -G;
  };
  const Eigen::MatrixXd analytic = denseBlock(jac, sys.nq(), sys.nq());
  ASSERT_GT(analytic.norm(), 1.0);
  const FdComparison c = compareJacobians(analytic, fdJacobian(minus_force, q), 1e-6, 1.0);
  EXPECT_TRUE(c.ok) << c.message;
}
