/// Singular value decompositions of dense matrices, compiled in one place.
#pragma once

#include <Eigen/Core>

namespace active_tensegrity::core
{
/// A = U diag(singular) V^T, the singular values in decreasing order. U and V hold what was asked for
/// (thin or full), and are empty otherwise.
struct Svd
{
  Eigen::VectorXd singular;
  Eigen::MatrixXd u;
  Eigen::MatrixXd v;
};

/// The SVD of `a` by Eigen's divide and conquer (BDCSVD; for fewer than 16 columns it is the one-sided
/// Jacobi SVD). `options` are Eigen's Compute{Thin,Full}{U,V} flags.
///
/// Eigen's SVD templates take about a minute to compile (release build, or clang's sanitizer build; nearly two
/// under GCC's sanitizers), as long as the longest files of the core; this function and jacobiSvd instantiate
/// them once, for every caller.
Svd svd(const Eigen::MatrixXd& a, unsigned int options);

/// The SVD of `a` by Eigen's one-sided Jacobi SVD with column-pivoting QR preconditioning (JacobiSVD): high
/// relative accuracy in the small singular values, for small matrices. `options` as for svd.
Svd jacobiSvd(const Eigen::MatrixXd& a, unsigned int options);
}  // namespace active_tensegrity::core
