#include "active_tensegrity/oracle/sparse_linear_solver.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace active_tensegrity::core
{
namespace
{
/// Dense LU only up to this many unknowns (its cost grows as n^3) ...
constexpr Eigen::Index kDenseMaxRows = 400;
/// ... and when the sparse factors fill at least this share of a dense matrix.
constexpr double kDenseFill = 0.4;
/// The static-pivot LU above this many unknowns.
constexpr Eigen::Index kStaticPivotMinRows = 400;
/// delta = kShift phi^2 / d: phi the largest entry of the constraint rows, d the largest diagonal entry
/// (the Schur complement of the constraint block is about phi^2 / d at its smallest). Two effects pull
/// against each other, measured on the Newton matrix of the 504-strut lattice (phi^2 / d about 0.04),
/// as the contraction rate of refinement with these factors: the shift itself (rate about 0.8 kShift)
/// and the pivots' growth as delta shrinks (relative residual of the factors' own solve 2e-12, 2e-10,
/// 2e-8, 2e-6 at kShift 1e-2, 1e-4, 1e-6, 1e-8). At 1e-6 both are about 1e-5: modified Newton cannot
/// tell these factors from exact ones.
constexpr double kShift = 1e-6;
/// After a refused factorization, this many factorizations use the sparse LU before it is tried again.
constexpr int kStaticPivotSkip = 4;
/// The check of each factorization: A 1 solved must come back within this of 1, the largest
/// contraction rate modified Newton keeps a matrix for (measured: about 3e-6 on the lattices).
constexpr double kStaticPivotCheck = 0.5;
/// After refused body blocks, this many factorizations use the exact methods; after distrusted ones as many,
/// doubled with each distrust up to kBodyBlockPauseMost while the body blocks go on failing, back to
/// kBodyBlockSkip once one serves until it is replaced.
constexpr int kBodyBlockSkip = 4;
constexpr int kBodyBlockPauseMost = 256;
/// ... but on the static pivots' matrices (the large ones) the pause after a distrust starts at one
/// factorization: there an exact factorization costs far more than the iterations a failing body-block matrix
/// wastes (on a large lattice one static-pivot factorization costs tens of residuals), and each is kept for many
/// steps with its costly solves. (On the tower's exact, reduced, matrices so short a pause costs iterations.)
constexpr int kBodyBlockSkipLarge = 1;
constexpr int kBodyBlockDoublingsMost = 8;
/// The refined static pivots (StaticPivotLU::solveRefined): their factorization check, A 1 refined must come back
/// within this of 1.
constexpr double kRefineCheck = 1e-8;

bool hasSymmetricPattern(const Eigen::SparseMatrix<double>& a)
{
  const Eigen::SparseMatrix<double> t = a.transpose();
  if (t.nonZeros() != a.nonZeros())
    return false;
  for (Eigen::Index k = 0; k < a.outerSize(); ++k)
  {
    Eigen::SparseMatrix<double>::InnerIterator x(a, k), y(t, k);
    for (; x && y; ++x, ++y)
      if (x.index() != y.index())
        return false;
    if (x || y)
      return false;
  }
  return true;
}
}  // namespace

bool SparseLinearSolver::factorizeSparse(const Eigen::SparseMatrix<double>& a)
{
  if (!lu_analyzed_)
  {
    lu_.analyzePattern(a);
    lu_analyzed_ = true;
    ++analyses_;
  }
  lu_.factorize(a);
  return lu_.info() == Eigen::Success;
}

bool SparseLinearSolver::factorizeStaticPivot(const Eigen::SparseMatrix<double>& a)
{
  const Eigen::Index n = a.rows();
  const double diag = a.diagonal().cwiseAbs().maxCoeff();
  double phi = 0.0;
  for (int r : no_diagonal_)  // (column r holds the row's entries: the pattern is symmetric)
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, r); it; ++it)
      phi = std::max(phi, std::abs(it.value()));
  if (!(diag > 0.0) || !(phi > 0.0) || !std::isfinite(diag) || !std::isfinite(phi))
    return false;
  const double delta = kShift * phi * phi / diag;
  // (static_lu_ analyzes a pattern it has not seen itself)
  if (!static_lu_.factorize(a, no_diagonal_, -delta))
    return false;
  check_b_ = a * Eigen::VectorXd::Ones(n);
  if (approximate_)
  {
    static_lu_.solve(check_b_, check_x_);
    return check_x_.allFinite() && (check_x_.array() - 1.0).abs().maxCoeff() <= kStaticPivotCheck;
  }
  refine_a_ = a;
  return solveRefined(check_b_, check_x_) && (check_x_.array() - 1.0).abs().maxCoeff() <= kRefineCheck;
}

bool SparseLinearSolver::solveRefined(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
{
  return static_lu_.solveRefined(refine_a_, b, x, refine_r_, refine_d_);
}

void SparseLinearSolver::distrustBodyBlocks()
{
  if (method_ != Method::kBodyBlocks || body_blocks_distrusted_)
    return;
  body_blocks_distrusted_ = true;
  const int base = static_pivot_pattern_ ? kBodyBlockSkipLarge : kBodyBlockSkip;
  body_block_skip_ = std::min(base << body_block_doublings_, kBodyBlockPauseMost);
  body_block_doublings_ = std::min(body_block_doublings_ + 1, kBodyBlockDoublingsMost);
}

bool SparseLinearSolver::factorize(const Eigen::SparseMatrix<double>& a)
{
  return factorizeApproximate(a) || factorizeExact(a);
}

void SparseLinearSolver::notePattern(const Eigen::SparseMatrix<double>& a)
{
  if (a.rows() != analyzed_rows_ || a.nonZeros() != analyzed_nonzeros_)
  {
    analyzed_rows_ = a.rows();
    analyzed_nonzeros_ = a.nonZeros();
    lu_analyzed_ = false;
    decided_ = false;
    static_pivot_pattern_ = false;
    static_pivot_skip_ = 0;
    body_block_skip_ = 0;
    exact_method_ = Method::kSparse;
    if (allow_static_pivot_ && a.rows() > kStaticPivotMinRows && hasSymmetricPattern(a))
    {
      no_diagonal_.clear();
      for (Eigen::Index k = 0; k < a.outerSize(); ++k)
        if (a.coeff(k, k) == 0.0)
          no_diagonal_.push_back(static_cast<int>(k));
      static_pivot_pattern_ = !no_diagonal_.empty();
    }
  }
}

bool SparseLinearSolver::factorizeApproximate(const Eigen::SparseMatrix<double>& a)
{
  notePattern(a);
  if (method_ == Method::kBodyBlocks && !body_blocks_distrusted_)
    body_block_doublings_ = 0;  // the last one served until it was replaced
  body_blocks_distrusted_ = false;
  if (allow_body_blocks_ && approximate_)
  {
    if (body_block_skip_ > 0)
      --body_block_skip_;
    else if (body_blocks_.factorize(a))
    {
      method_ = Method::kBodyBlocks;
      return true;
    }
    else
      body_block_skip_ = kBodyBlockSkip;
    ++body_block_refusals_;
  }
  method_ = Method::kNone;
  return false;
}

bool SparseLinearSolver::factorizeExact(const Eigen::SparseMatrix<double>& a)
{
  notePattern(a);  // (a no-op after factorizeApproximate on the same matrix)
  if (static_pivot_pattern_)
  {
    if (static_pivot_skip_ > 0)
      --static_pivot_skip_;
    else if (factorizeStaticPivot(a))
    {
      method_ = approximate_ ? Method::kStaticPivot : Method::kStaticPivotRefined;
      return true;
    }
    else
      static_pivot_skip_ = kStaticPivotSkip;
    // refused: the sparse LU, for this and the next kStaticPivotSkip factorizations
    method_ = Method::kSparse;
    ++static_pivot_refusals_;
    return factorizeSparse(a);
  }
  method_ = exact_method_;
  if (method_ == Method::kSparse)
  {
    if (!factorizeSparse(a))
      return false;
    const bool choose = !decided_ && allow_dense_;  // the first factorization of this pattern decides
    decided_ = true;
    if (!choose)
      return true;
    const double n = static_cast<double>(a.rows());
    const bool dense = a.rows() <= kDenseMaxRows && static_cast<double>(lu_.nnzL() + lu_.nnzU()) >= kDenseFill * n * n;
    if (!dense)
      return true;
    method_ = exact_method_ = Method::kDense;
  }
  dense_ = a;
  if (equilibrate_)
  {
    equilibrate(dense_, row_scale_, col_scale_, dense_);  // (coefficient-wise: in place)
  }
  dense_lu_.compute(dense_);
  return regular(dense_lu_);
}

int SparseLinearSolver::determinantSign() const
{
  switch (method_)
  {
    case Method::kDense:
      return core::determinantSign(dense_lu_);
    case Method::kStaticPivot:
    case Method::kStaticPivotRefined:
      return static_lu_.determinantSign();
    case Method::kBodyBlocks:
    case Method::kNone:
      return 0;
    case Method::kSparse:
      break;
  }
  return static_cast<int>(lu_.signDeterminant());
}

}  // namespace active_tensegrity::core
