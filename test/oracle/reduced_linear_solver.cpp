#include "active_tensegrity/oracle/reduced_linear_solver.h"

#include <algorithm>
#include <cmath>

#include <Eigen/QR>

namespace active_tensegrity::core
{
namespace
{
using Mat8 = Eigen::Matrix<double, 8, 8>;

/// Copies block `index` of m into the top left of a zero 8 x 8 matrix.
void padded(const BlockSparseMatrix& m, int index, Mat8& out)
{
  out.setZero();
  Eigen::Block<Mat8> view =
      out.topLeftCorner(m.groupSize(m.blocks()[index].first), m.groupSize(m.blocks()[index].second));
  m.block(index, view);
}

/// out (+)= a b for 8 x 8 matrices, the eight columns of out accumulated side by side: eight independent
/// chains of multiply-adds where Eigen's lazy product runs one chain per column (18 ns against 51 ns per
/// product on an AMD EPYC with AVX-512).
template <bool kAdd>
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
  if constexpr (kAdd)
  {
    out.col(0) += c0;
    out.col(1) += c1;
    out.col(2) += c2;
    out.col(3) += c3;
    out.col(4) += c4;
    out.col(5) += c5;
    out.col(6) += c6;
    out.col(7) += c7;
  }
  else
  {
    out.col(0) = c0;
    out.col(1) = c1;
    out.col(2) = c2;
    out.col(3) = c3;
    out.col(4) = c4;
    out.col(5) = c5;
    out.col(6) = c6;
    out.col(7) = c7;
  }
}

/// A block of A_r read from its 8 x 8 tiles (for BlockSparseMatrix::addBlock)
struct TileView
{
  const Mat8* tiles;
  int per_row, r, c;
  int rows() const
  {
    return r;
  }
  int cols() const
  {
    return c;
  }
  double operator()(int i, int j) const
  {
    return tiles[(i / 8) * per_row + j / 8](i % 8, j % 8);
  }
};

int root(std::vector<int>& parent, int g)
{
  while (parent[g] != g)
    g = parent[g] = parent[parent[g]];
  return g;
}
}  // namespace

void ReducedLinearSolver::analyze(const BlockSparseMatrix& m, int coordinate_groups)
{
  analyzed_rows_ = m.rows();
  analyzed_nonzeros_ = m.matrix().nonZeros();
  analyzed_groups_ = m.groups();
  const int groups = m.groups();
  clusters_.clear();
  group_cluster_.assign(groups, -1);
  group_index_.assign(groups, -1);
  group_map_.assign(groups, -1);
  reducible_ = false;
  bool small = true;
  for (int g = 0; g < groups; ++g)
    small = small && m.groupSize(g) <= kMaxGroup;
  if (!small)
    return;
  // the coordinate groups each constraint group acts on, with both of its blocks (row and column) there;
  // a constraint group coupled with another constraint group, or with one block of a pair only, stays
  std::vector<std::vector<int>> partners(groups);
  std::vector<bool> eliminable(groups, false);
  for (int c = coordinate_groups; c < groups; ++c)
    eliminable[c] = true;
  for (const auto& [gr, gc] : m.blocks())
  {
    if (gr == gc)
      continue;
    for (const auto& [c, other] : { std::make_pair(gr, gc), std::make_pair(gc, gr) })
    {
      if (c < coordinate_groups)
        continue;
      if (other >= coordinate_groups || m.blockIndex(other, c) < 0 || m.blockIndex(c, other) < 0)
        eliminable[c] = false;
      else if (std::find(partners[c].begin(), partners[c].end(), other) == partners[c].end())
        partners[c].push_back(other);
    }
  }
  for (int c = coordinate_groups; c < groups; ++c)
    eliminable[c] = eliminable[c] && !partners[c].empty();
  // clusters: the bodies joined by eliminable constraint groups
  std::vector<int> parent(coordinate_groups);
  for (int g = 0; g < coordinate_groups; ++g)
    parent[g] = g;
  for (int c = coordinate_groups; c < groups; ++c)
    if (eliminable[c])
      for (int g : partners[c])
        parent[root(parent, g)] = root(parent, partners[c].front());
  std::vector<int> size(coordinate_groups, 0), rows(coordinate_groups, 0);
  for (int g = 0; g < coordinate_groups; ++g)
    size[root(parent, g)] += m.groupSize(g);
  for (int c = coordinate_groups; c < groups; ++c)
    if (eliminable[c])
      rows[root(parent, partners[c].front())] += m.groupSize(c);
  // a component too large (or with more rows than coordinates) is split into its bodies: each keeps the
  // constraint groups that act on it alone (as many as its coordinates allow), the joints stay
  std::vector<bool> whole(coordinate_groups, false);
  for (int g = 0; g < coordinate_groups; ++g)
    if (root(parent, g) == g)
      whole[g] = size[g] <= kMaxCluster && rows[g] <= size[g] && size[g] - rows[g] <= kMaxClusterDof;
  // a cluster per kept component (keyed by its root) or per body of a split one
  const auto key = [&](int g) { return whole[root(parent, g)] ? root(parent, g) : g; };
  std::vector<int> key_cluster(coordinate_groups, -1);
  const auto cluster_of = [&](int g)
  {
    if (key_cluster[key(g)] < 0)
    {
      key_cluster[key(g)] = static_cast<int>(clusters_.size());
      clusters_.emplace_back();
    }
    return key_cluster[key(g)];
  };
  std::vector<bool> eliminated(groups, false);
  for (int c = coordinate_groups; c < groups; ++c)
  {
    if (!eliminable[c])
      continue;
    const int g = partners[c].front();
    if (!whole[root(parent, g)] && partners[c].size() > 1)
      continue;  // a joint of a split component
    Cluster& cl = clusters_[cluster_of(g)];
    if (!whole[root(parent, g)] && static_cast<int>(cl.rows.size()) + m.groupSize(c) > m.groupSize(g))
      continue;  // more one-body rows than coordinates: the rest stay (the matrix is then singular anyway)
    const int first_row = static_cast<int>(cl.rows.size());
    for (int i = 0; i < m.groupSize(c); ++i)
      cl.rows.push_back(m.groupOffset(c) + i);
    for (int p : partners[c])
      cl.links.push_back({ m.blockIndex(c, p), m.blockIndex(p, c), first_row, p });  // coordinate set below
    cl.diag_blocks.push_back(m.blockIndex(c, c));
    eliminated[c] = true;
  }
  // the clusters' groups: every coordinate group of a kept component, or the body itself
  for (int g = 0; g < coordinate_groups; ++g)
  {
    const int c = key_cluster[key(g)];
    if (c < 0 || clusters_[c].rows.empty())
      continue;
    Cluster& cl = clusters_[c];
    group_cluster_[g] = c;
    group_index_[g] = static_cast<int>(cl.groups.size());
    cl.groups.push_back(g);
    cl.local.push_back(cl.size);
    cl.size += m.groupSize(g);
  }
  reducible_ = false;
  eliminated_rows_ = 0;
  for (Cluster& cl : clusters_)
  {
    if (cl.rows.empty())
      continue;
    reducible_ = true;
    eliminated_rows_ += static_cast<int>(cl.rows.size());
    for (Cluster::Link& l : cl.links)
      l.coordinate = cl.local[group_index_[l.coordinate]];
    const int n = cl.size, k = static_cast<int>(cl.rows.size());
    cl.bt.setZero(n, k);
    cl.ct.setZero(n, k);
    cl.q.resize(n, n);
    cl.y.resize(n, k);
    cl.work.resize(n);
    cl.v.resize(n);
    cl.w.resize(k);
    cl.qr = Eigen::HouseholderQR<Eigen::MatrixXd>(n, k);
    cl.z.assign(cl.groups.size(), ZRows::Zero(kMaxGroup, n - k));
    cl.zt.assign(cl.groups.size(), ZRowsT::Zero(n - k, kMaxGroup));
    cl.tiles = (n - k + kMaxGroup - 1) / kMaxGroup;
    cl.z_tiles.assign(cl.groups.size() * cl.tiles, Mat8::Zero());
    cl.zt_tiles.assign(cl.groups.size() * cl.tiles, Mat8::Zero());
  }
  if (!reducible_)
    return;
  // A_r's groups: a cluster's at the place of its first body, the others where they are
  std::vector<int> sizes;
  std::vector<int> cluster_group(clusters_.size(), -1);
  for (int g = 0; g < groups; ++g)
  {
    if (eliminated[g])
      continue;
    const int c = group_cluster_[g];
    if (c < 0)
    {
      group_map_[g] = static_cast<int>(sizes.size());
      sizes.push_back(m.groupSize(g));
      continue;
    }
    if (cluster_group[c] < 0)
    {
      cluster_group[c] = static_cast<int>(sizes.size());
      sizes.push_back(clusters_[c].size - static_cast<int>(clusters_[c].rows.size()));
    }
    group_map_[g] = cluster_group[c];
  }
  std::vector<std::pair<int, int>> blocks;
  for (const auto& [gr, gc] : m.blocks())
    if (group_map_[gr] >= 0 && group_map_[gc] >= 0)
      blocks.emplace_back(group_map_[gr], group_map_[gc]);
  std::sort(blocks.begin(), blocks.end());
  blocks.erase(std::unique(blocks.begin(), blocks.end()), blocks.end());
  reduced_.init(sizes, blocks);
  full_offset_.resize(groups);
  full_size_.resize(groups);
  kept_offset_.assign(groups, -1);
  for (int g = 0; g < groups; ++g)
  {
    full_offset_[g] = m.groupOffset(g);
    full_size_[g] = m.groupSize(g);
    if (group_map_[g] >= 0 && group_cluster_[g] < 0)
      kept_offset_[g] = reduced_.groupOffset(group_map_[g]);
  }
  cluster_offset_.assign(clusters_.size(), -1);
  for (size_t c = 0; c < clusters_.size(); ++c)
    if (cluster_group[c] >= 0)
      cluster_offset_[c] = reduced_.groupOffset(cluster_group[c]);
  // the blocks of A kept, those touching a cluster copied (padded) for solve(): A xp into the kept groups and
  // the clusters' rows, A x into the clusters' rows
  blocks_ = m.blocks();
  block_map_.assign(blocks_.size(), -1);
  block_op_.assign(blocks_.size(), -1);
  rhs_products_.clear();
  force_products_.clear();
  int ops = 0;
  for (size_t i = 0; i < blocks_.size(); ++i)
  {
    const auto& [gr, gc] = blocks_[i];
    if (group_map_[gr] < 0 || group_map_[gc] < 0)
      continue;
    block_map_[i] = reduced_.blockIndex(group_map_[gr], group_map_[gc]);
    if (group_cluster_[gr] < 0 && group_cluster_[gc] < 0)
      continue;
    block_op_[i] = ops++;
    if (group_cluster_[gc] >= 0)
      rhs_products_.push_back({ block_op_[i], gr, gc });
    if (group_cluster_[gr] >= 0)
      force_products_.push_back({ block_op_[i], gr, gc });
  }
  ops_.resize(ops);
  // the tiles of A_r's blocks between a cluster and another group
  const auto tiles = [&](int g) { return group_cluster_[g] >= 0 ? clusters_[group_cluster_[g]].tiles : 1; };
  tile_offset_.assign(reduced_.blocks().size(), -1);
  tile_rows_.assign(reduced_.blocks().size(), 0);
  tile_cols_.assign(reduced_.blocks().size(), 0);
  tiled_blocks_.clear();
  int pool = 0;
  for (size_t i = 0; i < blocks_.size(); ++i)
  {
    const int j = block_map_[i];
    if (block_op_[i] < 0 || tile_offset_[j] >= 0)
      continue;
    tile_offset_[j] = pool;
    tile_rows_[j] = tiles(blocks_[i].first);
    tile_cols_[j] = tiles(blocks_[i].second);
    pool += tile_rows_[j] * tile_cols_[j];
    tiled_blocks_.push_back(j);
  }
  tiles_.resize(pool);
  acc_.assign(groups, Vec8::Zero());
  xp_.assign(groups, Vec8::Zero());
}

bool ReducedLinearSolver::bases(const BlockSparseMatrix& m)
{
  auto& block = block_;  // (fixed-size storage: no allocation)
  for (Cluster& cl : clusters_)
  {
    if (cl.rows.empty())
      continue;
    const int n = cl.size;
    const int k = static_cast<int>(cl.rows.size());
    for (int d : cl.diag_blocks)
    {
      m.block(d, block);
      if (block.cwiseAbs().maxCoeff() != 0.0)
        return false;
    }
    for (const Cluster::Link& l : cl.links)
    {
      m.block(l.row_block, block);
      cl.bt.block(l.coordinate, l.row, block.cols(), block.rows()) = block.transpose();
      m.block(l.col_block, block);
      cl.ct.block(l.coordinate, l.row, block.rows(), block.cols()) = block;
    }
    const double scale = cl.bt.cwiseAbs().maxCoeff();
    if (!(scale > 0.0) || !((cl.ct - cl.bt).cwiseAbs().maxCoeff() <= 1e-12 * scale))
      return false;
    cl.qr.compute(cl.bt);
    const auto r = cl.qr.matrixQR().topLeftCorner(k, k);
    const double largest = r.diagonal().cwiseAbs().maxCoeff();
    if (!(r.diagonal().cwiseAbs().minCoeff() > 1e-10 * largest))
      return false;  // the cluster's rows are dependent
    cl.qr.householderQ().evalTo(cl.q, cl.work);
    // Z = Q2 the null-space basis, Y = Q1 R^-T the right inverse (B = R^T Q1^T, so B Y = I)
    cl.y = cl.q.leftCols(k);
    r.triangularView<Eigen::Upper>().transpose().solveInPlace<Eigen::OnTheRight>(cl.y);
    for (size_t i = 0; i < cl.groups.size(); ++i)
    {
      const int rows = full_size_[cl.groups[i]];
      cl.z[i].topRows(rows) = cl.q.block(cl.local[i], k, rows, n - k);
      cl.zt[i].leftCols(rows) = cl.z[i].topRows(rows).transpose();
      for (int t = 0; t < cl.tiles; ++t)
      {
        const int cols = std::min(kMaxGroup, n - k - kMaxGroup * t);
        Mat8& z = cl.z_tiles[i * cl.tiles + t];
        z.topLeftCorner(rows, cols) = cl.z[i].block(0, kMaxGroup * t, rows, cols);
        cl.zt_tiles[i * cl.tiles + t] = z.transpose();
      }
    }
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
  for (Mat8& t : tiles_)
    t.setZero();
  // blocks padded to 8 x 8 (a strut has 7 coordinates), the clusters' Z in 8 x 8 tiles: every product is one of
  // fixed size, summed into the tiles of A_r's block: (Z_r^T A) Z_c tile by tile
  Mat8 left[kMaxClusterDof / kMaxGroup];
  for (size_t i = 0; i < blocks_.size(); ++i)
  {
    const int j = block_map_[i];
    if (j < 0)
      continue;
    const int index = static_cast<int>(i);
    if (block_op_[i] < 0)
    {
      reduced_.addBlock(j, m, index);
      continue;
    }
    const auto& [gr, gc] = blocks_[i];
    Mat8& a = ops_[block_op_[i]];
    padded(m, index, a);
    const int cr = group_cluster_[gr], cc = group_cluster_[gc];
    const int tr = tile_rows_[j], tc = tile_cols_[j];
    Mat8* out = &tiles_[tile_offset_[j]];
    if (cr >= 0)
    {
      const Mat8* zt = &clusters_[cr].zt_tiles[group_index_[gr] * tr];
      for (int t = 0; t < tr; ++t)
        multiply8<false>(zt[t], a, left[t]);
    }
    else
      left[0] = a;
    if (cc >= 0)
    {
      const Mat8* z = &clusters_[cc].z_tiles[group_index_[gc] * tc];
      for (int t = 0; t < tr; ++t)
        for (int u = 0; u < tc; ++u)
          multiply8<true>(left[t], z[u], out[t * tc + u]);
    }
    else
      for (int t = 0; t < tr; ++t)
        out[t] += left[t];
  }
  for (int j : tiled_blocks_)
  {
    const auto& [gr, gc] = reduced_.blocks()[j];
    reduced_.addBlock(j, TileView{ &tiles_[tile_offset_[j]], tile_cols_[j], reduced_.groupSize(gr),
                                   reduced_.groupSize(gc) });
  }
  factorized_size_ = reduced_.rows();
  return reduced_solver_.factorize(reduced_.matrix());
}

ReducedLinearSolver::Vec8 ReducedLinearSolver::load(const Eigen::VectorXd& v, int group) const
{
  Vec8 out = Vec8::Zero();
  out.head(full_size_[group]) = v.segment(full_offset_[group], full_size_[group]);
  return out;
}

void ReducedLinearSolver::solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
{
  if (!use_reduced_)
  {
    full_solver_.solve(b, x);
    return;
  }
  // the particular solution of every cluster's rows, xp = Y b_L, and its coordinate rows' right-hand sides
  for (const Cluster& cl : clusters_)
  {
    if (cl.rows.empty())
      continue;
    for (size_t r = 0; r < cl.rows.size(); ++r)
      cl.w(static_cast<Eigen::Index>(r)) = b(cl.rows[r]);
    cl.v.noalias() = cl.y * cl.w;
    for (size_t i = 0; i < cl.groups.size(); ++i)
    {
      const int g = cl.groups[i];
      xp_[g].setZero();
      xp_[g].head(full_size_[g]) = cl.v.segment(cl.local[i], full_size_[g]);
      acc_[g] = load(b, g);
    }
  }
  // the reduced right-hand side: the kept rows' b - A xp, the clusters' Z^T (b_q - A xp)
  rhs_.resize(reduced_.rows());
  const int groups = static_cast<int>(group_map_.size());
  for (int g = 0; g < groups; ++g)
    if (kept_offset_[g] >= 0)
      rhs_.segment(kept_offset_[g], full_size_[g]) = b.segment(full_offset_[g], full_size_[g]);
  for (const Product& p : rhs_products_)
  {
    const Vec8 product = ops_[p.op].lazyProduct(xp_[p.from]);
    if (group_cluster_[p.to] >= 0)
      acc_[p.to] -= product;
    else
      rhs_.segment(kept_offset_[p.to], full_size_[p.to]) -= product.head(full_size_[p.to]);
  }
  for (size_t c = 0; c < clusters_.size(); ++c)
  {
    const Cluster& cl = clusters_[c];
    if (cl.rows.empty())
      continue;
    const int d = cl.size - static_cast<int>(cl.rows.size());
    auto segment = rhs_.segment(cluster_offset_[c], d);
    segment.setZero();
    for (size_t i = 0; i < cl.groups.size(); ++i)
      segment.noalias() += cl.zt[i] * acc_[cl.groups[i]];
  }
  reduced_solver_.solve(rhs_, xr_);
  // x = xp + Z xr in the clusters, xr elsewhere
  x.resize(b.size());
  for (int g = 0; g < groups; ++g)
    if (kept_offset_[g] >= 0)
      x.segment(full_offset_[g], full_size_[g]) = xr_.segment(kept_offset_[g], full_size_[g]);
  for (size_t c = 0; c < clusters_.size(); ++c)
  {
    const Cluster& cl = clusters_[c];
    if (cl.rows.empty())
      continue;
    const int d = cl.size - static_cast<int>(cl.rows.size());
    for (size_t i = 0; i < cl.groups.size(); ++i)
    {
      const int g = cl.groups[i];
      const Vec8 piece = xp_[g] + cl.z[i] * xr_.segment(cluster_offset_[c], d);
      x.segment(full_offset_[g], full_size_[g]) = piece.head(full_size_[g]);
      acc_[g] = load(b, g);
    }
  }
  // the eliminated multipliers from the clusters' force rows: B^T lambda_L = b_q - (A x)_q without them, and
  // Y^T B^T = I
  for (const Product& p : force_products_)
    acc_[p.to] -= ops_[p.op].lazyProduct(load(x, p.from));
  for (const Cluster& cl : clusters_)
  {
    if (cl.rows.empty())
      continue;
    for (size_t i = 0; i < cl.groups.size(); ++i)
      cl.v.segment(cl.local[i], full_size_[cl.groups[i]]) = acc_[cl.groups[i]].head(full_size_[cl.groups[i]]);
    cl.w.noalias() = cl.y.transpose() * cl.v;
    for (size_t r = 0; r < cl.rows.size(); ++r)
      x(cl.rows[r]) = cl.w(static_cast<Eigen::Index>(r));
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
