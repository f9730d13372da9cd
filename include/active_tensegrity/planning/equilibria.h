/// Quasi-static equilibria as functions of the actuation values of chosen actuators, for planning
/// (docs/planning.md). Equilibria of a tensegrity depend on the path: every equilibrium here is reached
/// by continuation (the core's StaticSolver::followPath, warm-started) along a straight line in
/// actuation space from a known one, the nearest in a cache that starts with the start state (bounded:
/// the least recently used equilibria are dropped beyond kCacheCapacity). ROS-free and thread-safe:
/// solvers come from a pool, the cache is guarded.
#pragma once

#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::planning
{
/// What makes an equilibrium acceptable.
struct ValidityLimits
{
  /// every checked strut pair keeps a surface gap >= min_clearance (m) unless allow_contact
  double min_clearance = 0.0;
  /// when true, touching is allowed as long as every (Hertz, quasi-static) contact force <= max_contact_force
  bool allow_contact = false;
  double max_contact_force = std::numeric_limits<double>::infinity();  // N
  /// no material cable above this stress (Pa)
  double max_cable_stress = std::numeric_limits<double>::infinity();
};

/// The way an equilibrium was reached from the oracle's start: straight segments in actuation space, each
/// followed by continuation through valid equilibria only. An immutable list shared between equilibria: a
/// node holds one waypoint (the chosen actuators' values) and the node before it (null at the start).
struct PathNode
{
  std::vector<double> values;
  std::shared_ptr<const PathNode> before;
};

/// One quasi-static equilibrium and the figures validity needs.
struct Equilibrium
{
  bool converged = false;
  std::string message;            // why not, when not converged
  core::State state;              // q, lambda, u (all actuators)
  double min_gap = 0.0;           // m (+inf without checked pairs)
  double max_contact = 0.0;       // N, largest quasi-static contact force
  double max_cable_stress = 0.0;  // Pa
  double height = 0.0;            // m (the scene's height nodes)
  /// how it was reached from the start through valid equilibria only (continuation from an equilibrium that
  /// was, every increment valid); null when it was not (from another branch, or past an invalid one)
  std::shared_ptr<const PathNode> path;
};

/// The waypoints of a path, from the start.
std::vector<std::vector<double>> pathWaypoints(const std::shared_ptr<const PathNode>& path);

/// Most equilibria an oracle keeps (about 3 kB each for the tower).
constexpr size_t kCacheCapacity = 4096;

class EquilibriumOracle
{
public:
  /// model: the scene (its contact settings decide whether statics computes contact forces);
  /// actuators: indices of the actuators the values refer to (the others keep start's values);
  /// start: a converged equilibrium; step: largest continuation increment (m, max norm).
  EquilibriumOracle(const core::Model& model, std::vector<int> actuators, const core::State& start,
                    ValidityLimits limits, double step);
  ~EquilibriumOracle();

  /// The equilibrium at actuation values u, by continuation from the nearest cached one (cached too).
  Equilibrium at(const std::vector<double>& u) const;
  /// The cached equilibrium at exactly u, if there is one (no solve).
  bool known(const std::vector<double>& u, Equilibrium& e) const;
  /// Follows the straight line from `from` (an equilibrium) to u in increments <= step; every
  /// intermediate equilibrium goes to visit (when given); stops at the first one that fails to converge
  /// or, when check is true, is not valid (returns false). `end` receives the last equilibrium reached.
  bool follow(const Equilibrium& from, const std::vector<double>& u, Equilibrium& end, bool check = true,
              const std::function<void(const Equilibrium&)>& visit = {}) const;
  /// Converged and within the limits; `why` (when given) says which limit is broken.
  bool valid(const Equilibrium& e, std::string* why = nullptr) const;

  /// The chosen actuators' values in a state.
  std::vector<double> values(const core::State& s) const;
  const Equilibrium& start() const
  {
    return start_;
  }
  const ValidityLimits& limits() const
  {
    return limits_;
  }
  double step() const
  {
    return step_;
  }
  /// Plans on from `start` (a converged equilibrium, e.g. the last one a path reached): it becomes the start,
  /// and the cache is emptied down to it, so that every later equilibrium is reached by continuation from it
  /// (none from the branches the old cache held). The solves, the timings and the best equilibrium carry on.
  void restart(const Equilibrium& start);
  /// Static solves (continuation increments) done so far.
  long solves() const;
  /// Equilibria in the cache.
  size_t cached() const;
  /// The work of every static solve so far (summed over the solvers of the pool; a solver in use by
  /// another thread is counted once it is back).
  core::StepTimings timings() const;

  /// Polled before every continuation increment: when it returns true, follow() stops (returns false,
  /// `end` not converged, message "stopped") and at() answers with a non-converged equilibrium.
  void setStop(std::function<bool()> stop)
  {
    stop_ = std::move(stop);
  }
  /// The goal's distance of an equilibrium (>= 0, 0 at the goal): the oracle keeps the valid equilibrium
  /// nearest to the goal among those reached from the start through valid equilibria only (bestDistance,
  /// bestHeight, bestPath; +inf and no path before the first).
  void setGoalDistance(std::function<double(const Equilibrium&)> distance)
  {
    distance_ = std::move(distance);
  }
  double bestDistance() const;
  double bestHeight() const;
  /// The waypoints that reached the best equilibrium from the start (each segment followed by continuation
  /// through valid equilibria); empty before the first.
  std::vector<std::vector<double>> bestPath() const;

private:
  class SolverLease;
  Equilibrium measure(const core::State& s, const core::Summary& sum) const;
  void remember(const Equilibrium& e) const;

  core::Model model_;  // a copy, set to static analysis (Hertz contact in the measurements)
  std::vector<int> actuators_;
  ValidityLimits limits_;
  double step_;
  Equilibrium start_;

  struct Entry
  {
    Equilibrium equilibrium;
    std::vector<double> values;  // the chosen actuators' values
    unsigned long used = 0;      // the clock of the last use (the start: never dropped)
  };

  std::function<bool()> stop_;
  std::function<double(const Equilibrium&)> distance_;
  mutable std::mutex mutex_;
  mutable std::vector<std::unique_ptr<core::StaticSolver>> pool_;
  mutable std::vector<Entry> cache_;
  mutable unsigned long clock_ = 0;
  mutable long solves_ = 0;
  mutable double best_distance_ = std::numeric_limits<double>::infinity();
  mutable double best_height_ = std::numeric_limits<double>::infinity();
  mutable std::shared_ptr<const PathNode> best_path_;
};

/// Max-norm distance between two actuation vectors.
double actuationDistance(const std::vector<double>& a, const std::vector<double>& b);

}  // namespace active_tensegrity::planning
