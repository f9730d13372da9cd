/// The changing part of a simulation, and the Summary every solver returns.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>
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

/// Sparse LU whose symbolic analysis (ordering, elimination tree) is reused while the pattern stays.
/// A new pattern is detected by its size and number of stored entries: the Newton matrices
/// (BlockSparseMatrix) only ever grow, so every change of their pattern changes that number.
class SparseLinearSolver
{
public:
  bool factorize(const Eigen::SparseMatrix<double>& a);
  /// Symbolic analyses done so far (one per pattern seen).
  int analyses() const
  {
    return analyses_;
  }
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
  {
    x = lu_.solve(b);
  }

private:
  Eigen::SparseLU<Eigen::SparseMatrix<double>, Eigen::COLAMDOrdering<int>> lu_;
  Eigen::Index analyzed_rows_ = -1, analyzed_nonzeros_ = -1;
  int analyses_ = 0;
};

}  // namespace active_tensegrity::core
