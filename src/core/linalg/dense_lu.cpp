#include "active_tensegrity/core/linalg/dense_lu.h"

namespace active_tensegrity::core
{
void equilibrate(const Eigen::MatrixXd& a, Eigen::VectorXd& row, Eigen::VectorXd& col, Eigen::MatrixXd& out)
{
  row = a.cwiseAbs().rowwise().maxCoeff();
  for (Eigen::Index i = 0; i < row.size(); ++i)
    row(i) = row(i) > 0.0 ? 1.0 / row(i) : 1.0;
  out = row.asDiagonal() * a;
  col = out.cwiseAbs().colwise().maxCoeff().transpose();
  for (Eigen::Index j = 0; j < col.size(); ++j)
    col(j) = col(j) > 0.0 ? 1.0 / col(j) : 1.0;
  out = out * col.asDiagonal();
}

bool regular(const Eigen::PartialPivLU<Eigen::MatrixXd>& lu)
{
  // with partial pivoting on an equilibrated matrix a condition beyond 1e14 shows in its pivots in practice
  const auto pivots = lu.matrixLU().diagonal().cwiseAbs();  // (an expression: no allocation)
  if (pivots.size() > 0 && pivots.minCoeff() > 1e-8 * pivots.maxCoeff())
    return true;
  return lu.rcond() > 1e-14;
}

int determinantSign(const Eigen::PartialPivLU<Eigen::MatrixXd>& lu)
{
  int sign = lu.permutationP().determinant();
  const Eigen::MatrixXd& m = lu.matrixLU();
  for (Eigen::Index k = 0; k < m.rows(); ++k)
  {
    if (m(k, k) == 0.0)
      return 0;
    if (m(k, k) < 0.0)
      sign = -sign;
  }
  return sign;
}

}  // namespace active_tensegrity::core
