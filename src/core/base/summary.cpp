#include "active_tensegrity/core/base/summary.h"

#include <chrono>

#if defined(__x86_64__)
#include <cpuid.h>
#include <x86intrin.h>
#endif

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

namespace
{
std::uint64_t steadyNanoseconds()
{
  return static_cast<std::uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch()).count());
}

#if defined(__x86_64__)
// an invariant TSC (CPUID 0x80000007, EDX bit 8) counts at a constant rate whatever the core's frequency and state
bool invariantTsc()
{
  unsigned eax = 0, ebx = 0, ecx = 0, edx = 0;
  // (GCC's __get_cpuid_max returns unsigned, clang's int)
  if (static_cast<unsigned>(__get_cpuid_max(0x80000000u, nullptr)) < 0x80000007u)
    return false;
  __get_cpuid(0x80000007u, &eax, &ebx, &ecx, &edx);
  return (edx & (1u << 8)) != 0;
}
const bool kTsc = invariantTsc();
#else
const bool kTsc = false;
#endif

double secondsPerTick()
{
#if defined(__x86_64__)
  if (kTsc)
  {
    // the counter against steady_clock over half a millisecond (4e-5 of the rate at steady_clock's resolution)
    const std::uint64_t n0 = steadyNanoseconds();
    const std::uint64_t t0 = __rdtsc();
    std::uint64_t n1 = n0;
    while (n1 - n0 < 500000u)
      n1 = steadyNanoseconds();
    const std::uint64_t t1 = __rdtsc();
    if (t1 > t0)
      return 1e-9 * static_cast<double>(n1 - n0) / static_cast<double>(t1 - t0);
  }
#endif
  return 1e-9;  // (steady_clock's nanoseconds)
}
// (when the library loads: a calibration inside a timed part would count in it)
const double kSecondsPerTick = secondsPerTick();
}  // namespace

std::uint64_t partTicks()
{
#if defined(__x86_64__)
  if (kTsc)
    return __rdtsc();
#endif
  return steadyNanoseconds();
}

double partSeconds()
{
  return kSecondsPerTick;
}

}  // namespace active_tensegrity::core
