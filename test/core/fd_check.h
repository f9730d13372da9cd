// Finite-difference Jacobian checks used by the core tests (central differences; relative error
// with an absolute floor). Quaternion coordinates are perturbed directly in all four numbers: the
// formulas are polynomial in Theta, so the analytic derivatives hold off the unit sphere too.
#pragma once

#include <functional>
#include <sstream>
#include <string>

#include <Eigen/Core>

namespace active_tensegrity::test
{
struct FdComparison
{
  bool ok = false;
  double max_error = 0.0;  // max |analytic - numeric|
  double scale = 0.0;      // max(max |numeric|, floor)
  int row = -1, col = -1;  // where the largest error is
  std::string message;
};

/// Central-difference Jacobian of f at x with step h (relative to max(1, |x_j|)).
inline Eigen::MatrixXd fdJacobian(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
                                  const Eigen::VectorXd& x, double h = 1e-6)
{
  const Eigen::VectorXd f0 = f(x);
  Eigen::MatrixXd jac(f0.size(), x.size());
  for (int j = 0; j < x.size(); ++j)
  {
    const double step = h * std::max(1.0, std::abs(x(j)));
    Eigen::VectorXd xp = x, xm = x;
    xp(j) += step;
    xm(j) -= step;
    jac.col(j) = (f(xp) - f(xm)) / (2.0 * step);
  }
  return jac;
}

/// Passes when max |analytic - numeric| <= tol * max(max |numeric|, floor).
inline FdComparison compareJacobians(const Eigen::MatrixXd& analytic, const Eigen::MatrixXd& numeric, double tol,
                                     double floor)
{
  FdComparison c;
  if (analytic.rows() != numeric.rows() || analytic.cols() != numeric.cols())
  {
    c.message = "shape mismatch";
    return c;
  }
  const Eigen::MatrixXd diff = (analytic - numeric).cwiseAbs();
  Eigen::Index r = 0, k = 0;
  c.max_error = diff.size() ? diff.maxCoeff(&r, &k) : 0.0;
  c.row = static_cast<int>(r);
  c.col = static_cast<int>(k);
  c.scale = std::max(numeric.size() ? numeric.cwiseAbs().maxCoeff() : 0.0, floor);
  c.ok = std::isfinite(c.max_error) && c.max_error <= tol * c.scale;
  std::ostringstream s;
  s << "max error " << c.max_error << " at (" << c.row << ", " << c.col << ") against scale " << c.scale << " (tol "
    << tol << "); analytic " << (diff.size() ? analytic(r, k) : 0.0) << ", numeric "
    << (diff.size() ? numeric(r, k) : 0.0);
  c.message = s.str();
  return c;
}

}  // namespace active_tensegrity::test
