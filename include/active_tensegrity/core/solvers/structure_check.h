/// Structural diagnostics of a state (docs/physics.md, "Structural diagnostics"): the equilibrium matrix of the
/// structure in the sense of Pellegrino and Calladine (1986), adapted to rigid struts, and the tangent
/// stiffness on the constraint manifold.
///
/// In natural coordinates x (the free nodes' positions: strut ends, point masses; statics' layout, no spin rates), with
/// Phi the rows (one length row per strut, the pins and drives) and G = Phi_x:
///   N      an orthonormal basis of null(G) in the node metric P^T P (N^T P^T P N = I), P = dp/dx the
///          displacements of every node (strut ends, point masses) per coordinate; reduced quantities are then
///          in metres and N/m;
///   C      the compatibility matrix, one row dl_i/dx per tension element (a sliding cable is one member
///          with its total length), taken in the reduced coordinates: C N; A = (C N)^T is the equilibrium matrix;
///   r      rank(C N) (singular values above kRankTolerance times the largest);
///   s      = b - r self-stress states, b the tension elements (StructureReport::tension_members);
///          null(C N), dimension f - r (f = columns of N), the motions that stretch no member to first order;
///   rigid-body modes: the rigid motions of the whole structure (node fields u_i = t + w x x_i) that the
///          constraints allow and that stretch no member, counted by the rank of their node fields;
///   m      = dim null(C N) - rigid-body modes, the infinitesimal mechanisms;
///   K_t    = K + d(G^T lambda)/dx (K = -dF/dx: cables, springs, loads, gravity, static contact),
///          K_r = N^T K_t N symmetrized: the second derivative of the potential energy along the constraint
///          manifold at an equilibrium.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
/// Largest number of coordinates the dense diagnostics (and the modal analysis) take on.
constexpr int kMaxStructureCoordinates = 3000;
/// Relative tolerance of the ranks: singular values below this times the largest count as zero.
constexpr double kRankTolerance = 1e-9;
/// Relative tolerance of positive definiteness: eigenvalues of the reduced stiffness must exceed this times
/// the largest eigenvalue magnitude on the complement of the rigid-body modes (and 1e-9 N/m).
constexpr double kDefinitenessTolerance = 1e-8;

/// The linearization of a model about a state on its constraint manifold (see the header comment).
struct ReducedStructure
{
  Eigen::MatrixXd basis;                 // N, x (natural coordinates, buildNaturalModel(model, false)) x f
  Eigen::SparseMatrix<double> node_map;  // P, 3 n_points x x: the model's nodes first (Model::nodes order), then
                                         // strut ends no node stands at; ground points give zero rows
  int node_rows = 0;                     // rows of P that belong to Model::nodes (3 per node)
  Eigen::MatrixXd compatibility;         // C N, tension elements x f (Model::cables order)
  Eigen::MatrixXd stiffness;             // K_r, f x f, N/m
  Eigen::MatrixXd rigid;                 // f x (rigid-body modes): orthonormal basis of the rigid-body modes
  Eigen::MatrixXd mechanisms;            // f x m: orthonormal basis of the mechanisms (null(C N) minus the rigid modes)
  Eigen::VectorXd lambda;                // the multipliers used (the state's, or least squares)
  double residual = 0.0;                 // N: max norm of -F + G^T lambda with least-squares lambda
  int rank = 0;                          // rank of C N
};

/// The diagnostics of checkStructure.
struct StructureReport
{
  bool checked = false;  // false when refused (too many coordinates): `note` says why
  std::string note;
  int coordinates = 0;       // nq
  int free_coordinates = 0;  // f = dim null(G): the node motions the struts and pins allow
  int members = 0;           // every member: struts + tension_members
  int struts = 0;            // rigid struts
  int tension_members = 0;   // tension elements (cables, springs; a sliding cable counts once): the b of the
                             // equilibrium matrix, whose self-stress states are b - rank
  int rank = 0;              // rank of the equilibrium matrix
  int self_stress_states = 0;
  int mechanisms = 0;
  int rigid_body_modes = 0;
  /// K_r positive definite on the mechanisms (beyond kDefinitenessTolerance); without mechanisms, K_r
  /// positive definite on the complement of the rigid-body modes; and in both cases no negative eigenvalue
  /// (beyond the tolerance) of K_r on the rigid-body modes (an inverted pendulum's swing is one)
  bool prestress_stable = false;
  /// smallest eigenvalue of K_r on the rigid-body modes, N/m: 0 for a free structure, positive for a hanging
  /// one, negative for an inverted pendulum (NaN without rigid-body modes)
  double smallest_rigid_mode_eigenvalue = 0.0;
  /// smallest and largest eigenvalue of K_r on the complement of the rigid-body modes, N/m (NaN when that
  /// complement is empty)
  double smallest_stiffness_eigenvalue = 0.0;
  double largest_stiffness_eigenvalue = 0.0;
  /// tension-only elements carrying no tension at the state: slack, or within 1e-12 (relative) of their free
  /// length, where round-off alone decides whether they are taut
  std::vector<std::string> slack_cables;
  double equilibrium_residual = 0.0;  // N: max norm of -F + G^T lambda with least-squares lambda
};

/// The linearization of `model` about `state` (its natural coordinates when it carries them, else those of q; the
/// multipliers of an equilibrium of the statics at those coordinates, else least-squares ones; u, zero when its size
/// does not match the actuators). Velocities are taken as zero. Throws std::invalid_argument above
/// kMaxStructureCoordinates coordinates, or when a motion the constraints allow moves no node.
ReducedStructure reduceStructure(const Model& model, const State& state);

/// Orthonormal basis (f x (f - rigid-body modes)) of the complement of the rigid-body modes in the reduced
/// coordinates of r.
Eigen::MatrixXd rigidComplement(const ReducedStructure& r);

/// The spectrum of the reduced tangent stiffness K_r of a state on the complement of the rigid-body modes
/// (N/m, the node metric of StructureReport): what a critical point of an equilibrium path is judged by.
struct StiffnessSpectrum
{
  bool computed = false;      // false above `max_coordinates`, or when the state cannot be reduced
  int negative = 0;           // eigenvalues below -tol (the state's index of instability)
  double nearest_zero = 0.0;  // the eigenvalue of least magnitude (NaN with an empty complement)
  double tolerance = 0.0;     // tol: kDefinitenessTolerance times the largest magnitude, at least 1e-9 N/m
};

/// StiffnessSpectrum of `state`; not computed for a model of more than `max_coordinates` coordinates.
StiffnessSpectrum stiffnessSpectrum(const Model& model, const State& state, int max_coordinates);

/// Counts, stability and residual of a state (see StructureReport). Refuses (checked = false, note
/// "skipped: N coordinates, more than the limit of 3000") a model above kMaxStructureCoordinates.
StructureReport checkStructure(const Model& model, const State& state);

/// The size of a structure at q (m): the diagonal of the box around its nodes (Model::nodes, fixed ones
/// included); 0 for a single node. What an error or a drift is judged against ("far above its size").
double structureSize(const Model& model, const Eigen::VectorXd& q);

/// dim null(G) at q (natural coordinates, no spin rates): the node motions the struts and pins leave free.
int freeCoordinates(const Model& model, const Eigen::VectorXd& q);

/// What a run says about its start (runAnalysis, runModal): one warning each when the start is not in
/// equilibrium (force residual above 1e-6 of the largest member force, plus 1e-6 N), when tension elements
/// are slack there (named, the first ten), and when it is not prestress stable (the counts and the smallest
/// stiffness). Nothing for a state the diagnostics skip (above kMaxStructureCoordinates coordinates). A static
/// path that scales its loads is checked with them at its first load factor. With the ground on, one warning per
/// free point mass that has no radius (it does not touch the ground).
std::vector<std::string> startWarnings(const Model& model, const State& state);

}  // namespace active_tensegrity::core
