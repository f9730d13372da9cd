/// The constraint kinds (model.h, struct Constraint): per kind, its rows' value, Jacobian, reaction,
/// second derivative and right-hand sides, in one place. System (mechanics.h) loops over its constraints
/// and reaches a kind's functions through constraintKind() alone, so a new kind is one set of functions
/// here and one case there.
///
/// Rows of one constraint, with q the coordinates, lambda its multipliers, s(t) an actuation value:
///
/// kPoints (ball joints, ground pins, rheonomic actuation): for each direction d_k
///   Phi_k   = d_k . (p_a - p_b) - offset_k - s(t)      (s only when actuator >= 0; p_b the ground
///                                                      when b.body < 0)
///   Phi_q   = d_k^T (B_a - B_b)                         (B_P = dp/dq, kinematics.h)
///   d(Phi_q^T lambda)/dq = G(u_a, w) - G(u_b, w) on the orientation blocks of struts,
///             with w = sum_k lambda_k d_k and G(u, f) = d(B_Theta(Theta, u)^T f)/dTheta (rotation.h)
///   -Phi_t  = s_dot;   gamma = -d_k . (B_Theta(Theta_dot_a, u_a) Theta_dot_a - (same for b)) + s_ddot
///
/// kQuatNorm (a strut's Euler parameters stay unit):
///   Phi = Theta . Theta - 1,  Phi_q = 2 Theta^T,  d(Phi_q^T lambda)/dq = 2 lambda I_4,
///   -Phi_t = 0,  gamma = -2 Theta_dot . Theta_dot
///
/// kSpinLock (statics: a strut's spin about its own axis, (conj(Theta0) x Theta)_z = 0):
///   Phi = a . Theta,  Phi_q = a^T (constant),  d(Phi_q^T lambda)/dq = 0,  -Phi_t = 0,  gamma = 0
///
/// Every kind is at most quadratic in Theta, so the lambda-Hessian does not depend on q.
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/oracle/block_sparse.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/model/model.h"

namespace active_tensegrity::core
{
/// The rows of one constraint inside a global vector (phi, lambda, rhs): c.rows() numbers.
using ConstraintRows = Eigen::Ref<Eigen::VectorXd>;
using ConstConstraintRows = Eigen::Ref<const Eigen::VectorXd>;

/// The bodies whose coordinates a constraint's rows depend on (at most two; ground ends left out).
struct ConstraintBodies
{
  std::array<int, 2> body{ { -1, -1 } };
  int count = 0;
};

/// Rows a kPoints constraint may have (a ball joint has 3); check() refuses more.
constexpr int kMaxPointRows = 6;

/// The kPoints rows' directions and offsets of every constraint of a System, one after another.
struct ConstraintTables
{
  std::vector<Vec3> directions;
  std::vector<double> offsets;
};

/// A constraint as a residual reads it (System keeps one per constraint): its points as slots with their
/// bodies' offsets, a strut's Theta offset, its rows' directions and offsets in the System's tables. A
/// residual's loop thus reads two contiguous tables instead of the model's bodies and each Constraint's own
/// vectors (on the tower the constraints' share of a step fell by half).
struct ConstraintSlot
{
  Constraint::Kind kind = Constraint::Kind::kPoints;
  int row = 0;  // the first row in phi and lambda
  int rows = 0;
  int actuator = -1;                 // as Constraint::actuator
  int direction = 0;                 // kPoints: the first of its rows in ConstraintTables
  int theta = 0;                     // kQuatNorm, kSpinLock: the first coordinate of the strut's Theta in q
  PointSlot a, b;                    // kPoints
  Vec4 coefficients = Vec4::Zero();  // kSpinLock
};

/// The slot of constraint c whose rows start at `row`; its kPoints rows appended to `tables`.
ConstraintSlot constraintSlot(const Model& model, const Constraint& c, int row, ConstraintTables& tables);

/// The functions of one constraint kind. `group` is the constraint's block row in the Newton matrix
/// (BlockSparseMatrix groups: one per body, then one per constraint).
struct ConstraintKindFunctions
{
  /// Refuses a constraint the functions cannot evaluate (std::invalid_argument).
  void (*check)(const Constraint& c);
  ConstraintBodies (*bodies)(const Constraint& c);
  /// Phi(q, t) into its rows of phi.
  void (*value)(const ConstraintSlot& c, const ConstraintTables& t, const Eigen::VectorXd& q, const ActuationValues& u,
                Eigen::VectorXd& phi);
  /// Adds Phi_q into the blocks (group, body) and its transpose into (body, group).
  void (*addJacobian)(const Model& model, const Constraint& c, int group, const Eigen::VectorXd& q,
                      BlockSparseMatrix& jac);
  /// Adds Phi_q^T lambda (lambda: every constraint's, the slot's from its row on) into out (size nq).
  void (*addForce)(const ConstraintSlot& c, const ConstraintTables& t, const Eigen::VectorXd& q,
                   const Eigen::VectorXd& lambda, Eigen::VectorXd& out);
  /// Adds weight * d(Phi_q^T lambda)/dq into the body blocks of jac.
  void (*addLambdaHessian)(const Model& model, const Constraint& c, const Eigen::VectorXd& q,
                           ConstConstraintRows lambda, BlockSparseMatrix& jac, double weight);
  /// -Phi_t, the right-hand side of Phi_q qd = -Phi_t.
  void (*velocityRhs)(const Constraint& c, const ActuationValues& u, ConstraintRows rhs);
  /// gamma, the right-hand side of Phi_q qdd = gamma.
  void (*accelerationRhs)(const Model& model, const Constraint& c, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                          const ActuationValues& u, ConstraintRows rhs);
};

/// The functions of one kind: the one place where a constraint's kind is switched on.
const ConstraintKindFunctions& constraintKind(Constraint::Kind kind);

}  // namespace active_tensegrity::core
