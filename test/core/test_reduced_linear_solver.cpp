// ReducedLinearSolver: the Newton matrix with its one-body constraint rows eliminated solves as the whole
// matrix does, and reports the whole matrix's determinant sign.
#include <iostream>
#include <random>
#include <string>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/oracle/body_dynamics.h"
#include "active_tensegrity/oracle/reduced_linear_solver.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/oracle/body_statics.h"
#include "test_models.h"
#include "tower_fold.h"

using namespace active_tensegrity::test;

namespace
{
Model scene(const std::string& path)
{
  return loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/" + path);
}

/// The static Newton matrix of `system` at q (bodies moved by up to `shake`) and multipliers lambda, plus
/// `mass` times the mass matrix (which makes a mechanism's matrix regular).
BlockSparseMatrix newtonMatrix(const System& system, Eigen::VectorXd q, const Eigen::VectorXd& lambda, double mass)
{
  BlockSparseMatrix m = system.makeMatrix();
  m.setZero();
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(system.nq());
  Eigen::VectorXd f;
  system.appliedForce(q, zero, {}, f, &m, 1.0, 0.0);
  system.contactForce(q, zero, {}, ContactMode::kStatic, f, &m, 1.0, 0.0);
  system.addLambdaHessian(q, lambda, m, 1.0);
  system.addConstraintJacobian(q, m);
  if (mass > 0.0)
    system.addMass(q, m, mass);
  return m;
}

int struts(const Model& model)
{
  int n = 0;
  for (const Body& b : model.bodies)
    n += b.kind == BodyKind::kStrut ? 1 : 0;
  return n;
}

int denseSign(const Eigen::MatrixXd& a)
{
  const Eigen::PartialPivLU<Eigen::MatrixXd> lu(a);
  int sign = lu.permutationP().determinant();
  for (Eigen::Index i = 0; i < a.rows(); ++i)
    sign *= lu.matrixLU()(i, i) > 0.0 ? 1 : -1;
  return sign;
}

/// Solves with the reduced solver and with a dense LU of the whole matrix; returns the relative difference.
double compare(const BlockSparseMatrix& m, int bodies, ReducedLinearSolver& solver, std::mt19937& rng)
{
  EXPECT_TRUE(solver.factorize(m, bodies));
  const Eigen::MatrixXd dense(m.matrix());
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd b(dense.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i)
    b(i) = u(rng);
  Eigen::VectorXd x;
  solver.solve(b, x);
  const Eigen::VectorXd expected = dense.partialPivLu().solve(b);
  EXPECT_EQ(solver.determinantSign(), denseSign(dense));
  // the residual of the whole system, relative to the matrix and the solution
  const double residual = (dense * x - b).lpNorm<Eigen::Infinity>() /
                          (dense.cwiseAbs().rowwise().sum().maxCoeff() * x.lpNorm<Eigen::Infinity>());
  EXPECT_LT(residual, 1e-13);
  return (x - expected).lpNorm<Eigen::Infinity>() / expected.lpNorm<Eigen::Infinity>();
}
}  // namespace

TEST(ReducedLinearSolver, SolvesTheStaticNewtonMatricesOfTheShippedScenes)
{
  std::mt19937 rng(7);
  for (const char* path : { "config/scenes/quadruplex.yaml", "config/scenes/tower.yaml",
                            "config/scenes/prism_pinned.yaml", "test/scenes/snap_tripod.yaml" })
  {
    SCOPED_TRACE(path);
    const Model model = scene(path);
    const System system(model, spinLocks(model));
    const int bodies = static_cast<int>(model.bodies.size());
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    // away from the start: bodies moved, multipliers of every size (the lambda Hessian), a little mass
    // where the start is a mechanism
    Eigen::VectorXd q = model.q0;
    for (Eigen::Index i = 0; i < q.size(); ++i)
      q(i) += 0.01 * u(rng);
    Eigen::VectorXd lambda(system.nLambda());
    for (Eigen::Index i = 0; i < lambda.size(); ++i)
      lambda(i) = 100.0 * u(rng);
    ReducedLinearSolver solver;
    solver.allowDense(true, true);
    for (double mass : { 0.0, 1.0 })
    {
      const BlockSparseMatrix m = newtonMatrix(system, q, lambda, mass);
      EXPECT_LT(compare(m, bodies, solver, rng), 1e-9) << "mass " << mass;
      // every constraint of these scenes acts on one body (norms, spin locks, pins) but the struts' joints
      // and driven nodes: a strut loses at least its norm and spin lock (2 coordinates, 2 multipliers)
      EXPECT_EQ(solver.reduced(), system.nLambda() > 0);
      std::cerr << "[ measured ] " << path << ": " << solver.factorizedSize() << " of " << m.rows()
                << " unknowns factorized\n";
      if (system.nLambda() > 0)
      {
        EXPECT_LE(solver.factorizedSize(), m.rows() - 4 * struts(model))
            << solver.factorizedSize() << " of " << m.rows();
      }
      // with the elimination off the whole matrix is factorized, to the same answer
      ReducedLinearSolver whole;
      whole.allowDense(true, true);
      whole.allowReduction(false);
      EXPECT_LT(compare(m, bodies, whole, rng), 1e-9) << "mass " << mass;
      EXPECT_FALSE(whole.reduced());
      EXPECT_EQ(whole.factorizedSize(), m.rows());
    }
  }
}

TEST(ReducedLinearSolver, SolvesTheTowersDynamicNewtonMatricesThroughContact)
{
  // The dynamics solver's exact factorizations of systems of 65 to 400 unknowns: its Newton matrices (mass,
  // damping and stiffness with contact, the constraint rows scaled by 1 / (beta h^2)) at the paper's step and
  // at a step ten times longer (where adaptive steps go and the body blocks stop serving), solved as the whole
  // matrix is, with every strut's norm and pin and every driven point's rows eliminated.
  std::mt19937 rng(11);
  int touching = 0;
  const TowerVisit check = [&](const Model& m, BodyDynamicsSolver& solver, const BodyState& s, const ActuationLaw& law)
  {
    const double h = m.solver.dt;
    touching = static_cast<int>(activeContacts(m, s).size());
    for (double step : { h, 10.0 * h })
    {
      SCOPED_TRACE(::testing::Message() << "t " << s.t << " h " << step);
      BlockSparseMatrix jac = solver.system().makeMatrix();
      Eigen::VectorXd r;
      solver.residualAndJacobian(s, step, law(s.t + step), s.qdd, s.lambda, r, &jac);
      ReducedLinearSolver reduced;
      reduced.allowDense(true);
      EXPECT_LT(compare(jac, static_cast<int>(m.bodies.size()), reduced, rng), 1e-9);
      EXPECT_TRUE(reduced.reduced());
      // eliminated: 16 quaternion norms, 4 pinned nodes (3 rows each), 4 driven points (3 rows, 3 coordinates)
      // and the 12 ball joints (3 rows each) that join the struts into four chains
      EXPECT_EQ(reduced.factorizedSize(), jac.rows() - 2 * (16 + 4 * 3 + 4 * 3 + 12 * 3)) << jac.rows();
      std::cerr << "[ measured ] tower at t = " << s.t << " s, h = " << step << " s: " << reduced.factorizedSize()
                << " of " << jac.rows() << " unknowns factorized, " << (reduced.dense() ? "dense" : "sparse")
                << " LU\n";
    }
  };
  walkTowerFold({ 0.4, 1.75 }, check);
  EXPECT_GT(touching, 0);
}

TEST(ReducedLinearSolver, StaticsFactorizesWithIt)
{
  // the body coordinates' statics reduces every factorization it can, whatever the size (the quadruplex: 52 unknowns)
  const Model model = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/quadruplex.yaml");
  BodyStaticSolver solver(model, model.solver);
  BodyState s = bodyInitialState(model);
  ASSERT_TRUE(solver.solve(s, s.u).ok());
  ActuationValues end = s.u;
  for (ActuationValue& v : end)
    v.value = model.analysis.max_actuation;
  const Summary r = solver.followPath(s, end, model.analysis.steps, {});
  ASSERT_TRUE(r.ok()) << r.message;
  EXPECT_GT(solver.timings().factorizations, 0);
  EXPECT_EQ(solver.timings().reduced_factorizations, solver.timings().factorizations);
}
