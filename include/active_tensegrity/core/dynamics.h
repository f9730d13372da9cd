/// Index-3 DAE time integration (paper Sec. 5): Newton-Raphson on [qdd_{n+1}; lambda_{n+1}] with the
/// full analytic Jacobian (Eq. 68) and the constraint rows scaled by 1 / (beta h^2) (Bottasso et al.
/// 2007). Integrators: Newmark (gamma, beta) and generalized-alpha (Arnold & Bruls 2007, from
/// rho_infinity). A step whose Newton iteration fails is halved (up to max_step_cuts times).
#pragma once

#include <functional>

#include "active_tensegrity/core/state.h"

namespace active_tensegrity::core
{
/// s(t) for every actuator.
using ActuationLaw = std::function<ActuationValues(double t)>;

class DynamicsSolver
{
public:
  DynamicsSolver(const Model& model, const SolverOptions& options);

  /// Makes velocities and accelerations of `state` consistent with the constraints at state.t
  /// (velocities projected in the mass metric, accelerations and multipliers solved).
  Summary initialize(State& state, const ActuationLaw& law);
  /// Advances by h (halving it on failure); on failure `state` is left at the last good instant.
  Summary step(State& state, double h, const ActuationLaw& law);

  const System& system() const
  {
    return system_;
  }

  /// Effective Newmark coefficients and the generalized-alpha weights.
  struct Coefficients
  {
    double gamma, beta, alpha_m, alpha_f;
  };
  Coefficients coefficients() const
  {
    return coef_;
  }

  /// The Newton residual and Jacobian of one step at the unknowns (qdd_new, lambda_new); exposed for
  /// the finite-difference test of the full Jacobian.
  void residualAndJacobian(const State& start, double h, const ActuationValues& u, const Eigen::VectorXd& qdd_new,
                           const Eigen::VectorXd& lambda_new, Eigen::VectorXd& r, BlockSparseMatrix* jac);

private:
  /// Impact speeds v_0 the next step from `start` uses per checked pair (into step_speeds_): the
  /// remembered one of a live contact, else the approach rate at `start` (floored at min_impact_speed)
  /// for pairs close enough to touch within h.
  void prepareContact(const State& start, double h);
  void residual(const State& start, double h, const ActuationValues& u, const Eigen::VectorXd& qdd_new,
                const Eigen::VectorXd& lambda_new, Eigen::VectorXd& r, BlockSparseMatrix* jac);
  /// After a converged step: remember v_0 of pairs in contact at `end`, forget separated ones.
  void updateContactMemory(State& end);
  Summary attempt(State& state, double h, const ActuationLaw& law);
  Summary advance(State& state, double h, const ActuationLaw& law, int depth);
  void predict(const State& start, double h, const Eigen::VectorXd& qdd_new, Eigen::VectorXd& q, Eigen::VectorXd& qd,
               Eigen::VectorXd& acc) const;

  System system_;
  SolverOptions options_;
  Coefficients coef_;
  BlockSparseMatrix jac_;
  SparseLinearSolver linear_;
  Eigen::VectorXd q_, qd_, acc_, inertial_, applied_, cforce_, phi_, r_, dx_;
  std::vector<double> step_speeds_;  // v_0 per checked pair for the step being solved
  std::vector<int> candidates_;
};

}  // namespace active_tensegrity::core
