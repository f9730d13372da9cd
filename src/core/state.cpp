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

bool SparseLinearSolver::factorize(const Eigen::SparseMatrix<double>& a)
{
  if (a.rows() != analyzed_rows_ || a.nonZeros() != analyzed_nonzeros_)
  {
    lu_.analyzePattern(a);
    analyzed_rows_ = a.rows();
    analyzed_nonzeros_ = a.nonZeros();
    ++analyses_;
  }
  lu_.factorize(a);
  return lu_.info() == Eigen::Success;
}

}  // namespace active_tensegrity::core
