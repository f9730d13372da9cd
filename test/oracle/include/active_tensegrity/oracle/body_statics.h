/// Static equilibrium in the body (Euler-parameter) coordinates, the comparison for StaticSolver (statics.h), which
/// solves in natural coordinates: qd = qdd = 0, Newton on [q; lambda] for
///   -F(q) + Phi_q^T lambda = 0,  Phi(q, s) = 0,
/// under actuation (displacement) control. The spin of every strut about its own axis has no
/// stiffness in statics, so the solver adds one linear spin-lock row per strut,
/// (conj(Theta0) (x) Theta)_z = 0 with Theta0 the model's initial orientation.
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "active_tensegrity/oracle/mechanics.h"
#include "active_tensegrity/oracle/reduced_linear_solver.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/oracle/body_state.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::core
{
/// One spin-lock row per strut, (conj(Theta0) (x) Theta)_z = 0 with Theta0 the model's initial
/// orientation: the constraints an analysis in body coordinates about an equilibrium adds so that a strut's
/// spin about its own axis, which no element resists, is not a degree of freedom.
std::vector<Constraint> spinLocks(const Model& model);

/// Multipliers that best satisfy the force equations at a given q (least squares), for checks of
/// equilibrium and initial actuation forces.
Eigen::VectorXd leastSquaresMultipliers(const System& system, const Eigen::VectorXd& q, const ActuationValues& u = {});

class BodyStaticSolver
{
public:
  BodyStaticSolver(const Model& model, const SolverOptions& options);

  /// Newton from state (q, lambda) to the equilibrium under actuation values u (no step cutting); when
  /// plain Newton fails, a damped (Levenberg-Marquardt) Newton from the same start. Struts are first turned
  /// about their own axes to satisfy their spin locks (their nodes do not move): a state from dynamics,
  /// where friction spins struts, is a valid start.
  Summary solve(BodyState& state, const ActuationValues& u);

  /// The equilibrium at actuation u nearest to state's configuration (velocities ignored): solve() from
  /// it, and when that fails, dynamic relaxation with kinetic damping (the dynamics at fixed actuation, the
  /// velocities zeroed at every peak of the kinetic energy; contact without friction, as in statics), trying
  /// Newton from the relaxing state every 500 steps, for at most `max_steps` steps of solver.dt. On success state holds
  /// the equilibrium (u set, velocities zero); on failure it is left unchanged and the status and message say why.
  /// `stop` (when given) is polled every relaxation step: true ends the search (status kMaxIterations, the
  /// message says it was stopped).
  Summary relax(BodyState& state, const ActuationValues& u, long max_steps = 20000,
                const std::function<bool()>& stop = {});

  /// Follows the path of equilibria from state's actuation to u_end, the path parameter w running from 0 to
  /// 1 (u = (1 - w) u_start + w u_end) in `steps` equal load steps; calls `on_step` after every one
  /// (state.t = w). Predictor-corrector continuation (docs/physics.md, "Statics"): a tangent predictor
  /// dx/dw = -J^-1 dr/dw from the factorized tangent, modified-Newton correction that keeps the
  /// factorization while it contracts, increments halved (at most max_step_cuts times in a row) when the
  /// correction fails and doubled back after successes. Branch-jump guard: a corrected equilibrium further
  /// from the predicted one than the increment times the tangents at both ends (plus a floor of
  /// 100 newton_tolerance) is refused and the increment cut; when cutting to the smallest increment does not
  /// help, the path ends with status kBranchJump. Critical points passed are listed in criticalPoints()
  /// and as warnings in the returned summary. Stops at the first increment that fails after all cuts.
  Summary followPath(BodyState& state, const ActuationValues& u_end, int steps,
                     const std::function<void(const BodyState&, const Summary&)>& on_step);

  /// The point loads' factor along the path: f(w) = start + w (end - start) (default 1 to 1: loads as given);
  /// solve() applies f(0) until a path moves it.
  void setLoadPath(double start, double end)
  {
    load_start_ = start;
    load_end_ = end;
    system_.setLoadFactor(start);
  }
  /// Arc-length continuation in followPath (default off: the path parameter is stepped): passes limit
  /// points of the path parameter, where the path turns back (a load-driven snap-through). The first step
  /// is about 1/steps in w; the arc length then adapts; the path ends when w reaches 1 (or, with a message,
  /// after 100 steps per requested load step).
  void setArcLength(bool on)
  {
    arc_length_ = on;
  }

  /// Critical points passed by the last followPath.
  const std::vector<CriticalPoint>& criticalPoints() const
  {
    return critical_points_;
  }

  /// Force residual of the equilibrium equations at (q, lambda), N (max norm of -F + Phi_q^T lambda).
  double forceResidual(const BodyState& state);

  /// Where the solver's time went since construction (forces, contact, constraints, factorization, solve,
  /// total; Newton iterations and factorizations).
  const BodyStepTimings& timings() const
  {
    return timings_;
  }

  const System& system() const
  {
    return system_;
  }

private:
  Summary newton(BodyState& state, const ActuationValues& u);
  /// Levenberg-Marquardt from state; at most max_trials factorizations (0: 4 max_iterations).
  Summary dampedNewton(BodyState& state, const ActuationValues& u, int max_trials = 0);
  /// Factorizes jac_ with the sparse LU of solve() and the damped Newton (timed).
  bool factorizeFull();
  /// r_ (and jac_ when asked) at (q, lambda) under u.
  void assemble(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, const ActuationValues& u, bool with_jacobian);
  /// The actuation at path parameter w; sets the system's load factor to f(w).
  ActuationValues pathPoint(double w);
  /// dr/dw at q and w (central differences of the applied forces, exact constraint part).
  void parameterDerivative(const Eigen::VectorXd& q, double w, Eigen::VectorXd& out);
  /// Factorizes the path's Newton matrix at (q, lambda, u); records its determinant sign.
  bool factorizePath(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, const ActuationValues& u, double w);
  /// The path tangent dx/dw at q and w with the current path factorization (false without one).
  bool pathTangent(const Eigen::VectorXd& q, double w, Eigen::VectorXd& tangent);
  /// followPath with setArcLength(true); tangent: dx/dw at the start, when have_tangent.
  Summary followArcLength(BodyState& state, int steps,
                          const std::function<void(const BodyState&, const Summary&)>& on_step, Eigen::VectorXd tangent,
                          bool have_tangent);
  /// Modified-Newton correction of (q, lambda) to the equilibrium under u (w: for the determinant record;
  /// predicted_step: how far the predictor moved the coordinates, max norm).
  Summary correct(Eigen::VectorXd& q, Eigen::VectorXd& lambda, const ActuationValues& u, double w,
                  double predicted_step);
  /// At an accepted equilibrium (path parameter w): takes the sign of the path factorization as the
  /// path's, noting a critical point when it changed.
  void confirmSign(double w);
  /// One warning per critical point passed, into summary.warnings.
  void warnCriticalPoints(Summary& summary) const;

  System system_;
  SolverOptions options_;
  BlockSparseMatrix jac_;
  int nbodies_ = 0;                            // jac_'s first groups: the bodies' coordinates
  ReducedLinearSolver linear_;                 // solve() and the damped Newton
  ActuationValues path_u_start_, path_u_end_;  // the path being followed: u(w) between them
  double load_start_ = 1.0, load_end_ = 1.0;   // ... and the load factor f(w)
  bool arc_length_ = false;
  ReducedLinearSolver path_linear_;  // the continuation's tangent factorization
  bool path_factor_valid_ = false;
  int path_factor_age_ = 0;        // load increments since the path factorization was made
  double path_theta_ = 0.0;        // largest contraction rate measured with it
  Eigen::VectorXd path_factor_q_;  // the state it was made at
  double path_factor_w_ = 0.0;     // ... and the path parameter it was made at
  Eigen::VectorXd path_factor_lambda_;
  ActuationValues path_factor_u_;
  int path_factor_sign_ = 0;     // the sign of its determinant
  int sign_ = 0;                 // the path's determinant sign at the last accepted equilibrium (0: none yet)
  double sign_parameter_ = 0.0;  // the path parameter of the factorization that showed it
  BodyState sign_state_;         // ... and the state it was made at (q, lambda, u)
  std::vector<CriticalPoint> critical_points_;
  double damped_mu_hint_ = 0.0;  // the damping at which the last damped Newton first kept a step
  double wander_bound_ = 2.0;    // the diagonal of the nodes' bounding box at the start, at least 2
  BodyStepTimings timings_;
  Eigen::VectorXd force_rows_;  // 1 on the multipliers of kPoints constraints (forces), else 0
  Eigen::VectorXd zero_q_, F_, cforce_, phi_, r_, dx_, fplus_, fminus_;
};

}  // namespace active_tensegrity::core
