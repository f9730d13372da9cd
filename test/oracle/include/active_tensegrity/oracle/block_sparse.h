/// A sparse matrix made of dense blocks. Its pattern is set once for the blocks a scene always has
/// (bodies coupled by cables, joints and constraint rows), so that values are added in place and the
/// symbolic factorization is reused; blocks that only some states need (a strut pair in contact) are
/// added when first needed by reserve(), and the pattern then only grows (so its number of stored
/// entries tells a changed pattern: SparseLinearSolver analyzes it again then).
#pragma once

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
  /// The pattern's blocks (row group, column group), diagonal ones included, sorted; an index into it
  /// names a block for block() and addBlock().
  const std::vector<std::pair<int, int>>& blocks() const
  {
    return blocks_;
  }
  /// Index of block (gr, gc) in blocks(), or -1 when it is not in the pattern.
  int blockIndex(int gr, int gc) const;
  /// Copies block `index` of blocks() into out (resized to its rows and columns).
  template <class Out>
  void block(int index, Out& out) const
  {
    const auto& [gr, gc] = blocks_[index];
    const std::vector<int>& starts = block_starts_[index];
    const double* values = matrix_.valuePtr();
    out.resize(sizes_[gr], sizes_[gc]);
    for (int j = 0; j < sizes_[gc]; ++j)
      for (int i = 0; i < sizes_[gr]; ++i)
        out(i, j) = values[starts[j] + i];
  }
  /// Adds `block` into block `index` of blocks() (its size must match).
  template <class In>
  void addBlock(int index, const In& block)
  {
    const std::vector<int>& starts = block_starts_[index];
    double* values = matrix_.valuePtr();
    for (int j = 0; j < block.cols(); ++j)
      for (int i = 0; i < block.rows(); ++i)
        values[starts[j] + i] += block(i, j);
  }
  /// Adds block `index` of `other` (same group sizes) into block `index_here` of this matrix.
  void addBlock(int index_here, const BlockSparseMatrix& other, int index)
  {
    const auto& [gr, gc] = other.blocks_[index];
    const std::vector<int>& to = block_starts_[index_here];
    const std::vector<int>& from = other.block_starts_[index];
    double* values = matrix_.valuePtr();
    const double* source = other.matrix_.valuePtr();
    for (int j = 0; j < other.sizes_[gc]; ++j)
      for (int i = 0; i < other.sizes_[gr]; ++i)
        values[to[j] + i] += source[from[j] + i];
  }
  int groups() const
  {
    return static_cast<int>(sizes_.size());
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
  void build(std::vector<std::pair<int, int>> blocks);

  std::vector<int> sizes_, offsets_;
  std::vector<std::pair<int, int>> blocks_;  // the pattern's blocks (diagonal ones included), sorted
  Eigen::SparseMatrix<double> matrix_;
  // the blocks of row group g are blocks_[row_begin_[g] .. row_begin_[g + 1]) (found by a search over a
  // row's few blocks: measured faster than a hash map on the assembly of the tower's Newton matrix)
  std::vector<int> row_begin_;
  // for each block, the index in valuePtr() of its first row in each of its columns (contiguous rows)
  std::vector<std::vector<int>> block_starts_;
};

}  // namespace active_tensegrity::core
