#include "active_tensegrity/core/state.h"

#include <algorithm>
#include <cmath>
#include <vector>

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
/// The symmetric LDL^T above this many unknowns.
constexpr Eigen::Index kSymmetricMinRows = 400;
/// delta = kShift phi^2 / d: phi the largest entry of the constraint rows, d the largest diagonal entry
/// (the Schur complement of the constraint block is about phi^2 / d at its smallest). Measured on the
/// Newton matrix of the 504-strut lattice (phi^2 / d about 0.04): delta from 1e-12 to 1e-6 gives the
/// same contraction (1e-4 .. 1e-2, set by the antisymmetric part); 1e-14 lets the pivots grow until the
/// solve is useless (rate 0.3), and 0.04 itself makes the approximation useless (the check fails).
/// kShift sits in the middle of that band on a log scale.
constexpr double kShift = 1e-8;
/// After a refused LDL^T, this many factorizations use the sparse LU before the LDL^T is tried again.
constexpr int kSymmetricSkip = 4;
/// The check of each LDL^T: A 1 solved must come back within this of 1, the largest contraction rate
/// modified Newton keeps a matrix for. On the 504-strut lattice 0.5 rather than 0.1 took 9.96 to 9.30 ms
/// per step (fewer LU factorizations in the steel impacts, the same Newton iterations).
constexpr double kSymmetricCheck = 0.5;

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

bool SparseLinearSolver::factorizeSymmetric(const Eigen::SparseMatrix<double>& a)
{
  const Eigen::Index n = a.rows();
  sym_ = a.transpose();
  sym_ += a;
  sym_ *= 0.5;
  const double diag = sym_.diagonal().cwiseAbs().maxCoeff();
  double phi = 0.0;
  for (int r : no_diagonal_)
    for (Eigen::SparseMatrix<double>::InnerIterator it(sym_, r); it; ++it)
      phi = std::max(phi, std::abs(it.value()));
  if (!(diag > 0.0) || !(phi > 0.0) || !std::isfinite(diag) || !std::isfinite(phi))
    return false;
  const double delta = kShift * phi * phi / diag;
  std::vector<Eigen::Triplet<double>> shift;
  shift.reserve(no_diagonal_.size());
  for (int r : no_diagonal_)
    shift.emplace_back(r, r, -delta);
  shift_.resize(n, n);
  shift_.setFromTriplets(shift.begin(), shift.end());
  sym_ += shift_;
  if (!ldlt_analyzed_)
  {
    ldlt_.analyzePattern(sym_);
    ldlt_analyzed_ = true;
    ++analyses_;
  }
  ldlt_.factorize(sym_);
  if (ldlt_.info() != Eigen::Success || !ldlt_.vectorD().allFinite() || (ldlt_.vectorD().array() == 0.0).any())
    return false;
  check_b_ = a * Eigen::VectorXd::Ones(n);
  check_x_ = ldlt_.solve(check_b_);
  return check_x_.allFinite() && (check_x_.array() - 1.0).abs().maxCoeff() <= kSymmetricCheck;
}

void SparseLinearSolver::refuseSymmetric()
{
  if (symmetric_pattern_)
    symmetric_skip_ = kSymmetricSkip;
}

bool SparseLinearSolver::factorize(const Eigen::SparseMatrix<double>& a)
{
  if (a.rows() != analyzed_rows_ || a.nonZeros() != analyzed_nonzeros_)
  {
    analyzed_rows_ = a.rows();
    analyzed_nonzeros_ = a.nonZeros();
    lu_analyzed_ = false;
    ldlt_analyzed_ = false;
    decided_ = false;
    symmetric_pattern_ = false;
    symmetric_skip_ = 0;
    method_ = Method::kSparse;
    if (allow_symmetric_ && a.rows() > kSymmetricMinRows && hasSymmetricPattern(a))
    {
      no_diagonal_.clear();
      for (Eigen::Index k = 0; k < a.outerSize(); ++k)
        if (a.coeff(k, k) == 0.0)
          no_diagonal_.push_back(static_cast<int>(k));
      symmetric_pattern_ = !no_diagonal_.empty();
    }
  }
  if (symmetric_pattern_)
  {
    if (symmetric_skip_ > 0)
      --symmetric_skip_;
    else if (factorizeSymmetric(a))
    {
      method_ = Method::kSymmetric;
      return true;
    }
    else
      symmetric_skip_ = kSymmetricSkip;
    // refused: the sparse LU, for this and the next kSymmetricSkip factorizations
    method_ = Method::kSparse;
    ++symmetric_refusals_;
    return factorizeSparse(a);
  }
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
    method_ = Method::kDense;
  }
  dense_ = a;
  dense_lu_.compute(dense_);
  return dense_lu_.rcond() > 1e-14;
}

}  // namespace active_tensegrity::core
