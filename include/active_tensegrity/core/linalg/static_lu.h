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
///
/// Everything that depends on the pattern alone is done once, in analyzePattern: the order, where each
/// stored entry of A lands in P A P^T, the reach of every row and where each entry of the factors goes.
/// A factorization then scatters A's values and does the arithmetic; it allocates nothing.
class StaticPivotLU
{
public:
  /// The order, the elimination tree and the factors' pattern; `a` must have a symmetric pattern. Its
  /// diagonal is in the factors' pattern whether `a` stores it or not.
  void analyzePattern(const Eigen::SparseMatrix<double>& a);
  /// Factorizes A + shift * sum_r e_r e_r^T over the rows r in `shifted` (none by default). A pattern
  /// other than the analyzed one is analyzed first. False on a zero or non-finite pivot.
  bool factorize(const Eigen::SparseMatrix<double>& a, const std::vector<int>& shifted = {}, double shift = 0.0);
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const;
  /// x = A^-1 b for the matrix `a` the factors approximate (a shifted one's, say): solved, then corrected with a's
  /// residual (at most 8 corrections, each shrinking about by the factors' error) until a correction is below 1e-14 of
  /// x, or shrinks less than half (round-off), which passes when the smallest was below 1e-10 of x. False otherwise.
  /// `r` and `d`: work vectors.
  bool solveRefined(const Eigen::SparseMatrix<double>& a, const Eigen::VectorXd& b, Eigen::VectorXd& x,
                    Eigen::VectorXd& r, Eigen::VectorXd& d) const;
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
    return static_cast<Eigen::Index>(ux_.size());
  }
  /// Symbolic analyses so far (the first call, and one per change of pattern).
  int analyses() const
  {
    return analyses_;
  }

private:
  bool samePattern(const Eigen::SparseMatrix<double>& a) const;

  int n_ = 0;
  int analyses_ = 0;
  std::vector<int> perm_;               // row/column i of A is row/column perm_[i] of C = P A P^T
  std::vector<int> a_outer_, a_inner_;  // the analyzed pattern of A (by columns)
  std::vector<int> dest_;               // stored entry q of A (in storage order) -> its slot in cx_
  std::vector<int> diag_;               // slot of C(k, k) in cx_
  std::vector<int> up_p_, up_i_;        // C's upper part, diagonal included, by columns: rows i <= k
  std::vector<int> lo_p_, lo_i_;        // C's strict lower part by rows: columns j < k of row k
  std::vector<double> cx_;              // values: up_ (up_i_.size() slots), then lo_
  std::vector<int> lp_, li_;            // L by columns: starts and row indices
  std::vector<int> rp_, ri_, rpos_;     // each row k of L: its columns i (ascending) and their slots in li_
  struct Pair
  {
    double first, second;
  };
  std::vector<Pair> lu_;     // (L, U^T) by columns, interleaved: L(j, i) and U(i, j) side by side
  std::vector<double> lrx_;  // L by rows, in the slots of ri_ (for the solve)
  std::vector<double> ux_;   // U^T by columns, in the slots of li_ (for the solve)
  Eigen::VectorXd d_;
  std::vector<Pair> yw_;  // work: column k of U D and row k of D L, as they are solved for
  mutable Eigen::VectorXd t_;
};

}  // namespace active_tensegrity::core
