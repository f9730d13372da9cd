/// Dense LU helpers of the solvers that factorize small Newton matrices densely.
#pragma once

#include <Eigen/Core>
#include <Eigen/LU>

namespace active_tensegrity::core
{
/// `a` scaled by rows, then by columns, to a largest entry of 1 in each: out = diag(row) a diag(col) (an empty row or
/// column keeps 1; out may be a).
void equilibrate(const Eigen::MatrixXd& a, Eigen::VectorXd& row, Eigen::VectorXd& col, Eigen::MatrixXd& out);
/// Whether the LU of an equilibrated matrix is regular: its reciprocal condition above 1e-14, estimated only when the
/// pivots spread over more than 8 decades (a mechanism's matrix has a pivot at round-off; the estimate costs a few
/// triangular solves).
bool regular(const Eigen::PartialPivLU<Eigen::MatrixXd>& lu);
/// The sign of the determinant of a dense LU (0 when a pivot is zero).
int determinantSign(const Eigen::PartialPivLU<Eigen::MatrixXd>& lu);

}  // namespace active_tensegrity::core
