#include "active_tensegrity/oracle/body_block_solver.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <numeric>
#include <utility>

namespace active_tensegrity::core
{
namespace
{
/// A body system or Schur complement with a reciprocal condition estimate below this is refused.
constexpr double kMinRcond = 1e-13;
/// The products of a solve work on packs of four rows: a matrix is stored by columns of `ld` rows, ld a
/// multiple of kPack, the rows past its own zero.
constexpr int kPack = 4;
int padded(int rows)
{
  return (rows + kPack - 1) / kPack * kPack;
}
/// A pack is one vector register where the processor has 256-bit ones (AVX), else two of 128 bits (SSE2 in the
/// generic x86-64 build, where a 256-bit vector type is split through memory).
#if defined(__AVX__)
using Lane = double __attribute__((vector_size(32)));
#else
using Lane = double __attribute__((vector_size(16)));
#endif
constexpr int kLane = static_cast<int>(sizeof(Lane) / sizeof(double));
static_assert(kPack % kLane == 0);

/// y = A x for the packs of rows at a (column-major, `ld` rows in all), kPacks packs of them: each row's sum runs
/// over the columns in their order (so the result does not depend on where the data lie), the rows independent
/// of each other. y gets kPack kPacks entries.
template <int kPacks>
void multiplyPacks(const double* a, int ld, int cols, const double* x, double* y)
{
  constexpr int kLanes = kPacks * kPack / kLane;
  Lane sum[kLanes];
#pragma GCC unroll 16
  for (int l = 0; l < kLanes; ++l)
    sum[l] = Lane{};
  for (int c = 0; c < cols; ++c)
  {
    const double xc = x[c];
    const double* column = a + static_cast<std::ptrdiff_t>(c) * ld;
    // (unrolled, so that the sums stay in registers: left as a loop, -O2 kept them in memory)
#pragma GCC unroll 16
    for (int l = 0; l < kLanes; ++l)
    {
      Lane ac;
      std::memcpy(&ac, column + kLane * l, sizeof ac);
      sum[l] += ac * xc;
    }
  }
  std::memcpy(y, sum, sizeof sum);
}

/// y = A x for a column-major matrix at a with `ld` rows (a multiple of kPack, the padding rows zero) and `cols`
/// columns; y gets ld entries. (Written for the compiler's vectors: four rows per instruction with AVX2, two with
/// the generic x86-64's SSE2, up to four packs in flight, where a sum per row waited on its own additions.)
void multiplyColumns(const double* a, int ld, int cols, const double* x, double* y)
{
  int r = 0;
  for (; r + 4 * kPack <= ld; r += 4 * kPack)
    multiplyPacks<4>(a + r, ld, cols, x, y + r);
  switch ((ld - r) / kPack)
  {
    case 3:
      multiplyPacks<3>(a + r, ld, cols, x, y + r);
      break;
    case 2:
      multiplyPacks<2>(a + r, ld, cols, x, y + r);
      break;
    case 1:
      multiplyPacks<1>(a + r, ld, cols, x, y + r);
      break;
    default:
      break;
  }
}
}  // namespace

BodyBlockSolver::BodyBlockSolver(std::vector<int> body_sizes) : body_sizes_(std::move(body_sizes))
{
  for (size_t b = 0; b < body_sizes_.size(); ++b)
    body_of_column_.insert(body_of_column_.end(), body_sizes_[b], static_cast<int>(b));
  group_of_body_wanted_.resize(body_sizes_.size());
  std::iota(group_of_body_wanted_.begin(), group_of_body_wanted_.end(), 0);
}

void BodyBlockSolver::chooseGroups(const Eigen::SparseMatrix<double>& a, bool analyzed_pattern)
{
  const int nb = static_cast<int>(body_sizes_.size());
  const int nq = static_cast<int>(body_of_column_.size());
  std::vector<int>& group = group_of_body_wanted_;
  std::iota(group.begin(), group.end(), 0);
  if (nq > a.cols() || !groups_allowed_)
    return;
  body_diagonal_.assign(nb, 0.0);
  couplings_.clear();
  const double* v = a.valuePtr();
  const auto couple = [&](int p, int bi, int bj)
  {
    const double scale = std::min(body_diagonal_[bi], body_diagonal_[bj]);
    if (scale > 0.0 && std::abs(v[p]) >= kGroupCoupling * scale)
      couplings_.push_back({ std::abs(v[p]) / scale, { bi, bj } });
  };
  if (analyzed_pattern)  // the entries that matter, read off the pattern once
  {
    for (const auto& [p, b] : diagonal_entries_)
      body_diagonal_[b] = std::max(body_diagonal_[b], std::abs(v[p]));
    for (const Coupling& c : coupling_entries_)
      couple(c.p, c.a, c.b);
  }
  else
  {
    const int* outer = a.outerIndexPtr();
    const int* inner = a.innerIndexPtr();
    for (int j = 0; j < nq; ++j)
      for (int p = outer[j]; p < outer[j + 1]; ++p)
        if (inner[p] == j)
          body_diagonal_[body_of_column_[j]] = std::max(body_diagonal_[body_of_column_[j]], std::abs(v[p]));
    for (int j = 0; j < nq; ++j)
      for (int p = outer[j]; p < outer[j + 1]; ++p)
      {
        const int i = inner[p];
        if (i >= nq || i >= j)  // (above the diagonal: H's pattern is symmetric, and a coupling's two sides alike)
          continue;
        if (body_of_column_[i] != body_of_column_[j])
          couple(p, body_of_column_[i], body_of_column_[j]);
      }
  }
  if (couplings_.empty())
    return;
  // strongest first; a pair already together, or whose groups together would be too large, is left
  std::sort(couplings_.begin(), couplings_.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
  std::vector<int> columns(body_sizes_);
  const auto find = [&group](int b)
  {
    while (group[b] != b)
      b = group[b] = group[group[b]];
    return b;
  };
  for (const auto& c : couplings_)
  {
    const int x = find(c.second.first), y = find(c.second.second);
    if (x == y || columns[x] + columns[y] > kMaxGroupColumns)
      continue;
    group[std::max(x, y)] = std::min(x, y);
    columns[std::min(x, y)] += columns[std::max(x, y)];
  }
  for (int b = 0; b < nb; ++b)
    group[b] = find(b);
}

bool BodyBlockSolver::samePattern(const Eigen::SparseMatrix<double>& a) const
{
  if (a.rows() != n_ || a.cols() != n_ || static_cast<size_t>(a.nonZeros()) != a_inner_.size() || !a.isCompressed())
    return false;
  return std::equal(a_outer_.begin(), a_outer_.end(), a.outerIndexPtr()) &&
         std::equal(a_inner_.begin(), a_inner_.end(), a.innerIndexPtr());
}

bool BodyBlockSolver::analyze(const Eigen::SparseMatrix<double>& a)
{
  ++analyses_;
  usable_ = false;
  n_ = static_cast<int>(a.rows());
  a_outer_.assign(a.outerIndexPtr(), a.outerIndexPtr() + a.cols() + 1);
  a_inner_.assign(a.innerIndexPtr(), a.innerIndexPtr() + a.nonZeros());
  nq_ = std::accumulate(body_sizes_.begin(), body_sizes_.end(), 0);
  diagonal_entries_.clear();
  coupling_entries_.clear();
  body_entries_.clear();
  g_entries_.clear();
  gt_entries_.clear();
  constraint_block_entries_.clear();
  if (body_sizes_.empty() || nq_ > n_ || a.cols() != n_ || !a.isCompressed())  // (the pattern is read from its arrays)
    return false;
  // what chooseGroups reads: H's diagonal, and its entries above it that couple two bodies (in column order)
  for (int j = 0; j < nq_; ++j)
    for (int p = a_outer_[j]; p < a_outer_[j + 1]; ++p)
    {
      const int i = a_inner_[p];
      if (i == j)
        diagonal_entries_.emplace_back(p, body_of_column_[j]);
      else if (i < j && body_of_column_[i] != body_of_column_[j])
        coupling_entries_.push_back({ p, body_of_column_[i], body_of_column_[j] });
    }
  // the blocks: one per group of bodies (group_of_body_: each body's group named by its smallest body)
  group_of_body_ = group_of_body_wanted_;
  std::vector<int> block_of_group(body_sizes_.size(), -1);
  int nb = 0;
  for (int g : group_of_body_)
    if (block_of_group[g] < 0)
      block_of_group[g] = nb++;
  std::vector<int> body(nq_);
  for (int c = 0; c < nq_; ++c)
    body[c] = block_of_group[group_of_body_[body_of_column_[c]]];
  std::vector<std::vector<int>> columns(nb);
  for (int c = 0; c < nq_; ++c)
    columns[body[c]].push_back(c);
  std::vector<int> bodies_in_block(nb, 0);
  for (int g : group_of_body_)
    ++bodies_in_block[block_of_group[g]];
  grouped_bodies_ = 0;
  for (int g : group_of_body_)
    grouped_bodies_ += bodies_in_block[block_of_group[g]] > 1 ? 1 : 0;
  // the bodies each constraint row touches (in G and in Gt): -1 none, -2 more than one
  std::vector<int> owner(n_ - nq_, -1);
  const auto touch = [&](int row, int b)
  {
    int& o = owner[row - nq_];
    o = (o == -1 || o == b) ? b : -2;
  };
  for (int j = 0; j < n_; ++j)
    for (int p = a_outer_[j]; p < a_outer_[j + 1]; ++p)
    {
      const int i = a_inner_[p];
      if (j < nq_ && i >= nq_)
        touch(i, body[j]);
      else if (j >= nq_ && i < nq_)
        touch(j, body[i]);
    }
  joining_.clear();
  std::vector<int> join_pos(n_ - nq_, -1);
  for (int r = nq_; r < n_; ++r)
  {
    if (owner[r - nq_] == -1)
      return false;  // a row on no body: A is singular
    if (owner[r - nq_] == -2)
    {
      join_pos[r - nq_] = static_cast<int>(joining_.size());
      joining_.push_back(r);
    }
  }
  // each body's rows: its columns, then the constraint rows it owns; and the joining rows it takes part in
  std::vector<std::vector<int>> own(nb), joins(nb);
  for (int r = nq_; r < n_; ++r)
    if (owner[r - nq_] >= 0)
      own[owner[r - nq_]].push_back(r);
  for (int j = 0; j < n_; ++j)
    for (int p = a_outer_[j]; p < a_outer_[j + 1]; ++p)
    {
      const int i = a_inner_[p];
      if (j < nq_ && i >= nq_ && join_pos[i - nq_] >= 0)
        joins[body[j]].push_back(join_pos[i - nq_]);
      else if (j >= nq_ && i < nq_ && join_pos[j - nq_] >= 0)
        joins[body[i]].push_back(join_pos[j - nq_]);
    }
  blocks_.assign(nb, BodyBlock());
  rows_.clear();
  jidx_.clear();
  std::vector<int> local(n_, -1);  // a row's index in its body system
  int k_size = 0, kinv_size = 0, g_size = 0, w_size = 0, y_size = 0;
  int largest = 0;
  for (int b = 0; b < nb; ++b)
  {
    std::sort(joins[b].begin(), joins[b].end());
    joins[b].erase(std::unique(joins[b].begin(), joins[b].end()), joins[b].end());
    BodyBlock& bb = blocks_[b];
    bb.n = static_cast<int>(columns[b].size());
    bb.size = bb.n + static_cast<int>(own[b].size());
    if (bb.size > (bodies_in_block[b] == 1 ? kMaxBodyRows : kMaxGroupRows))
      return false;
    largest = std::max(largest, bb.size);
    bb.rows = static_cast<int>(rows_.size());
    rows_.insert(rows_.end(), columns[b].begin(), columns[b].end());
    rows_.insert(rows_.end(), own[b].begin(), own[b].end());
    for (int k = 0; k < bb.size; ++k)
      local[rows_[bb.rows + k]] = k;
    bb.joins = static_cast<int>(joins[b].size());
    bb.j_start = static_cast<int>(jidx_.size());
    jidx_.insert(jidx_.end(), joins[b].begin(), joins[b].end());
    bb.ld = padded(bb.size);
    bb.g_ld = padded(bb.joins);
    bb.k_start = k_size;
    bb.kinv_start = kinv_size;
    bb.g_start = g_size;
    bb.w_start = w_size;
    bb.y_start = y_size;
    k_size += bb.size * bb.size;
    kinv_size += bb.ld * bb.size;
    g_size += bb.g_ld * bb.n;
    w_size += bb.ld * bb.joins;
    y_size += bb.ld;
  }
  const auto joinLocal = [&](int b, int row)
  {
    const BodyBlock& bb = blocks_[b];
    const auto first = jidx_.begin() + bb.j_start;
    return static_cast<int>(std::lower_bound(first, first + bb.joins, join_pos[row - nq_]) - first);
  };
  for (int j = 0; j < n_; ++j)
    for (int p = a_outer_[j]; p < a_outer_[j + 1]; ++p)
    {
      const int i = a_inner_[p];
      if (i < nq_ && j < nq_)
      {
        if (body[i] != body[j])
          continue;
        const BodyBlock& bb = blocks_[body[i]];
        body_entries_.push_back({ p, bb.k_start + local[j] * bb.size + local[i] });
      }
      else if (i >= nq_ && j >= nq_)
        constraint_block_entries_.push_back(p);
      else
      {
        const int b = j < nq_ ? body[j] : body[i];
        const int row = j < nq_ ? i : j;  // the constraint row
        const BodyBlock& bb = blocks_[b];
        if (join_pos[row - nq_] < 0)
          body_entries_.push_back({ p, bb.k_start + local[j] * bb.size + local[i] });
        else if (j < nq_)  // G: g_ld x n, column-major
          g_entries_.push_back({ p, bb.g_start + local[j] * bb.g_ld + joinLocal(b, row) });
        else  // Gt: n x joins, column-major
          gt_entries_.push_back({ p, bb.g_start + joinLocal(b, row) * bb.n + local[i] });
      }
    }
  kx_.setZero(k_size);
  kinv_.setZero(kinv_size);
  gx_.setZero(g_size);
  gtx_.setZero(g_size);
  wx_.setZero(w_size);
  body_lu_.resize(std::max<size_t>(body_lu_.size(), largest + 1));
  y_.resize(y_size);
  int widest = padded(largest);
  for (const BodyBlock& bb : blocks_)
    widest = std::max(widest, bb.g_ld);
  v_.resize(widest);
  t_.resize(widest);
  const int nj = static_cast<int>(joining_.size());
  sparse_schur_ = nj > kDenseSchurRows;
  s_start_.assign(nb, 0);
  s_slot_.clear();
  if (sparse_schur_)
  {
    s_.resize(0, 0);
    std::vector<Eigen::Triplet<double>> entries;
    for (int k = 0; k < nj; ++k)
      entries.emplace_back(k, k, 0.0);
    for (const BodyBlock& bb : blocks_)
      for (int c = 0; c < bb.joins; ++c)
        for (int r = 0; r < bb.joins; ++r)
          entries.emplace_back(jidx_[bb.j_start + r], jidx_[bb.j_start + c], 0.0);
    s_sparse_.resize(nj, nj);
    s_sparse_.setFromTriplets(entries.begin(), entries.end());
    s_sparse_.makeCompressed();
    const int* outer = s_sparse_.outerIndexPtr();
    const int* inner = s_sparse_.innerIndexPtr();
    for (int b = 0; b < nb; ++b)
    {
      const BodyBlock& bb = blocks_[b];
      s_start_[b] = static_cast<int>(s_slot_.size());
      for (int c = 0; c < bb.joins; ++c)
        for (int r = 0; r < bb.joins; ++r)
        {
          const int row = jidx_[bb.j_start + r], col = jidx_[bb.j_start + c];
          s_slot_.push_back(static_cast<int>(std::lower_bound(inner + outer[col], inner + outer[col + 1], row) - inner));
        }
    }
  }
  else
    s_.resize(nj, nj);
  rhs_.resize(nj);
  xj_.resize(nj);
  usable_ = true;
  return true;
}

bool BodyBlockSolver::factorize(const Eigen::SparseMatrix<double>& a)
{
  const bool same = samePattern(a);
  chooseGroups(a, same);
  if ((!same || group_of_body_wanted_ != group_of_body_) && !analyze(a))
    return false;
  if (!usable_)
    return false;
  kx_.setZero();
  gx_.setZero();
  gtx_.setZero();
  const double* v = a.valuePtr();
  for (int p : constraint_block_entries_)
    if (v[p] != 0.0)
      return false;
  for (const Entry& e : body_entries_)
    kx_[e.slot] += v[e.p];
  for (const Entry& e : g_entries_)
    gx_[e.slot] += v[e.p];
  for (const Entry& e : gt_entries_)
    gtx_[e.slot] += v[e.p];
  s_.setZero();
  double* s_values = s_sparse_.valuePtr();
  if (sparse_schur_)
    std::fill(s_values, s_values + s_sparse_.nonZeros(), 0.0);
  for (size_t b = 0; b < blocks_.size(); ++b)
  {
    const BodyBlock& bb = blocks_[b];
    const Eigen::Map<const Eigen::MatrixXd> k(kx_.data() + bb.k_start, bb.size, bb.size);
    Eigen::PartialPivLU<Eigen::MatrixXd>& lu = body_lu_[bb.size];
    lu.compute(k);
    // (the condition estimate allocates: made only when the pivots spread over more than 8 decades)
    const auto pivots = lu.matrixLU().diagonal().cwiseAbs();
    if (!(pivots.minCoeff() > 1e-8 * pivots.maxCoeff()) && !(lu.rcond() > kMinRcond))
      return false;
    Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>> kinv(kinv_.data() + bb.kinv_start, bb.size, bb.size,
                                                              Eigen::OuterStride<>(bb.ld));
    // P (the identity with its rows permuted), written directly: P * I on a map permutes in place through an
    // allocated mask
    kinv.setZero();
    const auto& perm = lu.permutationP().indices();
    for (int i = 0; i < bb.size; ++i)
      kinv(perm[i], i) = 1.0;
    lu.matrixLU().triangularView<Eigen::UnitLower>().solveInPlace(kinv);
    lu.matrixLU().triangularView<Eigen::Upper>().solveInPlace(kinv);
    if (bb.joins == 0)
      continue;
    // W_b = K_b^-1 [Gt_b; 0] and S += G_b W_b (its first n rows)
    const Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>> g(gx_.data() + bb.g_start, bb.joins, bb.n,
                                                                       Eigen::OuterStride<>(bb.g_ld));
    const Eigen::Map<const Eigen::MatrixXd> gt(gtx_.data() + bb.g_start, bb.n, bb.joins);
    Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>> w(wx_.data() + bb.w_start, bb.size, bb.joins,
                                                           Eigen::OuterStride<>(bb.ld));
    w.noalias() = kinv.leftCols(bb.n) * gt;
    const int* jl = jidx_.data() + bb.j_start;
    const int* slot = s_slot_.data() + s_start_[b];
    for (int c = 0; c < bb.joins; ++c)
      for (int r = 0; r < bb.joins; ++r)
      {
        const double gw = g.row(r).dot(w.col(c).head(bb.n));
        if (sparse_schur_)
          s_values[*slot++] += gw;
        else
          s_(jl[r], jl[c]) += gw;
      }
  }
  if (sparse_schur_)
    return s_static_.factorize(s_sparse_);
  if (s_.rows() > 0)
  {
    s_lu_.compute(s_);
    const auto pivots = s_lu_.matrixLU().diagonal().cwiseAbs();
    if (!(pivots.minCoeff() > 1e-8 * pivots.maxCoeff()) && !(s_lu_.rcond() > kMinRcond))
      return false;
    s_pivot_inverse_ = s_lu_.matrixLU().diagonal().cwiseInverse();
  }
  return true;
}

void BodyBlockSolver::solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
{
  x.resize(n_);
  const int nj = static_cast<int>(joining_.size());
  for (int k = 0; k < nj; ++k)
    rhs_(k) = -b(joining_[k]);
  double* v = v_.data();
  double* t = t_.data();
  // y_b = K_b^-1 b_b, and the joining rows' right-hand side sum_b G_b y_b - b_J
  for (const BodyBlock& bb : blocks_)
  {
    const int* rows = rows_.data() + bb.rows;
    for (int k = 0; k < bb.size; ++k)
      v[k] = b(rows[k]);
    double* y = y_.data() + bb.y_start;
    multiplyColumns(kinv_.data() + bb.kinv_start, bb.ld, bb.size, v, y);
    if (bb.joins == 0)
      continue;
    multiplyColumns(gx_.data() + bb.g_start, bb.g_ld, bb.n, y, t);
    const int* jl = jidx_.data() + bb.j_start;
    for (int r = 0; r < bb.joins; ++r)
      rhs_(jl[r]) += t[r];
  }
  if (sparse_schur_)
    s_static_.solve(rhs_, xj_);
  else if (nj > 0)
  {
    // x_J = S^-1 rhs through S's LU factors (column-major): P, then each triangle column by column, a
    // vectorized update of the rows below (above) per column, U's pivots inverted once (Eigen's solve for a
    // vector went through its blocked kernels, about three times as long at the tower's 36 rows)
    const Eigen::MatrixXd& lu = s_lu_.matrixLU();
    const auto& perm = s_lu_.permutationP().indices();
    for (int k = 0; k < nj; ++k)
      xj_(perm[k]) = rhs_(k);
    for (int j = 0; j + 1 < nj; ++j)
      xj_.segment(j + 1, nj - j - 1) -= xj_(j) * lu.col(j).segment(j + 1, nj - j - 1);
    for (int j = nj - 1; j >= 0; --j)
    {
      xj_(j) *= s_pivot_inverse_(j);
      xj_.head(j) -= xj_(j) * lu.col(j).head(j);
    }
  }
  // x_b = y_b - W_b x_J
  for (const BodyBlock& bb : blocks_)
  {
    const int* rows = rows_.data() + bb.rows;
    const double* y = y_.data() + bb.y_start;
    if (bb.joins == 0)
    {
      for (int r = 0; r < bb.size; ++r)
        x(rows[r]) = y[r];
      continue;
    }
    const int* jl = jidx_.data() + bb.j_start;
    for (int c = 0; c < bb.joins; ++c)
      v[c] = xj_(jl[c]);
    multiplyColumns(wx_.data() + bb.w_start, bb.ld, bb.joins, v, t);
    for (int r = 0; r < bb.size; ++r)
      x(rows[r]) = y[r] - t[r];
  }
  for (int k = 0; k < nj; ++k)
    x(joining_[k]) = xj_(k);
}

}  // namespace active_tensegrity::core
