/// The adaptive steps' size rules (StepSizeControl), shared by the dynamics (AdaptiveStepper in dynamics.h, on the
/// natural coordinates) and the body coordinates' comparison (test/oracle). Variable time steps (solver.adaptive): the
/// step follows a local error estimate
/// (StepEstimate::error against solver.error_tolerance), a step that brings a pair into contact deeper
/// than solver.onset_depth is refused and retried at the interpolated onset time, a step that gains energy
/// no force accounts for, or loses it in contact, beyond solver.energy_tolerance (energy.h) is refused and halved, and
/// the step grows again after (docs/physics.md, "Adaptive time steps").
#pragma once

#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <sstream>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::core
{
/// Counts of what an BodyAdaptiveStepper did.
struct AdaptiveStats
{
  long accepted = 0;
  long rejected_error = 0;   // local error above the tolerance
  long rejected_onset = 0;   // a new contact entered too deep: retried at the interpolated onset
  long rejected_energy = 0;  // the step gained energy no force accounts for (a stiff event it did not resolve)
  long rejected_solver = 0;  // Newton failed or a pair would pass through: the step was cut
  long at_min_step = 0;      // steps accepted at dt_min with the error, onset depth or energy gain still too large
  double h_min = 0.0;        // smallest and largest accepted step (s)
  double h_max = 0.0;
};

/// The step-size rules of adaptive stepping, shared by BodyAdaptiveStepper and NaturalSolver::advanceTo: which step to
/// try next, and how a refusal or an acceptance changes it.
class StepSizeControl
{
public:
  /// The first step is options.dt (clamped to [dt_min, dt_max]).
  explicit StepSizeControl(const SolverOptions& options);

  struct Trial
  {
    double h = 0.0;
    bool clipped = false;  // shortened to land on the end (says little about a longer step)
    bool at_min = false;   // at dt_min, or what is left cannot be split: accepted whatever its checks say
  };
  /// The step to try with `remaining` (s) left to the end: the last one or two steps share what is left, never in
  /// pieces below dt_min.
  Trial next(double remaining) const;

  /// A step of h that failed (Newton, a pass-through): halved.
  void failed(double h);
  /// A step of h that brought a pair from gap `onset_gap` to depth `onset_depth` beyond solver.onset_depth: aimed at
  /// half the allowed depth.
  void tooDeep(double h, double onset_gap, double onset_depth);
  /// A step of h whose error was err (in tolerances, > 1).
  void tooLarge(double h, double err);
  /// A step of h refused for its energy: halved, and the steps after it kept below it for a while.
  void energyRefused(double h);
  /// A step of h accepted with error err (in tolerances): the next one follows the error, within the energy bound.
  void accepted(const Trial& t, double err);

  double nextStep() const
  {
    return h_;
  }

private:
  SolverOptions options_;
  double h_;
  double energy_bound_ = std::numeric_limits<double>::infinity();  // steps gaining energy were refused above it (s)
};

/// A step of h taken in pieces: a failed piece is halved, and each half may be halved again, up to
/// options.max_step_cuts levels and never below options.dt_min (the recursion of halving kept as a binary counter:
/// `depth` is the level of the current piece, its length h / 2^depth, and `done` the pieces of that length behind it;
/// two finished pieces of one level make one of the level above). `attempt(piece)` tries one piece, changing the state
/// only when it succeeds; `now()` is the state's time. The last piece ends where the step was to end. On failure the
/// summary gives the failed piece's status and message with the time and the piece's length.
template <class Attempt, class Now>
Summary stepInPieces(double h, const SolverOptions& options, const Attempt& attempt, const Now& now)
{
  Summary total;
  const double t_end = now() + h;
  int depth = 0;
  long long done = 0;
  while (depth > 0 || done == 0)
  {
    const double left = t_end - now();
    double piece = std::ldexp(h, -depth);
    if (piece >= left * (1.0 - 1e-9))
      piece = left;
    const Summary sum = attempt(piece);
    total.iterations += sum.iterations;
    total.residual = sum.residual;
    if (sum.ok())
    {
      ++done;
      while (depth > 0 && done % 2 == 0)
      {
        done /= 2;
        --depth;
      }
      continue;
    }
    if (sum.status == SolveStatus::kPassedThrough)
      ++total.crossings_refused;
    const bool below_min = 0.5 * piece < options.dt_min;
    if (depth >= options.max_step_cuts || below_min)
    {
      std::ostringstream msg;
      msg << sum.message << " at t = " << now() << " s with the step cut to " << piece << " s";
      if (below_min && depth < options.max_step_cuts)
        msg << " (a further cut would go below solver.dt_min = " << options.dt_min << " s)";
      total.status = sum.status;
      total.message = msg.str();
      return total;
    }
    ++total.step_cuts;
    ++depth;
    done *= 2;
  }
  return total;
}

}  // namespace active_tensegrity::core
