/// An approximate solver of the dynamic Newton matrix: the bodies' own blocks and the constraint rows,
/// without the couplings between bodies in the force block (docs/design.md, "The body coordinates as a test oracle").
#pragma once

#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>
#include <Eigen/SparseCore>

#include "active_tensegrity/core/linalg/static_lu.h"

namespace active_tensegrity::core
{
/// Solves A0 x = b for the matrix
///
///     A = [H  Gt]        A0 = [blockdiag(H_bb)  Gt]
///         [G   0]             [G                 0]
///
/// whose first rows and columns are grouped by body (H_bb: body b's own block of H, every coupling
/// H_bc between two bodies dropped) and whose last rows are constraint rows. A constraint row whose
/// entries (in G and in Gt) touch one body is eliminated with that body: each body's small system
/// K_b = [H_bb Gt_b; G_b 0] over its own rows is inverted. The rows that join bodies (ball joints)
/// are left to their Schur complement S = sum_b G_b K_b^-1 Gt_b, of the size of their number: dense LU up
/// to kDenseSchurRows of them, else StaticPivotLU in an AMD order (S is about G M^-1 G^T, whose pivots
/// need no search). A solve then costs a few small dense products per body and one solve with S, against
/// the triangular solves of the whole matrix, whose factors are filled by the couplings that A0 drops
/// (the sliding cables of the tower, the cables and contacts of a lattice).
///
/// In dynamics H = M + gamma' h C + beta' h^2 K: at small steps the mass dominates and A0 is close to
/// A (on the tower at the paper's step, I - A0^-1 A has a spectral radius of 0.005-0.15 over the fold).
/// Where it is not, modified Newton's contraction test sees it (SparseLinearSolver::distrustApproximation).
/// Bodies whose coupling in H is strong (touching steel struts: a contact tangent as large as the mass term)
/// are joined into one block with that coupling kept (kGroupCoupling), up to kMaxGroupColumns coordinates;
/// the groups follow the values of each factorized matrix (a change of groups is a new analysis). With
/// variable steps they are off (allowGroups): H's couplings against its mass terms grow as h^2, so the
/// groups followed the step size (219 analyses on the tower's adaptive fold) and served worse than single
/// bodies there (4.19 against 3.93 Newton iterations per step).
/// A check of A0 against A on one vector (A0^-1 A 1 against 1, as the static pivots have) says nothing
/// here: its largest error reached 3.8 on the tower while the iteration contracted at 0.15, the multipliers'
/// part of the vector weighing unlike the accelerations'.
class BodyBlockSolver
{
public:
  /// body_sizes: the sizes of the bodies' column groups, from the first column on; the columns after
  /// them are the constraint rows'.
  explicit BodyBlockSolver(std::vector<int> body_sizes = {});

  /// False when A0 cannot be formed or solved here: `a` not compressed, a constraint row touching no body,
  /// a nonzero entry between two constraint rows, a body system of more than kMaxBodyRows rows, a body
  /// system or dense Schur complement with a reciprocal condition below 1e-13, a sparse one with a zero
  /// pivot.
  bool factorize(const Eigen::SparseMatrix<double>& a);
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) const;
  /// Whether strongly coupled bodies may be solved together (default true); false: one block per body.
  /// Variable steps turn it off (DynamicsSolver::setVariableSteps): their couplings move with the step.
  void allowGroups(bool allow)
  {
    groups_allowed_ = allow;
  }
  bool groupsAllowed() const
  {
    return groups_allowed_;
  }

  /// The rows that join bodies (the Schur complement's size) in the last analyzed pattern.
  int joiningRows() const
  {
    return static_cast<int>(joining_.size());
  }
  /// Symbolic analyses so far (one per pattern).
  int analyses() const
  {
    return analyses_;
  }
  /// Bodies solved together in the last analyzed pattern (in groups of more than one body).
  int groupedBodies() const
  {
    return grouped_bodies_;
  }
  /// Each body's group in the last analyzed pattern, named by its smallest body.
  const std::vector<int>& groups() const
  {
    return group_of_body_;
  }
  /// Up to this many joining rows their Schur complement is factorized densely.
  static constexpr int kDenseSchurRows = 64;
  /// A body's coordinates and the rows it owns (a strut: 7, its quaternion norm and up to 8 more).
  static constexpr int kMaxBodyRows = 16;
  /// Two bodies whose coupling in H reaches this share of the smaller of their diagonals (largest entries
  /// compared) are solved together, their coupling kept (steel struts touching on the lattices; a lower share
  /// regroups more often, each regrouping a new analysis; the tower's contacts stay below it) ...
  static constexpr double kGroupCoupling = 0.2;
  /// ... while the group has at most this many coordinates (four struts), its system at most kMaxGroupRows.
  static constexpr int kMaxGroupColumns = 28;
  static constexpr int kMaxGroupRows = 48;

private:
  bool analyze(const Eigen::SparseMatrix<double>& a);
  bool samePattern(const Eigen::SparseMatrix<double>& a) const;
  /// The groups `a`'s values ask for (group_of_body_wanted_): strongly coupled bodies joined, strongest first.
  /// analyzed_pattern: `a` has the analyzed pattern, whose entries that matter here are listed.
  void chooseGroups(const Eigen::SparseMatrix<double>& a, bool analyzed_pattern);

  std::vector<int> body_sizes_;
  std::vector<int> body_of_column_;
  std::vector<int> group_of_body_;         // the analyzed pattern's groups (a group: its smallest body)
  std::vector<int> group_of_body_wanted_;  // the current values'
  int grouped_bodies_ = 0;
  std::vector<double> body_diagonal_;  // work of chooseGroups
  std::vector<std::pair<double, std::pair<int, int>>> couplings_;
  bool groups_allowed_ = true;
  int n_ = 0, nq_ = 0;
  int analyses_ = 0;
  bool usable_ = false;                 // the analyzed pattern can be solved this way
  std::vector<int> a_outer_, a_inner_;  // the analyzed pattern
  // where the stored entries of A go (position in A's values, slot): a body system's entries (into kx_), G's on
  // the joining rows (into gx_), Gt's on them (into gtx_); the entries between constraint rows (must be zero);
  // every other entry (a coupling between bodies) is dropped
  struct Entry
  {
    int p = 0;
    int slot = 0;
  };
  std::vector<Entry> body_entries_, g_entries_, gt_entries_;
  std::vector<int> constraint_block_entries_;
  // what chooseGroups reads in the analyzed pattern: H's diagonal entries (position, body) and those above
  // it that couple two bodies
  struct Coupling
  {
    int p = 0;
    int a = 0;
    int b = 0;
  };
  std::vector<std::pair<int, int>> diagonal_entries_;
  std::vector<Coupling> coupling_entries_;
  struct BodyBlock
  {
    // (the matrices a solve multiplies by are stored by columns of whole packs of rows, the padding zero: ld, g_ld)
    int size = 0;        // n_b + the rows it owns
    int ld = 0;          // size rounded up to whole packs
    int n = 0;           // n_b
    int k_start = 0;     // K_b in kx_ (column-major size x size)
    int kinv_start = 0;  // its inverse in kinv_ (column-major, ld x size)
    int rows = 0;        // its rows in rows_ (global indices: the body's columns, then its own constraint rows)
    int joins = 0;       // number of joining rows it takes part in
    int g_ld = 0;        // joins rounded up to whole packs
    int j_start = 0;     // their positions (in joining_) in jidx_
    int g_start = 0;     // G on them (column-major, g_ld x n) in gx_, Gt (n x joins, column-major) in gtx_
    int w_start = 0;     // W_b = K_b^-1 [Gt_b; 0] (column-major, ld x joins) in wx_
    int y_start = 0;     // the body's part of the work vector y_ (ld entries)
  };
  std::vector<BodyBlock> blocks_;
  std::vector<int> rows_;     // global index of each body system's rows
  std::vector<int> jidx_;     // joining-row positions per body
  std::vector<int> joining_;  // global rows that join bodies
  // values (Eigen's storage: aligned alike in every run, so Eigen's vectorized products on them sum in the same
  // order and a run repeats to the last bit; heap buffers of std::vector start at any 16 bytes)
  Eigen::VectorXd kx_, kinv_, gx_, gtx_, wx_;
  std::vector<Eigen::PartialPivLU<Eigen::MatrixXd>> body_lu_;  // one per size of body system (no allocation
                                                               // once each size was factorized)
  Eigen::MatrixXd s_;                                          // dense S
  Eigen::PartialPivLU<Eigen::MatrixXd> s_lu_;
  Eigen::VectorXd s_pivot_inverse_;  // 1 / U's diagonal of s_lu_
  bool sparse_schur_ = false;
  Eigen::SparseMatrix<double> s_sparse_;  // sparse S, and where each body's G_b W_b goes in its values
  std::vector<int> s_slot_;               // (per body, joins x joins column-major, from s_start)
  std::vector<int> s_start_;
  StaticPivotLU s_static_;
  mutable Eigen::VectorXd y_, rhs_, xj_, v_, t_;  // work of solve()
};

}  // namespace active_tensegrity::core
