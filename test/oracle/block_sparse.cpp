#include "active_tensegrity/oracle/block_sparse.h"

#include <algorithm>
#include <stdexcept>

namespace active_tensegrity::core
{
void BlockSparseMatrix::init(const std::vector<int>& group_sizes, const std::vector<std::pair<int, int>>& blocks)
{
  sizes_ = group_sizes;
  offsets_.assign(sizes_.size() + 1, 0);
  for (size_t g = 0; g < sizes_.size(); ++g)
    offsets_[g + 1] = offsets_[g] + sizes_[g];
  std::vector<std::pair<int, int>> all = blocks;
  for (size_t g = 0; g < sizes_.size(); ++g)
    all.emplace_back(static_cast<int>(g), static_cast<int>(g));
  build(std::move(all));
}

void BlockSparseMatrix::build(std::vector<std::pair<int, int>> all)
{
  const int n = offsets_.back();
  std::sort(all.begin(), all.end());
  all.erase(std::unique(all.begin(), all.end()), all.end());
  blocks_ = std::move(all);

  std::vector<Eigen::Triplet<double>> triplets;
  for (const auto& [gr, gc] : blocks_)
    for (int j = 0; j < sizes_[gc]; ++j)
      for (int i = 0; i < sizes_[gr]; ++i)
        triplets.emplace_back(offsets_[gr] + i, offsets_[gc] + j, 0.0);
  matrix_.resize(n, n);
  matrix_.setFromTriplets(triplets.begin(), triplets.end());
  matrix_.makeCompressed();

  row_begin_.assign(sizes_.size() + 1, 0);
  for (const auto& [gr, gc] : blocks_)
    ++row_begin_[gr + 1];
  for (size_t g = 0; g < sizes_.size(); ++g)
    row_begin_[g + 1] += row_begin_[g];
  block_starts_.clear();
  for (const auto& [gr, gc] : blocks_)
  {
    std::vector<int> starts(sizes_[gc]);
    for (int j = 0; j < sizes_[gc]; ++j)
    {
      const int col = offsets_[gc] + j;
      const int* inner = matrix_.innerIndexPtr();
      const int begin = matrix_.outerIndexPtr()[col];
      const int end = matrix_.outerIndexPtr()[col + 1];
      const int* it = std::lower_bound(inner + begin, inner + end, offsets_[gr]);
      starts[j] = static_cast<int>(it - inner);
    }
    block_starts_.push_back(std::move(starts));
  }
}

void BlockSparseMatrix::reserve(int gr, int gc)
{
  if (hasBlock(gr, gc) && hasBlock(gc, gr))
    return;
  const Eigen::SparseMatrix<double> old = matrix_;
  std::vector<std::pair<int, int>> all = blocks_;
  all.emplace_back(gr, gc);
  all.emplace_back(gc, gr);
  build(std::move(all));
  // the old entries are a subset of the new pattern: copy them column by column (both sorted by row)
  for (int col = 0; col < old.outerSize(); ++col)
  {
    int k = matrix_.outerIndexPtr()[col];
    for (Eigen::SparseMatrix<double>::InnerIterator it(old, col); it; ++it)
    {
      while (matrix_.innerIndexPtr()[k] != it.row())
        ++k;
      matrix_.valuePtr()[k] = it.value();
    }
  }
}

void BlockSparseMatrix::setZero()
{
  std::fill(matrix_.valuePtr(), matrix_.valuePtr() + matrix_.nonZeros(), 0.0);
}

int BlockSparseMatrix::blockIndex(int gr, int gc) const
{
  if (gr < 0 || gr >= static_cast<int>(sizes_.size()))
    return -1;
  const auto begin = blocks_.begin() + row_begin_[gr], end = blocks_.begin() + row_begin_[gr + 1];
  const auto it = std::lower_bound(begin, end, std::make_pair(gr, gc));
  return it != end && it->second == gc ? static_cast<int>(it - blocks_.begin()) : -1;
}

bool BlockSparseMatrix::hasBlock(int gr, int gc) const
{
  return blockIndex(gr, gc) >= 0;
}

void BlockSparseMatrix::add(int gr, int gc, const Eigen::Ref<const Eigen::MatrixXd>& block, double weight)
{
  const int index = blockIndex(gr, gc);
  if (index < 0)
    throw std::logic_error("BlockSparseMatrix::add: block outside the pattern");
  const std::vector<int>& starts = block_starts_[index];
  double* values = matrix_.valuePtr();
  for (int j = 0; j < block.cols(); ++j)
    for (int i = 0; i < block.rows(); ++i)
      values[starts[j] + i] += weight * block(i, j);
}

void BlockSparseMatrix::addTransposed(int gr, int gc, const Eigen::Ref<const Eigen::MatrixXd>& block, double weight)
{
  const int index = blockIndex(gc, gr);
  if (index < 0)
    throw std::logic_error("BlockSparseMatrix::addTransposed: block outside the pattern");
  const std::vector<int>& starts = block_starts_[index];
  double* values = matrix_.valuePtr();
  for (int j = 0; j < block.rows(); ++j)
    for (int i = 0; i < block.cols(); ++i)
      values[starts[j] + i] += weight * block(j, i);
}

}  // namespace active_tensegrity::core
