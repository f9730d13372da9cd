/// The changing part of a simulation, and the Summary every solver returns.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <Eigen/LU>
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

/// LU of the Newton matrices. Sparse (Eigen's SparseLU, COLAMD) with the symbolic analysis reused
/// while the pattern stays; a new pattern is detected by its size and number of stored entries (the
/// Newton matrices, BlockSparseMatrix, only ever grow, so every change of their pattern changes that
/// number). With allowDense(), a small matrix whose sparse factors fill at least 40 % of a dense one
/// (the tower: 200 unknowns, 53 %) is factorized densely instead (partial pivoting): the dense
/// triangular solves are about twice as fast there (docs/benchmarks.md). The choice is made once per
/// pattern, from the first sparse factorization.
class SparseLinearSolver
{
public:
  /// Lets the solver choose the dense LU for small, filled matrices (dynamics; statics keeps the sparse
  /// factors its mechanism detection and damped Newton were validated with).
  void allowDense(bool allow)
  {
    allow_dense_ = allow;
  }
  /// False when the matrix is singular: sparse, an exact zero pivot (round-off can hide a numerically
  /// singular matrix); dense, a reciprocal condition estimate below 1e-14.
  bool factorize(const Eigen::SparseMatrix<double>& a);
  /// Symbolic analyses done so far (one per pattern seen).
  int analyses() const
  {
    return analyses_;
  }
  bool dense() const
  {
    return dense_mode_;
  }
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
  {
    if (dense_mode_)
      x = dense_lu_.solve(b);
    else
      x = lu_.solve(b);
  }

private:
  Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>> lu_;
  Eigen::Index analyzed_rows_ = -1, analyzed_nonzeros_ = -1;
  int analyses_ = 0;
  bool allow_dense_ = false;
  bool decided_ = false;  // whether dense_mode_ was chosen for the current pattern
  bool dense_mode_ = false;
  Eigen::MatrixXd dense_;
  Eigen::PartialPivLU<Eigen::MatrixXd> dense_lu_;
};

}  // namespace active_tensegrity::core
