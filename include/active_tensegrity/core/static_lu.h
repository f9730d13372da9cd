/// Sparse LU without pivoting for matrices with a symmetric pattern, in a fill-reducing symmetric order.
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace active_tensegrity::core
{
/// P A P^T = L D U with L unit lower, U unit upper triangular and D diagonal, P from AMD on the pattern
/// of A (which must be symmetric). No pivoting: the pivots are the order's diagonal, so the factors
/// have the pattern of the Cholesky factor of that order (L and U^T share it), and the work is that of
/// two Cholesky factorizations. Stable for matrices whose symmetric part dominates and whose pivots stay
/// away from zero, as quasi-definite ones (a positive definite block, a negative definite one) do;
/// others are for the caller to check (a zero pivot is reported). The algorithm is the up-looking one
/// of LDL (Davis 2005, ACM TOMS 31(4), "Algorithm 849"), with the row of L and the column of U of each
/// step found by two sparse triangular solves over the same elimination-tree reach.
class StaticPivotLU
{
public:
  /// The order, the elimination tree and the factors' pattern; `a` must have a symmetric pattern and a
  /// stored diagonal (explicit zeros allowed).
  void analyzePattern(const Eigen::SparseMatrix<double>& a);
  /// False on a zero or non-finite pivot. The pattern must be the analyzed one.
  bool factorize(const Eigen::SparseMatrix<double>& a);
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const;
  /// Sign of det(A) = prod(D) (P A P^T has the determinant of A; L and U are unit triangular).
  int determinantSign() const
  {
    int sign = 1;
    for (Eigen::Index k = 0; k < d_.size(); ++k)
      sign = d_[k] < 0.0 ? -sign : (d_[k] == 0.0 ? 0 : sign);
    return sign;
  }
  /// Stored entries of L (those of U are as many).
  Eigen::Index factorNonZeros() const
  {
    return static_cast<Eigen::Index>(lx_.size());
  }

private:
  Eigen::Index n_ = 0;
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> perm_;  // P
  Eigen::SparseMatrix<double> c_, ct_;  // P A P^T and its transpose (column k of ct_: row k of c_)
  std::vector<int> parent_, lp_, li_;   // elimination tree; L's column starts and row indices
  std::vector<double> lx_, ux_;         // L by columns; U by rows in the same positions (U^T by columns)
  Eigen::VectorXd d_;
  // work arrays
  std::vector<int> flag_, pattern_, lnz_;
  Eigen::VectorXd y_, w_;
  mutable Eigen::VectorXd t_;
};

}  // namespace active_tensegrity::core
