/// tensegrity_bench: measurements that print numbers (never timed tests). One file per subcommand in this
/// folder, each with its entry point declared here; main.cpp prints the usage and dispatches. Exit status:
/// 0; 1 when a scene is refused or a run throws; 2 on bad arguments (usage, or an option value that is not
/// what it must be, named with the value); 3 when a measured run does not converge.
/// Argument parsing helpers: ../cli.h.
#pragma once

#include <algorithm>
#include <chrono>
#include <string>
#include <vector>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/scene/scene.h"

namespace active_tensegrity::tools::bench
{
// The subcommands; each returns the exit status, and throws BadArgument (status 2) or another
// std::exception (status 1), which main() reports.

/// `steps SCENE`: wall time, Newton iterations and heap allocations per step, and the time breakdown
/// (steps.cpp).
int steps(const std::string& scene, const std::vector<core::Override>& overrides, int repeat, bool peaks);
/// `contact-pair`: ns per call of one strut pair's contact evaluation (contact_pair.cpp).
int contactPair(int repeat);
/// `broad-phase`: broad- and narrow-phase time on random scenes of 10 to 1000 struts (broad_phase.cpp).
int broadPhase(int repeat);
/// `stress`: the stability stress cases, one table row each (stress.cpp).
/// Which stress cases run: the short ones only (`--quick`), those whose name contains one of `cases` (all if
/// empty), less those whose name contains one of `skipped`.
struct StressSelection
{
  bool quick_only = false;
  std::vector<std::string> cases;
  std::vector<std::string> skipped;
};
/// 0 when every selected case ended with finite numbers, 3 when one did not; 2 when a text names no case or
/// nothing is selected.
int stress(const StressSelection& select);
/// `lattice`: time per step against the number of struts on quadruplex lattices (lattice_cmd.cpp); reports
/// its own bad arguments (status 2; 3 when a size did not converge).
int lattice(const std::vector<std::string>& args);
/// `plan SCENE`: the folding planner over several seeds (plan.cpp).
int plan(const std::string& scene, const std::vector<std::string>& args);
/// `work-precision SCENE`: integrators and the MuJoCo peer against a fine reference (work_precision.cpp).
int workPrecision(const std::string& scene, const std::vector<std::string>& args);

/// `natural SCENE`: the body coordinates against the natural coordinates (core/solvers/natural.h) at equal error (natural.cpp).
int natural(const std::string& scene, const std::vector<std::string>& args);

/// The processor's model name and which of avx2, fma, avx512f it has (/proc/cpuinfo; "unknown" without it).
std::string cpuModel();
std::string cpuVectorFlags();

using Clock = std::chrono::steady_clock;

inline double seconds(Clock::time_point t0, Clock::time_point t1)
{
  return std::chrono::duration<double>(t1 - t0).count();
}

/// Keeps a result alive so that the timed calls cannot be dropped.
inline volatile double g_sink = 0.0;

/// Median over `repeat` samples of the time of one call of f (s); each sample runs f `calls` times.
template <typename F>
double medianPerCall(const F& f, int calls, int repeat)
{
  std::vector<double> t;
  for (int r = 0; r < repeat; ++r)
  {
    const Clock::time_point t0 = Clock::now();
    for (int i = 0; i < calls; ++i)
      f();
    t.push_back(seconds(t0, Clock::now()) / calls);
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

/// Calls per sample so that one sample takes about `target` seconds (at least 1).
template <typename F>
int callsFor(const F& f, double target)
{
  const Clock::time_point t0 = Clock::now();
  f();
  const double once = std::max(1e-9, seconds(t0, Clock::now()));
  return std::max(1, static_cast<int>(target / once));
}

/// A strut built in code: one layer of density 2000 kg/m^3, solid-cylinder mass and inertia (bench.cpp).
core::Body strut(const std::string& name, double length, double radius, double youngs_modulus, double poisson_ratio);

/// Heap allocations (malloc, calloc, realloc) made by this process so far (bench.cpp); -1 in a build with
/// AddressSanitizer, which replaces malloc itself (nothing is counted there).
long heapAllocations();

}  // namespace active_tensegrity::tools::bench
