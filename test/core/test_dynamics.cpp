// Time integration: the full Newton Jacobian of one step against finite differences, and physics
// invariants (energy, angular momentum, quaternion norm), a closed-form pendulum period, the
// measured order of accuracy of each integrator, and a clean failure status.
#include <algorithm>
#include <chrono>
#include <numeric>
#include <cmath>
#include <cstdio>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include <Eigen/SparseCholesky>

#include "active_tensegrity/oracle/body_rotation.h"
#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/oracle/sparse_linear_solver.h"
#include "active_tensegrity/oracle/body_dynamics.h"
#include "fd_check.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
SolverOptions options(Integrator integrator, double dt, double gamma = 0.5, double beta = 0.25, double rho = 1.0)
{
  SolverOptions o;
  o.integrator = integrator;
  o.dt = dt;
  o.newmark_gamma = gamma;
  o.newmark_beta = beta;
  o.rho_infinity = rho;
  o.newton_tolerance = 1e-12;
  o.max_iterations = 30;
  return o;
}

ActuationLaw constantLaw(size_t n, double value = 0.0)
{
  return [n, value](double) { return ActuationValues(n, ActuationValue{ value, 0.0, 0.0 }); };
}

/// One free strut, no forces: only its quaternion norm constraint.
Model freeStrut()
{
  return freeStrutModel("S", 1.2, 0.04, 7800.0, Vec3(0.2, -0.5, 1.0));
}

Vec3 angularMomentum(const Model& m, const State& s)
{
  Vec3 h = Vec3::Zero();
  for (const Body& b : m.bodies)
  {
    const Vec4 th = s.q.segment<4>(b.offset + 3);
    const Vec3 w_body = 2.0 * lMatrix(th) * s.qd.segment<4>(b.offset + 3);
    const Vec3 r = s.q.segment<3>(b.offset);
    h += rotationMatrix(th) * (b.inertia.asDiagonal() * w_body) + r.cross(b.mass * s.qd.segment<3>(b.offset));
  }
  return h;
}

/// The quadruplex of paper Sec. 6.1 (docs/scenes.md) vibrating freely about its prestressed equilibrium
/// (actuation held at 0), started with a velocity field.
struct Quadruplex
{
  Model model = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/quadruplex.yaml");
  State start(double speed, unsigned seed) const
  {
    State s = initialState(model);
    std::mt19937 rng(seed);
    s.qd = randomVector(model.nq, speed, rng);
    return s;
  }
};
}  // namespace

class NewtonJacobian : public ::testing::TestWithParam<Integrator>
{
};

TEST_P(NewtonJacobian, FullStepJacobianMatchesFiniteDifferences)
{
  const Model model = mixedModel();
  std::mt19937 rng(7);
  BodyDynamicsSolver solver(model, options(GetParam(), 1e-3, 0.6, 0.3025, 0.7));
  BodyState s = bodyInitialState(model);
  s.q = perturbed(model.q0, 0.05, rng);
  s.qd = randomVector(model.nq, 0.5, rng);
  s.qdd = randomVector(model.nq, 2.0, rng);
  s.acc = randomVector(model.nq, 2.0, rng);
  const double h = 2e-3;
  const ActuationValues u = { ActuationValue{ 0.05, 0.1, 0.0 } };
  const Eigen::VectorXd qdd = randomVector(model.nq, 5.0, rng);
  const Eigen::VectorXd lambda = randomVector(solver.system().nLambda(), 100.0, rng);
  Eigen::VectorXd x(model.nq + lambda.size());
  x << qdd, lambda;

  BlockSparseMatrix jac = solver.system().makeMatrix();
  Eigen::VectorXd r;
  solver.residualAndJacobian(s, h, u, qdd, lambda, r, &jac);
  const Eigen::MatrixXd analytic(jac.matrix());
  const Eigen::MatrixXd numeric = fdJacobian(
      [&](const Eigen::VectorXd& y) -> Eigen::VectorXd
      {
        Eigen::VectorXd out;
        solver.residualAndJacobian(s, h, u, y.head(model.nq), y.tail(lambda.size()), out, nullptr);
        return out;
      },
      x, 1e-3);  // a large step in qdd: q moves by only beta h^2 times it
  const auto c = compareJacobians(analytic, numeric, 1e-6, 1.0);
  EXPECT_TRUE(c.ok) << c.message;
}

INSTANTIATE_TEST_SUITE_P(Integrators, NewtonJacobian,
                         ::testing::Values(Integrator::kNewmark, Integrator::kGeneralizedAlpha));

TEST(Dynamics, TorqueFreeSpinningStrutKeepsEnergyMomentumAndNorm)
{
  // generalized-alpha with a little high-frequency damping: the undamped schemes (gamma = 1/2,
  // rho_inf = 1) are only marginally stable on index-3 DAEs and drift on this fast spin (docs/physics.md, "Dynamics")
  const Model model = freeStrut();
  DynamicsSolver solver(model, options(Integrator::kGeneralizedAlpha, 1e-3, 0.5, 0.25, 0.9));
  State s = initialState(model);
  // body angular velocity (1, 0.5, 30) rad/s: a strut spinning fast about its axis and tumbling
  const Vec4 th = s.q.segment<4>(3);
  const Vec3 w_body(1.0, 0.5, 30.0);
  s.qd.segment<4>(3) = 0.5 * lMatrix(th).transpose() * w_body;  // Theta_dot = 1/2 L^T w
  s.qd.segment<3>(0) = Vec3(0.1, 0.0, -0.2);
  ASSERT_TRUE(solver.initialize(s, constantLaw(0)).ok());
  const System sys(model);
  const double e0 = sys.kineticEnergy(s.q, s.qd);
  const Vec3 h0 = angularMomentum(model, s);
  double max_de = 0.0, max_dh = 0.0, max_norm = 0.0;
  for (int k = 0; k < 2000; ++k)
  {
    ASSERT_TRUE(solver.step(s, 1e-3, constantLaw(0)).ok());
    max_de = std::max(max_de, std::abs(sys.kineticEnergy(s.q, s.qd) - e0) / e0);
    max_dh = std::max(max_dh, (angularMomentum(model, s) - h0).norm() / h0.norm());
    max_norm = std::max(max_norm, std::abs(s.q.segment<4>(3).norm() - 1.0));
  }
  EXPECT_LT(max_de, 1e-4);
  EXPECT_LT(max_dh, 1e-4);
  EXPECT_LT(max_norm, 1e-10);
  // the body did tumble: its axis moved
  EXPECT_GT((rotationMatrix(s.q.segment<4>(3)).col(2) - rotationMatrix(model.q0.segment<4>(3)).col(2)).norm(), 0.1);
}

TEST(Dynamics, PinnedStrutSwingsWithThePendulumPeriod)
{
  // a strut hanging from a ground pin at its upper end: T = 2 pi sqrt(J_pivot / (m g L / 2))
  Model m;
  m.bodies.push_back(makeStrut("S", 1.0, 0.02, 7800.0));
  Constraint norm;
  norm.kind = Constraint::Kind::kQuatNorm;
  norm.body = 0;
  m.constraints.push_back(pointConstraint("pin", PointRef{ 0, Vec3(0, 0, 0.5) }, PointRef{ -1, Vec3::Zero() }));
  m.constraints.push_back(norm);
  m.gravity_enabled = true;
  finalizeModel(m);
  const double tilt = 0.02;
  const Vec3 axis(std::sin(tilt), 0.0, std::cos(tilt));  // body z points up towards the pin
  m.q0.setZero(7);
  m.q0.segment<3>(0) = -0.5 * axis;
  m.q0.segment<4>(3) = thetaFromZAxis(axis);
  const Body& b = m.bodies[0];
  const double j_pivot = b.inertia.x() + b.mass * 0.25;
  const double period = 2.0 * M_PI * std::sqrt(j_pivot / (b.mass * 9.81 * 0.5));

  DynamicsSolver solver(m, options(Integrator::kNewmark, 1e-3));
  State s = initialState(m);
  ASSERT_TRUE(solver.initialize(s, constantLaw(0)).ok());
  std::vector<double> crossings;
  double x_prev = s.q(0);
  for (int k = 0; k < 5000; ++k)
  {
    const double t_prev = s.t;
    ASSERT_TRUE(solver.step(s, 1e-3, constantLaw(0)).ok());
    if (x_prev < 0.0 && s.q(0) >= 0.0)
      crossings.push_back(t_prev + (s.t - t_prev) * (-x_prev) / (s.q(0) - x_prev));
    x_prev = s.q(0);
  }
  ASSERT_GE(crossings.size(), 3u);
  const double measured = (crossings.back() - crossings.front()) / (crossings.size() - 1);
  EXPECT_NEAR(measured / period, 1.0, 1e-3) << "measured " << measured << " s, closed form " << period << " s";
}

class EnergyConservation : public ::testing::TestWithParam<Integrator>
{
};

TEST_P(EnergyConservation, UndampedCableStructureKeepsEnergyBoundedOver10000Steps)
{
  Quadruplex quad;
  DynamicsSolver solver(quad.model, options(GetParam(), 1e-3, 0.5, 0.25, 1.0));
  State s = quad.start(0.3, 11);
  const ActuationLaw law = constantLaw(1);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  const System sys(quad.model);
  const double e0 = sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q);
  const double k0 = sys.kineticEnergy(s.q, s.qd);
  ASSERT_GT(k0, 0.1);
  double max_dev = 0.0, late_dev = 0.0;
  for (int k = 0; k < 10000; ++k)
  {
    const Summary r = solver.step(s, 1e-3, law);
    ASSERT_TRUE(r.ok()) << r.message;
    const double dev = std::abs(sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q) - e0) / k0;
    max_dev = std::max(max_dev, dev);
    if (k >= 9000)
      late_dev = std::max(late_dev, dev);
  }
  // bounded, and no secular drift: the last tenth is no worse than the bound over the whole run
  EXPECT_LT(max_dev, 2e-3) << "energy deviation relative to the initial kinetic energy";
  EXPECT_LE(late_dev, max_dev);
  EXPECT_TRUE(s.q.allFinite());
}

INSTANTIATE_TEST_SUITE_P(Integrators, EnergyConservation,
                         ::testing::Values(Integrator::kNewmark, Integrator::kGeneralizedAlpha));

TEST(Dynamics, PaperNewmarkDissipatesEnergy)
{
  Quadruplex quad;
  DynamicsSolver solver(quad.model, options(Integrator::kNewmark, 1e-3, 0.6, 0.3025));
  State s = quad.start(0.3, 11);
  const ActuationLaw law = constantLaw(1);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  const System sys(quad.model);
  double e_prev = sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q);
  const double e0 = e_prev;
  for (int k = 0; k < 2000; ++k)
  {
    ASSERT_TRUE(solver.step(s, 1e-3, law).ok());
    const double e = sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q);
    EXPECT_LE(e, e_prev + 1e-9 * e0) << "step " << k;  // gamma > 1/2 never adds energy
    e_prev = e;
  }
  EXPECT_LT(e_prev, e0);
}

namespace
{
// position error at T against a fine reference, for step h
double positionError(const Quadruplex& quad, const SolverOptions& o, double h, double T, const Eigen::VectorXd& ref)
{
  SolverOptions oo = o;
  oo.dt = h;
  DynamicsSolver solver(quad.model, oo);
  State s = quad.start(0.5, 5);
  const ActuationLaw law = constantLaw(1);
  EXPECT_TRUE(solver.initialize(s, law).ok());
  const int n = static_cast<int>(std::lround(T / h));
  for (int k = 0; k < n; ++k)
    EXPECT_TRUE(solver.step(s, h, law).ok());
  if (ref.size() == 0)
    return 0.0;
  double err = 0.0;
  for (const Body& b : quad.model.bodies)
    err = std::max(err, (s.q.segment<3>(b.offset) - ref.segment<3>(b.offset)).norm());
  return err;
}

Eigen::VectorXd reference(const Quadruplex& quad, double T)
{
  SolverOptions o = options(Integrator::kGeneralizedAlpha, 2.5e-5, 0.5, 0.25, 0.9);
  DynamicsSolver solver(quad.model, o);
  State s = quad.start(0.5, 5);
  const ActuationLaw law = constantLaw(1);
  EXPECT_TRUE(solver.initialize(s, law).ok());
  const int n = static_cast<int>(std::lround(T / o.dt));
  for (int k = 0; k < n; ++k)
    EXPECT_TRUE(solver.step(s, o.dt, law).ok());
  return s.q;
}

// least-squares slope of log(error) against log(h)
double slope(const std::vector<double>& h, const std::vector<double>& e)
{
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const double n = static_cast<double>(h.size());
  for (size_t i = 0; i < h.size(); ++i)
  {
    const double x = std::log(h[i]), y = std::log(e[i]);
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}
}  // namespace

TEST(Dynamics, MeasuredOrderOfAccuracy)
{
  Quadruplex quad;
  const double T = 0.4;
  const Eigen::VectorXd ref = reference(quad, T);
  const std::vector<double> steps = { 4e-3, 2e-3, 1e-3, 5e-4 };
  std::vector<double> e_newmark, e_alpha;
  for (double h : steps)
  {
    e_newmark.push_back(positionError(quad, options(Integrator::kNewmark, h, 0.6, 0.3025), h, T, ref));
    e_alpha.push_back(positionError(quad, options(Integrator::kGeneralizedAlpha, h, 0.5, 0.25, 0.9), h, T, ref));
  }
  const double p_newmark = slope(steps, e_newmark);
  const double p_alpha = slope(steps, e_alpha);
  std::printf("order: Newmark(0.6, 0.3025) %.3f, generalized-alpha(0.9) %.3f\n", p_newmark, p_alpha);
  for (size_t i = 0; i < steps.size(); ++i)
    std::printf("  h = %.1e  error Newmark %.3e  generalized-alpha %.3e\n", steps[i], e_newmark[i], e_alpha[i]);
  EXPECT_NEAR(p_newmark, 1.0, 0.2);
  EXPECT_NEAR(p_alpha, 2.0, 0.25);
}

TEST(Dynamics, FailedStepReportsStatusAndKeepsTheLastGoodState)
{
  Quadruplex quad;
  SolverOptions o = options(Integrator::kNewmark, 1e-2);
  o.max_iterations = 1;  // Newton cannot converge to 1e-12 in one iteration
  o.max_step_cuts = 2;
  DynamicsSolver solver(quad.model, o);
  State s = quad.start(0.5, 3);
  const ActuationLaw law = constantLaw(1);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  const State before = s;
  const Summary r = solver.step(s, 1e-2, law);
  EXPECT_EQ(r.status, SolveStatus::kMaxIterations);
  EXPECT_EQ(r.step_cuts, 2);  // h -> h/2 -> h/4, then max_step_cuts is reached
  EXPECT_FALSE(r.message.empty());
  EXPECT_EQ(s.t, before.t);
  EXPECT_TRUE(s.q.isApprox(before.q));
  EXPECT_TRUE(s.q.allFinite());
}

TEST(Dynamics, StepCutsStopAtTheSmallestStepWhateverTheirAllowedNumber)
{
  // steps that always fail, with a million cuts allowed (they recursed once per cut and overflowed the
  // stack): halving stops before a piece would be shorter than dt_min
  Quadruplex quad;
  SolverOptions o = options(Integrator::kNewmark, 1e-2);
  o.max_iterations = 2;
  o.newton_tolerance = 1e-30;  // below round-off: no step converges
  o.max_step_cuts = 1000000;
  o.dt_min = 1e-5;
  DynamicsSolver solver(quad.model, o);
  State s = quad.start(0.5, 3);
  const ActuationLaw law = constantLaw(1);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  const State before = s;
  const Summary r = solver.step(s, 1e-2, law);
  EXPECT_EQ(r.status, SolveStatus::kMaxIterations);
  EXPECT_EQ(r.step_cuts, 9);  // 1e-2 / 2^9 = 1.95e-5; one more cut would give 9.8e-6 < dt_min
  EXPECT_NE(r.message.find("solver.dt_min"), std::string::npos) << r.message;
  EXPECT_EQ(s.t, before.t);
  EXPECT_TRUE(s.q.isApprox(before.q));
}

TEST(Dynamics, ACutStepCoversTheWholeStep)
{
  // a step that converges only in pieces still ends exactly h later, with every piece counted: Newton
  // allowed few iterations on a long step of the vibrating quadruplex
  Quadruplex quad;
  bool found = false;
  for (int iterations = 2; iterations <= 6 && !found; ++iterations)
  {
    SolverOptions o = options(Integrator::kNewmark, 5e-2);
    o.max_iterations = iterations;
    o.max_step_cuts = 8;
    DynamicsSolver solver(quad.model, o);
    State s = quad.start(2.0, 5);
    const ActuationLaw law = constantLaw(1);
    ASSERT_TRUE(solver.initialize(s, law).ok());
    const double t0 = s.t;
    const Summary r = solver.step(s, 5e-2, law);
    if (!r.ok() || r.step_cuts == 0)
      continue;
    found = true;
    SCOPED_TRACE(iterations);
    EXPECT_NEAR(s.t, t0 + 5e-2, 1e-15);
    EXPECT_GE(r.iterations, r.step_cuts + 1);  // every attempt took at least one iteration
    EXPECT_TRUE(s.q.allFinite());
  }
  EXPECT_TRUE(found) << "no iteration limit made the step converge only after cuts";
}

TEST(Dynamics, InitializationProjectsVelocitiesOntoTheConstraints)
{
  Quadruplex quad;
  DynamicsSolver solver(quad.model, options(Integrator::kNewmark, 1e-3));
  State s = quad.start(1.0, 9);
  const ActuationValue rate{ 0.0, 0.2, 0.0 };
  const ActuationLaw law = [rate](double) { return ActuationValues{ rate }; };
  ASSERT_TRUE(solver.initialize(s, law).ok());
  Eigen::VectorXd rhs;
  System(quad.model).velocityRhs({ rate }, rhs);
  EXPECT_LT((System(quad.model).constraintJacobianDense(s.q) * s.qd - rhs).lpNorm<Eigen::Infinity>(), 1e-10);
}

TEST(Dynamics, InitializationProjectsPositionsOntoTheConstraints)
{
  Quadruplex quad;
  DynamicsSolver solver(quad.model, options(Integrator::kNewmark, 1e-3));
  const ActuationLaw law = constantLaw(1);
  // a consistent start is left where it is (to the round-off of forming its nodes)
  State s = quad.start(0.0, 9);
  const Eigen::VectorXd q0 = s.q;
  ASSERT_TRUE(solver.initialize(s, law).ok());
  EXPECT_LT((s.q - q0).lpNorm<Eigen::Infinity>(), 1e-15);
  // a strut moved off its joints by 1 mm and a quaternion off the unit sphere: brought back, nearby
  State bad = quad.start(0.0, 9);
  const Body& b = quad.model.bodies[0];
  bad.q.segment<3>(b.offset) += Vec3(1e-3, -5e-4, 2e-4);
  bad.q.segment<4>(b.offset + 3) *= 1.001;
  const Summary sum = solver.initialize(bad, law);
  ASSERT_TRUE(sum.ok()) << sum.message;
  EXPECT_GT(sum.iterations, 0);
  Eigen::VectorXd phi;
  System(quad.model).constraintValue(bad.q, bad.u, phi);
  EXPECT_LT(phi.lpNorm<Eigen::Infinity>(), 1e-12 * (1.0 + bad.q.lpNorm<Eigen::Infinity>()));
  EXPECT_NEAR(bad.q.segment<4>(b.offset + 3).norm(), 1.0, 1e-12);
  EXPECT_LT((bad.q - q0).lpNorm<Eigen::Infinity>(), 2e-3);
  // and the first step from it is an ordinary one (no violent correction)
  ASSERT_TRUE(solver.step(bad, 1e-3, law).ok());
  EXPECT_LT((bad.q - q0).lpNorm<Eigen::Infinity>(), 2e-3);
}

namespace
{
struct NewtonRun
{
  double distance = 0.0;  // largest distance of q to the reference over the run
  StepTimings timings;
};

// 3000 steps of 1 ms of the quadruplex vibrating with large amplitude (cables going slack and taut),
// trapezoidal rule, against `ref` (the same run at a tight tolerance, filled in when empty)
NewtonRun vibrate(const Quadruplex& quad, const SolverOptions& o, std::vector<Eigen::VectorXd>& ref,
                  double* energy_deviation = nullptr)
{
  const ActuationLaw law = constantLaw(1);
  DynamicsSolver solver(quad.model, o);
  State s = quad.start(0.3, 11);
  EXPECT_TRUE(solver.initialize(s, law).ok());
  const System sys(quad.model);
  const double e0 = sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q);
  const double k0 = sys.kineticEnergy(s.q, s.qd);
  const bool fill = ref.empty();
  NewtonRun run;
  double dev = 0.0;
  for (int k = 0; k < 3000; ++k)
  {
    const Summary r = solver.step(s, 1e-3, law);
    EXPECT_TRUE(r.ok()) << r.message;
    if (!r.ok())
      break;
    if (fill)
      ref.push_back(s.q);
    else
      run.distance = std::max(run.distance, (s.q - ref[k]).lpNorm<Eigen::Infinity>());
    dev = std::max(dev, std::abs(sys.kineticEnergy(s.q, s.qd) + sys.potentialEnergy(s.q) - e0) / k0);
  }
  if (energy_deviation)
    *energy_deviation = dev;
  run.timings = solver.timings();
  return run;
}
}  // namespace

TEST(Dynamics, ModifiedNewtonReusesTheMatrixAndItsErrorFollowsTheTolerance)
{
  // Modified Newton accepts an iterate when the error estimated to be left in it (the increment times
  // theta / (1 - theta), docs/physics.md) is within the tolerance. Its distance to a tight full-Newton run
  // must shrink with the tolerance, at a small fraction of full Newton's factorizations (measured with
  // the quadratic first guess: 1e-5 -> 8.4e-6 m, 1e-6 -> 3.9e-7, 1e-8 -> 3.1e-9; a linear guess leaves
  // larger first multiplier errors, not all iterated away: 9.5e-8 at 1e-8).
  Quadruplex quad;
  SolverOptions full = options(Integrator::kNewmark, 1e-3);
  full.reuse_jacobian = false;
  full.newton_tolerance = 1e-12;
  std::vector<Eigen::VectorXd> ref;
  const NewtonRun tight = vibrate(quad, full, ref);
  ASSERT_EQ(ref.size(), 3000u);

  SolverOptions reuse = full;
  reuse.reuse_jacobian = true;
  double max_dev = 0.0;
  reuse.newton_tolerance = 1e-5;
  const NewtonRun loose = vibrate(quad, reuse, ref);
  reuse.newton_tolerance = 1e-6;
  const NewtonRun mid = vibrate(quad, reuse, ref, &max_dev);
  reuse.newton_tolerance = 1e-8;
  const NewtonRun fine = vibrate(quad, reuse, ref);
  full.newton_tolerance = 1e-6;
  const NewtonRun full_mid = vibrate(quad, full, ref);

  for (const auto& [tol, run] : { std::pair<double, NewtonRun>{ 1e-5, loose }, { 1e-6, mid }, { 1e-8, fine } })
  {
    // within a small multiple of the tolerance over 3000 steps
    EXPECT_LT(run.distance, 10.0 * tol) << "tolerance " << tol;
    // the matrix is rebuilt rarely (slack/taut changes, age, a step's ninth iteration), most iterations reuse it
    EXPECT_LT(run.timings.factorizations, run.timings.newton_iterations / 10) << "tolerance " << tol;
  }
  EXPECT_LT(mid.distance, 0.1 * loose.distance);
  EXPECT_LT(fine.distance, 0.1 * mid.distance);
  // full Newton factorizes at every iteration; modified Newton at a small fraction of those
  EXPECT_EQ(full_mid.timings.factorizations, full_mid.timings.newton_iterations);
  EXPECT_LT(mid.timings.factorizations, full_mid.timings.factorizations / 20);
  EXPECT_LT(max_dev, 2e-3);
  std::printf("[ measured ] 3000 steps, distance to full Newton at 1e-12 (%ld iterations): modified Newton at "
              "1e-5 %.2e (%ld iterations / %ld factorizations), 1e-6 %.2e (%ld / %ld), 1e-8 %.2e (%ld / %ld); "
              "full Newton at 1e-6 %.2e (%ld / %ld); energy deviation %.2e\n",
              tight.timings.newton_iterations, loose.distance, loose.timings.newton_iterations,
              loose.timings.factorizations, mid.distance, mid.timings.newton_iterations, mid.timings.factorizations,
              fine.distance, fine.timings.newton_iterations, fine.timings.factorizations, full_mid.distance,
              full_mid.timings.newton_iterations, full_mid.timings.factorizations, max_dev);
}

namespace
{
struct AdaptiveRun
{
  double error = 0.0;  // largest strut-centre position error at T (m)
  AdaptiveStats stats;
};

AdaptiveRun adaptiveError(const Quadruplex& quad, SolverOptions o, double tol, double T, const Eigen::VectorXd& ref)
{
  o.adaptive = true;
  o.error_tolerance = tol;
  o.newton_tolerance = 1e-3 * tol;
  o.dt = 1e-4;
  o.dt_max = 0.05;
  DynamicsSolver solver(quad.model, o);
  State s = quad.start(0.5, 5);
  const ActuationLaw law = constantLaw(1);
  EXPECT_TRUE(solver.initialize(s, law).ok());
  AdaptiveStepper stepper(solver, o);
  EXPECT_TRUE(stepper.advanceTo(s, T, law).ok());
  EXPECT_EQ(s.t, T);
  AdaptiveRun run;
  run.stats = stepper.stats();
  for (const Body& b : quad.model.bodies)
    run.error = std::max(run.error, (s.q.segment<3>(b.offset) - ref.segment<3>(b.offset)).norm());
  return run;
}
}  // namespace

TEST(AdaptiveSteps, ErrorFollowsTheToleranceAndStepsFollowTheError)
{
  // the freely vibrating quadruplex against the fine fixed-step reference. The tolerance bounds the
  // error per step (~ h^3), so the steps shrink about 100^(1/3) = 4.6-fold when it tightens 100-fold and
  // the global error, at most the sum of the local ones, about 100^(2/3) = 22-fold
  Quadruplex quad;
  const double T = 0.4;
  const Eigen::VectorXd ref = reference(quad, T);
  const SolverOptions o = options(Integrator::kGeneralizedAlpha, 1e-4, 0.5, 0.25, 0.9);
  const AdaptiveRun loose = adaptiveError(quad, o, 1e-4, T, ref);
  const AdaptiveRun tight = adaptiveError(quad, o, 1e-6, T, ref);
  std::printf("[ measured ] tol 1e-4: error %.3e m in %ld steps (%ld refused); tol 1e-6: error %.3e m in %ld steps "
              "(%ld refused)\n",
              loose.error, loose.stats.accepted, loose.stats.rejected_error, tight.error, tight.stats.accepted,
              tight.stats.rejected_error);
  EXPECT_LT(tight.error, loose.error / 12.0);
  EXPECT_LT(tight.error, static_cast<double>(tight.stats.accepted) * 1e-6);
  EXPECT_LT(loose.error, static_cast<double>(loose.stats.accepted) * 1e-4);
  const double growth = static_cast<double>(tight.stats.accepted) / loose.stats.accepted;
  EXPECT_GT(growth, 2.5);  // 100^(1/3) = 4.6
  EXPECT_LT(growth, 8.0);
}

TEST(AdaptiveSteps, LandsOnOutputTimesAndActuationBreakpoints)
{
  // the quadruplex compression with a sharp ramp (start 0.013 s, end 0.113 s): every output row and both
  // kinks are steps of the run
  Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/quadruplex.yaml");
  m.analysis.type = AnalysisType::kDynamic;
  m.analysis.duration = 0.15;
  m.analysis.output_interval = 0.01;
  m.analysis.max_actuation = 0.05;
  m.analysis.schedule = RampSchedule{ 0.5, 0.013, 0.05, 0.0 };
  m.solver.adaptive = true;
  m.solver.dt = 1e-3;
  std::vector<double> outputs, steps;
  const RunResult r = runAnalysis(
      m, [&](const State& s) { outputs.push_back(s.t); }, {}, [&](const State& s) { steps.push_back(s.t); });
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  ASSERT_EQ(outputs.size(), 16u);  // 0, 0.01, ..., 0.15
  for (size_t i = 0; i < outputs.size(); ++i)
    EXPECT_NEAR(outputs[i], 0.01 * static_cast<double>(i), 1e-12);
  for (double kink : { 0.013, 0.113 })
    EXPECT_TRUE(std::any_of(steps.begin(), steps.end(), [&](double t) { return std::abs(t - kink) < 1e-12; }))
        << "no step ends at " << kink;
  EXPECT_EQ(r.solver_steps, static_cast<int>(steps.size()));
  EXPECT_EQ(r.adaptive.accepted, static_cast<long>(steps.size()));
  EXPECT_EQ(r.final_state.u[0].value, 0.05);
}

TEST(AdaptiveSteps, NoStepIsShorterThanTheSmallestStep)
{
  // a ramp that starts 1e-9 s after an output time and a duration 5e-8 s past the last one: both would
  // need steps far below dt_min; the breakpoint is left to the step to the output and the last output
  // moves to the end
  Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/quadruplex.yaml");
  m.analysis.type = AnalysisType::kDynamic;
  m.analysis.duration = 0.05 + 5e-8;
  m.analysis.output_interval = 0.01;
  m.analysis.max_actuation = 0.01;
  m.analysis.schedule = RampSchedule{ 0.5, 0.01 + 1e-9, 0.01, 0.0 };
  m.solver.adaptive = true;
  m.solver.dt = 1e-3;
  m.solver.dt_min = 1e-7;
  std::vector<double> outputs, steps = { 0.0 };
  const RunResult r = runAnalysis(
      m, [&](const State& s) { outputs.push_back(s.t); }, {}, [&](const State& s) { steps.push_back(s.t); });
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  for (size_t i = 1; i < steps.size(); ++i)
    EXPECT_GE(steps[i] - steps[i - 1], m.solver.dt_min * (1.0 - 1e-9)) << "step " << i << " ends at " << steps[i];
  ASSERT_EQ(outputs.size(), 6u);  // 0, 0.01, ..., 0.04, and the end
  EXPECT_EQ(outputs.back(), m.analysis.duration);
  EXPECT_EQ(r.final_state.t, m.analysis.duration);
}

TEST(FixedSteps, ALastStepShorterThanTheSmallestStepIsMergedIntoTheOneBefore)
{
  Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/quadruplex.yaml");
  m.analysis.type = AnalysisType::kDynamic;
  m.analysis.duration = 0.01 + 1e-9;
  m.analysis.max_actuation = 0.01;
  m.analysis.schedule = RampSchedule{ 0.5, 0.0, 0.01, 0.0 };
  m.solver.dt = 1e-3;
  std::vector<double> steps = { 0.0 };
  const RunResult r = runAnalysis(
      m, [](const State&) {}, {}, [&](const State& s) { steps.push_back(s.t); });
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  ASSERT_EQ(steps.size(), 11u);  // ten steps, the last 1e-9 s longer
  EXPECT_EQ(steps.back(), m.analysis.duration);
  for (size_t i = 1; i < steps.size(); ++i)
    EXPECT_GE(steps[i] - steps[i - 1], 1e-3 * (1.0 - 1e-9));
}

TEST(LinearSolver, DenseAndSparseFactorsSolveAlikeAndTellASingularMatrix)
{
  // a 60 x 60 matrix filled at about 50 %: with allowDense the solver switches to the dense LU after its
  // first (sparse) factorization; both give the same solution, and both refuse a singular matrix
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  std::bernoulli_distribution present(0.5);
  const int n = 60;
  std::vector<Eigen::Triplet<double>> entries;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      if (i == j || present(rng))
        entries.emplace_back(i, j, i == j ? 10.0 + value(rng) : value(rng));
  Eigen::SparseMatrix<double> a(n, n);
  a.setFromTriplets(entries.begin(), entries.end());
  a.makeCompressed();
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i)
    b(i) = value(rng);

  SparseLinearSolver sparse, dense;
  dense.allowDense(true);
  Eigen::VectorXd xs, xd;
  ASSERT_TRUE(sparse.factorize(a));
  ASSERT_TRUE(dense.factorize(a));  // first call: sparse factors, then the choice
  ASSERT_TRUE(dense.factorize(a));
  EXPECT_FALSE(sparse.dense());
  EXPECT_TRUE(dense.dense());
  sparse.solve(b, xs);
  dense.solve(b, xd);
  EXPECT_LT((a * xd - b).lpNorm<Eigen::Infinity>(), 1e-12);
  EXPECT_LT((xs - xd).lpNorm<Eigen::Infinity>(), 1e-12);

  // the sign of the determinant, from either factors, is the dense determinant's; flipping one row's sign
  // flips it
  const double det = Eigen::MatrixXd(a).determinant();
  ASSERT_NE(det, 0.0);
  EXPECT_EQ(sparse.determinantSign(), det > 0.0 ? 1 : -1);
  EXPECT_EQ(dense.determinantSign(), det > 0.0 ? 1 : -1);
  Eigen::SparseMatrix<double> flipped = a;
  for (int j = 0; j < n; ++j)
    if (a.coeff(5, j) != 0.0)
      flipped.coeffRef(5, j) = -a.coeff(5, j);
  ASSERT_TRUE(sparse.factorize(flipped));
  ASSERT_TRUE(dense.factorize(flipped));
  EXPECT_EQ(sparse.determinantSign(), det > 0.0 ? -1 : 1);
  EXPECT_EQ(dense.determinantSign(), det > 0.0 ? -1 : 1);

  // two equal rows: singular. The dense factors tell it by their condition; the sparse factors only
  // by an exact zero pivot, which round-off hides here (so the dense one is used in dynamics only,
  // where a singular matrix cuts the step either way)
  Eigen::SparseMatrix<double> s = a;
  for (int j = 0; j < n; ++j)
    s.coeffRef(1, j) = a.coeff(0, j);
  s.makeCompressed();
  EXPECT_FALSE(dense.factorize(s));
  EXPECT_TRUE(dense.dense());
}

namespace
{
/// A saddle-point matrix [A Phi^T; Phi 0] like the Newton matrices: A (nq x nq) banded with `diagonal`
/// (+-1) on its diagonal (0: +-1e-12), symmetric plus `skew` times an antisymmetric band; Phi (nl x nq) with six
/// entries a row, one of them a unit entry on a coordinate of the row's own (well-conditioned, as joint
/// rows are).
Eigen::SparseMatrix<double> saddleMatrix(int nq, int nl, double skew, std::mt19937& rng, double diagonal = 20.0)
{
  std::uniform_real_distribution<double> value(-1.0, 1.0);
  std::vector<Eigen::Triplet<double>> e;
  for (int i = 0; i < nq; ++i)
  {
    const double spread = value(rng);
    e.emplace_back(i, i, diagonal > 0.0 ? diagonal + spread : 1e-12 * spread);
    for (int k = 1; k <= 3 && i + k < nq; ++k)
    {
      const double s = value(rng);
      const double w = skew * value(rng);
      e.emplace_back(i, i + k, s + w);
      e.emplace_back(i + k, i, s - w);
    }
  }
  std::uniform_int_distribution<int> column(0, nq - 1);
  for (int r = 0; r < nl; ++r)
  {
    // a coordinate of its own (3 r) with a unit entry, as a joint row has, and five others: well posed
    std::set<int> cols;
    while (cols.size() < 5)
    {
      const int c = column(rng);
      if (c % 3 != 0 || c / 3 >= nl)
        cols.insert(c);
    }
    e.emplace_back(nq + r, 3 * r, 1.0);
    e.emplace_back(3 * r, nq + r, 1.0);
    for (int c : cols)
    {
      const double v = 0.3 * value(rng);
      e.emplace_back(nq + r, c, v);
      e.emplace_back(c, nq + r, v);
    }
  }
  Eigen::SparseMatrix<double> a(nq + nl, nq + nl);
  a.setFromTriplets(e.begin(), e.end());
  a.makeCompressed();
  return a;
}
}  // namespace

TEST(LinearSolver, StaticPivotsOfALargeSaddleMatrixNearlySolveItAndAnUnstableOneGetsTheLu)
{
  // above 400 unknowns, allowStaticPivot factorizes the matrix with its constraint block shifted by
  // -delta, without pivoting: an approximation (exact() false), antisymmetric part included, that
  // iterative refinement, as modified Newton does, takes to the LU's solution at a rate of about 1e-5.
  // A matrix whose diagonal is tiny against its off-diagonal entries (pivots near zero in any order
  // without pivoting) fails the check and gets the sparse LU (exact); the static pivots are tried again
  // after four factorizations.
  std::mt19937 rng(5);
  const Eigen::SparseMatrix<double> a = saddleMatrix(450, 150, 1.0, rng);
  Eigen::VectorXd b = Eigen::VectorXd::Random(a.rows());
  SparseLinearSolver lu, fast;
  fast.allowStaticPivot(true);
  ASSERT_TRUE(lu.factorize(a));
  ASSERT_TRUE(fast.factorize(a));
  EXPECT_TRUE(fast.staticPivot());
  EXPECT_FALSE(fast.exact());
  EXPECT_TRUE(lu.exact());
  // the shift is far too small to change the sign of the determinant
  const double dense_det = Eigen::MatrixXd(a).partialPivLu().determinant();
  if (std::isfinite(dense_det) && dense_det != 0.0)
  {
    EXPECT_EQ(fast.determinantSign(), dense_det > 0.0 ? 1 : -1);
  }
  EXPECT_EQ(fast.determinantSign(), lu.determinantSign());
  Eigen::VectorXd exact, x = Eigen::VectorXd::Zero(a.rows()), dx;
  lu.solve(b, exact);
  ASSERT_LT((a * exact - b).lpNorm<Eigen::Infinity>(), 1e-10);
  double previous = 0.0, worst_rate = 0.0;
  for (int k = 0; k < 6; ++k)
  {
    fast.solve(b - a * x, dx);
    x += dx;
    const double size = dx.lpNorm<Eigen::Infinity>();
    if (k > 0 && size > 1e-11)
      worst_rate = std::max(worst_rate, size / previous);
    previous = size;
  }
  EXPECT_GT(worst_rate, 0.0);  // an approximation: refinement has work to do
  EXPECT_LT(worst_rate, 1e-3);
  EXPECT_LT((x - exact).lpNorm<Eigen::Infinity>(), 1e-10);

  // the same pattern with a diagonal 1e-12 of its neighbours: refused, the LU instead, and exact
  std::mt19937 same_a(11), same_b(11);  // one pattern, two diagonals
  const Eigen::SparseMatrix<double> unstable = saddleMatrix(450, 150, 1.0, same_a, 0.0);
  const Eigen::SparseMatrix<double> sound = saddleMatrix(450, 150, 1.0, same_b);
  ASSERT_EQ(sound.nonZeros(), unstable.nonZeros());
  SparseLinearSolver fallback;
  fallback.allowStaticPivot(true);
  ASSERT_TRUE(fallback.factorize(unstable));
  EXPECT_FALSE(fallback.staticPivot());
  EXPECT_TRUE(fallback.exact());
  EXPECT_EQ(fallback.staticPivotRefusals(), 1);
  fallback.solve(b, x);
  EXPECT_LT((unstable * x - b).lpNorm<Eigen::Infinity>(), 1e-8 * (1.0 + x.lpNorm<Eigen::Infinity>()));
  for (int k = 0; k < 4; ++k)
    ASSERT_TRUE(fallback.factorize(unstable));  // the pause: LU without trying
  EXPECT_EQ(fallback.staticPivotRefusals(), 5);
  // after the pause the static pivots are tried again and kept
  ASSERT_TRUE(fallback.factorize(sound));
  EXPECT_TRUE(fallback.staticPivot());
  EXPECT_EQ(fallback.staticPivotRefusals(), 5);

  // below 400 unknowns the choice is never made
  SparseLinearSolver small;
  small.allowStaticPivot(true);
  ASSERT_TRUE(small.factorize(saddleMatrix(200, 60, 1.0, rng)));
  EXPECT_FALSE(small.staticPivot());
}

TEST(LinearSolver, WithApproximationsSuspendedStaticPivotsAreRefinedToRoundOffOrRefused)
{
  // full Newton suspends the approximate methods: a large saddle matrix still gets the static pivots, but
  // every solve is refined against the matrix, so that it is exact (the LU's solution to round-off) in one
  // call; a matrix whose refinement does not reach round-off gets the sparse LU
  std::mt19937 rng(5);
  const Eigen::SparseMatrix<double> a = saddleMatrix(450, 150, 1.0, rng);
  const Eigen::VectorXd b = Eigen::VectorXd::Random(a.rows());
  SparseLinearSolver lu, refined;
  refined.allowStaticPivot(true);
  refined.allowApproximate(false);
  ASSERT_TRUE(lu.factorize(a));
  ASSERT_TRUE(refined.factorize(a));
  EXPECT_TRUE(refined.staticPivotRefined());
  EXPECT_FALSE(refined.staticPivot());
  EXPECT_TRUE(refined.exact());
  EXPECT_EQ(refined.staticPivotRefusals(), 0);
  EXPECT_EQ(refined.determinantSign(), lu.determinantSign());
  Eigen::VectorXd exact, x;
  lu.solve(b, exact);
  refined.solve(b, x);
  EXPECT_LT((x - exact).lpNorm<Eigen::Infinity>(), 1e-10 * (1.0 + exact.lpNorm<Eigen::Infinity>()));
  EXPECT_LT((a * x - b).lpNorm<Eigen::Infinity>(), 1e-10);
  // the same factors without refinement are off by the shift (the approximate method, restored)
  refined.allowApproximate(true);
  ASSERT_TRUE(refined.factorize(a));
  EXPECT_TRUE(refined.staticPivot());
  refined.solve(b, x);
  EXPECT_GT((x - exact).lpNorm<Eigen::Infinity>(), 1e-10 * (1.0 + exact.lpNorm<Eigen::Infinity>()));

  // pivots near zero (diagonal 1e-12 of its neighbours): refused, the sparse LU instead, exact
  std::mt19937 same(11);
  const Eigen::SparseMatrix<double> unstable = saddleMatrix(450, 150, 1.0, same, 0.0);
  SparseLinearSolver fallback;
  fallback.allowStaticPivot(true);
  fallback.allowApproximate(false);
  ASSERT_TRUE(fallback.factorize(unstable));
  EXPECT_FALSE(fallback.staticPivotRefined());
  EXPECT_TRUE(fallback.exact());
  EXPECT_EQ(fallback.staticPivotRefusals(), 1);
  fallback.solve(b, x);
  EXPECT_LT((unstable * x - b).lpNorm<Eigen::Infinity>(), 1e-8 * (1.0 + x.lpNorm<Eigen::Infinity>()));
}

TEST(PartTimers, AgreeWithTheSteadyClock)
{
  // the part timers' clock (the time-stamp counter where it is invariant) against steady_clock over the same spin of
  // 20 ms: a wrong rate (or a counter that does not count wall time) shows as a ratio far from 1; the two readings
  // of each clock are a few nanoseconds apart, so a preemption lengthens both intervals alike
  double scoped = 0.0, lapped = 0.0;
  std::chrono::steady_clock::duration spun{};
  {
    const ScopeTimer scope(scoped);
    LapTimer laps;
    const auto t0 = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - t0 < std::chrono::milliseconds(20)) {}
    spun = std::chrono::steady_clock::now() - t0;
    laps.lap(lapped);
  }
  const double wall = std::chrono::duration<double>(spun).count();
  EXPECT_NEAR(scoped / wall, 1.0, 0.02) << scoped << " s against " << wall << " s";
  EXPECT_NEAR(lapped / wall, 1.0, 0.02) << lapped << " s against " << wall << " s";
  EXPECT_GT(partSeconds(), 0.0);
}

TEST(StaticPivotLU, SolvesANonsymmetricMatrixWithSymmetricPatternExactlyAndReportsAZeroPivot)
{
  // diagonally dominant, pattern symmetric, values not: L D U without pivoting is exact to round-off
  // (a mix-up of L and U, or of the rows and columns of the order, would leave a residual of order 1)
  std::mt19937 rng(7);
  const Eigen::SparseMatrix<double> a = saddleMatrix(300, 0, 1.0, rng);
  StaticPivotLU lu;
  lu.analyzePattern(a);
  ASSERT_TRUE(lu.factorize(a));
  const Eigen::VectorXd b = Eigen::VectorXd::Random(a.rows());
  Eigen::VectorXd x;
  lu.solve(b, x);
  EXPECT_LT((a * x - b).lpNorm<Eigen::Infinity>(), 1e-12);
  EXPECT_GE(lu.factorNonZeros(), (a.nonZeros() - a.rows()) / 2);  // at least the strict lower part
  // refactorized with other values of the same pattern: exact again (no stale work arrays)
  Eigen::SparseMatrix<double> c = a;
  c.coeffs() *= 1.0 + 0.1 * Eigen::ArrayXd::Random(c.nonZeros());
  ASSERT_TRUE(lu.factorize(c));
  lu.solve(b, x);
  EXPECT_LT((c * x - b).lpNorm<Eigen::Infinity>(), 1e-12);
  // a matrix whose first pivot in any order is exactly zero: [[0 1]; [1 0]]
  Eigen::SparseMatrix<double> z(2, 2);
  const std::vector<Eigen::Triplet<double>> e = { { 0, 0, 0.0 }, { 1, 1, 0.0 }, { 0, 1, 1.0 }, { 1, 0, 1.0 } };
  z.setFromTriplets(e.begin(), e.end());
  StaticPivotLU zlu;
  zlu.analyzePattern(z);
  EXPECT_FALSE(zlu.factorize(z));
}

TEST(StaticPivotLU, ShiftsTheGivenDiagonalAndFollowsAChangeOfPattern)
{
  // a saddle matrix stores no diagonal in its constraint rows: the factors of A with -delta there must
  // solve the matrix with those entries put in, to round-off (a shift on the wrong rows, or lost because
  // the diagonal was not stored, leaves a residual of order delta)
  // (shuffled: in saddleMatrix's own order AMD leaves the constraint rows where they are, and a shift
  // put on the wrong one of the two orders would go unseen)
  std::mt19937 rng(11);
  std::vector<int> shuffle(260);
  std::iota(shuffle.begin(), shuffle.end(), 0);
  std::shuffle(shuffle.begin(), shuffle.end(), rng);
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> q(260);
  q.indices() = Eigen::Map<const Eigen::VectorXi>(shuffle.data(), 260);
  Eigen::SparseMatrix<double> a = saddleMatrix(200, 60, 1.0, rng);
  a = q * a * q.transpose();
  a.makeCompressed();
  std::vector<int> rows;
  for (int r = 200; r < 260; ++r)
    rows.push_back(shuffle[r]);
  const double delta = 0.25;
  Eigen::SparseMatrix<double> shifted = a;
  for (int r : rows)
    shifted.coeffRef(r, r) -= delta;
  ASSERT_NE(shifted.nonZeros(), a.nonZeros());  // (the diagonal of those rows was not stored)
  StaticPivotLU lu;
  lu.analyzePattern(a);
  ASSERT_TRUE(lu.factorize(a, rows, -delta));
  const Eigen::VectorXd b = Eigen::VectorXd::Random(a.rows());
  Eigen::VectorXd x;
  lu.solve(b, x);
  EXPECT_LT((shifted * x - b).lpNorm<Eigen::Infinity>(), 1e-11);
  EXPECT_GT((a * x - b).lpNorm<Eigen::Infinity>(), 1e-3);
  EXPECT_EQ(lu.analyses(), 1);
  // another pattern with as many entries: one entry moved. Analyzed again, then exact for it
  Eigen::SparseMatrix<double> moved = a;
  int gone = -1, added = 1;
  for (Eigen::SparseMatrix<double>::InnerIterator it(a, 0); it; ++it)
    if (it.row() != 0 && gone < 0)
      gone = static_cast<int>(it.row());
  while (a.coeff(added, 0) != 0.0)
    ++added;
  moved.coeffRef(gone, 0) = 0.0;
  moved.coeffRef(0, gone) = 0.0;
  moved.prune(0.0, 0.0);
  moved.coeffRef(added, 0) = 0.5;
  moved.coeffRef(0, added) = -0.5;
  moved.makeCompressed();
  ASSERT_EQ(moved.nonZeros(), a.nonZeros());
  // (shifted as well: without the shift a constraint row's zero diagonal may come up as a pivot)
  ASSERT_TRUE(lu.factorize(moved, rows, -delta));
  EXPECT_EQ(lu.analyses(), 2);
  Eigen::SparseMatrix<double> moved_shifted = moved;
  for (int r : rows)
    moved_shifted.coeffRef(r, r) -= delta;
  lu.solve(b, x);
  EXPECT_LT((moved_shifted * x - b).lpNorm<Eigen::Infinity>(), 1e-11);
}

TEST(StaticPivotLU, OrdersASaddleMatrixForTheFillOfItsShiftedPattern)
{
  // a grid's saddle matrix (a 2-D grid of unknowns, a constraint row per horizontal edge) stores no diagonal in its
  // constraint rows: the factors must have the fill of the shifted matrix's Cholesky factor in AMD's order, as
  // Eigen's SimplicialLDLT finds it (ordered on the pattern without those diagonal entries, AMD leaves several times
  // the fill)
  const int side = 24, unknowns = side * side;
  std::vector<Eigen::Triplet<double>> t;
  for (int i = 0; i < side; ++i)
    for (int j = 0; j < side; ++j)
    {
      const int k = i * side + j;
      t.emplace_back(k, k, 4.0);
      if (j + 1 < side)
      {
        t.emplace_back(k, k + 1, -1.0);
        t.emplace_back(k + 1, k, -1.0);
      }
      if (i + 1 < side)
      {
        t.emplace_back(k, k + side, -1.0);
        t.emplace_back(k + side, k, -1.0);
      }
    }
  std::vector<int> rows;
  int r = unknowns;
  for (int i = 0; i < side; ++i)
    for (int j = 0; j + 1 < side; ++j, ++r)
    {
      for (const auto& [c, v] : { std::pair{ i * side + j, 1.0 }, std::pair{ i * side + j + 1, -1.0 } })
      {
        t.emplace_back(r, c, v);
        t.emplace_back(c, r, v);
      }
      rows.push_back(r);
    }
  Eigen::SparseMatrix<double> a(r, r);
  a.setFromTriplets(t.begin(), t.end());
  const double delta = 1e-3;
  Eigen::SparseMatrix<double> shifted = a;
  for (const int k : rows)
    shifted.coeffRef(k, k) -= delta;
  StaticPivotLU lu;
  ASSERT_TRUE(lu.factorize(a, rows, -delta));
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(shifted);
  ASSERT_EQ(ldlt.info(), Eigen::Success);
  const Eigen::Index cholesky = ldlt.matrixL().nestedExpression().nonZeros();
  std::printf("[ measured ] the grid's factors: %ld entries in L, %ld in the Cholesky factor of AMD's order\n",
              static_cast<long>(lu.factorNonZeros()), static_cast<long>(cholesky));
  EXPECT_LE(lu.factorNonZeros(), cholesky);
  const Eigen::VectorXd b = Eigen::VectorXd::Random(a.rows());
  Eigen::VectorXd x;
  lu.solve(b, x);
  EXPECT_LT((shifted * x - b).lpNorm<Eigen::Infinity>(), 1e-9);
}

TEST(LinearSolver, EquilibratedDenseFactorsJudgeTheStructureNotItsUnits)
{
  // a regular saddle matrix whose stiffness block is scaled by 1e12 against unit constraint rows: its
  // reciprocal condition is about 1e-15 as it stands (the plain dense LU calls it singular); equilibrated,
  // it factorizes and solves to round-off. Two equal rows stay singular either way.
  std::mt19937 rng(13);
  Eigen::SparseMatrix<double> a = saddleMatrix(120, 40, 0.3, rng);
  for (int k = 0; k < a.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, k); it; ++it)
      if (it.row() < 120 && it.col() < 120)
        it.valueRef() *= 1e12;
  const Eigen::VectorXd b = Eigen::VectorXd::Random(a.rows());
  SparseLinearSolver plain, scaled;
  plain.allowDense(true);
  scaled.allowDense(true, true);
  ASSERT_TRUE(scaled.factorize(a));  // (first call: sparse factors, then the choice)
  ASSERT_TRUE(scaled.factorize(a));
  ASSERT_TRUE(scaled.dense());
  Eigen::VectorXd x;
  scaled.solve(b, x);
  // backward error: the residual against the sizes it is made of
  const double size = Eigen::MatrixXd(a).cwiseAbs().rowwise().sum().maxCoeff() * x.lpNorm<Eigen::Infinity>() +
                      b.lpNorm<Eigen::Infinity>();
  EXPECT_LT((a * x - b).lpNorm<Eigen::Infinity>() / size, 1e-13);
  plain.factorize(a);
  EXPECT_FALSE(plain.factorize(a));
  EXPECT_TRUE(plain.dense());

  Eigen::SparseMatrix<double> s = a;
  for (int j = 0; j < a.cols(); ++j)
    if (a.coeff(0, j) != 0.0 || a.coeff(1, j) != 0.0)
      s.coeffRef(1, j) = a.coeff(0, j);
  s.makeCompressed();
  EXPECT_FALSE(scaled.factorize(s));
}

TEST(LinearSolver, DenseFactorsTellSingularFromIllConditionedByTheirCondition)
{
  // A = U diag(s) V^T with s from 1 down to 10^-e: the condition is estimated only when the pivots spread
  // over more than 8 decades; either way a reciprocal condition above 1e-14 factorizes and one below does not
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  const int n = 60;
  const auto orthogonal = [&]()
  {
    Eigen::MatrixXd m(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        m(i, j) = g(rng);
    return Eigen::MatrixXd(Eigen::HouseholderQR<Eigen::MatrixXd>(m).householderQ());
  };
  for (const auto& [decades, regular] : { std::make_pair(4.0, true), std::make_pair(11.0, true),
                                          std::make_pair(17.0, false), std::make_pair(30.0, false) })
  {
    Eigen::VectorXd s(n);
    for (int i = 0; i < n; ++i)
      s(i) = std::pow(10.0, -decades * i / (n - 1));
    const Eigen::MatrixXd a = orthogonal() * s.asDiagonal() * orthogonal().transpose();
    const Eigen::SparseMatrix<double> sparse = a.sparseView();
    SparseLinearSolver solver;
    solver.allowDense(true);
    solver.factorize(sparse);  // (first call: sparse factors, then the choice)
    EXPECT_EQ(solver.factorize(sparse), regular) << "condition 1e" << decades;
    EXPECT_TRUE(solver.dense());
    if (regular)
    {
      const Eigen::VectorXd b = Eigen::VectorXd::Random(n);
      Eigen::VectorXd x;
      solver.solve(b, x);
      EXPECT_LT((a * x - b).norm() / (a.norm() * x.norm()), 1e-13) << "condition 1e" << decades;
    }
  }
}
