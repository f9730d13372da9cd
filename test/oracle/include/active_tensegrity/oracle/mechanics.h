/// Kinematics, forces and constraints of a Model, and their assembly into global vectors and a
/// fixed-pattern sparse matrix.
///
/// Sign convention (paper Eq. 60 and 67): the equations of motion are
///   M(q) qdd + Qv(q, qd) - F(q, qd, t) + Phi_q^T lambda = 0,  Phi(q, t) = 0,
/// with F the applied forces (cables, springs, gravity), Qv the quadratic velocity term, and the
/// tangents K = -dF/dq (stiffness) and C = -dF/dqd (damping).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/oracle/body_kinematics.h"
#include "active_tensegrity/oracle/body_contact.h"
#include "active_tensegrity/oracle/block_sparse.h"
#include "active_tensegrity/core/contact/broad_phase.h"
#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/oracle/constraints.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/contact/contact_search.h"
#include "active_tensegrity/oracle/near_slot_cache.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/oracle/slot_values.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::core
{
/// The body coordinates' solvers' counts: StepTimings and their own linear solvers' and Newton policy's.
struct BodyStepTimings : StepTimings
{
  long static_pivot_factorizations = 0;  // factorizations with the approximate static-pivot LU (SparseLinearSolver)
  long body_block_factorizations = 0;    // ... with the approximate body blocks (SparseLinearSolver)
  long reduced_factorizations = 0;       // ... exact, with the one-body rows eliminated (ReducedLinearSolver)
  long full_newton_retries = 0;   // dynamics: steps retried in full Newton after modified Newton ran out of iterations
  long contact_reach_misses = 0;  // dynamics: converged iterates that moved beyond the contact slots' reach
  long fresh_starts = 0;     // dynamics: steps begun with a new matrix because kept ones had diverged (modified Newton)
  long newton_switches = 0;  // dynamics: steps that went on in full Newton when modified Newton did not contract with a
                             // matrix exact at one of their own iterates
  long body_block_distrusts = 0;  // dynamics: body-block matrices that did not contract in the step that built them,
                                  // followed by exact factorizations (SparseLinearSolver::distrustBodyBlocks)
  long body_block_rebuilds = 0;   // dynamics, fixed steps: such matrices that had contracted at first, the iterate
                                  // 100 Newton tolerances or more from where they were built: rebuilt there as body
                                  // blocks
  long static_pivots_kept = 0;    // dynamics: steps that kept a static-pivot matrix though the touching pairs had
                                  // changed, the next factorization being static pivots too (the body blocks paused)
};

/// The equations of one model plus optional extra constraints (e.g. statics' spin locks), with a
/// sparse Jacobian whose pattern is fixed at construction: rows and columns are [q; lambda], one
/// group per body then one per constraint. Not thread-safe (contact scratch): one System per thread.
class System
{
public:
  explicit System(const Model& model, std::vector<Constraint> extra_constraints = {});

  const Model& model() const
  {
    return model_;
  }
  const std::vector<Constraint>& constraints() const
  {
    return constraints_;
  }
  int nq() const
  {
    return model_.nq;
  }
  int nLambda() const
  {
    return n_lambda_;
  }
  int size() const
  {
    return model_.nq + n_lambda_;
  }
  int constraintRow(int c) const
  {
    return constraint_slots_[c].row;
  }

  /// The factor the point loads (Model::loads) are applied with: 1 unless a static path scales them
  /// (analysis.load_factor).
  void setLoadFactor(double factor)
  {
    load_factor_ = factor;
  }
  double loadFactor() const
  {
    return load_factor_;
  }

  /// Forces applied from outside the scene (a push, a disturbance): constant world-frame point forces, like
  /// Model::loads but not scaled by the load factor, in force until replaced. Each call counts in
  /// externalLoadsEpoch() (caches of the energy key on it).
  void setExternalLoads(std::vector<PointLoad> loads)
  {
    external_loads_ = std::move(loads);
    ++external_loads_epoch_;
  }
  const std::vector<PointLoad>& externalLoads() const
  {
    return external_loads_;
  }
  unsigned long externalLoadsEpoch() const
  {
    return external_loads_epoch_;
  }

  /// F(q, qd, u): cables (pulled in by u), springs, gravity, loads (times the load factor), external loads. Adds
  /// k_weight K + c_weight
  /// C into jac when not null.
  void appliedForce(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const ActuationValues& u, Eigen::VectorXd& F,
                    BlockSparseMatrix* jac, double k_weight, double c_weight) const;
  /// Strut contact and ground contact (contact.h) at (q, qd), when enabled: adds the generalized
  /// contact forces into F (not cleared) and k_weight K + c_weight C into jac (when not null). Only the
  /// broad phase's candidates reach the narrow phase. impact_speeds: v_0 per contact slot (dynamics;
  /// may be empty in statics). The pairs' states for output come from activeContacts() (observables.h).
  void contactForce(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const SlotValues& impact_speeds,
                    ContactMode mode, Eigen::VectorXd& F, BlockSparseMatrix* jac, double k_weight,
                    double c_weight) const;
  /// The same for the listed contact slots alone (the caller knows no other slot can touch at q).
  void contactForce(const std::vector<int>& slots, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                    const SlotValues& impact_speeds, ContactMode mode, Eigen::VectorXd& F, BlockSparseMatrix* jac,
                    double k_weight, double c_weight) const;
  /// The first checked pair whose struts passed through each other between q0 and q1 (contact.h,
  /// passedThrough), or -1. Only pairs within reach of each other at q1 (the broad phase with boxes grown
  /// by the largest motion of a strut point between q0 and q1) are judged: a pair that crossed was in
  /// touch at the crossing, so it is never further apart than that motion at q1.
  int firstPassedThrough(const Eigen::VectorXd& q0, const Eigen::VectorXd& q1) const;
  /// The same among the listed contact slots (ground slots skipped): a pair that crossed was in touch at the
  /// crossing, so a list of every pair within twice the largest motion of q0 holds it.
  int firstPassedThrough(const std::vector<int>& slots, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1) const;
  /// "struts 'A' and 'B' passed through each other": the message of status kPassedThrough.
  std::string passedThroughMessage(int pair) const;
  /// Contact slots that can touch at q with boxes grown by margin (m): checked strut pairs (when strut contact is
  /// on), then ground contacts within margin of the ground.
  void contactCandidates(const Eigen::VectorXd& q, double margin, std::vector<int>& out) const;
  /// The contact slots within 2 reach (m) of touching at q (nearContactSlots above; `known_gap` as there).
  void nearContacts(const Eigen::VectorXd& q, double reach, std::vector<int>& out,
                    const SlotValues* known_gap = nullptr) const;
  /// M(q) qdd + Qv(q, qd). Adds m_weight M + k_weight d(M qdd + Qv)/dq + c_weight dQv/dqd into jac.
  void inertialForce(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                     Eigen::VectorXd& out, BlockSparseMatrix* jac, double m_weight, double k_weight,
                     double c_weight) const;
  /// Mass matrix M(q) into jac (weighted).
  void addMass(const Eigen::VectorXd& q, BlockSparseMatrix& jac, double weight) const;
  /// Phi(q, t) with actuation values u; with driven_only, the rows of driven constraints (those of an actuator)
  /// and zeros elsewhere (the only rows that depend on u).
  void constraintValue(const Eigen::VectorXd& q, const ActuationValues& u, Eigen::VectorXd& phi,
                       bool driven_only = false) const;
  /// Phi_q^T lambda.
  void constraintForce(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, Eigen::VectorXd& out) const;
  /// Adds Phi_q (rows of lambda, columns of q) and its transpose into jac.
  void addConstraintJacobian(const Eigen::VectorXd& q, BlockSparseMatrix& jac) const;
  /// Adds weight * d(Phi_q^T lambda)/dq into jac.
  void addLambdaHessian(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, BlockSparseMatrix& jac,
                        double weight) const;
  /// The right-hand side of Phi_q qd = -Phi_t.
  void velocityRhs(const ActuationValues& u, Eigen::VectorXd& rhs) const;
  /// The right-hand side of Phi_q qdd = gamma (acceleration-level constraint).
  void accelerationRhs(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const ActuationValues& u,
                       Eigen::VectorXd& rhs) const;
  /// Phi_q as a dense matrix (tests and small checks only).
  Eigen::MatrixXd constraintJacobianDense(const Eigen::VectorXd& q) const;

  /// Kinetic and potential energy (J). The potential includes every contact's elastic energy when contact is
  /// enabled (contactElasticEnergy: Hertz's is exact while the crossing angle, hence K, stays put).
  double kineticEnergy(const Eigen::VectorXd& q, const Eigen::VectorXd& qd) const;
  double potentialEnergy(const Eigen::VectorXd& q, const ActuationValues& u = {}) const;

  /// A fresh matrix with this system's fixed pattern (zero values); contactForce() adds the blocks of
  /// strut pairs in contact to it as they are needed (BlockSparseMatrix::reserve).
  BlockSparseMatrix makeMatrix() const
  {
    return pattern_;
  }

private:
  /// Adds a world-frame force at a point of a body into F, and its stiffness (a strut's orientation) into jac.
  void addPointForce(const PointRef& point, const Vec3& force, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                     Eigen::VectorXd& F, BlockSparseMatrix* jac, double k_weight) const;
  int bodyGroup(int body) const
  {
    return body;
  }
  int constraintGroup(int c) const
  {
    return static_cast<int>(model_.bodies.size()) + c;
  }
  /// Calls f(constraint, its kind's functions, first row, group) for every constraint.
  template <class F>
  void forEachConstraint(F&& f) const;

  const Model& model_;
  std::vector<Constraint> constraints_;
  std::vector<ConstraintSlot> constraint_slots_;  // the constraints as residuals read them, with their rows
  ConstraintTables constraint_tables_;            // their kPoints rows' directions and offsets
  int n_lambda_ = 0;
  BlockSparseMatrix pattern_;
  BroadPhase broad_phase_;
  Eigen::VectorXd zero_q_;               // zero velocities (for positions-only point kinematics)
  std::vector<PointSlot> cable_points_;  // every cable's points in one table, cable by cable
  std::vector<int> cable_first_;         // each cable's first entry in it
  double load_factor_ = 1.0;
  std::vector<PointLoad> external_loads_;
  unsigned long external_loads_epoch_ = 0;
  mutable std::vector<int> candidates_;  // scratch of contactForce
  mutable NearSlotCache near_slots_;     // of nearContacts
  mutable ContactContribution contribution_;
  mutable BodyFrames frames_;        // scratch of appliedForce without tangents
  mutable PointForceSum point_sum_;  // of appliedForce without tangents
};

/// Generalized inertia of one strut: the 4x4 rotational mass 4 L^T J L.
Mat4 rotationalMass(const Body& body, const Vec4& theta);

}  // namespace active_tensegrity::core
