// BodyBlockSolver: the Newton matrix without the couplings between bodies, solved body by body with the
// joining rows' Schur complement; and the dynamics that use it for modified Newton.
#include <algorithm>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/oracle/body_block_solver.h"
#include "active_tensegrity/oracle/body_dynamics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/oracle/sparse_linear_solver.h"
#include "tower_fold.h"

using namespace active_tensegrity::core;
using active_tensegrity::test::TowerVisit;
using active_tensegrity::test::walkTowerFold;

namespace
{
/// A saddle matrix [H Gt; G 0] in body groups: each body's own block of H a random matrix with a dominant
/// diagonal (mass-like), couplings of `coupling` between neighbouring bodies, one-body rows per body as
/// given, and joining rows: 3 between each listed pair of bodies (a ball joint) and one row on each listed
/// triple. Gt is G^T plus `skew` times a random matrix on the same entries (a Newton matrix need not be
/// symmetric).
struct Saddle
{
  std::vector<int> sizes;
  Eigen::MatrixXd a;  // dense, with the couplings
  int nq = 0;
};

Saddle makeSaddle(const std::vector<int>& sizes, const std::vector<int>& own_rows,
                  const std::vector<std::pair<int, int>>& joints, const std::vector<std::vector<int>>& triples,
                  double coupling, double skew, std::mt19937& rng)
{
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Saddle s;
  s.sizes = sizes;
  std::vector<int> offset;
  for (int n : sizes)
  {
    offset.push_back(s.nq);
    s.nq += n;
  }
  std::vector<Eigen::RowVectorXd> rows;  // G's rows
  for (size_t b = 0; b < sizes.size(); ++b)
    for (int k = 0; k < own_rows[b]; ++k)
    {
      Eigen::RowVectorXd g = Eigen::RowVectorXd::Zero(s.nq);
      for (int c = 0; c < sizes[b]; ++c)
        g(offset[b] + c) = u(rng);
      rows.push_back(g);
    }
  for (const auto& [p, q] : joints)
    for (int k = 0; k < 3; ++k)
    {
      Eigen::RowVectorXd g = Eigen::RowVectorXd::Zero(s.nq);
      g(offset[p] + k) = 1.0;
      g(offset[q] + k) = -1.0;
      for (int c = 3; c < sizes[p]; ++c)
        g(offset[p] + c) = 0.3 * u(rng);
      for (int c = 3; c < sizes[q]; ++c)
        g(offset[q] + c) = 0.3 * u(rng);
      rows.push_back(g);
    }
  for (const std::vector<int>& t : triples)
  {
    Eigen::RowVectorXd g = Eigen::RowVectorXd::Zero(s.nq);
    for (int b : t)
      for (int c = 0; c < sizes[b]; ++c)
        g(offset[b] + c) = u(rng);
    rows.push_back(g);
  }
  const int m = static_cast<int>(rows.size());
  s.a = Eigen::MatrixXd::Zero(s.nq + m, s.nq + m);
  for (size_t b = 0; b < sizes.size(); ++b)
  {
    const int n = sizes[b];
    Eigen::MatrixXd h = Eigen::MatrixXd::NullaryExpr(n, n, [&] { return 0.5 * u(rng); });
    h.diagonal().array() += 10.0;
    s.a.block(offset[b], offset[b], n, n) = h;
    if (b + 1 < sizes.size())
    {
      s.a.block(offset[b], offset[b + 1], n, sizes[b + 1]).setConstant(coupling);
      s.a.block(offset[b + 1], offset[b], sizes[b + 1], n).setConstant(coupling);
    }
  }
  for (int r = 0; r < m; ++r)
  {
    s.a.block(s.nq + r, 0, 1, s.nq) = rows[r];
    for (int c = 0; c < s.nq; ++c)
      if (rows[r](c) != 0.0)
        s.a(c, s.nq + r) = rows[r](c) + skew * u(rng);
  }
  return s;
}

/// A with the couplings between bodies zeroed, except within a group (groups: each body's group; empty: every
/// body alone): the matrix BodyBlockSolver solves.
Eigen::MatrixXd withoutCouplings(const Saddle& s, const std::vector<int>& groups = {})
{
  Eigen::MatrixXd a0 = s.a;
  std::vector<int> body;
  for (size_t b = 0; b < s.sizes.size(); ++b)
    body.insert(body.end(), s.sizes[b], groups.empty() ? static_cast<int>(b) : groups[b]);
  for (int i = 0; i < s.nq; ++i)
    for (int j = 0; j < s.nq; ++j)
      if (body[i] != body[j])
        a0(i, j) = 0.0;
  return a0;
}

/// A chain of n struts joined end to end, each with one row of its own, neighbours coupled at 0.2.
Saddle longStrutChain(int n, std::mt19937& rng)
{
  std::vector<std::pair<int, int>> joints;
  for (int b = 0; b + 1 < n; ++b)
    joints.emplace_back(b, b + 1);
  return makeSaddle(std::vector<int>(n, 7), std::vector<int>(n, 1), joints, {}, 0.2, 0.1, rng);
}

Eigen::SparseMatrix<double> sparse(const Eigen::MatrixXd& a)
{
  Eigen::SparseMatrix<double> m = a.sparseView(0.0, 0.0);
  m.makeCompressed();
  return m;
}

/// The relative difference between BodyBlockSolver's solution and the dense LU's of A0 (its groups' couplings
/// kept), on a random b.
double solveError(BodyBlockSolver& solver, const Saddle& s, std::mt19937& rng)
{
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Eigen::VectorXd b = Eigen::VectorXd::NullaryExpr(s.a.rows(), [&] { return u(rng); });
  Eigen::VectorXd x;
  solver.solve(b, x);
  const Eigen::VectorXd x0 = withoutCouplings(s, solver.groups()).partialPivLu().solve(b);
  return (x - x0).norm() / x0.norm();
}
}  // namespace

TEST(BodyBlockSolver, SolvesTheMatrixWithoutTheCouplingsBetweenBodies)
{
  // struts (7), point masses (3); one-body rows (a quaternion norm, a pin); ball joints and a row on three
  // bodies. The solution is A0's (couplings zeroed), not A's: with couplings of 0.3 the two differ.
  std::mt19937 rng(7);
  const Saddle s = makeSaddle({ 7, 7, 3, 7, 3, 7 }, { 1, 4, 3, 1, 0, 1 }, { { 0, 1 }, { 1, 3 }, { 3, 5 } },
                              { { 2, 4, 5 } }, 0.3, 0.2, rng);
  BodyBlockSolver solver(s.sizes);
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_EQ(solver.joiningRows(), 10);
  EXPECT_LT(solveError(solver, s, rng), 1e-12);
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(s.a.rows());
  Eigen::VectorXd x;
  solver.solve(b, x);
  EXPECT_GT((x - s.a.partialPivLu().solve(b)).norm(), 1e-3 * x.norm());  // the couplings are really dropped
  // and a matrix without couplings is solved exactly
  const Saddle plain = makeSaddle({ 7, 7, 3, 7, 3, 7 }, { 1, 4, 3, 1, 0, 1 }, { { 0, 1 }, { 1, 3 }, { 3, 5 } },
                                  { { 2, 4, 5 } }, 0.0, 0.2, rng);
  ASSERT_TRUE(solver.factorize(sparse(plain.a)));
  solver.solve(b, x);
  EXPECT_LT((plain.a * x - b).norm(), 1e-12 * b.norm());
}

TEST(BodyBlockSolver, ManyJoiningRowsGoToTheSparseSchurComplement)
{
  // a chain of 40 struts joined end to end: 117 joining rows, beyond the dense Schur complement's 64
  std::mt19937 rng(11);
  const Saddle s = longStrutChain(40, rng);
  BodyBlockSolver solver(s.sizes);
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_GT(solver.joiningRows(), BodyBlockSolver::kDenseSchurRows);
  EXPECT_LT(solveError(solver, s, rng), 1e-11);
  EXPECT_LT(solveError(solver, s, rng), 1e-11);
}

namespace
{
/// A chain of six struts joined end to end (each with one row of its own), neighbours coupled at `coupling`
/// against diagonals of about 10.
Saddle strutChain(double coupling, std::mt19937& rng)
{
  const std::vector<int> sizes(6, 7), own(6, 1);
  const std::vector<std::pair<int, int>> joints = { { 0, 1 }, { 1, 2 }, { 2, 3 }, { 3, 4 }, { 4, 5 } };
  return makeSaddle(sizes, own, joints, {}, coupling, 0.1, rng);
}

/// The chain with couplings of 0.3 (3 % of the diagonals: dropped), but bodies 1 and 2 coupled at 4 (40 %).
Saddle chainWithStrongPair(std::mt19937& rng)
{
  Saddle s = strutChain(0.3, rng);
  s.a.block(7, 14, 7, 7).setConstant(4.0);
  s.a.block(14, 7, 7, 7).setConstant(4.0);
  return s;
}
}  // namespace

TEST(BodyBlockSolver, StronglyCoupledBodiesAreSolvedTogether)
{
  // the strongly coupled pair is one group, their coupling and the joint between them kept, the rest dropped
  std::mt19937 rng(5);
  const Saddle s = chainWithStrongPair(rng);
  BodyBlockSolver solver(s.sizes);
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_EQ(solver.groupedBodies(), 2);
  EXPECT_EQ(solver.groups(), (std::vector<int>{ 0, 1, 1, 3, 4, 5 }));
  EXPECT_EQ(solver.joiningRows(), 12) << "the joint between bodies 1 and 2 is the group's own";
  EXPECT_LT(solveError(solver, s, rng), 1e-12);
  Eigen::VectorXd x;
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(s.a.rows());
  solver.solve(b, x);
  EXPECT_GT((x - withoutCouplings(s).partialPivLu().solve(b)).norm(), 1e-3 * x.norm()) << "the strong coupling is kept";

  // every neighbour strongly coupled: groups of at most four struts (kMaxGroupColumns), strongest first
  Saddle strong = strutChain(4.0, rng);
  strong.a.block(28, 35, 7, 7).setConstant(6.0);  // bodies 4 and 5 the strongest pair
  strong.a.block(35, 28, 7, 7).setConstant(6.0);
  ASSERT_TRUE(solver.factorize(sparse(strong.a)));
  const std::vector<int>& g = solver.groups();
  EXPECT_EQ(g[5], 4) << "the strongest pair is joined";
  for (int b = 0; b < 6; ++b)
    EXPECT_LE(std::count(g.begin(), g.end(), g[b]) * 7, BodyBlockSolver::kMaxGroupColumns) << "body " << b;
  EXPECT_EQ(solver.groupedBodies(), 6);
  EXPECT_LT(solveError(solver, strong, rng), 1e-12);

  // weak couplings again: every body alone (a new analysis)
  const int analyses = solver.analyses();
  const Saddle weak = strutChain(0.3, rng);
  ASSERT_TRUE(solver.factorize(sparse(weak.a)));
  EXPECT_EQ(solver.analyses(), analyses + 1);
  EXPECT_EQ(solver.groupedBodies(), 0);
  EXPECT_LT(solveError(solver, weak, rng), 1e-12);
}

TEST(BodyBlockSolver, GroupsCanBeTurnedOff)
{
  // the strongly coupled pair of the test above: with groups off every body is alone, and the solve is that
  // of the matrix without any coupling between bodies
  std::mt19937 rng(5);
  const Saddle s = chainWithStrongPair(rng);
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(s.a.rows());
  const Eigen::VectorXd alone = withoutCouplings(s).partialPivLu().solve(b);
  Eigen::VectorXd x;

  BodyBlockSolver solver(s.sizes);
  solver.allowGroups(false);
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_EQ(solver.groupedBodies(), 0);
  EXPECT_EQ(solver.groups(), (std::vector<int>{ 0, 1, 2, 3, 4, 5 }));
  solver.solve(b, x);
  EXPECT_LT((x - alone).norm(), 1e-12 * alone.norm());
  // on again: the pair is one group (a new analysis of the same pattern)
  const int analyses = solver.analyses();
  solver.allowGroups(true);
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_EQ(solver.analyses(), analyses + 1);
  EXPECT_EQ(solver.groupedBodies(), 2);
  solver.solve(b, x);
  EXPECT_GT((x - alone).norm(), 1e-3 * alone.norm());

  // through SparseLinearSolver: the setting holds when the body blocks are (re)declared after it
  SparseLinearSolver linear;
  linear.allowBodyGroups(false);
  linear.allowBodyBlocks(s.sizes);
  ASSERT_TRUE(linear.factorize(sparse(s.a)));
  ASSERT_TRUE(linear.bodyBlocks());
  linear.solve(b, x);
  EXPECT_LT((x - alone).norm(), 1e-12 * alone.norm());
}

TEST(BodyBlockSolver, FollowsAChangeOfPatternAndRefusesWhatItCannotSolve)
{
  std::mt19937 rng(3);
  Saddle s = makeSaddle({ 7, 7, 3 }, { 1, 1, 0 }, { { 0, 1 }, { 1, 2 } }, {}, 0.0, 0.0, rng);
  BodyBlockSolver solver(s.sizes);
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_EQ(solver.analyses(), 1);
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_EQ(solver.analyses(), 1);
  // a new entry, a coupling between bodies 0 and 1: analyzed again, and dropped
  s.a(1, 8) = 0.7;
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_EQ(solver.analyses(), 2);
  EXPECT_LT(solveError(solver, s, rng), 1e-12);

  // an entry between two constraint rows
  Eigen::MatrixXd a = s.a;
  a(s.nq, s.nq + 1) = a(s.nq + 1, s.nq) = 1.0;
  EXPECT_FALSE(solver.factorize(sparse(a)));
  // a constraint row on no body (its entries gone)
  a = s.a;
  a.row(s.nq).setZero();
  a.col(s.nq).setZero();
  a(s.nq, s.nq) = 0.0;
  EXPECT_FALSE(solver.factorize(sparse(a)));
  // a singular body system: the point mass's block zero
  a = s.a;
  a.block(14, 14, 3, 3).setZero();
  EXPECT_FALSE(solver.factorize(sparse(a)));
  // a body with more than kMaxBodyRows rows of its own
  const Saddle big = makeSaddle({ 7, 7 }, { BodyBlockSolver::kMaxBodyRows - 6, 1 }, { { 0, 1 } }, {}, 0.0, 0.0, rng);
  BodyBlockSolver other(big.sizes);
  EXPECT_FALSE(other.factorize(sparse(big.a)));
  // and a good matrix after the refusals
  ASSERT_TRUE(solver.factorize(sparse(s.a)));
  EXPECT_LT(solveError(solver, s, rng), 1e-12);
}

TEST(LinearSolver, DistrustedBodyBlocksPauseLongerEachTimeUntilOneServes)
{
  // 4, 8, 16 exact factorizations after successive distrusts; back to 4 after a body-block factorization
  // that served until the next one
  std::mt19937 rng(5);
  const Saddle s = makeSaddle({ 7, 7, 7 }, { 1, 1, 1 }, { { 0, 1 }, { 1, 2 } }, {}, 0.1, 0.0, rng);
  const Eigen::SparseMatrix<double> a = sparse(s.a);
  SparseLinearSolver solver;
  solver.allowDense(true);
  solver.allowBodyBlocks(s.sizes);
  const auto exactRun = [&]
  {
    int n = 0;
    while (true)
    {
      EXPECT_TRUE(solver.factorize(a));
      if (solver.bodyBlocks())
        return n;
      EXPECT_TRUE(solver.exact());
      ++n;
    }
  };
  ASSERT_TRUE(solver.factorize(a));
  ASSERT_TRUE(solver.bodyBlocks());
  EXPECT_FALSE(solver.exact());
  solver.distrustBodyBlocks();
  EXPECT_EQ(exactRun(), 4);
  solver.distrustBodyBlocks();
  EXPECT_EQ(exactRun(), 8);
  solver.distrustBodyBlocks();
  EXPECT_EQ(exactRun(), 16);
  ASSERT_TRUE(solver.factorize(a));  // the last body blocks served: the pause is back to 4
  ASSERT_TRUE(solver.bodyBlocks());
  solver.distrustBodyBlocks();
  EXPECT_EQ(exactRun(), 4);
  EXPECT_EQ(solver.bodyBlockRefusals(), 4 + 8 + 16 + 4);
  // suspended approximations give exact factors
  solver.allowApproximate(false);
  ASSERT_TRUE(solver.factorize(a));
  EXPECT_TRUE(solver.exact());
  Eigen::VectorXd x;
  solver.solve(Eigen::VectorXd::Ones(a.rows()), x);
  EXPECT_LT((s.a * x - Eigen::VectorXd::Ones(a.rows())).norm(), 1e-12 * x.norm());
}

TEST(LinearSolver, OnLargeMatricesTheDistrustPauseStartsAtOneStaticPivotFactorization)
{
  // a chain of 60 struts (657 unknowns: the static pivots' range): 1, 2, 4 static-pivot factorizations after
  // successive distrusts, back to 1 after body blocks that served; the costly exact kind is announced meanwhile
  std::mt19937 rng(13);
  const Saddle s = longStrutChain(60, rng);
  const Eigen::SparseMatrix<double> a = sparse(s.a);
  SparseLinearSolver solver;
  solver.allowDense(true);
  solver.allowStaticPivot(true);
  solver.allowBodyBlocks(s.sizes);
  // the static-pivot factorizations until the body blocks return, `pause` of them expected: until the last,
  // the next factorization is announced as the large exact kind
  const auto staticRun = [&](int pause)
  {
    int n = 0;
    while (n <= pause)
    {
      EXPECT_TRUE(solver.factorize(a));
      if (solver.bodyBlocks())
        return n;
      EXPECT_TRUE(solver.staticPivot());
      EXPECT_FALSE(solver.exact());
      ++n;
      EXPECT_EQ(solver.nextIsLargeExact(), n < pause) << n;
    }
    return n;
  };
  ASSERT_TRUE(solver.factorize(a));
  ASSERT_TRUE(solver.bodyBlocks());
  EXPECT_FALSE(solver.nextIsLargeExact());
  solver.distrustBodyBlocks();
  EXPECT_TRUE(solver.nextIsLargeExact());
  EXPECT_EQ(staticRun(1), 1);
  solver.distrustBodyBlocks();
  EXPECT_EQ(staticRun(2), 2);
  solver.distrustBodyBlocks();
  EXPECT_EQ(staticRun(4), 4);
  ASSERT_TRUE(solver.factorize(a));  // the last body blocks served: the pause is back to 1
  ASSERT_TRUE(solver.bodyBlocks());
  solver.distrustBodyBlocks();
  EXPECT_EQ(staticRun(1), 1);
  EXPECT_FALSE(solver.nextIsLargeExact());
  solver.allowApproximate(false);  // suspended body blocks: every factorization is the large exact kind
  EXPECT_TRUE(solver.nextIsLargeExact());
  // a small matrix never announces it (its exact factorizations are the dense or sparse LU)
  const Saddle small = makeSaddle({ 7, 7, 7 }, { 1, 1, 1 }, { { 0, 1 }, { 1, 2 } }, {}, 0.1, 0.0, rng);
  SparseLinearSolver lu;
  lu.allowStaticPivot(true);
  lu.allowBodyBlocks(small.sizes);
  ASSERT_TRUE(lu.factorize(sparse(small.a)));
  lu.distrustBodyBlocks();
  EXPECT_FALSE(lu.nextIsLargeExact());
}

TEST(LinearSolver, FactorizeApproximateLeavesTheExactFactorizationToTheCaller)
{
  // the two halves of factorize(): the body blocks when they serve, else nothing factorized (the dynamics
  // solver then factorizes with the one-body rows eliminated), in the same pause after a distrust
  std::mt19937 rng(9);
  const Saddle s = makeSaddle({ 7, 7, 7 }, { 1, 1, 1 }, { { 0, 1 }, { 1, 2 } }, {}, 0.1, 0.0, rng);
  const Eigen::SparseMatrix<double> a = sparse(s.a);
  SparseLinearSolver solver;
  solver.allowDense(true);
  ASSERT_FALSE(solver.factorizeApproximate(a));  // no body blocks allowed
  EXPECT_FALSE(solver.bodyBlocks());
  EXPECT_FALSE(solver.dense());
  ASSERT_TRUE(solver.factorizeExact(a));
  EXPECT_TRUE(solver.exact());
  solver.allowBodyBlocks(s.sizes);
  ASSERT_TRUE(solver.factorizeApproximate(a));
  EXPECT_TRUE(solver.bodyBlocks());
  solver.distrustBodyBlocks();
  for (int k = 0; k < 4; ++k)
  {
    EXPECT_FALSE(solver.factorizeApproximate(a)) << k;
    EXPECT_FALSE(solver.bodyBlocks());
  }
  EXPECT_TRUE(solver.factorizeApproximate(a));
  solver.allowApproximate(false);
  EXPECT_FALSE(solver.factorizeApproximate(a));
  // what factorizeExact() gives solves the whole matrix
  ASSERT_TRUE(solver.factorizeExact(a));
  Eigen::VectorXd x;
  solver.solve(Eigen::VectorXd::Ones(a.rows()), x);
  EXPECT_LT((s.a * x - Eigen::VectorXd::Ones(a.rows())).norm(), 1e-12 * x.norm());
  // factorizeExact() alone sees a new pattern too (the sparse LU analyzes it again)
  SparseLinearSolver lu;
  ASSERT_TRUE(lu.factorizeExact(a));
  const Saddle other = makeSaddle({ 7, 7, 7, 7 }, { 1, 1, 1, 1 }, { { 0, 1 }, { 2, 3 } }, {}, 0.1, 0.0, rng);
  ASSERT_TRUE(lu.factorizeExact(sparse(other.a)));
  EXPECT_EQ(lu.analyses(), 2);
  lu.solve(Eigen::VectorXd::Ones(other.a.rows()), x);
  EXPECT_LT((other.a * x - Eigen::VectorXd::Ones(other.a.rows())).norm(), 1e-12 * x.norm());
}

TEST(BodyBlocks, TheTowersNewtonMatrixIsCloseToItsBodyBlocks)
{
  // The premise of body blocks: at the paper's step the mass dominates the tower's Newton matrix, so the
  // iteration with A0 (couplings between bodies dropped) contracts fast. The spectral radius of I - A0^-1 A at
  // three instants of the fold, the last two with struts in contact (measured: 3.2e-6, 0.016, 0.016).
  int touching = 0;
  const TowerVisit check =
      [&touching](const Model& m, BodyDynamicsSolver& solver, const BodyState& s, const ActuationLaw& law)
  {
    const double h = m.solver.dt;
    touching = static_cast<int>(activeContacts(m, s).size());
    BlockSparseMatrix jac = solver.system().makeMatrix();
    Eigen::VectorXd r;
    solver.residualAndJacobian(s, h, law(s.t + h), s.qdd, s.lambda, r, &jac);
    Eigen::SparseMatrix<double> a = jac.matrix();
    a.makeCompressed();
    std::vector<int> sizes;
    for (const Body& b : m.bodies)
      sizes.push_back(b.nq);
    BodyBlockSolver blocks(sizes);
    ASSERT_TRUE(blocks.factorize(a));
    const Eigen::MatrixXd dense(a);
    Eigen::MatrixXd a0_inv_a(dense.rows(), dense.cols());
    Eigen::VectorXd x;
    for (Eigen::Index c = 0; c < dense.cols(); ++c)
    {
      blocks.solve(dense.col(c), x);
      a0_inv_a.col(c) = x;
    }
    const Eigen::MatrixXd e = Eigen::MatrixXd::Identity(dense.rows(), dense.cols()) - a0_inv_a;
    const double rho = e.eigenvalues().cwiseAbs().maxCoeff();
    std::printf("[ measured ] tower at t = %.2f s (%d pairs touching): spectral radius of I - A0^-1 A %.3g\n", s.t,
                touching, rho);
    EXPECT_LT(rho, 0.2) << s.t;
    EXPECT_GT(rho, 1e-6) << s.t;  // (the couplings are there, and dropped)
  };
  walkTowerFold({ 0.4, 1.5, 1.75 }, check);
  EXPECT_GT(touching, 0);
}
