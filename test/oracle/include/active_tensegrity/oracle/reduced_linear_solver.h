/// The Newton matrix of coordinates and multipliers solved with every one-body constraint eliminated
/// (docs/design.md, "The body coordinates as a test oracle").
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/QR>

#include "active_tensegrity/oracle/block_sparse.h"
#include "active_tensegrity/oracle/sparse_linear_solver.h"

namespace active_tensegrity::core
{
/// Solves A x = b for a Newton matrix
///   A = [ H   G^T ]   (coordinates q, then multipliers lambda)
///       [ G   0   ]
/// by eliminating the constraint rows that act within a cluster of bodies: a cluster is a set of bodies
/// joined by constraint rows that act on them and on nothing else (a strut's quaternion norm and spin
/// lock, a pin of a strut's node, a point mass's pin, and the ball joints between struts: the tower's
/// four chains of four struts jointed end to end). For a cluster with such rows B (k x n, full row rank),
/// an orthonormal basis Z of their null space (n x (n - k)) and a right inverse Y (B Y = I) come from a
/// QR factorization of B^T; the cluster's coordinate increment is Y b_L + Z y, and the system left is
///   A_r = [ Z^T H Z   Z^T G_C^T ]   in (y, the other multipliers),
///         [ G_C Z     0         ]
/// with Z the block diagonal of the clusters' bases (identity for bodies in none). Every block of A
/// between kept groups becomes the block of A_r between their clusters, multiplied by the rows of Z that
/// belong to its bodies; A_r is factorized by a SparseLinearSolver (dense LU when it fills, sparse LU
/// otherwise). The eliminated multipliers come back from Y^T times the cluster's force rows. On the tower
/// (200 unknowns in dynamics) A_r has 48; the dense LU's work falls with the cube of the size.
///
/// The elimination needs each eliminated row's column to be its row transposed (true of the constraint
/// Jacobian and its transpose as System assembles them), a zero diagonal block, and the cluster's rows to
/// be independent; a matrix that fails any of these is factorized whole, as is one with no such rows. A
/// cluster of more than kMaxCluster coordinates or kMaxClusterDof kept ones (a lattice whose struts are
/// all jointed together) is not formed: its bodies' own rows are eliminated body by body, its joints kept.
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
  static constexpr int kMaxGroup = 8;                        // largest group (a strut: 7 coordinates)
  static constexpr int kMaxCluster = 64;                     // coordinates of a cluster eliminated together
  static constexpr int kMaxClusterDof = 32;                  // and the most it keeps
  using Mat8 = Eigen::Matrix<double, kMaxGroup, kMaxGroup>;  // a block, padded with zeros
  using Vec8 = Eigen::Matrix<double, kMaxGroup, 1>;
  /// A group's rows of a cluster's Z (padded to kMaxGroup rows with zeros), and its transpose
  using ZRows = Eigen::Matrix<double, kMaxGroup, Eigen::Dynamic, Eigen::ColMajor, kMaxGroup, kMaxClusterDof>;
  using ZRowsT = Eigen::Matrix<double, Eigen::Dynamic, kMaxGroup, Eigen::RowMajor, kMaxClusterDof, kMaxGroup>;
  struct Cluster
  {
    std::vector<int> groups;  // A's coordinate groups
    std::vector<int> local;   // each one's first coordinate in the cluster's
    int size = 0;             // coordinates n
    std::vector<int> rows;    // the full indices of its eliminated rows, stacked by constraint group
    // (row block (c, g), column block (g, c), first row of c in `rows`, first coordinate of g) per
    // eliminated constraint group c and coordinate group g it acts on
    struct Link
    {
      int row_block, col_block, row, coordinate;
    };
    std::vector<Link> links;
    std::vector<int> diag_blocks;  // blocks (c, c) of its constraint groups
    Eigen::MatrixXd bt, ct, q, y;  // B^T, the multipliers' columns (which must equal it), Q, the right inverse
    Eigen::VectorXd work;          // QR's workspace
    mutable Eigen::VectorXd v, w;  // solve()'s
    Eigen::HouseholderQR<Eigen::MatrixXd> qr;
    std::vector<ZRows, Eigen::aligned_allocator<ZRows>> z;     // per group: its rows of Z
    std::vector<ZRowsT, Eigen::aligned_allocator<ZRowsT>> zt;  // ... transposed
    int tiles = 0;                                             // ceil((n - k) / 8)
    // per group, its rows of Z in 8 x 8 tiles (`tiles` of them, by columns of Z), and each transposed: for
    // factorize()'s fixed-size products; solve() uses z and zt, whose width is the cluster's (solving with the
    // padded tiles instead took 3-6 % longer on the tower's adaptive fold)
    std::vector<Mat8, Eigen::aligned_allocator<Mat8>> z_tiles, zt_tiles;
  };
  /// A product of solve(): a block of A (padded) times a piece of x, from group `from` into group `to`
  struct Product
  {
    int op, to, from;
  };
  /// Analyzes m's pattern: the clusters, the reduced groups and A_r's pattern.
  void analyze(const BlockSparseMatrix& m, int coordinate_groups);
  /// The bases of every cluster at m's values; false when the elimination does not apply there.
  bool bases(const BlockSparseMatrix& m);
  Vec8 load(const Eigen::VectorXd& v, int group) const;

  bool allow_reduction_ = true;
  Eigen::Index analyzed_rows_ = -1, analyzed_nonzeros_ = -1;
  int analyzed_groups_ = -1;
  bool reducible_ = false;  // the pattern has rows to eliminate
  bool use_reduced_ = false;
  int factorized_size_ = 0;
  int eliminated_rows_ = 0;
  std::vector<Cluster> clusters_;
  std::vector<int> group_cluster_;            // A's group -> its cluster, or -1
  std::vector<int> group_index_;              // A's coordinate group -> its index in its cluster's groups
  std::vector<int> group_map_;                // A's group -> A_r's group, or -1 (eliminated constraint group)
  std::vector<int> block_map_;                // A's block -> A_r's block, or -1
  std::vector<int> block_op_;                 // A's block -> its padded copy in ops_, or -1
  std::vector<int> kept_offset_;              // A's group -> its offset in A_r (groups in no cluster)
  std::vector<int> cluster_offset_;           // cluster -> its offset in A_r
  std::vector<int> full_offset_, full_size_;  // A's groups' offsets and sizes
  std::vector<Product> rhs_products_;         // A xp into the kept rows and the clusters' rows
  std::vector<Product> force_products_;       // A x into the clusters' rows
  std::vector<Mat8, Eigen::aligned_allocator<Mat8>> ops_;  // the blocks of A that touch a cluster, padded
  // A_r's blocks that touch a cluster, summed in 8 x 8 tiles before they are added: their first tile in
  // tiles_ (-1: none), tiles per row and column
  std::vector<int> tile_offset_, tile_rows_, tile_cols_;
  std::vector<int> tiled_blocks_;
  std::vector<Mat8, Eigen::aligned_allocator<Mat8>> tiles_;
  BlockSparseMatrix reduced_;
  SparseLinearSolver reduced_solver_, full_solver_;
  std::vector<std::pair<int, int>> blocks_;  // A's blocks (its pattern analyzed)
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxGroup, kMaxGroup> block_;  // bases()'
  mutable Eigen::VectorXd rhs_, xr_;
  mutable std::vector<Vec8, Eigen::aligned_allocator<Vec8>> acc_;  // per coordinate group in a cluster
  mutable std::vector<Vec8, Eigen::aligned_allocator<Vec8>> xp_;   // ... its particular solution
};

}  // namespace active_tensegrity::core
