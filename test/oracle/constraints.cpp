#include "active_tensegrity/oracle/body_kinematics.h"
#include "active_tensegrity/oracle/body_rotation.h"
#include "active_tensegrity/oracle/constraints.h"

#include <stdexcept>
#include <string>

#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::core
{
namespace
{
/// Zero velocities of at least n coordinates, for point kinematics at positions only (per thread: no
/// allocation once a thread has seen its largest model).
const Eigen::VectorXd& zeroVelocities(int n)
{
  thread_local Eigen::VectorXd zero;
  if (zero.size() < n)
    zero = Eigen::VectorXd::Zero(n);
  return zero;
}

/// The position Jacobian B_P of a point on a body (its first nq columns).
PointKinematics positionKinematics(const Model& model, const PointRef& point, const Eigen::VectorXd& q)
{
  return pointKinematics(model, point, q, zeroVelocities(static_cast<int>(q.size())), false);
}

// ---- kPoints: d_k . (p_a - p_b) - offset_k - s(t) ----

// d_k^T B rows of a kPoints constraint for one end
// (at most kMaxPointRows rows and 7 columns: on the stack, no allocation in the step loop)
using PointRows = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxPointRows, 7>;

PointRows pointRows(const Constraint& c, const PointKinematics& k)
{
  PointRows rows(c.rows(), k.nq);
  for (int r = 0; r < c.rows(); ++r)
    rows.row(r) = c.directions[r].transpose() * k.jac.leftCols(k.nq);
  return rows;
}

// sum_k lambda_k d_k: the world force a kPoints constraint applies to end a (and minus it to end b)
Vec3 combinedDirection(const Constraint& c, ConstConstraintRows lambda)
{
  Vec3 w = Vec3::Zero();
  for (int k = 0; k < c.rows(); ++k)
    w += lambda(k) * c.directions[k];
  return w;
}

// calls f(end, sign) for each end of a kPoints constraint that lies on a body: +1 for a, -1 for b
template <class F>
void forEachBodyEnd(const Constraint& c, F&& f)
{
  if (c.a.body >= 0)
    f(c.a, 1.0);
  if (c.b.body >= 0)
    f(c.b, -1.0);
}

void pointsCheck(const Constraint& c)
{
  if (c.rows() > kMaxPointRows)
    throw std::invalid_argument("constraint '" + c.name + "' has " + std::to_string(c.rows()) + " rows; at most " +
                                std::to_string(kMaxPointRows) + " are supported");
}

ConstraintBodies pointsBodies(const Constraint& c)
{
  ConstraintBodies out;
  forEachBodyEnd(c, [&out](const PointRef& end, double) { out.body[out.count++] = end.body; });
  return out;
}

void pointsValue(const ConstraintSlot& c, const ConstraintTables& t, const Eigen::VectorXd& q, const ActuationValues& u,
                 Eigen::VectorXd& phi)
{
  const Vec3 d = slotPosition(c.a, q) - slotPosition(c.b, q);
  const double s = c.actuator >= 0 ? u[c.actuator].value : 0.0;
  for (int k = 0; k < c.rows; ++k)
    phi(c.row + k) = t.directions[c.direction + k].dot(d) - t.offsets[c.direction + k] - s;
}

void pointsJacobian(const Model& model, const Constraint& c, int group, const Eigen::VectorXd& q, BlockSparseMatrix& jac)
{
  forEachBodyEnd(c,
                 [&](const PointRef& end, double sign)
                 {
                   const PointRows rows = sign * pointRows(c, positionKinematics(model, end, q));
                   jac.add(group, end.body, rows);
                   jac.addTransposed(group, end.body, rows);
                 });
}

void pointsForce(const ConstraintSlot& c, const ConstraintTables& t, const Eigen::VectorXd& q,
                 const Eigen::VectorXd& lambda, Eigen::VectorXd& out)
{
  // w = sum_k lambda_k d_k, the world force on end a (minus it on end b)
  Vec3 w = Vec3::Zero();
  for (int k = 0; k < c.rows; ++k)
    w += lambda(c.row + k) * t.directions[c.direction + k];
  addSlotForce(c.a, q, w, out);
  addSlotForce(c.b, q, -w, out);
}

void pointsLambdaHessian(const Model& model, const Constraint& c, const Eigen::VectorXd& /*q*/,
                         ConstConstraintRows lambda, BlockSparseMatrix& jac, double weight)
{
  const Vec3 w = combinedDirection(c, lambda);
  Eigen::Matrix<double, 7, 7> h;
  forEachBodyEnd(c,
                 [&](const PointRef& end, double sign)
                 {
                   if (model.bodies[end.body].kind != BodyKind::kStrut)
                     return;
                   h.setZero();
                   h.bottomRightCorner<4, 4>() = sign * pointHessianTheta(end.local, w);
                   jac.add(end.body, end.body, h, weight);
                 });
}

void pointsVelocityRhs(const Constraint& c, const ActuationValues& u, ConstraintRows rhs)
{
  rhs.setConstant(c.actuator >= 0 ? u[c.actuator].rate : 0.0);
}

void pointsAccelerationRhs(const Model& model, const Constraint& c, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                           const ActuationValues& u, ConstraintRows rhs)
{
  // d^2 p / dt^2 = B qdd + B_Theta(thd) thd
  Vec3 quad = Vec3::Zero();
  forEachBodyEnd(c,
                 [&](const PointRef& end, double sign)
                 {
                   const PointKinematics k = pointKinematics(model, end, q, qd);
                   quad += sign * k.dv_dq.leftCols(k.nq) * qd.segment(model.bodies[k.body].offset, k.nq);
                 });
  const double sdd = c.actuator >= 0 ? u[c.actuator].accel : 0.0;
  for (int k = 0; k < c.rows(); ++k)
    rhs(k) = -c.directions[k].dot(quad) + sdd;
}

// ---- kQuatNorm and kSpinLock: one row on the Euler parameters of one strut ----

void noCheck(const Constraint& /*c*/) {}

ConstraintBodies strutBodies(const Constraint& c)
{
  ConstraintBodies out;
  out.body[0] = c.body;
  out.count = 1;
  return out;
}

// the row's Jacobian, 4 numbers on Theta: 2 Theta for the norm, a for the spin lock
using ThetaRow = Vec4 (*)(const Model& model, const Constraint& c, const Eigen::VectorXd& q);

Vec4 quatNormRow(const Model& model, const Constraint& c, const Eigen::VectorXd& q)
{
  return 2.0 * thetaOf(q, model.bodies[c.body]);
}

Vec4 spinLockRow(const Model& /*model*/, const Constraint& c, const Eigen::VectorXd& /*q*/)
{
  return c.coefficients;
}

template <ThetaRow theta_row>
void thetaRowJacobian(const Model& model, const Constraint& c, int group, const Eigen::VectorXd& q,
                      BlockSparseMatrix& jac)
{
  Eigen::Matrix<double, 1, 7> row = Eigen::Matrix<double, 1, 7>::Zero();
  row.tail<4>() = theta_row(model, c, q);
  jac.add(group, c.body, row);
  jac.addTransposed(group, c.body, row);
}

void quatNormForce(const ConstraintSlot& c, const ConstraintTables& /*t*/, const Eigen::VectorXd& q,
                   const Eigen::VectorXd& lambda, Eigen::VectorXd& out)
{
  out.segment<4>(c.theta) += 2.0 * lambda(c.row) * q.segment<4>(c.theta);  // quatNormRow's 2 Theta
}

void spinLockForce(const ConstraintSlot& c, const ConstraintTables& /*t*/, const Eigen::VectorXd& /*q*/,
                   const Eigen::VectorXd& lambda, Eigen::VectorXd& out)
{
  out.segment<4>(c.theta) += lambda(c.row) * c.coefficients;  // spinLockRow's a
}

void noRhs(const Constraint& /*c*/, const ActuationValues& /*u*/, ConstraintRows rhs)
{
  rhs.setZero();
}

void quatNormValue(const ConstraintSlot& c, const ConstraintTables& /*t*/, const Eigen::VectorXd& q,
                   const ActuationValues& /*u*/, Eigen::VectorXd& phi)
{
  phi(c.row) = q.segment<4>(c.theta).squaredNorm() - 1.0;
}

void quatNormLambdaHessian(const Model& /*model*/, const Constraint& c, const Eigen::VectorXd& /*q*/,
                           ConstConstraintRows lambda, BlockSparseMatrix& jac, double weight)
{
  Eigen::Matrix<double, 7, 7> h = Eigen::Matrix<double, 7, 7>::Zero();
  h.bottomRightCorner<4, 4>() = 2.0 * lambda(0) * Mat4::Identity();
  jac.add(c.body, c.body, h, weight);
}

void quatNormAccelerationRhs(const Model& model, const Constraint& c, const Eigen::VectorXd& /*q*/,
                             const Eigen::VectorXd& qd, const ActuationValues& /*u*/, ConstraintRows rhs)
{
  rhs(0) = -2.0 * thetaOf(qd, model.bodies[c.body]).squaredNorm();
}

void spinLockValue(const ConstraintSlot& c, const ConstraintTables& /*t*/, const Eigen::VectorXd& q,
                   const ActuationValues& /*u*/, Eigen::VectorXd& phi)
{
  phi(c.row) = c.coefficients.dot(q.segment<4>(c.theta));
}

void spinLockLambdaHessian(const Model& /*model*/, const Constraint& /*c*/, const Eigen::VectorXd& /*q*/,
                           ConstConstraintRows /*lambda*/, BlockSparseMatrix& /*jac*/, double /*weight*/)
{
}

void spinLockAccelerationRhs(const Model& /*model*/, const Constraint& /*c*/, const Eigen::VectorXd& /*q*/,
                             const Eigen::VectorXd& /*qd*/, const ActuationValues& /*u*/, ConstraintRows rhs)
{
  rhs.setZero();
}

const ConstraintKindFunctions kPointsFunctions = { pointsCheck,       pointsBodies,         pointsValue,
                                                   pointsJacobian,    pointsForce,          pointsLambdaHessian,
                                                   pointsVelocityRhs, pointsAccelerationRhs };
const ConstraintKindFunctions kQuatNormFunctions = { noCheck,       strutBodies,
                                                     quatNormValue, thetaRowJacobian<quatNormRow>,
                                                     quatNormForce, quatNormLambdaHessian,
                                                     noRhs,         quatNormAccelerationRhs };
const ConstraintKindFunctions kSpinLockFunctions = { noCheck,       strutBodies,
                                                     spinLockValue, thetaRowJacobian<spinLockRow>,
                                                     spinLockForce, spinLockLambdaHessian,
                                                     noRhs,         spinLockAccelerationRhs };
}  // namespace

ConstraintSlot constraintSlot(const Model& model, const Constraint& c, int row, ConstraintTables& tables)
{
  ConstraintSlot slot;
  slot.kind = c.kind;
  slot.row = row;
  slot.rows = c.rows();
  slot.actuator = c.actuator;
  slot.direction = static_cast<int>(tables.directions.size());
  slot.coefficients = c.coefficients;
  if (c.kind == Constraint::Kind::kPoints)
  {
    slot.a = pointSlot(model, c.a);
    slot.b = pointSlot(model, c.b);
    for (int k = 0; k < c.rows(); ++k)
    {
      tables.directions.push_back(c.directions[k]);
      tables.offsets.push_back(c.offsets[k]);
    }
  }
  else
    slot.theta = model.bodies[c.body].offset + 3;
  return slot;
}

const ConstraintKindFunctions& constraintKind(Constraint::Kind kind)
{
  switch (kind)
  {
    case Constraint::Kind::kPoints:
      return kPointsFunctions;
    case Constraint::Kind::kQuatNorm:
      return kQuatNormFunctions;
    case Constraint::Kind::kSpinLock:
      return kSpinLockFunctions;
  }
  throw std::logic_error("unknown constraint kind");
}

}  // namespace active_tensegrity::core
