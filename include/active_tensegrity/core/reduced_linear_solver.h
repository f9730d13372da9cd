/// The Newton matrix of coordinates and multipliers solved with every one-body constraint eliminated
/// (docs/physics.md, "Linear solvers").
#pragma once

#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/block_sparse.h"
#include "active_tensegrity/core/sparse_linear_solver.h"

namespace active_tensegrity::core
{
/// Solves A x = b for a Newton matrix
///   A = [ H   G^T ]   (coordinates q, then multipliers lambda)
///       [ G   0   ]
/// by eliminating the constraint rows that act on one body only (a strut's quaternion norm and spin lock,
/// a pin of a strut's node, a point mass's pin): for a body with such rows B (k x n, full row rank), an
/// orthonormal basis Z of their null space (n x (n - k)) and a right inverse Y (B Y = I) come from a QR
/// factorization of B^T; the body's coordinate increment is Y b_L + Z y, and the system left is
///   A_r = [ Z^T H Z   Z^T G_C^T ]   in (y, the other multipliers),
///         [ G_C Z     0         ]
/// with Z the block diagonal of the bodies' bases (identity for bodies without one-body rows). Its
/// blocks are those of A between the groups kept, each multiplied by small dense bases, so A_r keeps A's
/// block pattern; it is factorized by a SparseLinearSolver (dense LU when it fills, sparse LU otherwise).
/// Each block is transformed once, as T_r^T A_i T_c with T = [Z Y] per body (8 x 8, padded with zeros),
/// which also gives the products the solve needs (A Y for the particular solution, Y^T A for the
/// multipliers). The eliminated multipliers come back from Y^T times the body's force rows. On the tower (216
/// unknowns) A_r has 104; the dense LU's work falls with the cube of the size.
///
/// The elimination needs each eliminated row's column to be its row transposed (true of the constraint
/// Jacobian and its transpose as System assembles them), a zero diagonal block, and the body's rows to be
/// independent; a matrix that fails any of these is factorized whole, as is one with no one-body rows.
/// sign(det A) = (-1)^(rows eliminated) sign(det A_r): determinantSign() reports A's.
class ReducedLinearSolver
{
public:
  /// As SparseLinearSolver::allowDense, for the matrix factorized (reduced or whole).
  void allowDense(bool allow, bool equilibrate = false)
  {
    reduced_solver_.allowDense(allow, equilibrate);
    full_solver_.allowDense(allow, equilibrate);
  }
  /// Turns the elimination off (every matrix is factorized whole; for comparisons).
  void allowReduction(bool allow)
  {
    allow_reduction_ = allow;
  }
  /// Factorizes m; its first `coordinate_groups` groups are the bodies' coordinates, the rest constraint
  /// groups. False when the matrix is singular (as SparseLinearSolver::factorize).
  bool factorize(const BlockSparseMatrix& m, int coordinate_groups);
  /// x = A^-1 b for the matrix last factorized.
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const;
  int determinantSign() const;
  /// Symbolic analyses of the linear solvers below (one per pattern each).
  int analyses() const
  {
    return reduced_solver_.analyses() + full_solver_.analyses();
  }
  /// Whether the last matrix was factorized reduced, and the size of what was factorized.
  bool reduced() const
  {
    return use_reduced_;
  }
  int factorizedSize() const
  {
    return factorized_size_;
  }
  /// Whether the last factorization was dense.
  bool dense() const
  {
    return use_reduced_ ? reduced_solver_.dense() : full_solver_.dense();
  }

private:
  static constexpr int kMaxGroup = 8;  // largest group eliminated through (a strut: 7 coordinates)
  using Small = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxGroup, kMaxGroup>;
  using Mat8 = Eigen::Matrix<double, kMaxGroup, kMaxGroup>;  // a group's block, padded with zeros
  struct Body
  {
    int group = -1;                // coordinate group in A
    int offset = 0, size = 0;      // its coordinates in A
    std::vector<int> rows;         // the full indices of its one-body constraint rows, stacked
    std::vector<int> row_blocks;   // blocks (c, group) of its constraint groups c, in order
    std::vector<int> col_blocks;   // blocks (group, c)
    std::vector<int> diag_blocks;  // blocks (c, c)
    Mat8 t, tt;  // [Z Y]: null-space basis (size x (size - k)), right inverse (size x k); padded; and T^T
  };
  /// Analyzes m's pattern: the one-body constraint groups, the reduced groups and A_r's pattern.
  void analyze(const BlockSparseMatrix& m, int coordinate_groups);
  /// The bases of every eliminated body at m's values; false when the elimination does not apply there.
  bool bases(const BlockSparseMatrix& m);

  bool allow_reduction_ = true;
  Eigen::Index analyzed_rows_ = -1, analyzed_nonzeros_ = -1;
  int analyzed_groups_ = -1;
  bool reducible_ = false;  // the pattern has one-body rows
  bool use_reduced_ = false;
  int factorized_size_ = 0;
  int eliminated_rows_ = 0;
  std::vector<Body, Eigen::aligned_allocator<Body>> bodies_;  // the bodies with one-body rows
  std::vector<int> group_body_;                               // A's group -> index into bodies_, or -1
  std::vector<int> group_map_;                      // A's group -> A_r's group, or -1 (eliminated constraint group)
  std::vector<int> block_map_;                      // A's block -> A_r's block, or -1
  std::vector<int> kept_offset_;                    // A's group -> its offset in A_r (kept groups)
  std::vector<int> full_offset_, full_size_;        // A's groups' offsets and sizes
  std::vector<int> rhs_blocks_, force_blocks_;      // A's blocks (kept rows, eliminated body's columns), and
                                                    // (eliminated body's rows, kept columns)
  std::vector<int> rhs_position_, force_position_;  // A's block -> index into those lists, or -1
  // per such block T_r^T A_i T_c (A_i T_c where the rows are kept whole), and T_r^T A_i, with T = [Z Y]
  // per body (padded)
  std::vector<Mat8, Eigen::aligned_allocator<Mat8>> rhs_ops_, force_ops_;
  BlockSparseMatrix reduced_;
  SparseLinearSolver reduced_solver_, full_solver_;
  std::vector<std::pair<int, int>> blocks_;  // A's blocks (its pattern analyzed)
  mutable Eigen::VectorXd rhs_, xr_;
  mutable std::vector<Eigen::Matrix<double, kMaxGroup, 1>> tb_;   // per body: T^T b_q (padded)
  mutable std::vector<Eigen::Matrix<double, kMaxGroup, 1>> blt_;  // ... its rows' b_L after the Z part
};

}  // namespace active_tensegrity::core
