#include "active_tensegrity/core/summary.h"

namespace active_tensegrity::core
{
const char* toString(SolveStatus s)
{
  switch (s)
  {
    case SolveStatus::kConverged:
      return "converged";
    case SolveStatus::kMaxIterations:
      return "max_iterations";
    case SolveStatus::kSingular:
      return "singular";
    case SolveStatus::kNonFinite:
      return "non_finite";
    case SolveStatus::kPassedThrough:
      return "passed_through";
    case SolveStatus::kBranchJump:
      return "branch_jump";
  }
  return "unknown";
}

}  // namespace active_tensegrity::core
