/// Static equilibrium (paper Sec. 5; docs/physics.md, "Statics") in natural coordinates (natural.h): velocities zero,
/// Newton on the free nodes' positions x and the rows' multipliers lambda for
///   -F(x, u) + G(x)^T lambda = 0,  Phi(x, u) = 0,
/// under actuation (displacement) control, contact without damping or friction. A strut's spin about its own axis is
/// not a coordinate, so statics needs no spin locks (nor the spin rates dynamics gives a scene with friction: statics
/// has none, and its matrices are the smaller for it). The solved state carries its natural coordinates
/// (State::natural, marked as an equilibrium) and their body poses (State::q, each strut's frame carried onto its axis
/// along the shortest arc from its pose before) and its multipliers (State::natural.lambda).
#pragma once

#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::core
{
/// A critical point of an equilibrium path passed by StaticSolver::followPath: the sign of the determinant
/// of the tangent (Newton) matrix, which equals (-1)^(constraint rows) times the sign of the determinant of
/// the tangent stiffness on the constraint manifold, changed between two factorizations: an odd number of
/// the reduced stiffness's eigenvalues passed through zero.
struct CriticalPoint
{
  /// "bifurcation" when the path parameter kept its direction through it (a simple bifurcation point
  /// crossed: the path followed goes on along the branch it was on, which turned unstable or stable), or
  /// "limit_point" when the parameter turned back there (arc-length continuation only).
  std::string kind;
  double parameter = 0.0;           // path parameter at the equilibrium where the new sign was found
  double previous_parameter = 0.0;  // ... and where the old sign was last seen (the point lies between)
  int sign_before = 0, sign_after = 0;
  /// The reduced tangent stiffness at the two equilibria that bracket the point (StiffnessSpectrum of their body
  /// poses, structure_check.h):
  /// its eigenvalue nearest zero and its number of negative eigenvalues; NaN and -1 where not computed (a
  /// model of more than kMaxCriticalPointCoordinates coordinates, a point after the first
  /// kMaxCriticalPointSpectra of a path).
  double eigenvalue_before = std::numeric_limits<double>::quiet_NaN();
  double eigenvalue_after = std::numeric_limits<double>::quiet_NaN();
  int negative_before = -1, negative_after = -1;
};

/// Largest model (coordinates) whose critical points get the stiffness spectrum on both sides (a dense
/// eigenproblem of the reduced stiffness per side).
constexpr int kMaxCriticalPointCoordinates = 1000;
/// ... and for the first this many critical points of a path.
constexpr size_t kMaxCriticalPointSpectra = 20;

class StaticSolver
{
public:
  /// Throws std::invalid_argument naming what the natural coordinates do not cover (buildNaturalModel, natural.h).
  StaticSolver(const Model& model, const SolverOptions& options);
  ~StaticSolver();
  StaticSolver(StaticSolver&&) noexcept;
  StaticSolver& operator=(StaticSolver&&) noexcept;

  /// Newton from the state's configuration (its natural coordinates, or its body poses q) to the equilibrium under
  /// actuation values u (no step cutting); when plain Newton fails, a damped (Levenberg-Marquardt) Newton from the same
  /// start. On failure the state is unchanged.
  Summary solve(State& state, const ActuationValues& u);

  /// The equilibrium at actuation u nearest to state's configuration (velocities ignored): solve() from it, and when
  /// that fails, dynamic relaxation with kinetic damping (the dynamics at fixed actuation, the velocities zeroed at
  /// every peak of the kinetic energy; contact without friction, as in statics), trying Newton from the relaxing state
  /// every 500 steps, for at most `max_steps` steps of solver.dt. On success state holds the equilibrium (u set,
  /// velocities zero); on failure it is left unchanged and the status and message say why. `stop` (when given) is
  /// polled every relaxation step: true ends the search (status kMaxIterations, the message says it was stopped).
  Summary relax(State& state, const ActuationValues& u, long max_steps = 20000, const std::function<bool()>& stop = {});

  /// Follows the path of equilibria from state's actuation to u_end, the path parameter w running from 0 to 1
  /// (u = (1 - w) u_start + w u_end) in `steps` equal load steps; calls `on_step` after every one (state.t = w).
  /// Predictor-corrector continuation (docs/physics.md, "Statics"): a tangent predictor dz/dw = -J^-1 dr/dw from the
  /// factorized tangent, modified-Newton correction that keeps the factorization while it contracts, increments
  /// halved (at most max_step_cuts times in a row) when the correction fails and doubled back after successes.
  /// Branch-jump guard: a corrected equilibrium further from the predicted one than the increment times the tangents
  /// at both ends (plus a floor of 100 newton_tolerance) is refused and the increment cut; when cutting to the
  /// smallest increment does not help, the path ends with status kBranchJump. Critical points passed are listed in
  /// criticalPoints() and as warnings in the returned summary. Stops at the first increment that fails after all cuts.
  Summary followPath(State& state, const ActuationValues& u_end, int steps,
                     const std::function<void(const State&, const Summary&)>& on_step);

  /// The point loads' factor along the path: f(w) = start + w (end - start) (default 1 to 1: loads as given);
  /// solve() applies f(0) until a path moves it.
  void setLoadPath(double start, double end);
  /// Arc-length continuation in followPath (default off: the path parameter is stepped): passes limit points of the
  /// path parameter, where the path turns back (a load-driven snap-through). The first step is about 1/steps in w;
  /// the arc length then adapts; the path ends when w reaches 1 (or, with a message, after 100 steps per requested
  /// load step).
  void setArcLength(bool on);

  /// Critical points passed by the last followPath.
  const std::vector<CriticalPoint>& criticalPoints() const;

  /// The force residual at the state's configuration (N, max norm over the free nodes of -F + G^T lambda) with the
  /// multipliers that fit it best (least squares): whether the configuration is an equilibrium at all.
  double forceResidual(const State& state);

  /// Where the solver's time went since construction (forces, contact, constraints, factorization, solve, total;
  /// Newton iterations, factorizations and symbolic analyses).
  const StepTimings& timings() const;

  const Model& model() const;

  struct Impl;

private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace active_tensegrity::core
