#include "active_tensegrity/core/linalg/static_lu.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/OrderingMethods>

namespace active_tensegrity::core
{
void StaticPivotLU::analyzePattern(const Eigen::SparseMatrix<double>& a)
{
  ++analyses_;
  n_ = static_cast<int>(a.rows());
  const int n = n_;
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> amd;
  Eigen::AMDOrdering<int> ordering;
  {
    // on the pattern with every diagonal entry: without those of the rows that store none (a saddle point's constraint
    // rows), Eigen's AMD orders for several times the fill (on a 504-strut lattice's Newton matrix 111 k entries in L
    // against 20 k)
    Eigen::SparseMatrix<double> identity(n, n);
    identity.setIdentity();
    ordering(Eigen::SparseMatrix<double>(a + identity), amd);
  }
  // as Eigen's SimplicialLDLT: the permuted matrix is P A P^T with P = amd^-1, which moves i to perm_[i]
  const Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> p = amd.inverse();
  perm_.assign(p.indices().data(), p.indices().data() + n);

  // A's pattern, and where each of its entries lands: C's upper part by columns, its strict lower part by rows
  a_outer_.assign(n + 1, 0);
  a_inner_.clear();
  std::vector<int> up_count(n, 1), lo_count(n, 0);  // (every column of the upper part has its diagonal)
  for (int j = 0; j < n; ++j)
  {
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it)
    {
      const int i = static_cast<int>(it.row());
      a_inner_.push_back(i);
      const int pi = perm_[i], pj = perm_[j];
      if (pi < pj)
        ++up_count[pj];
      else if (pi > pj)
        ++lo_count[pi];
    }
    a_outer_[j + 1] = static_cast<int>(a_inner_.size());
  }
  up_p_.assign(n + 1, 0);
  lo_p_.assign(n + 1, 0);
  for (int k = 0; k < n; ++k)
  {
    up_p_[k + 1] = up_p_[k] + up_count[k];
    lo_p_[k + 1] = lo_p_[k] + lo_count[k];
  }
  const int up_size = up_p_[n];
  up_i_.assign(up_size, 0);
  lo_i_.assign(lo_p_[n], 0);
  diag_.assign(n, 0);
  std::vector<int> up_next(up_p_.begin(), up_p_.end() - 1), lo_next(lo_p_.begin(), lo_p_.end() - 1);
  for (int k = 0; k < n; ++k)  // the diagonal first in each column
  {
    diag_[k] = up_next[k];
    up_i_[up_next[k]++] = k;
  }
  dest_.assign(a_inner_.size(), 0);
  for (int j = 0; j < n; ++j)
    for (int q = a_outer_[j]; q < a_outer_[j + 1]; ++q)
    {
      const int pi = perm_[a_inner_[q]], pj = perm_[j];
      if (pi == pj)
        dest_[q] = diag_[pj];
      else if (pi < pj)
      {
        dest_[q] = up_next[pj];
        up_i_[up_next[pj]++] = pi;
      }
      else
      {
        dest_[q] = up_size + lo_next[pi];
        lo_i_[lo_next[pi]++] = pj;
      }
    }
  cx_.assign(up_size + lo_p_[n], 0.0);

  // elimination tree, and the reach of each row k of L (its nonzero columns) from C's upper column k
  std::vector<int> parent(n, -1), flag(n, -1), lnz(n, 0);
  rp_.assign(n + 1, 0);
  ri_.clear();
  for (int k = 0; k < n; ++k)
  {
    flag[k] = k;
    for (int q = up_p_[k]; q < up_p_[k + 1]; ++q)
      for (int i = up_i_[q]; flag[i] != k; i = parent[i])
      {
        if (parent[i] == -1)
          parent[i] = k;
        ++lnz[i];
        flag[i] = k;
        ri_.push_back(i);
      }
    std::sort(ri_.begin() + rp_[k], ri_.end());  // ascending is a topological order: L(j, i) != 0 needs j > i
    rp_[k + 1] = static_cast<int>(ri_.size());
  }
  lp_.assign(n + 1, 0);
  for (int k = 0; k < n; ++k)
    lp_[k + 1] = lp_[k] + lnz[k];
  li_.assign(lp_[n], 0);
  rpos_.assign(ri_.size(), 0);
  std::fill(lnz.begin(), lnz.end(), 0);
  for (int k = 0; k < n; ++k)  // rows in increasing order fill each column of L in increasing order
    for (int r = rp_[k]; r < rp_[k + 1]; ++r)
    {
      const int i = ri_[r];
      rpos_[r] = lp_[i] + lnz[i]++;
      li_[rpos_[r]] = k;
    }
  lu_.assign(lp_[n], Pair{ 0.0, 0.0 });
  lrx_.assign(lp_[n], 0.0);
  ux_.assign(lp_[n], 0.0);
  d_.resize(n);
  yw_.assign(n, Pair{ 0.0, 0.0 });
}

bool StaticPivotLU::samePattern(const Eigen::SparseMatrix<double>& a) const
{
  if (a.rows() != n_ || a.cols() != n_ || a.nonZeros() != static_cast<Eigen::Index>(a_inner_.size()))
    return false;
  for (int j = 0; j < n_; ++j)
  {
    int q = a_outer_[j];
    for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it, ++q)
      if (q >= a_outer_[j + 1] || a_inner_[q] != it.row())
        return false;
    if (q != a_outer_[j + 1])
      return false;
  }
  return true;
}

bool StaticPivotLU::factorize(const Eigen::SparseMatrix<double>& a, const std::vector<int>& shifted, double shift)
{
  if (!samePattern(a))
    analyzePattern(a);
  const int n = n_;
  std::fill(cx_.begin(), cx_.end(), 0.0);
  {
    int q = 0;
    for (int j = 0; j < n; ++j)
      for (Eigen::SparseMatrix<double>::InnerIterator it(a, j); it; ++it)
        cx_[dest_[q++]] = it.value();
  }
  for (int r : shifted)
    cx_[diag_[perm_[r]]] += shift;
  const double* up_x = cx_.data();
  const double* lo_x = cx_.data() + up_p_[n];
  for (int k = 0; k < n; ++k)
  {
    // y: column k of C down to the diagonal (-> U(:, k) D), w: row k left of it (-> D L(k, :)^T); the two
    // are solved for together, (y, w) interleaved as are (L, U^T) in lu_: one index, one 128-bit update
    for (int q = up_p_[k]; q < up_p_[k + 1]; ++q)
      yw_[up_i_[q]].first += up_x[q];
    for (int q = lo_p_[k]; q < lo_p_[k + 1]; ++q)
      yw_[lo_i_[q]].second += lo_x[q];
    double dk = yw_[k].first;
    yw_[k].first = 0.0;
    for (int r = rp_[k]; r < rp_[k + 1]; ++r)
    {
      const int i = ri_[r];
      const int end = rpos_[r];  // the slot of L(k, i): column i's entries above it are final
      const double yi = yw_[i].first;
      const double wi = yw_[i].second;
      yw_[i] = { 0.0, 0.0 };
      const Pair* lu = lu_.data();
      const int* li = li_.data();
      Pair* yw = yw_.data();
      for (int p = lp_[i]; p < end; ++p)
      {
        Pair& t = yw[li[p]];
        t.first -= lu[p].first * yi;    // L's column i
        t.second -= lu[p].second * wi;  // U's row i
      }
      const double l_ki = wi / d_[i];
      const double u_ik = yi / d_[i];
      dk -= l_ki * yi;
      lu_[end] = { l_ki, u_ik };
      lrx_[r] = l_ki;
      ux_[end] = u_ik;
    }
    d_[k] = dk;
    if (dk == 0.0 || !std::isfinite(dk))
    {
      std::fill(yw_.begin(), yw_.end(), Pair{ 0.0, 0.0 });
      return false;
    }
  }
  return true;
}

void StaticPivotLU::solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
{
  const int n = n_;
  t_.resize(n);
  for (int i = 0; i < n; ++i)
    t_[perm_[i]] = b[i];
  // both triangles by rows, as gathers: four partial sums break the chain of additions
  const auto gather = [this](const int* index, const double* value, int begin, int end)
  {
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    int p = begin;
    for (; p + 3 < end; p += 4)
    {
      s0 += value[p] * t_[index[p]];
      s1 += value[p + 1] * t_[index[p + 1]];
      s2 += value[p + 2] * t_[index[p + 2]];
      s3 += value[p + 3] * t_[index[p + 3]];
    }
    for (; p < end; ++p)
      s0 += value[p] * t_[index[p]];
    return (s0 + s1) + (s2 + s3);
  };
  for (int k = 0; k < n; ++k)  // L
    t_[k] -= gather(ri_.data(), lrx_.data(), rp_[k], rp_[k + 1]);
  t_.array() /= d_.array();
  for (int j = n - 1; j >= 0; --j)  // U
    t_[j] -= gather(li_.data(), ux_.data(), lp_[j], lp_[j + 1]);
  x.resize(n);
  for (int i = 0; i < n; ++i)
    x[i] = t_[perm_[i]];
}

bool StaticPivotLU::solveRefined(const Eigen::SparseMatrix<double>& a, const Eigen::VectorXd& b, Eigen::VectorXd& x,
                                 Eigen::VectorXd& r, Eigen::VectorXd& d) const
{
  constexpr int kRefineMost = 8;
  constexpr double kRefineRoundOff = 1e-14;
  constexpr double kRefineStalled = 1e-10;
  solve(b, x);
  double previous = std::numeric_limits<double>::infinity();
  for (int k = 0; k < kRefineMost; ++k)
  {
    r = b;
    r.noalias() -= a * x;
    solve(r, d);
    x += d;
    const double size = d.lpNorm<Eigen::Infinity>();
    if (!std::isfinite(size))
      return false;
    if (size <= kRefineRoundOff * x.lpNorm<Eigen::Infinity>())
      return true;
    if (size > 0.5 * previous)
      return previous <= kRefineStalled * x.lpNorm<Eigen::Infinity>();
    previous = size;
  }
  return previous <= kRefineStalled * x.lpNorm<Eigen::Infinity>();
}

}  // namespace active_tensegrity::core
