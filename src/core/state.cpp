#include "active_tensegrity/core/state.h"

namespace active_tensegrity::core
{
State initialState(const Model& model)
{
  State s;
  s.q = model.q0;
  s.qd.setZero(model.nq);
  s.qdd.setZero(model.nq);
  s.acc.setZero(model.nq);
  s.lambda.setZero(model.n_lambda);
  s.u.assign(model.actuators.size(), ActuationValue{});
  s.contact_speed.assign(model.checked_pairs.size(), 0.0);
  return s;
}

const char* toString(SolveStatus s)
{
  switch (s)
  {
    case SolveStatus::kConverged:
      return "converged";
    case SolveStatus::kMaxIterations:
      return "max_iterations";
    case SolveStatus::kSingular:
      return "singular";
    case SolveStatus::kNonFinite:
      return "non_finite";
    case SolveStatus::kPassedThrough:
      return "passed_through";
  }
  return "unknown";
}

namespace
{
/// Dense LU only up to this many unknowns (its cost grows as n^3) ...
constexpr Eigen::Index kDenseMaxRows = 400;
/// ... and when the sparse factors fill at least this share of a dense matrix.
constexpr double kDenseFill = 0.4;
}  // namespace

bool SparseLinearSolver::factorize(const Eigen::SparseMatrix<double>& a)
{
  if (a.rows() != analyzed_rows_ || a.nonZeros() != analyzed_nonzeros_)
  {
    lu_.analyzePattern(a);
    analyzed_rows_ = a.rows();
    analyzed_nonzeros_ = a.nonZeros();
    ++analyses_;
    decided_ = false;
    dense_mode_ = false;
  }
  if (!dense_mode_)
  {
    lu_.factorize(a);
    if (lu_.info() != Eigen::Success)
      return false;
    if (decided_ || !allow_dense_)
      return true;
    decided_ = true;
    const double n = static_cast<double>(a.rows());
    dense_mode_ = a.rows() <= kDenseMaxRows && static_cast<double>(lu_.nnzL() + lu_.nnzU()) >= kDenseFill * n * n;
    if (!dense_mode_)
      return true;
  }
  dense_ = a;
  dense_lu_.compute(dense_);
  return dense_lu_.rcond() > 1e-14;
}

}  // namespace active_tensegrity::core
