/// A sparse matrix made of dense blocks. Its pattern is set once for the blocks a scene always has
/// (bodies coupled by cables, joints and constraint rows), so that values are added in place and the
/// symbolic factorization is reused; blocks that only some states need (a strut pair in contact) are
/// added when first needed by reserve(), and the pattern then only grows (so its number of stored
/// entries tells a changed pattern: SparseLinearSolver analyzes it again then).
#pragma once

#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace active_tensegrity::core
{
class BlockSparseMatrix
{
public:
  /// groups: the sizes of the row/column groups (square matrix); blocks: (row group, column group)
  /// pairs that may be non-zero (diagonal blocks are always included).
  void init(const std::vector<int>& group_sizes, const std::vector<std::pair<int, int>>& blocks);

  void setZero();
  /// Adds `block` (rows = size of gr, cols = size of gc) into block (gr, gc); the block must be in the pattern.
  void add(int gr, int gc, const Eigen::Ref<const Eigen::MatrixXd>& block, double weight = 1.0);
  /// Adds `block` transposed into (gc, gr).
  void addTransposed(int gr, int gc, const Eigen::Ref<const Eigen::MatrixXd>& block, double weight = 1.0);
  bool hasBlock(int gr, int gc) const;
  /// Makes (gr, gc) and (gc, gr) part of the pattern, keeping every value; a no-op when they are.
  /// Growing costs a rebuild of the matrix (O(non-zeros)); it happens once per block.
  void reserve(int gr, int gc);

  const Eigen::SparseMatrix<double>& matrix() const
  {
    return matrix_;
  }
  int groupOffset(int g) const
  {
    return offsets_[g];
  }
  int groupSize(int g) const
  {
    return sizes_[g];
  }
  int rows() const
  {
    return static_cast<int>(matrix_.rows());
  }

private:
  static std::uint64_t key(int gr, int gc)
  {
    return (static_cast<std::uint64_t>(gr) << 32) | static_cast<std::uint32_t>(gc);
  }
  void build(std::vector<std::pair<int, int>> blocks);

  std::vector<int> sizes_, offsets_;
  std::vector<std::pair<int, int>> blocks_;  // the pattern's blocks (diagonal ones included), sorted
  Eigen::SparseMatrix<double> matrix_;
  // for each block, the index in valuePtr() of its first row in each of its columns (contiguous rows)
  std::unordered_map<std::uint64_t, int> block_index_;
  std::vector<std::vector<int>> block_starts_;
};

}  // namespace active_tensegrity::core
