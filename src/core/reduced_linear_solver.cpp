#include "active_tensegrity/core/reduced_linear_solver.h"

#include <algorithm>
#include <cmath>

#include <Eigen/QR>

namespace active_tensegrity::core
{
namespace
{
using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, 8, 1>;

/// Copies block `index` of m into the top left of a zero 8 x 8 matrix.
void padded(const BlockSparseMatrix& m, int index, Eigen::Matrix<double, 8, 8>& out)
{
  out.setZero();
  Eigen::Block<Eigen::Matrix<double, 8, 8>> view =
      out.topLeftCorner(m.groupSize(m.blocks()[index].first), m.groupSize(m.blocks()[index].second));
  m.block(index, view);
}

using Mat8 = Eigen::Matrix<double, 8, 8>;

/// out = a b for 8 x 8 matrices, the eight columns of out accumulated side by side: eight independent chains
/// of multiply-adds where Eigen's lazy product runs one chain per column (measured: 18 ns against 51 ns per
/// product on an AMD EPYC with AVX-512; one product is eight vector operations per column either way).
void multiply8(const Mat8& a, const Mat8& b, Mat8& out)
{
  using Col = Eigen::Matrix<double, 8, 1>;
  Col c0 = a.col(0) * b(0, 0), c1 = a.col(0) * b(0, 1), c2 = a.col(0) * b(0, 2), c3 = a.col(0) * b(0, 3);
  Col c4 = a.col(0) * b(0, 4), c5 = a.col(0) * b(0, 5), c6 = a.col(0) * b(0, 6), c7 = a.col(0) * b(0, 7);
  for (int k = 1; k < 8; ++k)
  {
    const Col ak = a.col(k);
    c0 += ak * b(k, 0);
    c1 += ak * b(k, 1);
    c2 += ak * b(k, 2);
    c3 += ak * b(k, 3);
    c4 += ak * b(k, 4);
    c5 += ak * b(k, 5);
    c6 += ak * b(k, 6);
    c7 += ak * b(k, 7);
  }
  out.col(0) = c0;
  out.col(1) = c1;
  out.col(2) = c2;
  out.col(3) = c3;
  out.col(4) = c4;
  out.col(5) = c5;
  out.col(6) = c6;
  out.col(7) = c7;
}
}  // namespace

void ReducedLinearSolver::analyze(const BlockSparseMatrix& m, int coordinate_groups)
{
  analyzed_rows_ = m.rows();
  analyzed_nonzeros_ = m.matrix().nonZeros();
  analyzed_groups_ = m.groups();
  const int groups = m.groups();
  bodies_.clear();
  group_body_.assign(groups, -1);
  group_map_.assign(groups, -1);
  reducible_ = false;
  bool small = true;
  for (int g = 0; g < groups; ++g)
    small = small && m.groupSize(g) <= kMaxGroup;
  // the one coordinate group each constraint group is coupled with (-1: none yet, -2: more than one, or
  // another constraint group)
  std::vector<int> partner(groups, -1);
  for (const auto& [gr, gc] : m.blocks())
  {
    if (gr == gc)
      continue;
    for (const auto& [c, other] : { std::make_pair(gr, gc), std::make_pair(gc, gr) })
    {
      if (c < coordinate_groups)
        continue;
      if (other >= coordinate_groups)
        partner[c] = -2;
      else if (partner[c] == -1)
        partner[c] = other;
      else if (partner[c] != other)
        partner[c] = -2;
    }
  }
  std::vector<bool> eliminated(groups, false);
  if (small)
  {
    for (int c = coordinate_groups; c < groups; ++c)
    {
      const int g = partner[c];
      if (g < 0 || m.blockIndex(c, g) < 0 || m.blockIndex(g, c) < 0)
        continue;
      if (group_body_[g] < 0)
      {
        Body b;
        b.group = g;
        b.offset = m.groupOffset(g);
        b.size = m.groupSize(g);
        group_body_[g] = static_cast<int>(bodies_.size());
        bodies_.push_back(b);
      }
      Body& b = bodies_[group_body_[g]];
      if (static_cast<int>(b.rows.size()) + m.groupSize(c) > b.size)
        continue;  // more one-body rows than coordinates: the rest stay (the matrix is then singular anyway)
      for (int i = 0; i < m.groupSize(c); ++i)
        b.rows.push_back(m.groupOffset(c) + i);
      b.row_blocks.push_back(m.blockIndex(c, g));
      b.col_blocks.push_back(m.blockIndex(g, c));
      b.diag_blocks.push_back(m.blockIndex(c, c));
      eliminated[c] = true;
    }
  }
  reducible_ = !bodies_.empty();
  if (!reducible_)
    return;
  std::vector<int> sizes;
  for (int g = 0; g < groups; ++g)
  {
    if (eliminated[g])
      continue;
    group_map_[g] = static_cast<int>(sizes.size());
    const int body = group_body_[g];
    sizes.push_back(body >= 0 ? m.groupSize(g) - static_cast<int>(bodies_[body].rows.size()) : m.groupSize(g));
  }
  std::vector<std::pair<int, int>> blocks;
  for (const auto& [gr, gc] : m.blocks())
    if (group_map_[gr] >= 0 && group_map_[gc] >= 0)
      blocks.emplace_back(group_map_[gr], group_map_[gc]);
  reduced_.init(sizes, blocks);
  block_map_.assign(m.blocks().size(), -1);
  for (size_t i = 0; i < m.blocks().size(); ++i)
  {
    const auto& [gr, gc] = m.blocks()[i];
    if (group_map_[gr] >= 0 && group_map_[gc] >= 0)
      block_map_[i] = reduced_.blockIndex(group_map_[gr], group_map_[gc]);
  }
  kept_offset_.assign(groups, -1);
  full_offset_.resize(groups);
  full_size_.resize(groups);
  for (int g = 0; g < groups; ++g)
  {
    full_offset_[g] = m.groupOffset(g);
    full_size_[g] = m.groupSize(g);
  }
  eliminated_rows_ = 0;
  for (int g = 0; g < groups; ++g)
    if (group_map_[g] >= 0)
      kept_offset_[g] = reduced_.groupOffset(group_map_[g]);
  for (const Body& b : bodies_)
    eliminated_rows_ += static_cast<int>(b.rows.size());
  // the blocks of the two products in solve(): A xp into the kept rows; A x into the eliminated bodies' rows
  blocks_ = m.blocks();
  rhs_blocks_.clear();
  force_blocks_.clear();
  rhs_position_.assign(m.blocks().size(), -1);
  force_position_.assign(m.blocks().size(), -1);
  for (size_t i = 0; i < m.blocks().size(); ++i)
  {
    const auto& [gr, gc] = m.blocks()[i];
    if (group_body_[gc] >= 0 && group_map_[gr] >= 0)
    {
      rhs_position_[i] = static_cast<int>(rhs_blocks_.size());
      rhs_blocks_.push_back(static_cast<int>(i));
    }
    if (group_body_[gr] >= 0 && group_map_[gc] >= 0)
    {
      force_position_[i] = static_cast<int>(force_blocks_.size());
      force_blocks_.push_back(static_cast<int>(i));
    }
  }
  rhs_ops_.resize(rhs_blocks_.size());
  force_ops_.resize(force_blocks_.size());
  tb_.resize(bodies_.size());
  blt_.resize(bodies_.size());
}

bool ReducedLinearSolver::bases(const BlockSparseMatrix& m)
{
  Small block, bt, ct;
  for (Body& b : bodies_)
  {
    const int n = b.size;
    const int k = static_cast<int>(b.rows.size());
    bt.resize(n, k);  // B^T
    ct.resize(n, k);  // the multipliers' columns, which must equal B^T
    int row = 0;
    for (size_t i = 0; i < b.row_blocks.size(); ++i)
    {
      m.block(b.row_blocks[i], block);
      const int kc = static_cast<int>(block.rows());
      bt.middleCols(row, kc) = block.transpose();
      m.block(b.col_blocks[i], block);
      ct.middleCols(row, kc) = block;
      m.block(b.diag_blocks[i], block);
      if (block.cwiseAbs().maxCoeff() != 0.0)
        return false;
      row += kc;
    }
    const double scale = bt.cwiseAbs().maxCoeff();
    if (!(scale > 0.0) || !((ct - bt).cwiseAbs().maxCoeff() <= 1e-12 * scale))
      return false;
    const Eigen::HouseholderQR<Small> qr(bt);
    const auto r = qr.matrixQR().topLeftCorner(k, k);
    const double largest = r.diagonal().cwiseAbs().maxCoeff();
    if (!(r.diagonal().cwiseAbs().minCoeff() > 1e-10 * largest))
      return false;  // the body's rows are dependent
    Small q(n, n);
    SmallVector workspace(n);
    qr.householderQ().evalTo(q, workspace);
    // T = [Z Y]: Z the null-space basis Q2, Y = Q1 R^-T the right inverse (B = R^T Q1^T, so B Y = I)
    Small t = q.leftCols(k).transpose();
    r.triangularView<Eigen::Upper>().solveInPlace(t);
    b.t.setZero();
    b.t.topLeftCorner(n, n - k) = q.rightCols(n - k);
    b.t.block(0, n - k, n, k) = t.transpose();
    b.tt = b.t.transpose();  // kept transposed: products with a plain left factor vectorize by columns
  }
  return true;
}

bool ReducedLinearSolver::factorize(const BlockSparseMatrix& m, int coordinate_groups)
{
  const bool new_pattern =
      m.rows() != analyzed_rows_ || m.matrix().nonZeros() != analyzed_nonzeros_ || m.groups() != analyzed_groups_;
  if (new_pattern)
    analyze(m, coordinate_groups);
  use_reduced_ = allow_reduction_ && reducible_ && bases(m);
  if (!use_reduced_)
  {
    factorized_size_ = m.rows();
    return full_solver_.factorize(m.matrix());
  }
  reduced_.setZero();
  // every product on 8 x 8 matrices padded with zeros (fixed sizes: unrolled and vectorized; a strut has 7
  // coordinates)
  Mat8 block, left, out;
  for (size_t i = 0; i < m.blocks().size(); ++i)
  {
    const int j = block_map_[i];
    if (j < 0)
      continue;
    const auto& [gr, gc] = m.blocks()[i];
    const int br = group_body_[gr], bc = group_body_[gc];
    const int index = static_cast<int>(i);
    if (br < 0 && bc < 0)
    {
      reduced_.addBlock(j, m, index);
      continue;
    }
    padded(m, index, block);
    // with T = [Z Y] per body: T_r^T A T_c in one pair of products; its Z-Z part goes into A_r, and the
    // products solve() needs are kept whole: T_r^T A (rows of Y_r^T A) and (T_r^T) A T_c (columns of A Y_c)
    if (br >= 0)
      multiply8(bodies_[br].tt, block, left);
    else
      left = block;
    if (force_position_[i] >= 0)
      force_ops_[force_position_[i]] = left;
    const int rr = reduced_.groupSize(group_map_[gr]), rc = reduced_.groupSize(group_map_[gc]);
    if (bc >= 0)
    {
      Mat8& whole = rhs_ops_[rhs_position_[i]];
      multiply8(left, bodies_[bc].t, whole);
      reduced_.addBlock(j, whole.topLeftCorner(rr, rc));
    }
    else
      reduced_.addBlock(j, left.topLeftCorner(rr, rc));
  }
  factorized_size_ = reduced_.rows();
  return reduced_solver_.factorize(reduced_.matrix());
}

void ReducedLinearSolver::solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
{
  if (!use_reduced_)
  {
    full_solver_.solve(b, x);
    return;
  }
  using Vec8 = Eigen::Matrix<double, 8, 1>;
  const auto load = [](const Eigen::VectorXd& v, int offset, int size)
  {
    Vec8 out = Vec8::Zero();
    out.head(size) = v.segment(offset, size);
    return out;
  };
  // per body: T^T b_q (Z^T b_q, then Y^T b_q) and the one-body rows' right-hand sides b_L, placed after
  // the Z part (the kept products have A Y_c in the columns after Z_c's; zeros against Z_c)
  for (size_t i = 0; i < bodies_.size(); ++i)
  {
    const Body& body = bodies_[i];
    const int k = static_cast<int>(body.rows.size());
    tb_[i].noalias() = body.tt.lazyProduct(load(b, body.offset, body.size));
    blt_[i].setZero();
    for (int r = 0; r < k; ++r)
      blt_[i](body.size - k + r) = b(body.rows[r]);
  }
  // the reduced right-hand side Z^T (b - A xp), xp = Y b_L the particular solution of the one-body rows
  rhs_.resize(reduced_.rows());
  const int groups = static_cast<int>(group_map_.size());
  for (int g = 0; g < groups; ++g)
  {
    if (group_map_[g] < 0)
      continue;
    const int offset = full_offset_[g], size = full_size_[g], reduced = reduced_.groupSize(group_map_[g]);
    const int body = group_body_[g];
    if (body >= 0)
      rhs_.segment(kept_offset_[g], reduced) = tb_[body].head(reduced);
    else
      rhs_.segment(kept_offset_[g], size) = b.segment(offset, size);
  }
  for (size_t p = 0; p < rhs_blocks_.size(); ++p)
  {
    const auto& [gr, gc] = blocks_[rhs_blocks_[p]];
    const int reduced = reduced_.groupSize(group_map_[gr]);
    const Vec8 product = rhs_ops_[p].lazyProduct(blt_[group_body_[gc]]);  // whole: vectorized by columns
    rhs_.segment(kept_offset_[gr], reduced) -= product.head(reduced);
  }
  reduced_solver_.solve(rhs_, xr_);
  // x = xp + Z xr = T [xr; b_L]
  x.resize(b.size());
  for (int g = 0; g < groups; ++g)
  {
    if (group_map_[g] < 0)
      continue;
    const int offset = full_offset_[g], size = full_size_[g];
    const int body = group_body_[g];
    if (body >= 0)
    {
      Vec8& v = blt_[body];
      const int reduced = reduced_.groupSize(group_map_[g]);
      v.head(reduced) = xr_.segment(kept_offset_[g], reduced);
      const Vec8 xb = bodies_[body].t.lazyProduct(v);
      x.segment(offset, size) = xb.head(size);
    }
    else
      x.segment(offset, size) = xr_.segment(kept_offset_[g], size);
  }
  // the eliminated multipliers from the body's force rows: B^T dlambda_L = b_q - (A x)_q, and Y^T B^T = I;
  // in T^T A (kept per block) the rows after Z_r's are Y_r^T A
  for (size_t p = 0; p < force_blocks_.size(); ++p)
  {
    const auto& [gr, gc] = blocks_[force_blocks_[p]];
    tb_[group_body_[gr]].noalias() -= force_ops_[p].lazyProduct(load(x, full_offset_[gc], full_size_[gc]));
  }
  for (size_t i = 0; i < bodies_.size(); ++i)
  {
    const Body& body = bodies_[i];
    const int k = static_cast<int>(body.rows.size());
    for (int r = 0; r < k; ++r)
      x(body.rows[r]) = tb_[i](body.size - k + r);
  }
}

int ReducedLinearSolver::determinantSign() const
{
  if (!use_reduced_)
    return full_solver_.determinantSign();
  const int s = reduced_solver_.determinantSign();
  return eliminated_rows_ % 2 == 0 ? s : -s;
}

}  // namespace active_tensegrity::core
