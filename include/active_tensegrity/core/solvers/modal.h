/// Natural modes about an equilibrium (docs/physics.md, "Modal analysis"): the constrained generalized
/// eigenproblem
///   K_r phi = omega^2 M_r phi,   K_r = N^T K_t N,   M_r = N^T M N,
/// in the reduced coordinates of structure_check.h (N an orthonormal basis of the motions the constraints and
/// the spin locks allow, in the node metric), K_t the tangent stiffness with its geometric part (prestress,
/// loads, gravity, the constraints' curvature through the multipliers, static contact), M the mass matrix
/// (System::addMass). The mode's coordinates are dq = N phi. Rigid-body modes come out at omega^2 = 0 when
/// nothing resists them (gravity does, for a pendulum).
#pragma once

#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::core
{
/// Eigenvalues below this times the largest eigenvalue magnitude are round-off: reported as exactly 0.
constexpr double kZeroEigenvalue = 1e-9;
/// Largest analysis.modes a scene may ask for.
constexpr int kMaxModes = 1000;

/// One natural mode.
struct NaturalMode
{
  double eigenvalue = 0.0;    // omega^2, 1/s^2 (negative: the equilibrium is unstable along the mode)
  double omega = 0.0;         // rad/s, sqrt(eigenvalue); -sqrt(-eigenvalue) for a negative eigenvalue
  double frequency_hz = 0.0;  // omega / (2 pi), negative like omega
  /// dx = N phi in natural coordinates (the free nodes' positions, buildNaturalModel(model, false)), scaled so that
  /// the largest node displacement is 1 (its sign: that displacement's largest component is positive)
  Eigen::VectorXd shape;
  std::vector<Vec3> node_displacements;  // P dx per Model::nodes (zero at ground points; below 1e-12, 0)
};

struct ModalAnalysis
{
  int free_coordinates = 0;        // columns of N: how many modes there are
  std::vector<NaturalMode> modes;  // the lowest ones, ascending eigenvalue
};

/// The `count` lowest modes about `state` (an equilibrium; multipliers and actuation as reduceStructure
/// takes them). Throws std::invalid_argument above kMaxStructureCoordinates coordinates.
ModalAnalysis naturalModes(const Model& model, const State& state, int count);

/// What runModal returns.
struct ModalRun
{
  Summary summary;            // of the static solves; warnings of the modal analysis appended
  State equilibrium;          // the state the modes are about
  StructureReport structure;  // its diagnostics (checkStructure)
  ModalAnalysis modal;
  double wall_time = 0.0;  // s
};

/// A modal scene's analysis: the equilibrium at the start (StaticSolver::solve), followed along the path to
/// analysis.max_actuation in analysis.steps load steps (StaticSolver::followPath) when that is positive, then
/// its analysis.modes lowest natural modes and its structural diagnostics. When a static solve fails the
/// summary says so and there are no modes; a degenerate equilibrium (a mass matrix that is not positive definite
/// on the free coordinates) ends with status kSingular.
ModalRun runModal(const Model& model);

}  // namespace active_tensegrity::core
