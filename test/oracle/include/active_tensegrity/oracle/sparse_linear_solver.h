/// The linear solver of the Newton matrices (sparse LU, dense LU or static pivots; see the class).
#pragma once

#include <limits>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>

#include "active_tensegrity/oracle/body_block_solver.h"
#include "active_tensegrity/core/linalg/static_lu.h"

#include "active_tensegrity/core/linalg/dense_lu.h"

namespace active_tensegrity::core
{
/// Factorizations of the Newton matrices. Sparse LU (Eigen's SparseLU, COLAMD) with the symbolic
/// analysis reused while the pattern stays; a new pattern is detected by its size and number of stored
/// entries (the Newton matrices, BlockSparseMatrix, only ever grow, so every change of their pattern
/// changes that number). Two choices beside it, each made once per pattern:
/// - allowDense(): a small matrix whose sparse factors fill at least 40 % of a dense one (the tower:
///   200 unknowns, 53 %) is factorized densely instead (partial pivoting): the dense triangular solves
///   are about twice as fast there (docs/benchmarks.md).
/// - allowStaticPivot(): a large matrix (over 400 unknowns) with a symmetric pattern is factorized
///   without pivoting (StaticPivotLU) in an AMD order, after -delta is put on the diagonal of the rows
///   that have none (the constraint rows), delta about 1e-6 of the constraint block's Schur complement.
///   Shifted so, the Newton matrix is nearly quasi-definite (a dominant positive block, a negative one),
///   whose pivots stay away from zero in any symmetric order, so the order can follow the fill alone;
///   sparse LU's row pivoting spoils it. On a lattice of 504 struts the factors hold 7x fewer entries than
///   the LU's (docs/benchmarks.md). The shift makes the solve approximate (a contraction of about 1e-5
///   when refined): for modified Newton, whose contraction test sees it (exact() is false). Each
///   factorization is checked on one right-hand side (A 1 must come back within 0.5 of 1); a matrix
///   failing that, or with a zero pivot, gets the sparse LU, and so do the next four factorizations.
///   With the approximate methods suspended (allowApproximate(false): full Newton) the same factors serve
///   as an exact method: every solve is refined against the matrix until its corrections reach round-off
///   (exact() is true), and the check must refine A 1 to within 1e-8 of 1. On a lattice of 2000 struts
///   (22 000 unknowns) the sparse LU's factors hold 13-15 million entries against the static pivots' 3
///   million, and a factorization took about 0.7 s against 0.1 s.
/// - allowBodyBlocks(): a matrix of body groups and constraint rows is solved through BodyBlockSolver, the
///   couplings between bodies dropped (modified Newton in dynamics, at steps where the mass dominates).
///   Approximate, so exact() is false. A refused one (BodyBlockSolver::factorize) and the next four after it
///   get the other methods; so do the next ones after distrustBodyBlocks().

class SparseLinearSolver
{
public:
  /// Lets the solver choose the dense LU for small, filled matrices (dynamics; statics with equilibrate).
  /// equilibrate: the dense matrix is scaled, rows then columns to a largest entry of 1, before it is
  /// factorized and its condition judged (statics: stiff contact next to unit constraint rows would
  /// otherwise read as singular); solves undo the scaling.
  void allowDense(bool allow, bool equilibrate = false)
  {
    allow_dense_ = allow;
    equilibrate_ = equilibrate;
  }
  /// Lets the solver choose the static-pivot LU for large matrices (modified Newton).
  void allowStaticPivot(bool allow)
  {
    allow_static_pivot_ = allow;
  }
  /// Lets the solver use BodyBlockSolver on matrices whose first columns are grouped by body as given
  /// (sizes from the first column on; empty: never).
  void allowBodyBlocks(const std::vector<int>& body_sizes)
  {
    const bool groups = body_blocks_.groupsAllowed();
    body_blocks_ = BodyBlockSolver(body_sizes);
    body_blocks_.allowGroups(groups);
    allow_body_blocks_ = !body_sizes.empty();
  }
  /// Whether the body blocks may join strongly coupled bodies (BodyBlockSolver::allowGroups; default true).
  void allowBodyGroups(bool allow)
  {
    body_blocks_.allowGroups(allow);
  }
  /// Suspends (false) or restores (true) the approximate methods, as allowed: the body blocks, and the static
  /// pivots' unrefined solves (while suspended, the static pivots are refined to round-off at every solve).
  void allowApproximate(bool allow)
  {
    approximate_ = allow;
  }
  /// Whether the approximate methods are allowed (allowApproximate), so that a caller can restore the setting.
  bool approximateAllowed() const
  {
    return approximate_;
  }
  /// The caller found the last factorization, when it is the body blocks, too far off (modified Newton did
  /// not contract with it): the next factorizations use the other methods (4, or 1 where they are the static
  /// pivots, doubled with each distrust while the body blocks keep failing, up to 256; back to 4 or 1 once a
  /// body-block factorization serves until the next factorization).
  void distrustBodyBlocks();
  /// Whether the next factorization would be an exact one of a large matrix (the static pivots' pattern, the body
  /// blocks not allowed, suspended or in their pause): the costly kind, which DynamicsSolver does not make only
  /// because the touching pairs changed.
  bool nextIsLargeExact() const
  {
    return static_pivot_pattern_ && (!allow_body_blocks_ || !approximate_ || body_block_skip_ > 0);
  }
  /// False when the matrix is singular: sparse, an exact zero pivot (round-off can hide a numerically
  /// singular matrix); dense, a reciprocal condition estimate below 1e-14; static pivots, a zero pivot
  /// in both them and the sparse LU.
  bool factorize(const Eigen::SparseMatrix<double>& a);
  /// The first half of factorize(): the body blocks when they are allowed, not suspended and take the matrix
  /// (true), else false with nothing factorized (bodyBlocks() and the other methods' queries false, solve()
  /// not to be called): the caller factorizes the matrix exactly by other means (DynamicsSolver: with the
  /// one-body rows eliminated), or calls factorizeExact().
  bool factorizeApproximate(const Eigen::SparseMatrix<double>& a);
  /// The second half: the static pivots when allowed (large matrices), else the sparse or the dense LU.
  bool factorizeExact(const Eigen::SparseMatrix<double>& a);
  /// Symbolic analyses done so far (one per pattern seen, two when the static pivots were refused).
  int analyses() const
  {
    return analyses_ + static_lu_.analyses() + body_blocks_.analyses();
  }
  bool dense() const
  {
    return method_ == Method::kDense;
  }
  bool staticPivot() const
  {
    return method_ == Method::kStaticPivot;
  }
  bool bodyBlocks() const
  {
    return method_ == Method::kBodyBlocks;
  }
  /// Factorizations that fell back from the body blocks to the other methods (refused, distrusted or in the
  /// pause after them).
  int bodyBlockRefusals() const
  {
    return body_block_refusals_;
  }
  /// Factorizations that fell back from the static pivots to the sparse LU (refused, or in the
  /// pause after a refusal).
  int staticPivotRefusals() const
  {
    return static_pivot_refusals_;
  }
  /// Whether solve() solves the factorized matrix to round-off (false: the shifted static pivots, the body
  /// blocks; true for the static pivots refined to round-off, which staticPivot() does not count).
  bool exact() const
  {
    return method_ != Method::kStaticPivot && method_ != Method::kBodyBlocks;
  }
  /// Whether the last factorization is the static pivots refined to round-off at every solve (the exact
  /// method of large symmetric patterns while the approximate methods are suspended).
  bool staticPivotRefined() const
  {
    return method_ == Method::kStaticPivotRefined;
  }
  /// Sign of the determinant of the last factorized matrix (+1, -1, or 0 when a pivot is exactly zero);
  /// with the static pivots that of the shifted matrix; with the body blocks 0 (not computed). A change of sign along a
  /// path of Newton matrices says that an odd number of eigenvalues passed through zero (statics: a critical point).
  int determinantSign() const;
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
  {
    switch (method_)
    {
      case Method::kDense:
        if (equilibrate_)
          x = col_scale_.cwiseProduct(dense_lu_.solve(row_scale_.cwiseProduct(b)));
        else
          x = dense_lu_.solve(b);
        break;
      case Method::kStaticPivot:
        static_lu_.solve(b, x);
        break;
      case Method::kStaticPivotRefined:
        solveRefined(b, x);
        break;
      case Method::kSparse:
        x = lu_.solve(b);
        break;
      case Method::kBodyBlocks:
        body_blocks_.solve(b, x);
        break;
      case Method::kNone:
        x.setConstant(b.size(), std::numeric_limits<double>::quiet_NaN());  // (a caller's error: no factorization)
        break;
    }
  }

private:
  enum class Method
  {
    kSparse,
    kDense,
    kStaticPivot,
    kStaticPivotRefined,  // the static pivots, every solve refined against refine_a_ to round-off
    kBodyBlocks,
    kNone  // factorizeApproximate() declined: nothing factorized here
  };
  /// A new pattern (size or number of entries): every choice made for the last one is made again.
  void notePattern(const Eigen::SparseMatrix<double>& a);
  bool factorizeSparse(const Eigen::SparseMatrix<double>& a);
  bool factorizeStaticPivot(const Eigen::SparseMatrix<double>& a);
  /// x = A^-1 b through the static pivots, refined against refine_a_: true when the corrections reached
  /// round-off (false: they stalled above 1e-10 of the solution, or were still shrinking after 8).
  bool solveRefined(const Eigen::VectorXd& b, Eigen::VectorXd& x) const;

  mutable Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>> lu_;  // (signDeterminant)
  bool lu_analyzed_ = false;           // lu_ holds the analysis of the current pattern
  bool static_pivot_pattern_ = false;  // the current pattern gets the static pivots when they pass
  int static_pivot_skip_ = 0;          // factorizations left before they are tried again
  int static_pivot_refusals_ = 0;
  Eigen::Index analyzed_rows_ = -1, analyzed_nonzeros_ = -1;
  int analyses_ = 0;
  bool allow_dense_ = false;
  bool equilibrate_ = false;
  Eigen::VectorXd row_scale_, col_scale_;  // D_r, D_c of the equilibrated dense matrix D_r A D_c
  bool allow_static_pivot_ = false;
  bool decided_ = false;  // whether the dense LU was chosen or not for the current pattern
  Method method_ = Method::kSparse;
  Eigen::MatrixXd dense_;
  Eigen::PartialPivLU<Eigen::MatrixXd> dense_lu_;
  StaticPivotLU static_lu_;
  bool approximate_ = true;
  bool allow_body_blocks_ = false;
  int body_block_skip_ = 0;              // factorizations left before the body blocks are tried again
  int body_block_doublings_ = 0;         // of the skip after the next distrust (kBodyBlockSkip or 1 at first)
  bool body_blocks_distrusted_ = false;  // the current factorization is distrusted body blocks
  int body_block_refusals_ = 0;
  BodyBlockSolver body_blocks_;
  Method exact_method_ = Method::kSparse;  // the method of the pattern's exact factorizations
  std::vector<int> no_diagonal_;           // rows of the pattern without a diagonal entry (they get -delta)
  Eigen::VectorXd check_b_, check_x_;
  Eigen::SparseMatrix<double> refine_a_;         // the matrix the refined static pivots solve
  mutable Eigen::VectorXd refine_r_, refine_d_;  // a refinement's residual and correction
};

}  // namespace active_tensegrity::core
