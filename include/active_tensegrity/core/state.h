/// The changing part of a simulation, and the Summary every solver returns.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <Eigen/LU>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseLU>

#include "active_tensegrity/core/mechanics.h"

namespace active_tensegrity::core
{
struct State
{
  double t = 0.0;          // s (dynamics) or load parameter (statics)
  Eigen::VectorXd q;       // coordinates, 7 per strut, 3 per point mass
  Eigen::VectorXd qd;      // their time derivatives
  Eigen::VectorXd qdd;     // accelerations
  Eigen::VectorXd acc;     // generalized-alpha pseudo-accelerations (equal to qdd for Newmark)
  Eigen::VectorXd lambda;  // multipliers of the model's constraints (then any solver-added ones)
  ActuationValues u;       // actuation values at t
  /// Contact memory per checked pair: the impact speed v_0 (m/s) of a live contact, 0 when the pair
  /// is apart. Set at contact onset, forgotten at separation (dynamics).
  std::vector<double> contact_speed;
};

/// A state at rest in the model's initial configuration.
State initialState(const Model& model);

enum class SolveStatus
{
  kConverged,
  kMaxIterations,  // Newton did not converge within max_iterations (after all step cuts)
  kSingular,       // the Newton matrix could not be factorized (a mechanism, or a degenerate state)
  kNonFinite,      // a NaN or infinity appeared
  kPassedThrough   // the solution has two checked struts passed through each other (contact tunnelling)
};

const char* toString(SolveStatus s);

struct Summary
{
  SolveStatus status = SolveStatus::kConverged;
  int iterations = 0;         // Newton iterations, all attempts included
  int step_cuts = 0;          // times a step or load increment was halved
  int crossings_refused = 0;  // dynamics: steps refused (and cut) because a strut would pass through another
  double residual = 0.0;      // last increment norm (dynamics) or force residual (statics)
  std::string message;
  bool ok() const
  {
    return status == SolveStatus::kConverged;
  }
};

/// Factorizations of the Newton matrices. Sparse LU (Eigen's SparseLU, COLAMD) with the symbolic
/// analysis reused while the pattern stays; a new pattern is detected by its size and number of stored
/// entries (the Newton matrices, BlockSparseMatrix, only ever grow, so every change of their pattern
/// changes that number). Two choices beside it, each made once per pattern:
/// - allowDense(): a small matrix whose sparse factors fill at least 40 % of a dense one (the tower:
///   200 unknowns, 53 %) is factorized densely instead (partial pivoting): the dense triangular solves
///   are about twice as fast there (docs/benchmarks.md).
/// - allowSymmetric(): a large matrix (over 400 unknowns) with a symmetric pattern gets an *approximate*
///   factorization: the LDL^T of its symmetric part, with -delta on the diagonal of the rows that have none
///   (the constraint rows), in Eigen's SimplicialLDLT with an AMD ordering. The constraint block made
///   negative definite, the matrix is quasi-definite, whose LDL^T exists for any symmetric ordering
///   (Vanderbei 1995), so the ordering can follow the fill alone; sparse LU's row pivoting cannot. On a
///   lattice of 504 struts its factors hold 7x fewer entries than the LU's (docs/benchmarks.md). It solves
///   the matrix only approximately (the antisymmetric part of friction and the quaternion terms, delta):
///   for modified Newton only, whose contraction test sees the difference (exact() is false). Each
///   factorization is checked on one right-hand side (A 1 must come back within 0.5 of 1); a matrix
///   failing that, or a failed LDL^T, gets the sparse LU, and so do the next four factorizations
///   (steel impacts on the lattices: a large antisymmetric friction and damping tangent for a while).
class SparseLinearSolver
{
public:
  /// Lets the solver choose the dense LU for small, filled matrices (dynamics; statics keeps the sparse
  /// factors its mechanism detection and damped Newton were validated with).
  void allowDense(bool allow)
  {
    allow_dense_ = allow;
  }
  /// Lets the solver choose the approximate symmetric LDL^T for large matrices (modified Newton).
  void allowSymmetric(bool allow)
  {
    allow_symmetric_ = allow;
  }
  /// False when the matrix is singular: sparse, an exact zero pivot (round-off can hide a numerically
  /// singular matrix); dense, a reciprocal condition estimate below 1e-14; symmetric, a zero pivot in
  /// both the LDL^T and the sparse LU.
  bool factorize(const Eigen::SparseMatrix<double>& a);
  /// Symbolic analyses done so far (one per pattern seen, two when the LDL^T was refused).
  int analyses() const
  {
    return analyses_;
  }
  bool dense() const
  {
    return method_ == Method::kDense;
  }
  bool symmetric() const
  {
    return method_ == Method::kSymmetric;
  }
  /// Factorizations that fell back from the symmetric LDL^T to the sparse LU (refused, or in the
  /// pause after a refusal).
  int symmetricRefusals() const
  {
    return symmetric_refusals_;
  }
  /// The next four factorizations use the sparse LU (modified Newton: the symmetric factors
  /// of this step contracted too slowly although they passed their check).
  void refuseSymmetric();
  /// Whether solve() solves the factorized matrix to round-off (false: the symmetric approximation).
  bool exact() const
  {
    return method_ != Method::kSymmetric;
  }
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
  {
    switch (method_)
    {
      case Method::kDense:
        x = dense_lu_.solve(b);
        break;
      case Method::kSymmetric:
        x = ldlt_.solve(b);
        break;
      case Method::kSparse:
        x = lu_.solve(b);
        break;
    }
  }

private:
  enum class Method
  {
    kSparse,
    kDense,
    kSymmetric
  };
  bool factorizeSparse(const Eigen::SparseMatrix<double>& a);
  bool factorizeSymmetric(const Eigen::SparseMatrix<double>& a);

  Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>> lu_;
  bool lu_analyzed_ = false;        // lu_ holds the analysis of the current pattern
  bool ldlt_analyzed_ = false;      // ldlt_ likewise
  bool symmetric_pattern_ = false;  // the current pattern gets the symmetric LDL^T when it passes
  int symmetric_skip_ = 0;          // factorizations left before the LDL^T is tried again
  int symmetric_refusals_ = 0;
  Eigen::Index analyzed_rows_ = -1, analyzed_nonzeros_ = -1;
  int analyses_ = 0;
  bool allow_dense_ = false;
  bool allow_symmetric_ = false;
  bool decided_ = false;  // whether the dense LU was chosen or not for the current pattern
  Method method_ = Method::kSparse;
  Eigen::MatrixXd dense_;
  Eigen::PartialPivLU<Eigen::MatrixXd> dense_lu_;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt_;
  Eigen::SparseMatrix<double> sym_, shift_;  // the symmetric part and -delta on the constraint rows
  std::vector<int> no_diagonal_;             // rows of the pattern without a diagonal entry
  Eigen::VectorXd check_b_, check_x_;
};

}  // namespace active_tensegrity::core
