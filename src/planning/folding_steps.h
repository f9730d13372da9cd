/// The folding planner's steps, which planFolding (folding_planner.cpp) runs: the request's checks and its clock
/// (request.cpp), the OMPL search and its shortcutting (search.cpp), the goal, following the path from the start and
/// blending it into a trajectory (path.cpp), and the dynamic verification (verification.cpp). Private to the planning
/// library.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include <ompl/base/Planner.h>
#include <ompl/base/PlannerStatus.h>
#include <ompl/base/SpaceInformation.h>
#include <ompl/base/spaces/RealVectorBounds.h>

#include "active_tensegrity/planning/folding_planner.h"
#include "active_tensegrity/core/solvers/actuation_control.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/modal.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/base/text.h"
#include "active_tensegrity/planning/trajectory.h"
#include "active_tensegrity/planning/validity.h"

namespace active_tensegrity::planning::detail
{
namespace ob = ompl::base;
using Values = std::vector<double>;
using Allocator = std::function<ob::PlannerPtr(const ob::SpaceInformationPtr&)>;

/// The OMPL planners a request can name, by name.
const std::map<std::string, Allocator>& planners();

/// Searches of one request at most: a path cut when followed from the start (another branch of equilibria) is
/// searched on from where it stopped being valid, with the next seed, while the deadline allows.
constexpr int kSearchesMost = 8;

/// The request's one deadline, its cancel and its progress reports (PlanControl). Planners may poll from
/// several threads: the flags are atomic, the reports serialized.
class RequestClock
{
public:
  using Clock = std::chrono::steady_clock;

  RequestClock(double time_limit, const PlanControl& control)
    : control_(control)
    , t0_(Clock::now())
    , main_(t0_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(time_limit)))
    , end_(main_)
  {
  }
  void watch(const EquilibriumOracle* oracle)
  {
    oracle_ = oracle;
  }
  double elapsed() const
  {
    return std::chrono::duration<double>(Clock::now() - t0_).count();
  }
  void phase(const char* name)
  {
    const std::lock_guard<std::mutex> lock(report_mutex_);
    phase_ = name;
  }
  /// Whether the current phase must stop: past its end, or cancelled (before the answer is being made).
  bool stop()
  {
    report();
    const Clock::time_point t = Clock::now();
    if (t > main_)
      timed_out_ = true;
    if (!answering_ && !cancelled_ && control_.cancelled && control_.cancelled())
      cancelled_ = true;
    return t > end_.load() || (!answering_ && cancelled_);
  }
  /// The request ran out: its deadline passed or it was cancelled.
  bool out()
  {
    stop();
    if (!cancelled_ && control_.cancelled && control_.cancelled())
      cancelled_ = true;
    return timed_out_ || cancelled_;
  }
  /// From now on the answer is being made: a cancel no longer stops the phase, which ends at the deadline
  /// or, when that is less than `grace` s away, `grace` s from now.
  void answering(double grace)
  {
    answering_ = true;
    end_ = std::max(main_,
                    Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(grace)));
  }
  /// Back to searching (from an answer phase that found the path cut): the deadline ends the phase, and a cancel
  /// stops it again.
  void searching()
  {
    answering_ = false;
    end_ = main_;
  }
  /// The last report, once the answer is made: phase "done" with the figures of the returned path's end.
  void done(double best_height, double best_distance)
  {
    if (!control_.progress)
      return;
    const std::lock_guard<std::mutex> lock(report_mutex_);
    PlanProgress p;
    p.elapsed = elapsed();
    p.phase = "done";
    p.best_height = best_height;
    p.best_distance = best_distance;
    if (oracle_)
      p.equilibrium_solves = oracle_->solves();
    control_.progress(p);
  }
  bool timedOut() const
  {
    return timed_out_;
  }
  bool cancelled() const
  {
    return cancelled_;
  }

private:
  void report()
  {
    if (!control_.progress)
      return;
    std::unique_lock<std::mutex> lock(report_mutex_, std::try_to_lock);
    if (!lock.owns_lock())
      return;
    const double now = elapsed();
    if (reported_ && now - last_report_ < control_.progress_period)
      return;
    reported_ = true;
    last_report_ = now;
    PlanProgress p;
    p.elapsed = now;
    p.phase = phase_;
    if (oracle_)
    {
      p.equilibrium_solves = oracle_->solves();
      p.best_distance = oracle_->bestDistance();
      p.best_height = oracle_->bestHeight();
    }
    control_.progress(p);
  }

  const PlanControl& control_;
  const EquilibriumOracle* oracle_ = nullptr;
  Clock::time_point t0_, main_;
  std::atomic<Clock::time_point> end_;
  std::atomic<bool> timed_out_{ false }, cancelled_{ false }, answering_{ false };
  std::mutex report_mutex_;
  std::string phase_ = "search";
  bool reported_ = false;
  double last_report_ = 0.0;
};

/// How the chosen actuators, moving at the start, come to rest: each braked from its rate at its acceleration
/// limit (the time-optimal stop), sampled as the first part of the trajectory.
struct Stop
{
  std::vector<double> values;  // where each comes to rest
  double duration = 0.0;       // s until the last is at rest (0: all at rest already)
  Trajectory prefix;           // from the start's values and rates to rest (no points when duration is 0)
};

/// A search's outcome (searchOnce).
struct Search
{
  ob::PlannerStatus status;
  ob::SpaceInformationPtr si;
  bool solved = false;
  std::vector<Values> raw;
};

/// The request checked against the model: "" or what is wrong with it, naming the field and the value; `idx` gets
/// the chosen actuators' indices.
std::string checkRequest(const core::Model& model, const PlanRequest& r, std::vector<int>& idx);

/// The stop of the chosen actuators from `now` (their values and rates at the start); "" or why not (a stop
/// outside an actuator's range).
std::string stopping(const core::Model& model, const std::vector<int>& idx, const core::ActuationValues& now,
                     const PlanRequest& r, Stop& stop);

/// The trajectory as it runs: the stop, then the path's trajectory from where it ends (its first point, at
/// rest there, is the stop's last), slowed by `scale`.
Trajectory executed(const Stop& stop, const PlanResult& path, double scale);

/// The goal's distance of an equilibrium (0 at the goal).
std::function<double(const Equilibrium&)> goalDistance(const EquilibriumOracle& oracle, const PlanRequest& r);

/// The end of the followed path meets the goal (valid, at or below the target height, or at the target values).
bool meetsGoal(const EquilibriumOracle& oracle, const PlanRequest& r, const Equilibrium& e);

/// A one-point plan: the start meets the goal.
void stayAtStart(const EquilibriumOracle& oracle, PlanResult& out);

/// Cheap necessary conditions: for a height target, one continuation to every actuator's upper bound, and a
/// target below the lowest height met on it is reported as unreachable; for target values, their
/// equilibrium reached straight from the start must be valid. Empty when the goal may be reachable.
std::string reachability(const EquilibriumOracle& oracle, const PlanRequest& r, const std::vector<double>& upper);

/// Greedy deterministic shortcutting: from each kept waypoint, the farthest one reachable in one valid edge.
/// Once `stop` fires the remaining waypoints are kept as they are.
std::vector<Values> shortcut(const ob::SpaceInformationPtr& si, const std::vector<Values>& raw, RequestClock& clock);

/// One search from the oracle's start: the OMPL problem, its sampler and goal seeded by `seed`, solved within the
/// clock. `raw` is the solution path (`solved`), or, when the clock stopped a search without an exact one, the path
/// to the valid equilibrium nearest the goal reached from the request's start through valid equilibria (the
/// oracle's best, which the progress reports) when that is nearer the goal than the oracle's start and than the end
/// of the planner's approximate path; empty when there is none.
Search searchOnce(const EquilibriumOracle& oracle, const PlanRequest& r, const ob::RealVectorBounds& bounds,
                  double extent, unsigned seed, RequestClock& clock);

/// Follows the path from the start through every waypoint (the path the trajectory drives); fills the
/// figures along it, the waypoints reached and the status; `cut` says where the path stopped being valid (untouched
/// when it did not; waypoints numbered from `offset`, the waypoints before this path's start). Returns the last
/// equilibrium reached.
Equilibrium followFromStart(const EquilibriumOracle& oracle, const PlanRequest& r, const std::vector<Values>& simple,
                            RequestClock& clock, PlanResult& out, std::string& cut, size_t offset = 0);

/// out's trajectory (times, positions, velocities, accelerations, duration) set from t.
void setTrajectory(const Trajectory& t, PlanResult& out);

/// Corners blended within r.blend_tolerance: the blended curve followed from the start by continuation; a
/// corner whose arc fails is tightened (halved three times, then passed at rest) and the curve checked
/// again. On success the trajectory is the time-optimal one along the curve and the figures are the
/// curve's; otherwise (out of time, a curve that ends elsewhere) the rest-to-rest one stays, with a note.
void blend(const EquilibriumOracle& oracle, const PlanRequest& r, RequestClock& clock, PlanResult& out);

/// The dynamic verification (and the speed-limit search) of out's trajectory, run after `stop` from `start` under
/// `law`; scales out's trajectory in place (not the stop).
void verify(const core::Model& model, const core::State& start, const core::ActuationController& law, const Stop& stop,
            const PlanRequest& r, const core::State& end, RequestClock& clock, PlanResult& out);
}  // namespace active_tensegrity::planning::detail
