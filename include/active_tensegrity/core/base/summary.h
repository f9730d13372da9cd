/// What every solver returns: how it ended (SolveStatus) and its counts (Summary).
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace active_tensegrity::core
{
enum class SolveStatus
{
  kConverged,
  kMaxIterations,  // Newton did not converge within max_iterations (after all step cuts)
  kSingular,       // the Newton matrix could not be factorized (a mechanism, or a degenerate state)
  kNonFinite,      // a NaN or infinity appeared
  kPassedThrough,  // the solution has two checked struts passed through each other (contact tunnelling)
  kBranchJump      // statics: a corrected equilibrium lay further from the predicted one than the guard allows
                   // at the smallest increment (a jump to another branch of equilibria)
};

const char* toString(SolveStatus s);

struct Summary
{
  SolveStatus status = SolveStatus::kConverged;
  int iterations = 0;         // Newton iterations, all attempts included
  int step_cuts = 0;          // times a step or load increment was halved
  int crossings_refused = 0;  // dynamics: steps refused (and cut) because a strut would pass through another
  double residual = 0.0;      // last increment norm (dynamics) or force residual (statics)
  std::string message;
  /// What a run should not keep quiet about although it went on (slack cables or no equilibrium at the
  /// start, critical points passed, ...): one sentence each, printed on stderr and listed in summaries.
  std::vector<std::string> warnings;
  bool ok() const
  {
    return status == SolveStatus::kConverged;
  }
};

/// Wall time (s) a solver spent in each part of its steps (DynamicsSolver: time steps; StaticSolver: load
/// increments), summed since construction (or DynamicsSolver::resetTimings()). Measured with the part timers around
/// each part (partTicks below): about ten readings per Newton iteration.
struct StepTimings
{
  double forces = 0.0;         // inertial and applied (cable, spring, actuator) forces with their tangents
  double contact = 0.0;        // broad phase, impact speeds, contact forces and tangents, pass-through check
  double constraints = 0.0;    // constraint values, forces, Jacobian and lambda-Hessian
  double factorization = 0.0;  // numeric factorization of the Newton matrix (sparse, dense or static-pivot LU)
  double solve = 0.0;          // triangular solves
  double total = 0.0;          // whole step() / followPath() calls (the rest is vector work and bookkeeping)
  long newton_iterations = 0;
  long factorizations = 0;
  long analyses = 0;       // symbolic analyses of the Newton matrix (a new pattern)
  long most_touching = 0;  // dynamics: the most contact slots touching at the end of an accepted step (not of one the
                           // adaptive step control refused); a maximum, not a sum

  StepTimings& operator+=(const StepTimings& o)
  {
    forces += o.forces;
    contact += o.contact;
    constraints += o.constraints;
    factorization += o.factorization;
    solve += o.solve;
    total += o.total;
    newton_iterations += o.newton_iterations;
    factorizations += o.factorizations;
    analyses += o.analyses;
    most_touching = std::max(most_touching, o.most_touching);
    return *this;
  }
};

/// The clock of the solvers' part timers (ScopeTimer, LapTimer): the processor's time-stamp counter where it runs at
/// a constant rate (x86-64 with an invariant TSC: a read costs a third of steady_clock's), else steady_clock.
/// partTicks() is a reading, partSeconds() the seconds per tick (the counter's rate against steady_clock over half a
/// millisecond when the library loads).
std::uint64_t partTicks();
double partSeconds();

/// Adds the wall time of its scope to `sum` (s).
class ScopeTimer
{
public:
  explicit ScopeTimer(double& sum) : sum_(sum), start_(partTicks()) {}
  ~ScopeTimer()
  {
    sum_ += static_cast<double>(partTicks() - start_) * partSeconds();
  }
  ScopeTimer(const ScopeTimer&) = delete;
  ScopeTimer& operator=(const ScopeTimer&) = delete;

private:
  double& sum_;
  std::uint64_t start_;
};

/// Times consecutive parts with one clock reading between each two: lap(sum) adds the time since the last lap (or
/// the construction) to sum.
class LapTimer
{
public:
  LapTimer() : last_(partTicks()) {}
  void lap(double& sum)
  {
    const std::uint64_t now = partTicks();
    sum += static_cast<double>(now - last_) * partSeconds();
    last_ = now;
  }

private:
  std::uint64_t last_;
};

}  // namespace active_tensegrity::core
