/// The tensegrity_sim node: steps the core's DynamicsSolver on a scene in simulated time, paced to a
/// real-time factor, drives the actuators from ~actuation and ~trajectory through the core's
/// ActuationController, and publishes tf, ~contacts, ~cables, ~struts, ~actuators, ~markers, ~status and
/// (optionally) /clock; plans foldings (the ~plan_folding service and action) and follows trajectories
/// (the ~follow_trajectory action). No physics here: only conversion, pacing and delegation (docs/ros.md).
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>

#include <actionlib/server/simple_action_server.h>
#include <boost/thread/recursive_mutex.hpp>
#include <diagnostic_updater/diagnostic_updater.h>
#include <dynamic_reconfigure/server.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>
#include <tf2_msgs/TFMessage.h>
#include <trajectory_msgs/JointTrajectory.h>

#include "active_tensegrity/ActuationCommand.h"
#include "active_tensegrity/ApplyWrench.h"
#include "active_tensegrity/FollowTrajectoryAction.h"
#include "active_tensegrity/PlanFoldingAction.h"
#include "active_tensegrity/PlanFolding.h"
#include "active_tensegrity/SimConfig.h"
#include "active_tensegrity/SimStatus.h"
#include "active_tensegrity/TargetWrench.h"
#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/solvers/actuation_control.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/planning/folding_planner.h"
#include "active_tensegrity/ros/messages.h"
#include "active_tensegrity/ros/sim_params.h"

namespace active_tensegrity::ros_layer
{
class SimNode
{
public:
  /// Loads nothing itself: the model comes loaded (and validated) from the scene. Throws
  /// std::runtime_error when the initial state cannot be made consistent.
  SimNode(ros::NodeHandle& nh, ros::NodeHandle& private_nh, SimParams params, core::Model model);

  /// Steps until ROS shuts down; the messages go out from a publishing thread of their own meanwhile, and the
  /// callbacks run on the spinner's threads.
  void run();
  ~SimNode();

private:
  using WallClock = std::chrono::steady_clock;

  void onActuation(const active_tensegrity::ActuationCommand::ConstPtr& msg);
  void onTrajectory(const trajectory_msgs::JointTrajectory::ConstPtr& msg);
  /// Starts the controller and the solver (and, with ~adaptive, a new step-size controller) from the scene's
  /// initial state s (the start and ~reset).
  core::Summary restart(core::State& s);
  bool onReset(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool onPause(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res);
  /// ~apply_wrench: a push on a target for a duration of simulated time (or until ~clear_wrenches).
  bool onApplyWrench(active_tensegrity::ApplyWrench::Request& req, active_tensegrity::ApplyWrench::Response& res);
  /// ~wrench: a standing load on a target, replacing the one the topic put there before (zero: removed).
  void onWrench(const active_tensegrity::TargetWrench::ConstPtr& msg);
  bool onClearWrenches(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  /// The point loads of a wrench on a named target at the live state (mutex held), or the reason it cannot be
  /// applied (then `loads` is left empty); `note` says what was dropped (a torque's part along a strut).
  std::string wrenchLoads(const std::string& target, const geometry_msgs::Wrench& wrench,
                          std::vector<core::PointLoad>& loads, std::string& note) const;
  /// Drops the pushes that have ended at state_.t, gives the solver the loads of those acting (when they
  /// changed), and returns when the next one ends (+inf: none) (mutex held).
  double applyPushes();
  /// Plans from the live state (the path from the quasi-static equilibrium nearest to it, the verification from
  /// the state itself); with `execute` the simulation is held from the request to the answer, so that the
  /// trajectory runs from the state it was verified from.
  bool onPlan(active_tensegrity::PlanFolding::Request& req, active_tensegrity::PlanFolding::Response& res);
  /// The ~plan_folding action: as the service, with progress as feedback and cancel (its own thread).
  void onPlanGoal(const active_tensegrity::PlanFoldingGoalConstPtr& goal);
  /// The ~follow_trajectory action: the trajectory through the controller, feedback per actuator, path and
  /// goal tolerances in simulated time; a new goal preempts, a cancel holds the actuators (its own thread).
  void onFollowGoal(const active_tensegrity::FollowTrajectoryGoalConstPtr& goal);
  /// What the service and the action share: request (service request or action goal) to answer (service
  /// response or action result), planning with `control`, and the execution.
  template <typename Request, typename Answer>
  void plan(const Request& req, Answer& res, const planning::PlanControl& control);

  /// Logs and counts a rejected command (mutex held); the log line at most every two wall seconds per kind of
  /// command (the count stays in ~status and /diagnostics).
  void reject(const std::string& what, const std::string& reason);
  /// Whether a log line of `kind` may go now (one per kind every two wall seconds); `held` gets how many were
  /// held back since the last one that went (mutex held).
  bool logDue(const std::string& kind, int& held);
  /// dynamic_reconfigure: applies each changed live parameter that checkLiveParam accepts; a refused one keeps
  /// its value (put back into `config`, which the server answers with) and is logged and counted.
  void onReconfigure(active_tensegrity::SimConfig& config, uint32_t level);
  /// /diagnostics: the simulation (real-time factor against the requested one, step cuts, solver status,
  /// contacts, pushes), the commands (accepted, rejected) and the planner.
  void diagnoseSimulation(diagnostic_updater::DiagnosticStatusWrapper& status);
  void diagnoseCommands(diagnostic_updater::DiagnosticStatusWrapper& status);
  void diagnosePlanner(diagnostic_updater::DiagnosticStatusWrapper& status);
  /// One publication for the publishing thread, in the order the loop made them: a state's topics, /clock alone
  /// (a publication the wall-rate cap left out), or the markers the last publication went without (the simulation
  /// stopped, so that rviz shows where).
  struct Outgoing
  {
    enum class Kind
    {
      kState,
      kClock,
      kMissedMarkers
    };
    Kind kind = Kind::kState;
    core::State state;  // (actuator forces formed by the loop thread, which owns the solver)
    ros::Time stamp;
    // the state's active contacts as the solver formed them, copied under the mutex
    std::vector<core::ContactPairState> contacts;
    bool have_contacts = false;
    bool clear_markers = false;            // a ~reset came before this: fresh markers
    bool markers_now = false;              // a (re)start: markers with this publication whatever ~marker_rate
    std::optional<MarkerOptions> options;  // new marker options, from this publication on
    double marker_rate = 0.0;
    bool publish_clock = false;
  };
  /// Loop thread: hands a publication to the publishing thread; waits while kPublishQueue are waiting (the
  /// subscribers set the pace then: no publication is dropped). Returns the seconds it waited.
  double send(Outgoing&& out);
  /// The publishing thread: takes publications in order until stop_publishing_.
  void publishLoop();
  /// Publishing thread: builds and publishes `out`'s topics; ~markers only when due (~marker_rate), else the
  /// state is kept in last_published_ for the markers a stop asks for.
  void publish(Outgoing& out);
  static constexpr size_t kPublishQueue = 4;
  /// One stepping (mutex held): to the next publication (adaptive steps) or one step of dt; a failure pauses the
  /// simulation at the last good state.
  void stepOnce(double dt, double next_publish, const core::ActuationLaw& law);
  /// Fills and publishes ~status (mutex held).
  void publishStatus();
  ros::Time stamp(double t) const;
  bool running() const
  {
    return !paused_by_user_ && !failed_ && plan_holds_ == 0;
  }
  /// ~status's solver_status when the solver has not failed (mutex held).
  std::string runState() const
  {
    return running() ? "running" : plan_holds_ > 0 ? "planning" : "paused";
  }

  SimParams params_;
  core::Model model_;
  core::DynamicsSolver solver_;
  std::unique_ptr<core::AdaptiveStepper> stepper_;  // with ~adaptive (a new one at every reset)
  core::ActuationController controller_;
  // (loop thread only) the parameters the loop reads: a copy of params_ made under the mutex when a live change
  // (params_epoch_) came
  SimParams loop_params_;
  uint64_t loop_params_epoch_ = 0;
  // (publishing thread only) the messages' builder; when ~markers may go next; the last publication's state when
  // it went without them
  MessageBuilder builder_;
  WallClock::time_point next_markers_ = WallClock::time_point::min();
  bool markers_missed_ = false;
  core::State last_published_;
  std::vector<core::ContactPairState> last_contacts_;
  bool last_have_contacts_ = false;
  ros::Time last_stamp_;

  std::mutex mutex_;  // guards everything below that callbacks touch (and params_, which dynamic_reconfigure sets)
  uint64_t params_epoch_ = 0;  // counts the live changes of params_
  bool repace_ = false;        // the real-time factor changed: pace from the live state
  core::State state_;
  bool paused_by_user_ = false;
  bool failed_ = false;
  // the actuators' last motion, from the stepping that set them moving to the one after which they had all arrived:
  // its simulated and wall durations (s), for /diagnostics (the real-time factor of a fold, publishing included)
  bool was_moving_ = false;
  double motion_start_sim_ = 0.0;
  WallClock::time_point motion_start_wall_;
  double last_motion_sim_ = 0.0, last_motion_wall_ = 0.0;
  // ~plan_folding requests with execute under way: the simulation does not step while there is one
  int plan_holds_ = 0;
  // counts every change of the actuation or the state other than stepping (commands, trajectories, resets, plan
  // executions): a plan executes only when nothing changed since its request
  uint64_t actuation_epoch_ = 0;
  bool clear_markers_ = false;
  // with publish_clock, stamps are stamp_origin_ + state.t: the wall time of the start, then simulated time
  // (monotonic across resets)
  double stamp_origin_ = 0.0;
  std::string solver_status_ = "running";
  std::string message_;
  uint32_t accepted_ = 0, rejected_ = 0;
  std::string last_rejection_;
  uint64_t steps_ = 0, step_cuts_ = 0;
  size_t contacts_ = 0;  // active contacts at the last publication
  // log lines per kind: when the last went, how many were held back since
  std::map<std::string, std::pair<WallClock::time_point, int>> log_times_;
  // what the last diagnostics update saw (a rise since then is a warning)
  uint64_t diagnosed_cuts_ = 0;
  uint32_t diagnosed_rejected_ = 0;
  // the planner: requests being planned, answered, the last answer
  int plans_running_ = 0;
  uint32_t plans_answered_ = 0;
  std::string last_plan_ = "none yet";
  bool last_plan_ok_ = true;
  // pushes from outside (~apply_wrench, ~wrench): each a set of world-frame point loads acting until `end`
  struct Push
  {
    uint64_t id = 0;
    std::string target;
    std::vector<core::PointLoad> loads;
    double end = 0.0;       // simulated s (+inf: until cleared)
    bool standing = false;  // from ~wrench (replaced by the next message for its target)
    core::Vec3 force = core::Vec3::Zero(), torque = core::Vec3::Zero();  // as asked (N, N m)
  };
  std::vector<Push> pushes_;
  uint64_t next_push_id_ = 1;
  std::vector<uint64_t> acting_pushes_;  // the ids whose loads the solver has
  double rtf_ = 0.0, publish_share_ = 0.0, publish_wait_share_ = 0.0;

  // between the loop and the publishing thread: the publications waiting, the publishing thread's busy time and
  // the active contacts of the last publication it made
  std::mutex out_mutex_;
  std::condition_variable out_cv_;
  std::deque<Outgoing> outgoing_;
  bool stop_publishing_ = false;
  double publishing_busy_ = 0.0;  // s, since the loop last took it
  size_t published_contacts_ = 0;
  std::thread publisher_;

  ros::Publisher contacts_pub_, cables_pub_, struts_pub_, actuators_pub_, markers_pub_, status_pub_, clock_pub_;
  ros::Subscriber actuation_sub_, trajectory_sub_, wrench_sub_;
  ros::ServiceServer reset_srv_, pause_srv_, plan_srv_, apply_wrench_srv_, clear_wrenches_srv_;
  ros::Publisher tf_pub_;  // (tf2's broadcaster with the queue of ~queue_size)
  diagnostic_updater::Updater diagnostics_;
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<active_tensegrity::SimConfig>> reconfigure_;
  // the action servers last: their threads run callbacks that use everything above
  std::unique_ptr<actionlib::SimpleActionServer<active_tensegrity::PlanFoldingAction>> plan_action_;
  std::unique_ptr<actionlib::SimpleActionServer<active_tensegrity::FollowTrajectoryAction>> follow_action_;
};

/// The whole node for main(): parameters, scene, SimNode, spinner. Returns the exit code (1 when the
/// parameters or the scene are refused, with the reason logged).
int runSimNode();

}  // namespace active_tensegrity::ros_layer
