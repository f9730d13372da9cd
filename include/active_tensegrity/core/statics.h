/// Static equilibrium (paper Sec. 5; docs/physics.md, "Statics"): qd = qdd = 0, Newton on [q; lambda] for
///   -F(q) + Phi_q^T lambda = 0,  Phi(q, s) = 0,
/// under actuation (displacement) control. The spin of every strut about its own axis has no
/// stiffness in statics, so the solver adds one linear spin-lock row per strut,
/// (conj(Theta0) (x) Theta)_z = 0 with Theta0 the model's initial orientation.
#pragma once

#include <functional>

#include "active_tensegrity/core/sparse_linear_solver.h"
#include "active_tensegrity/core/state.h"
#include "active_tensegrity/core/summary.h"

namespace active_tensegrity::core
{
/// One spin-lock row per strut, (conj(Theta0) (x) Theta)_z = 0 with Theta0 the model's initial
/// orientation: the constraints statics (and every analysis about an equilibrium) adds so that a strut's
/// spin about its own axis, which no element resists, is not a degree of freedom.
std::vector<Constraint> spinLocks(const Model& model);

class StaticSolver
{
public:
  StaticSolver(const Model& model, const SolverOptions& options);

  /// Newton from state (q, lambda) to the equilibrium under actuation values u (no step cutting); when
  /// plain Newton fails, a damped (Levenberg-Marquardt) Newton from the same start.
  Summary solve(State& state, const ActuationValues& u);

  /// Follows the path from state's actuation to u_end in `steps` equal increments, warm-started
  /// (secant predictor) and halving an increment when Newton fails. Calls `on_step` after every
  /// requested step. Stops at the first increment that fails after all cuts.
  Summary followPath(State& state, const ActuationValues& u_end, int steps,
                     const std::function<void(const State&, const Summary&)>& on_step);

  /// Force residual of the equilibrium equations at (q, lambda), N (max norm of -F + Phi_q^T lambda).
  double forceResidual(const State& state);

  const System& system() const
  {
    return system_;
  }

private:
  Summary newton(State& state, const ActuationValues& u);
  Summary dampedNewton(State& state, const ActuationValues& u);
  /// r_ (and jac_ when asked) at (q, lambda) under u.
  void assemble(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, const ActuationValues& u, bool with_jacobian);

  System system_;
  SolverOptions options_;
  BlockSparseMatrix jac_;
  SparseLinearSolver linear_;
  Eigen::VectorXd F_, cforce_, phi_, r_, dx_;
};

/// Multipliers that best satisfy the force equations at a given q (least squares), for checks of
/// equilibrium and initial actuation forces.
Eigen::VectorXd leastSquaresMultipliers(const System& system, const Eigen::VectorXd& q, const ActuationValues& u = {});

}  // namespace active_tensegrity::core
