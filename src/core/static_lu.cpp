#include "active_tensegrity/core/static_lu.h"

#include <cmath>

#include <Eigen/OrderingMethods>

namespace active_tensegrity::core
{
void StaticPivotLU::analyzePattern(const Eigen::SparseMatrix<double>& a)
{
  n_ = a.rows();
  const int n = static_cast<int>(n_);
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> amd;
  Eigen::AMDOrdering<int> ordering;
  ordering(a, amd);
  perm_ = amd.inverse();  // as Eigen's SimplicialLDLT: the permuted matrix is P A P^T with P = amd^-1
  c_ = perm_ * a * perm_.transpose();
  c_.makeCompressed();
  // elimination tree and column counts of L from the upper part of column k (rows i < k)
  parent_.assign(n, -1);
  flag_.assign(n, -1);
  lnz_.assign(n, 0);
  for (int k = 0; k < n; ++k)
  {
    flag_[k] = k;
    for (Eigen::SparseMatrix<double>::InnerIterator it(c_, k); it; ++it)
    {
      int i = static_cast<int>(it.row());
      if (i >= k)
        continue;
      for (; flag_[i] != k; i = parent_[i])
      {
        if (parent_[i] == -1)
          parent_[i] = k;
        ++lnz_[i];
        flag_[i] = k;
      }
    }
  }
  lp_.assign(n + 1, 0);
  for (int k = 0; k < n; ++k)
    lp_[k + 1] = lp_[k] + lnz_[k];
  li_.assign(lp_[n], 0);
  lx_.assign(lp_[n], 0.0);
  ux_.assign(lp_[n], 0.0);
  d_.resize(n);
  pattern_.assign(n, 0);
  y_.setZero(n);
  w_.setZero(n);
}

bool StaticPivotLU::factorize(const Eigen::SparseMatrix<double>& a)
{
  const int n = static_cast<int>(n_);
  c_ = perm_ * a * perm_.transpose();
  ct_ = c_.transpose();
  for (int k = 0; k < n; ++k)
  {
    // y: column k of C above the diagonal (-> U(:, k) D), w: row k left of it (-> D L(k, :)^T)
    int top = n;
    flag_[k] = k;
    lnz_[k] = 0;
    for (Eigen::SparseMatrix<double>::InnerIterator it(c_, k); it; ++it)
    {
      int i = static_cast<int>(it.row());
      if (i > k)
        continue;
      y_[i] += it.value();
      int len = 0;
      for (; flag_[i] != k; i = parent_[i])
      {
        pattern_[len++] = i;
        flag_[i] = k;
      }
      while (len > 0)
        pattern_[--top] = pattern_[--len];
    }
    for (Eigen::SparseMatrix<double>::InnerIterator it(ct_, k); it; ++it)
      if (it.row() < k)
        w_[it.row()] += it.value();
    d_[k] = y_[k];
    y_[k] = 0.0;
    for (; top < n; ++top)
    {
      const int i = pattern_[top];
      const double yi = y_[i];
      const double wi = w_[i];
      y_[i] = 0.0;
      w_[i] = 0.0;
      const int p2 = lp_[i] + lnz_[i];
      int p = lp_[i];
      for (; p < p2; ++p)
      {
        y_[li_[p]] -= lx_[p] * yi;  // L's column i
        w_[li_[p]] -= ux_[p] * wi;  // U's row i
      }
      const double l_ki = wi / d_[i];
      d_[k] -= l_ki * yi;
      li_[p] = k;
      lx_[p] = l_ki;
      ux_[p] = yi / d_[i];
      ++lnz_[i];
    }
    if (d_[k] == 0.0 || !std::isfinite(d_[k]))
    {
      y_.setZero();
      w_.setZero();
      return false;
    }
  }
  return true;
}

void StaticPivotLU::solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
{
  const int n = static_cast<int>(n_);
  t_ = perm_ * b;
  for (int j = 0; j < n; ++j)  // L
    for (int p = lp_[j]; p < lp_[j + 1]; ++p)
      t_[li_[p]] -= lx_[p] * t_[j];
  t_.array() /= d_.array();
  for (int j = n - 1; j >= 0; --j)  // U, by its rows
    for (int p = lp_[j]; p < lp_[j + 1]; ++p)
      t_[j] -= ux_[p] * t_[li_[p]];
  x = perm_.transpose() * t_;
}

}  // namespace active_tensegrity::core
