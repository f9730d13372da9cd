/// What every solver returns: how it ended (SolveStatus) and its counts (Summary).
#pragma once

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

}  // namespace active_tensegrity::core
