/// Struts in natural (nodal) coordinates: the unknowns are the positions of the free nodes (strut ends and point
/// masses), a strut is the pair of its end nodes with one row |r_b - r_a|^2 = L^2, and its kinetic energy
///   T = 1/2 m |(v_a + v_b)/2|^2 + 1/2 (J_t / L^2) |v_b - v_a|^2
/// (translation plus rotation about its centre, J_t the transverse moment of inertia about the centre) gives a
/// constant mass matrix: per strut the 6x6 block [d I, o I; o I, d I] with d = m/4 + J_t/L^2, o = m/4 - J_t/L^2.
/// Struts that share a node share its coordinates (no ball-joint rows), pinned nodes have none, driven nodes
/// follow their actuator, and point masses are nodes with mass. A strut's spin angle about its own axis is not a
/// coordinate: no force has stiffness there.
///
/// Strut contact acts on the axis segments between the nodes with the law of contact.h (crossing-angle Hertz
/// stiffness, cores, Lankarani-Nikravesh damping, modified Coulomb friction); the ground's spheres sit at nodes.
/// The contact points are material points of each strut moving with its angular velocity
/// w = u x u_dot / L^2 + w_s e (u = r_b - r_a, e = u / L): in a scene with friction each strut has a spin rate w_s
/// about its axis, with the axial moment of inertia J_a as its (constant) mass. An axisymmetric strut's spin obeys
/// J_a w_s_dot = (axial moment) exactly, and it acts on the transverse motion through the gyroscopic couple of
/// -J_a w_s e_dot. No force depends on the spin angle, which is not tracked. The tangents are exact: forward-mode
/// automatic differentiation of the same kernels (natural.cpp).
///
/// The package's dynamics (DynamicsSolver and AdaptiveStepper in dynamics.h run it on a State): the scene's point
/// loads and forces from outside (on strut axes and point masses), Newmark or generalized-alpha at fixed or adaptive
/// steps (error, onset and energy control). StaticSolver (statics.h) is statics built on its static
/// residual and Jacobian (no spin locks: a strut's spin is not a coordinate).
#pragma once

#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>

#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/contact/broad_phase.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/linalg/dense_lu.h"
#include "active_tensegrity/core/model/actuation_law.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/linalg/static_lu.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::core
{
struct NaturalNode
{
  enum class Kind
  {
    kFree,
    kFixed,
    kDriven
  };
  Kind kind = Kind::kFree;
  Vec3 position0 = Vec3::Zero();  // m, at the scene's start
  int actuator = -1;              // kDriven: the actuator that moves it along `direction` by its value
  Vec3 direction = Vec3::Zero();
  int column = -1;  // kFree: its first coordinate
};

struct NaturalStrut
{
  int a = -1, b = -1;  // nodes at the body's -L/2 and +L/2 ends
  int body = -1;
  int spin = -1;        // the column of its spin rate about its axis (scenes with friction), or -1
  double length = 0.0;  // m
  double radius = 0.0;  // m (outermost layer)
};

/// A row against the ground on a free node: direction . r - offset - s(t) = 0 (s the actuator's value, or 0): a
/// partial pin or an unguided drive.
struct NaturalRow
{
  int node = -1;
  Vec3 direction = Vec3::Zero();
  double offset = 0.0;
  int actuator = -1;
};

/// A contact of the natural coordinates: a checked strut pair (nodes a, b of each strut) or a sphere on the ground
/// (the strut's nodes a and b with the sphere at one of them, or a point mass's node). Made per slot when asked
/// (naturalContactSlot): a scene with `pairs: auto` has a slot for every two struts, and nothing of that size is built.
struct NaturalContactSlot
{
  int slot = -1;  // the model's contact slot (contact.h)
  bool ground = false;
  int nodes[4] = { -1, -1, -1, -1 };
  int struts[2] = { -1, -1 };  // the struts whose spins it turns
  int sphere_end = 0;          // ground: the sphere at nodes[0] (0) or nodes[1] (1)
  // its constants: each strut's (or the sphere's) radius and 1 / length; the pair's stiffnesses at a right angle
  // and the sleeves' thickness (contact.h), or the sphere's stiffness
  double radius[2] = { 0.0, 0.0 };
  double inv_length[2] = { 0.0, 0.0 };
  double stiffness90 = 0.0, core_stiffness90 = 0.0, core_gap = 0.0;
};

/// A force at a point of a strut's axis or at a point mass, shared by the nodes it lies between.
struct NaturalLoad
{
  int nodes[2] = { -1, -1 };
  double weights[2] = { 0.0, 0.0 };  // (1 - s, s) at the fraction s of the axis from nodes[0]; (1, 0) at one node
  Vec3 force = Vec3::Zero();         // N, world frame
};

struct NaturalModel
{
  const Model* model = nullptr;
  std::vector<NaturalNode> nodes;
  std::vector<NaturalStrut> struts;
  std::vector<NaturalRow> rows;                     // after the struts' rows
  std::vector<std::vector<int>> cable_nodes;        // per Model::cables entry: the node of each point
  std::vector<int> strut_of_body;                   // per body: its index in `struts`, or -1
  std::vector<int> node_of_body;                    // per point-mass body: its node, or -1
  int positions = 0;                                // the free nodes' coordinates (3 each), first
  int coordinates = 0;                              // then one spin rate per strut when the scene has friction
  Eigen::SparseMatrix<double> mass;                 // constant, coordinates x coordinates
  Eigen::VectorXd gravity;                          // the weight's generalized force
  std::vector<NaturalLoad> loads;                   // the scene's point loads (Model::loads, at load factor 1)
  std::vector<NaturalContactSlot> ground_contacts;  // per Model::ground_contacts entry (slots after the pairs')
  double floor_sin = 0.0;                           // sin(contact.min_crossing_angle)
};

/// The natural-coordinate description of `model` (positions at model.q0). Throws std::invalid_argument naming what
/// the formulation does not cover (a cable or joint away from a strut end or a point mass, a joint of two bodies at
/// different points).
/// With `spin` false no strut has a spin rate (friction then cannot turn a strut about its axis).
NaturalModel buildNaturalModel(const Model& model, bool spin = true);

/// `load` as the natural coordinates apply it. Throws std::invalid_argument naming the load when its point is off a
/// strut's axis (its moment about the axis would be lost) or away from a point mass. A load on the ground is no load.
NaturalLoad naturalLoad(const NaturalModel& nm, const PointLoad& load);

/// At rest at the scene's start.
NaturalState naturalInitialState(const NaturalModel& nm);

/// The position and velocity of node i at (x, v) under actuation u (inline: every force, contact and output reads them).
inline Vec3 naturalNodePosition(const NaturalModel& nm, int i, const Eigen::VectorXd& x, const ActuationValues& u)
{
  const NaturalNode& n = nm.nodes[static_cast<size_t>(i)];
  if (n.kind == NaturalNode::Kind::kFree)
    return x.segment<3>(n.column);
  if (n.kind == NaturalNode::Kind::kFixed)
    return n.position0;
  return n.position0 + (u.empty() ? 0.0 : u[static_cast<size_t>(n.actuator)].value) * n.direction;
}
inline Vec3 naturalNodeVelocity(const NaturalModel& nm, int i, const Eigen::VectorXd& v, const ActuationValues& u)
{
  const NaturalNode& n = nm.nodes[static_cast<size_t>(i)];
  if (n.kind == NaturalNode::Kind::kFree)
    return v.segment<3>(n.column);
  if (n.kind == NaturalNode::Kind::kFixed)
    return Vec3::Zero();
  return (u.empty() ? 0.0 : u[static_cast<size_t>(n.actuator)].rate) * n.direction;
}

/// The body coordinates of the same configuration (state.h): strut centres and the rotation that takes z to the
/// strut's axis with no spin; point masses at their nodes.
Eigen::VectorXd naturalToBodyCoordinates(const NaturalModel& nm, const Eigen::VectorXd& x, const ActuationValues& u);

/// A State's body poses and its natural coordinates (State::natural). writeBodyPoses writes q and qd from the natural
/// coordinates at s.u (and s.t from theirs): strut centres and velocities, each strut's frame carried from its last
/// pose along the shortest arc onto the new axis and turned by the spin its spin rate integrated since
/// (NaturalState::frame_spin), point masses at their nodes. naturalFromBody forms the natural coordinates of q and qd
/// (nodes at the struts' ends, spin rates from the angular velocities; accelerations and multipliers zero).
/// carriesNaturalOf: whether s carries natural coordinates of nm's layout whose strut centres and point masses are
/// q's (and their velocities qd's) bit for bit, as writeBodyPoses left them.
/// writeBodyPoses is carryBodyFrames (the frames alone, in q's Euler parameters) then writeBodyMotion (the rest, from
/// the frames q carries): a loop that reads the poses at some steps only carries the frames at every step and writes
/// the rest when read, with the same poses as writing them at every step.
void writeBodyPoses(const NaturalModel& nm, State& s);
void carryBodyFrames(const NaturalModel& nm, State& s);
void writeBodyMotion(const NaturalModel& nm, State& s);
void naturalFromBody(const NaturalModel& nm, State& s);
bool carriesNaturalOf(const NaturalModel& nm, const State& s);

/// Contact slot `slot` of the model (a checked strut pair's or a ground contact's).
NaturalContactSlot naturalContactSlot(const NaturalModel& nm, int slot);

/// What one contact reads: its nodes' positions and velocities (NaturalContactSlot::nodes) and the struts' spin rates.
struct NaturalContactInput
{
  Vec3 r[4] = { Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero() };
  Vec3 v[4] = { Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero() };
  double spin[2] = { 0.0, 0.0 };
};
NaturalContactInput naturalContactInput(const NaturalModel& nm, const NaturalContactSlot& c, const Eigen::VectorXd& x,
                                        const Eigen::VectorXd& v, const ActuationValues& u);

/// Contact c with impact speed v0: `force` (14: 3 per node, then the two spins) gets its
/// generalized forces; with `stiffness` and `damping` (14x14) also K = -dF/dr and C = -dF/dv (over the nodes'
/// velocities and the spin rates), exact.
ContactPairState naturalContact(const NaturalModel& nm, const NaturalContactSlot& c, const NaturalContactInput& in,
                                double impact_speed, Eigen::Matrix<double, 14, 1>* force,
                                Eigen::Matrix<double, 14, 14>* stiffness, Eigen::Matrix<double, 14, 14>* damping);

/// Counts of a NaturalSolver's work.
struct NaturalStats
{
  long steps = 0;
  long iterations = 0;
  long factorizations = 0;
  long analyses = 0;               // orderings and symbolic analyses of a sparse Newton matrix (a new pattern)
  long static_pivots = 0;          // sparse Newton matrices factorized with static pivots (the rest: sparse LU)
  long static_pivot_refusals = 0;  // static-pivot factorizations that failed their check (then the sparse LU)
  long contact_evaluations = 0;    // pair evaluations in contact (force, with or without tangents)
  long rejected_error = 0, rejected_onset = 0, rejected_solver = 0, rejected_energy = 0;
  // adaptive steps (advanceTo): accepted, of them at dt_min with their checks still failing, the smallest and largest
  long accepted = 0, at_min_step = 0;
  double h_min = 0.0, h_max = 0.0;
  // wall time (s) in dynamic steps' parts (summary.h's part timers around each): applied forces and their tangents;
  // contact (listing, forces and tangents, the pass-through check, the end's contacts); constraint rows;
  // factorizations; triangular solves
  double forces_time = 0.0, contact_time = 0.0, constraints_time = 0.0, factorization_time = 0.0, solve_time = 0.0;
};

/// Modified Newton's policy in a dynamic step: when the Newton matrix is kept, built anew or distrusted, and how it is
/// factorized. NaturalSolver::tryStep follows it; SolverOptions holds what a scene sets (reuse_jacobian,
/// max_jacobian_age, newton_tolerance, max_iterations).
struct NewtonPolicy
{
  /// A step's iterations from this one on build their own matrix (full Newton).
  int full_newton_from = 8;
  /// A kept matrix is built anew for a step size that differs from its own by more than this share.
  double step_change = 0.25;
  /// ... and once the iteration's contraction rate with it exceeds this (it no longer contracts).
  double contraction = 0.5;
  /// The least contraction rate assumed of a kept matrix when judging the error an increment leaves.
  double rate_floor = 0.05;
  /// Newton matrices up to this size are factorized dense, larger ones sparse.
  int dense_most = 160;
  /// Sparse: static pivots with the constraint rows' diagonal shifted by -static_shift phi^2 / d (phi the rows'
  /// largest entry, d the largest diagonal entry); after a refused factorization, this many use the sparse LU.
  double static_shift = 1e-6;
  int static_pivot_skip = 4;
  /// A static-pivot factorization's check: A 1 solved comes back within static_check of 1 (the contraction rate
  /// modified Newton tolerates), refined within static_refined_check.
  double static_check = 0.5;
  double static_refined_check = 1e-8;
  /// Dense: a kept factorization is inverted (a solve is then one product) while the recent factorizations served on
  /// average at least inverse_solves times their size in solves; the average's weight of the last.
  double inverse_solves = 0.75;
  double solves_average = 0.25;

  /// Whether a step starts with a matrix built anew: none kept, a step size changed, the matrix too old, or the pairs
  /// touching at the start not those it was built with.
  bool rebuildAtStart(bool have, double h, double h_built, int age, int max_age, bool contacts_changed) const
  {
    return !have || std::abs(h - h_built) > step_change * h_built || age >= max_age || contacts_changed;
  }
  /// Whether iteration `it` builds its own matrix (full Newton).
  bool fullNewton(int it, bool reuse_jacobian) const
  {
    return !reuse_jacobian || it >= full_newton_from;
  }
};

/// Index-3 Newmark or generalized-alpha in natural coordinates with modified Newton, by the body solver's rules
/// (dynamics.h): the Newton matrix [M + beta h^2 K + gamma h C, G^T; G, 0] (dense LU up to 160 unknowns, sparse LU
/// above) is kept across steps and built anew for a new step size, after solver.max_jacobian_age steps, when the pairs
/// touching at a step's start change, or when the iteration stops contracting; an iterate is accepted when the error
/// its contraction rate implies is within the tolerance. Newton starts from the accelerations extrapolated through the
/// last three steps. The contacts within a margin are listed through the broad phase and kept until the nodes have
/// moved half of it.
class NaturalSolver
{
public:
  NaturalSolver(const NaturalModel& nm, const SolverOptions& options);

  /// Consistent accelerations and multipliers at s (forces at s.t).
  Summary initialize(NaturalState& s, const ActuationLaw& law);
  /// Forces from outside the scene from s on (each converted by naturalLoad, all before any is applied; on a refusal
  /// nothing changes). The forces jump there, so the integration restarts from s: accelerations and multipliers
  /// consistent with them, Newton's first guess not extrapolated across the jump.
  Summary setExternalLoads(const std::vector<PointLoad>& loads, NaturalState& s, const ActuationLaw& law);

  /// One step of h; on failure s is unchanged.
  Summary tryStep(NaturalState& s, double h, const ActuationLaw& law);
  /// One step of h, halved on failure (at most options.max_step_cuts times); on failure s is at the last good instant.
  Summary step(NaturalState& s, double h, const ActuationLaw& law);
  /// Positions and velocities of s moved onto the constraints under u by the least change in the mass metric (Newton on
  /// the positions to a correction of at most 1e-12 (1 + |x|), then the velocity rows), for a state formed from
  /// elsewhere (body poses, a caller's positions).
  Summary project(NaturalState& s, const ActuationValues& u);
  /// The energy where the last accepted adaptive step ended, and that step's energy check (advanceTo).
  const EnergyPoint& lastEnergy() const
  {
    return start_energy_;
  }
  const StepEnergyCheck& lastEnergyCheck() const
  {
    return last_check_;
  }
  /// Fixed steps of options.dt to t_end (a failed step is halved up to max_step_cuts times), or adaptive steps
  /// when options.adaptive (error, onset and energy control as AdaptiveStepper's). on_step after each.
  Summary advanceTo(NaturalState& s, double t_end, const ActuationLaw& law,
                    const std::function<void(const NaturalState&)>& on_step = {})
  {
    return advance(s, t_end, law, on_step, options_.adaptive);
  }
  /// advanceTo with adaptive steps whatever options.adaptive says.
  Summary advanceAdaptive(NaturalState& s, double t_end, const ActuationLaw& law,
                          const std::function<void(const NaturalState&)>& on_step = {})
  {
    return advance(s, t_end, law, on_step, true);
  }
  /// The adaptive steps' settings (dt, dt_min, dt_max, error_tolerance, onset_depth, energy_tolerance) from `o`, and
  /// a fresh step-size history.
  void setAdaptiveOptions(const SolverOptions& o);

  // ---- statics' parts (StaticSolver, statics.h; velocities zero: contact without damping or friction)
  /// The static residual at (x, lambda) under the actuation values of u, r = [G^T lambda - F; Phi] (the coordinates'
  /// entries, then one per row; a spin rate's entry 0), into staticResidual(); with `tangent` also its Jacobian
  /// [K + sum_k lambda_k Phi_k'', G^T; G, 0] (a spin rate's diagonal the mass scale) for factorizeStatic. The contacts
  /// are listed from x, and listed again when a node has moved further than the listing allows for.
  void assembleStatic(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, const ActuationValues& u, bool tangent);
  const Eigen::VectorXd& staticResidual() const
  {
    return residual_;
  }
  /// Adds mu times the mass matrix to the Jacobian assembleStatic built (Levenberg-Marquardt damping).
  void addStaticMass(double mu);
  /// Factorizes the Jacobian assembleStatic built; false when it is singular (a reciprocal condition below 1e-14 when
  /// dense, a zero pivot when sparse).
  bool factorizeStatic();
  /// The sign of the last factorization's determinant (0: singular).
  int determinantSign();
  /// The Jacobian assembleStatic built, dense (for checks; a lattice's is large).
  Eigen::MatrixXd assembledMatrix() const;
  /// The diagonal of the Jacobian assembleStatic built, and its rows' block G (rows x coordinates).
  Eigen::VectorXd assembledDiagonal() const;
  Eigen::SparseMatrix<double> assembledRows() const;
  /// Solves with the last factorization.
  void solve(const Eigen::VectorXd& rhs, Eigen::VectorXd& out);
  /// The point loads' factor: Model::loads times it (1 unless set).
  void setLoadFactor(double factor)
  {
    load_factor_ = factor;
  }
  /// The slot of the first checked strut pair whose axes passed through each other while the nodes moved in straight
  /// lines from their positions at (x0, u0) to those at (x1, u1), or -1.
  int passedThrough(const Eigen::VectorXd& x0, const ActuationValues& u0, const Eigen::VectorXd& x1,
                    const ActuationValues& u1);
  /// The touching contacts at a static equilibrium x under u (assembleStatic's listing), with their forces.
  void staticContacts(const Eigen::VectorXd& x, const ActuationValues& u, std::vector<ContactPairState>& out);

  /// The applied forces other than contact (weight, cables and springs, the spinning struts' gyroscopic couples) at
  /// (x, v) under u into `force`, and their tangents K = -dF/dx and C = -dF/dv (dense) when asked.
  void appliedForces(const Eigen::VectorXd& x, const Eigen::VectorXd& v, const ActuationValues& u,
                     Eigen::VectorXd& force, Eigen::MatrixXd* stiffness, Eigen::MatrixXd* damping);

  /// Every actuator's force at s under u into `out` (Model::actuators order, N; s the state the last step ended in, or
  /// initialized): along its direction at each node it drives, the reaction that prescribes the node's motion, or a
  /// driven row's multiplier; plus the tension of each cable it pulls in.
  void actuationForces(const NaturalState& s, const ActuationValues& u, std::vector<double>& out);

  /// The energy of s and the powers acting on it (energy.h's account; s the state the last step ended in, or
  /// initialized): translation and rotation of every strut (its spin included) and point mass, cables and contacts,
  /// the weight and the point loads, the drives' power (pulled cables, driven rows and driven nodes), the dampers' and
  /// contacts' dissipation.
  EnergyPoint energyAt(const NaturalState& s, const ActuationValues& u);

  /// The touching contacts at s, the end of the last accepted step (those the solver keeps listed: all within its
  /// margin), with their impact speeds.
  std::vector<ContactPairState> contactsAt(const NaturalState& s) const;
  void contactsAt(const NaturalState& s, std::vector<ContactPairState>& out) const;

  const NaturalStats& stats() const
  {
    return stats_;
  }
  /// Modified Newton's policy the steps follow.
  const NewtonPolicy& policy() const
  {
    return policy_;
  }

private:
  NewtonPolicy policy_;
  /// tryStep's start: the near pairs for the step, Newton's first guess (acc_, lambda_: through the last three step
  /// ends quadratic, through two linear, else the start's) and the predictors c0_, x_pred_, v_pred_.
  void startStep(const NaturalState& s, double h);
  /// tryStep's end once Newton has converged at x_: the step is refused (kPassedThrough) when a strut passed through
  /// another; else its error, the end's contacts and contact memory, and the state written into s.
  Summary endStep(NaturalState& s, double h, double c1);
  Summary advance(NaturalState& s, double t_end, const ActuationLaw& law,
                  const std::function<void(const NaturalState&)>& on_step, bool adaptive);
  void forces(const Eigen::VectorXd& x, const Eigen::VectorXd& v, bool tangents);
  void contactForces(const Eigen::VectorXd& x, const Eigen::VectorXd& v, bool tangents);

  const NaturalModel& nm_;
  const Model& model_;
  SolverOptions options_;
  double beta_, gamma_;
  double alpha_m_ = 0.0, alpha_f_ = 0.0;  // generalized-alpha (0 with Newmark)
  ActuationValues u_;
  /// The Newton matrix's entries as triplets (duplicates summed): M + k_weight K + c_weight C and the rows.
  struct Entries
  {
    std::vector<Eigen::Triplet<double>> triplets;
    Eigen::MatrixXd dense;  // small matrices: summed here instead
    bool to_dense = false;
    double k_weight = 0.0, c_weight = 0.0;
    void clear(int size, bool small)
    {
      triplets.clear();
      to_dense = small;
      if (small)
        dense.setZero(size, size);
    }
    void add(int r, int c, double v)
    {
      if (to_dense)
        dense(r, c) += v;
      else if (v != 0.0)
        triplets.emplace_back(r, c, v);
    }
    void block(int r, int c, const Mat3& m, double w)
    {
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i)
          add(r + i, c + j, w * m(i, j));
    }
    void diagonal(int r, int c, double v)
    {
      for (int i = 0; i < 3; ++i)
        add(r + i, c + i, v);
    }
    /// g at rows r.. of column c and its transpose at row c
    void column(int r, int c, const Vec3& g)
    {
      for (int i = 0; i < 3; ++i)
      {
        add(r + i, c, g(i));
        add(c, r + i, g(i));
      }
    }
    void addMatrix(const Eigen::SparseMatrix<double>& m, double w = 1.0)
    {
      for (int k = 0; k < m.outerSize(); ++k)
        for (Eigen::SparseMatrix<double>::InnerIterator it(m, k); it; ++it)
          add(static_cast<int>(it.row()), static_cast<int>(it.col()), w * it.value());
    }
  };
  /// How a sparse Newton matrix is factorized: with partial pivoting (sparse LU), or with static pivots (faster, the
  /// constraint rows shifted: an approximation, kept for modified Newton) and optionally refined to round-off at
  /// every solve.
  enum class Pivots
  {
    kPartial,
    kStatic,
    kStaticRefined
  };
  /// Factorizes the matrix of `entries_` (size x size): dense when small, else sparse as `pivots` asks (static pivots
  /// fall back to the sparse LU when their check fails); false when singular.
  bool factorize(int size, Pivots pivots = Pivots::kPartial);
  /// The static-pivot factorization of sparse_ and its check; false when refused.
  bool factorizeStaticPivot(bool refined);
  /// A solve with the refined static pivots; false when the refinement does not reach round-off.
  bool solveRefined(const Eigen::VectorXd& rhs, Eigen::VectorXd& out);
  Eigen::VectorXd solve(const Eigen::VectorXd& rhs);

  std::vector<NaturalLoad> external_;  // setExternalLoads
  Eigen::VectorXd f_;                  // applied forces at the iterate
  /// Adds f at node i: to f_ at a free node, to *held_ (when collecting) at a fixed or driven one.
  __attribute__((always_inline)) void addNodeForce(int i, const Vec3& f)
  {
    const int col = nm_.nodes[static_cast<size_t>(i)].column;
    if (col >= 0)
      f_.segment<3>(col) += f;
    else if (held_)
      (*held_)[static_cast<size_t>(i)] += f;
  }
  std::vector<Vec3>* held_ = nullptr;  // forces() collects the fixed and driven nodes' forces here when set
  bool driven_only_ = false;           // forces() then forms only what acts on a driven node (drivenReactions)
  std::vector<char> cable_driven_;     // per cable: it runs through a driven node
  std::vector<Vec3> held_force_;
  // the adaptive steps' energy check: the energy where the step starts, whether contacts touched there
  EnergyPoint start_energy_;
  double start_energy_t_ = 0.0;
  bool start_energy_valid_ = false;
  bool in_contact_ = false;
  ActuationValues u_start_;
  std::vector<double> reaction_along_;  // per driven node: its reaction along its direction (drivenReactions)
  /// The reactions of every driven node at s under u into reaction_along_ (kept for the same state: actuator forces
  /// and the energy account both ask at each step's end).
  void drivenReactions(const NaturalState& s, const ActuationValues& u);
  bool reactions_valid_ = false;
  double reactions_t_ = 0.0;
  long reactions_steps_ = -1;
  Eigen::VectorXd reactions_x_, reactions_v_;
  ActuationValues reactions_u_;
  std::vector<Vec3> pos_, vel_;  // every node's position and velocity at the iterate (forces())
  Entries entries_;
  Eigen::SparseMatrix<double> sparse_;
  Eigen::PartialPivLU<Eigen::MatrixXd> dense_lu_;
  // a dense factorization that serves many solves is inverted (NewtonPolicy::inverse_solves): the solves each
  // factorization served, averaged (exponentially) over the last ones
  Eigen::MatrixXd dense_inverse_;
  bool use_inverse_ = false;
  long solves_since_factor_ = 0;
  double solves_per_factor_ = 0.0;
  Eigen::SparseLU<Eigen::SparseMatrix<double>> sparse_lu_;
  std::vector<int> pattern_outer_, pattern_inner_;  // the pattern of the last sparse matrix
  bool pattern_ready_ = false;                      // ... recorded
  bool lu_analysed_ = false;                        // sparse_lu_ analysed that pattern
  bool pattern_symmetric_ = false;                  // that pattern is symmetric
  // static pivots: their factors (of sparse_, or of symmetric_ where sparse_'s pattern is not symmetric), in use for
  // the last factorization, refined at every solve; the factorizations left to the sparse LU after a refusal; the
  // shifted rows (the constraint rows); the check's and the refinement's work
  StaticPivotLU static_lu_;
  Eigen::SparseMatrix<double> symmetric_;
  bool static_mode_ = false, static_refined_ = false;
  int static_skip_ = 0;
  std::vector<int> shifted_rows_;
  Eigen::VectorXd check_b_, check_x_, refine_r_, refine_d_;
  bool dense_mode_ = true;
  Eigen::VectorXd residual_, rhs_, correction_, acc_, lambda_, x_, v_;
  ActuationValues u_end_, u_onset_;  // an adaptive step's end, and a refused onset's start (advance)
public:
  /// The actuation values of the last step's end (or of the state initialize or energyAt was given).
  const ActuationValues& actuation() const
  {
    return u_;
  }

private:
  Eigen::VectorXd c0_, x_pred_, v_pred_, a_end_;  // a step's predictors and end accelerations (tryStep)
  NaturalState static_state_;                     // assembleStatic's listing state (velocities zero, no contact memory)
  std::vector<Vec3> static_nodes_;                // ... its nodes' positions
  bool static_listed_ = false;                    // whether the listing is assembleStatic's
  Eigen::VectorXd zero_v_;
  double load_factor_ = 1.0;
  bool scaled_ = false;                    // the dense factorization is of the equilibrated matrix (factorizeStatic)
  Eigen::VectorXd row_scale_, col_scale_;  // ... R J C
  Eigen::MatrixXd equilibrated_;
  /// Lists the contacts for a static state x under u_ when a node has moved further from the listing than it allows.
  void listStatic(const Eigen::VectorXd& x);
  NaturalState trial_;  // an adaptive step's trial (advanceTo)
  struct History
  {
    double t = 0.0;
    Eigen::VectorXd a, lambda;
  };
  History history_[2];  // the starts of the last two accepted steps, newest first (Newton's first guess)
  int history_count_ = 0;
  double last_end_t_ = -1.0;
  std::vector<int> touching_, factor_contacts_;  // slots touching at the step's start, and when factorized
  int factor_age_ = 0;                           // steps since the factorization
  double mass_scale_ = 1.0;                      // the mass matrix's largest entry
  double theta_ = 0.0;                           // the largest contraction rate seen with the factorization
  bool theta_known_ = false;
  bool have_lu_ = false;
  double lu_h_ = 0.0;
  /// The listed contacts whose gap at s is within 2 * motion (near_, indices into listed_), with the impact speed
  /// each uses in the step.
  void findNear(const NaturalState& s, double motion);
  /// Modified Newton's acceptance: the increment `scaled` (in tolerances), made with a kept matrix (`kept`: it updates
  /// the largest contraction rate seen with it) or with one built for this step (`fresh`); the error it leaves, in
  /// tolerances. `previous`: the last increment with the same matrix.
  double errorLeft(double scaled, bool kept, bool fresh, double& previous);
  /// Whether the iteration contracts (the largest rate seen with the matrix at most policy_.contraction).
  bool contracting() const
  {
    return !(theta_ > policy_.contraction);
  }
  /// A new factorization: its contraction rate unknown.
  void freshMatrix(double& previous);
  /// The constraint rows at x (rows n.. of residual_: Phi / phi_divisor; its first n entries: G^T lambda) and, with
  /// build, G, G^T and hessian_weight sum_k lambda_k Phi_k'' into entries_; pos_ must hold the nodes at x.
  void constraintRows(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, double phi_divisor,
                      double hessian_weight, bool build);
  /// The slot of the first near strut pair whose axes passed through each other between the step's start and x_, or
  /// -1.
  int firstPassedThrough() const;
  /// The largest distance a node moved between x0 and x1.
  double largestMotion(const Eigen::VectorXd& x0, const Eigen::VectorXd& x1) const;

  /// A contact within the listing margin: its slot's constants, its gap and approach rate where the last accepted step
  /// ended (when the list is unchanged since), and the impact speed the step being solved uses.
  struct Listed
  {
    NaturalContactSlot c;
    double end_gap = 0.0, end_rate = 0.0;
    double step_speed = 0.0;
  };
  std::vector<Listed> listed_;  // ascending by slot
  std::vector<int> near_;       // indices into listed_
  BroadPhase broad_phase_;
  std::vector<int> direct_pairs_;  // the checked pairs' slots when few (checked without the broad phase)
  bool use_broad_phase_ = false;
  std::vector<int> candidates_;
  std::vector<Vec3> listed_nodes_, node_now_;
  double list_margin_ = 0.0;
  long list_version_ = 0;  // listings so far
  double end_t_ = -1.0;
  long end_list_version_ = -1;
  bool have_list_ = false;
  Eigen::VectorXd broad_q_;
  double near_motion_ = 0.0;
  std::vector<Vec3> points_;
  double error_ = 0.0;
  double onset_depth_ = 0.0;
  StepSizeControl control_;  // the adaptive steps' sizes (advanceTo)
  StepEnergyCheck last_check_;
  NaturalStats stats_;
};

}  // namespace active_tensegrity::core
