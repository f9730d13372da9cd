#include "active_tensegrity/oracle/body_kinematics.h"
#include "active_tensegrity/oracle/body_rotation.h"
#include "active_tensegrity/oracle/cable_tangents.h"

#include <array>
#include <cstdlib>
#include <vector>

#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
CableState evaluateCableTangents(const Model& model, const Cable& cable, const Eigen::VectorXd& q,
                                 const Eigen::VectorXd& qd, const ActuationValues& u, bool damping, Eigen::VectorXd* F,
                                 BlockSparseMatrix* jac, double k_weight, double c_weight)
{
  // l = sum_k |p_{k+1} - p_k|; dl/dp_j = w_j = n_{j-1} - n_j (n_k the unit vector of segment k)
  const int m = static_cast<int>(cable.points.size());
  if (!jac)
    return evaluateCable(model, cable, q, qd, u, damping, F);
  // per-thread scratch: no allocation once a thread has seen its longest cable
  thread_local std::vector<PointKinematics> kin;
  if (static_cast<int>(kin.size()) < m)
    kin.resize(m);
  std::array<Vec3, Cable::kMaxPoints> n, dd, w, e;
  std::array<double, Cable::kMaxPoints> seg;
  double length = 0.0, rate = 0.0;
  for (int j = 0; j < m; ++j)
    pointKinematics(model, cable.points[j], q, qd, jac != nullptr, kin[j]);
  for (int k = 0; k + 1 < m; ++k)
  {
    const Vec3 d = kin[k + 1].p - kin[k].p;
    seg[k] = d.norm();
    dd[k] = kin[k + 1].v - kin[k].v;
    // a zero-length segment has no direction and no length to contribute
    n[k] = seg[k] > 0.0 ? Vec3(d / seg[k]) : Vec3::Zero();
    length += seg[k];
    rate += n[k].dot(dd[k]);
  }
  const CableState s = cableLaw(cable, length, rate, u, damping);
  if (s.slack || (!F && !jac))
    return s;
  const double k_axial = s.stiffness;
  const double c = damping ? cable.damping : 0.0;
  const double tension = s.tension;

  // e_j: the part of dl_dot/dq through the turning of the segments, e_j^T B_j summed over points
  for (int j = 0; j < m; ++j)
  {
    w[j] = (j > 0 ? n[j - 1] : Vec3::Zero()) - (j + 1 < m ? n[j] : Vec3::Zero());
    e[j].setZero();
    if (j > 0 && seg[j - 1] > 0.0)
      e[j] += (dd[j - 1] - n[j - 1] * n[j - 1].dot(dd[j - 1])) / seg[j - 1];
    if (j + 1 < m && seg[j] > 0.0)
      e[j] -= (dd[j] - n[j] * n[j].dot(dd[j])) / seg[j];
  }
  // generalized force -T B_j^T w_j on the body of point j
  if (F)
    for (int j = 0; j < m; ++j)
      if (kin[j].body >= 0)
      {
        const Body& b = model.bodies[kin[j].body];
        F->segment(b.offset, b.nq) -= tension * kin[j].jac.leftCols(b.nq).transpose() * w[j];
      }
  if (!jac)
    return s;

  // K = -dF/dq = g^T (k g + c h) + T d2l/dq2 and C = -dF/dqd = c g^T g, with g = dl/dq = sum_j w_j^T B_j,
  // h = dl_dot/dq = sum_j (w_j^T dv_dq_j + e_j^T B_j), and
  // d2l/dq2 = sum_k (B_{k+1} - B_k)^T (I - n_k n_k^T)/l_k (B_{k+1} - B_k) + sum_j G(u_j, w_j)
  // Each pair of points (x, y) on bodies gets one block, added once: the rank-one axial part, the damping
  // part, the strut's point Hessian (x = y) and the segments' geometric stiffness (the segments x and y
  // both end on: x - 1 and x when x = y, min(x, y) when they are neighbours), so that no entry is scattered more
  // than once.
  using Row7 = Eigen::Matrix<double, 1, 7>;
  using Col7 = Eigen::Matrix<double, 7, 1>;
  std::array<Mat3, Cable::kMaxPoints> D;
  for (int k = 0; k + 1 < m; ++k)
    D[k] = seg[k] > 0.0 ? Mat3((tension / seg[k]) * (Mat3::Identity() - n[k] * n[k].transpose())) : Mat3::Zero();
  Eigen::Matrix<double, 7, 7> blk;
  for (int x = 0; x < m; ++x)
  {
    if (kin[x].body < 0)
      continue;
    const int nx = kin[x].nq;
    const Col7 gx = kin[x].jac.transpose() * w[x];
    for (int y = 0; y < m; ++y)
    {
      if (kin[y].body < 0)
        continue;
      const int ny = kin[y].nq;
      const Row7 dy = (k_axial * w[y] + c * e[y]).transpose() * kin[y].jac + c * w[y].transpose() * kin[y].dv_dq;
      blk.noalias() = gx * dy;
      if (x == y)
      {
        Mat3 Dxx = Mat3::Zero();
        if (x > 0)
          Dxx += D[x - 1];
        if (x + 1 < m)
          Dxx += D[x];
        blk.noalias() += kin[x].jac.transpose() * Dxx * kin[x].jac;
        if (model.bodies[kin[x].body].kind == BodyKind::kStrut)
          blk.bottomRightCorner<4, 4>() += tension * pointHessianTheta(cable.points[x].local, w[x]);
      }
      else if (std::abs(x - y) == 1)
        blk.noalias() -= kin[x].jac.transpose() * D[std::min(x, y)] * kin[y].jac;
      blk *= k_weight;
      if (c != 0.0 && c_weight != 0.0)
        blk.noalias() += (c_weight * c) * gx * (kin[y].jac.transpose() * w[y]).transpose();
      jac->add(kin[x].body, kin[y].body, blk.topLeftCorner(nx, ny), 1.0);
    }
  }
  return s;
}

}  // namespace active_tensegrity::core
