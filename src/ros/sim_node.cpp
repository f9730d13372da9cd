#include "active_tensegrity/ros/sim_node.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <thread>
#include <utility>

#include <rosgraph_msgs/Clock.h>

#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/base/text.h"
#include "active_tensegrity/planning/folding_planner.h"

namespace active_tensegrity::ros_layer
{
namespace
{
double seconds(std::chrono::steady_clock::duration d)
{
  return std::chrono::duration<double>(d).count();
}

std::chrono::steady_clock::duration wallSpan(double seconds)
{
  return std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds));
}

/// A JointTrajectory's points as the controller takes them (velocities only when some point has them).
void trajectoryArrays(const trajectory_msgs::JointTrajectory& msg, std::vector<double>& times,
                      std::vector<std::vector<double>>& positions, std::vector<std::vector<double>>& velocities)
{
  bool any_velocity = false;
  for (const trajectory_msgs::JointTrajectoryPoint& p : msg.points)
  {
    times.push_back(p.time_from_start.toSec());
    positions.push_back(p.positions);
    velocities.push_back(p.velocities);
    any_velocity = any_velocity || !p.velocities.empty();
  }
  if (!any_velocity)
    velocities.clear();
}

/// The service request or action goal as the planner's request: 0 means "no limit" or the default, every
/// other value goes to the planner as given (which refuses negative and NaN limits, naming the field).
template <typename Request>
planning::PlanRequest planRequest(const Request& req, const SimParams& params)
{
  planning::PlanRequest r;
  r.actuators = req.actuators;
  r.target_height = req.target_values.empty() ? req.target_height : std::nan("");
  r.target_values = req.target_values;
  r.limits.min_clearance = req.min_clearance;
  r.limits.allow_contact = req.allow_contact;
  r.limits.max_contact_force = req.allow_contact ? req.max_contact_force : INFINITY;
  r.limits.max_cable_stress = req.max_cable_stress == 0.0 ? INFINITY : req.max_cable_stress;
  r.max_speeds = req.max_speeds.empty() ? std::vector<double>{ params.default_speed } : req.max_speeds;
  r.max_accelerations =
      req.max_accelerations.empty() ? std::vector<double>{ params.default_acceleration } : req.max_accelerations;
  r.planner = req.planner.empty() ? "RRTConnect" : req.planner;
  r.time_limit = req.time_limit == 0.0 ? 10.0 : req.time_limit;
  r.seed = req.seed;
  r.verify_dynamics = req.verify_dynamics;
  r.find_speed_limit = req.find_speed_limit;
  r.max_bending_stress = req.max_bending_stress == 0.0 ? INFINITY : req.max_bending_stress;
  r.settle_time = req.settle_time;
  r.blend_tolerance = req.blend_tolerance;
  r.reachability_check = !req.skip_reachability_check;
  return r;
}

/// The planner's result into the service response or action result (not `executed`).
template <typename Answer>
void fillAnswer(const planning::PlanResult& plan, Answer& res)
{
  res.status = static_cast<uint8_t>(plan.status);
  res.message = plan.message;
  res.trajectory.header.stamp = ros::Time(0);
  res.trajectory.joint_names = plan.names;
  res.trajectory.points.clear();
  for (size_t k = 0; k < plan.times.size(); ++k)
  {
    trajectory_msgs::JointTrajectoryPoint p;
    p.positions = plan.positions[k];
    p.velocities = plan.velocities[k];
    p.accelerations = plan.accelerations[k];
    p.time_from_start = ros::Duration(plan.times[k]);
    res.trajectory.points.push_back(p);
  }
  res.min_gap = std::isfinite(plan.min_gap) ? plan.min_gap : 0.0;
  res.peak_contact_force = plan.peak_contact_force;
  res.final_height = plan.final_height;
  res.equilibrium_solves = static_cast<uint32_t>(plan.equilibrium_solves);
  res.planning_time = plan.planning_time;
  res.stopped_by_time_limit = plan.stopped_by_time_limit;
  res.cancelled = plan.cancelled;
  res.duration = plan.duration;
  res.rest_to_rest_duration = plan.rest_to_rest_duration;
  res.stop_duration = plan.stop_duration;
  res.dynamics_verified = plan.dynamics_verified;
  res.dynamics_within_limits = plan.dynamics_within_limits;
  res.dynamic_peak_contact_force = plan.dynamic_peak_contact_force;
  res.dynamic_peak_bending_stress = plan.dynamic_peak_bending_stress;
  res.dynamic_min_gap = std::isfinite(plan.dynamic_min_gap) ? plan.dynamic_min_gap : 0.0;
  res.settle_duration = plan.settle_duration;
  res.time_scale = plan.time_scale;
}

bool finite(const core::State& s)
{
  if (!s.q.allFinite() || !s.qd.allFinite() || !s.natural.lambda.allFinite())
    return false;
  for (const core::ActuationValue& u : s.u)
    if (!std::isfinite(u.value) || !std::isfinite(u.rate))
      return false;
  return true;
}
}  // namespace

SimNode::SimNode(ros::NodeHandle& nh, ros::NodeHandle& pnh, SimParams params, core::Model model)
  : params_(std::move(params))
  , model_(std::move(model))
  , solver_(model_, model_.solver)
  , controller_(model_, core::initialState(model_).u)
  , loop_params_(params_)
  , builder_(model_, params_.frame_id, params_.markers, params_.tf_prefix)
  , diagnostics_(nh, pnh)
{
  state_ = core::initialState(model_);
  const core::Summary init = restart(state_);
  if (!init.ok() || !finite(state_))
    throw std::runtime_error("the initial state of scene '" + params_.scene + "' is not consistent: " + init.message);
  paused_by_user_ = params_.start_paused;
  // simulated stamps start at the wall time of the start (a date in bags and tools, never time 0)
  stamp_origin_ = ros::WallTime::now().toSec();

  const auto kQueue = static_cast<uint32_t>(params_.queue_size);
  contacts_pub_ = pnh.advertise<active_tensegrity::ContactArray>("contacts", kQueue);
  cables_pub_ = pnh.advertise<active_tensegrity::CableArray>("cables", kQueue);
  struts_pub_ = pnh.advertise<active_tensegrity::StrutArray>("struts", kQueue);
  actuators_pub_ = pnh.advertise<sensor_msgs::JointState>("actuators", kQueue);
  markers_pub_ = pnh.advertise<visualization_msgs::MarkerArray>("markers", kQueue);
  tf_pub_ = nh.advertise<tf2_msgs::TFMessage>("/tf", kQueue);
  status_pub_ = pnh.advertise<active_tensegrity::SimStatus>("status", 10, true);
  if (params_.publish_clock)
    clock_pub_ = nh.advertise<rosgraph_msgs::Clock>("/clock", 10);
  actuation_sub_ = pnh.subscribe("actuation", 10, &SimNode::onActuation, this);
  trajectory_sub_ = pnh.subscribe("trajectory", 10, &SimNode::onTrajectory, this);
  reset_srv_ = pnh.advertiseService("reset", &SimNode::onReset, this);
  pause_srv_ = pnh.advertiseService("pause", &SimNode::onPause, this);
  plan_srv_ = pnh.advertiseService("plan_folding", &SimNode::onPlan, this);
  apply_wrench_srv_ = pnh.advertiseService("apply_wrench", &SimNode::onApplyWrench, this);
  clear_wrenches_srv_ = pnh.advertiseService("clear_wrenches", &SimNode::onClearWrenches, this);
  wrench_sub_ = pnh.subscribe("wrench", 10, &SimNode::onWrench, this);
  plan_action_ = std::make_unique<actionlib::SimpleActionServer<active_tensegrity::PlanFoldingAction>>(
      pnh, "plan_folding", [this](const active_tensegrity::PlanFoldingGoalConstPtr& g) { onPlanGoal(g); }, false);
  follow_action_ = std::make_unique<actionlib::SimpleActionServer<active_tensegrity::FollowTrajectoryAction>>(
      pnh, "follow_trajectory", [this](const active_tensegrity::FollowTrajectoryGoalConstPtr& g) { onFollowGoal(g); },
      false);
  plan_action_->start();
  follow_action_->start();

  diagnostics_.setHardwareID("tensegrity_sim: " + model_.name);
  diagnostics_.add("simulation", this, &SimNode::diagnoseSimulation);
  diagnostics_.add("commands", this, &SimNode::diagnoseCommands);
  diagnostics_.add("planner", this, &SimNode::diagnosePlanner);
  // the server starts from the parameter server, where runSimNode wrote the effective values
  reconfigure_ = std::make_unique<dynamic_reconfigure::Server<active_tensegrity::SimConfig>>(reconfigure_mutex_, pnh);
  reconfigure_->setCallback([this](active_tensegrity::SimConfig& c, uint32_t level) { onReconfigure(c, level); });
}

void SimNode::onReconfigure(active_tensegrity::SimConfig& config, uint32_t /*level*/)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  const std::vector<std::pair<std::string, double*>> fields = {
    { "real_time_factor", &config.real_time_factor },
    { "publish_rate", &config.publish_rate },
    { "max_publish_wall_rate", &config.max_publish_wall_rate },
    { "marker_rate", &config.marker_rate },
    { "default_speed", &config.default_speed },
    { "default_acceleration", &config.default_acceleration },
    { "contact_force_scale", &config.contact_force_scale },
    { "cable_tension_scale", &config.cable_tension_scale },
    { "cable_width", &config.cable_width },
    { "strut_alpha", &config.strut_alpha },
  };
  SimParams next = params_;
  std::ostringstream changed;
  for (const auto& [name, value] : fields)
  {
    const double now = liveParam(params_, name);
    if (*value == now)
      continue;
    if (const std::string err = checkLiveParam(name, *value); !err.empty())
    {
      reject("dynamic_reconfigure", err + " (kept at " + core::shortestNumber(now) + ")");
      *value = now;
      continue;
    }
    setLiveParam(next, name, *value);
    changed << (changed.tellp() > 0 ? ", " : "") << name << " = " << core::shortestNumber(*value);
  }
  resolveCommandDefaults(next, model_);
  config.default_speed = next.default_speed;  // (the effective ones: 0 asks for the scene's)
  config.default_acceleration = next.default_acceleration;
  if (next.real_time_factor != params_.real_time_factor)
    repace_ = true;
  params_ = next;
  ++params_epoch_;
  if (changed.tellp() > 0)
    ROS_INFO_STREAM("tensegrity_sim: live parameters: " << changed.str());
}

bool SimNode::logDue(const std::string& kind, int& held)
{
  const WallClock::time_point now = WallClock::now();
  auto [it, first] = log_times_.try_emplace(kind, now, 0);
  if (!first && now - it->second.first < std::chrono::seconds(2))
  {
    ++it->second.second;
    return false;
  }
  held = first ? 0 : it->second.second;
  it->second = { now, 0 };
  return true;
}

void SimNode::diagnoseSimulation(diagnostic_updater::DiagnosticStatusWrapper& d)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  const bool slow = running() && params_.real_time_factor > 0.0 && rtf_ > 0.0 && rtf_ < 0.9 * params_.real_time_factor;
  const bool cut = step_cuts_ > diagnosed_cuts_;
  std::ostringstream summary;
  if (failed_)
    summary << "the solver failed (" << solver_status_ << "): " << message_ << "; call ~reset";
  else if (!running())
    summary << runState();
  else
    summary << "running at " << core::roundedNumber(rtf_, 3) << "x real time"
            << (params_.real_time_factor > 0.0 ? " (asked " + core::shortestNumber(params_.real_time_factor) + "x)" :
                                                 std::string(" (as fast as possible)"));
  if (!failed_ && slow)
    summary << "; slower than asked";
  if (!failed_ && cut)
    summary << "; " << (step_cuts_ - diagnosed_cuts_) << " step cuts since the last report";
  using diagnostic_msgs::DiagnosticStatus;
  d.summary(failed_       ? DiagnosticStatus::ERROR :
            (slow || cut) ? DiagnosticStatus::WARN :
                            DiagnosticStatus::OK,
            summary.str());
  d.add("scene", model_.name);
  d.add("sim_time", state_.t);
  d.add("steps", steps_);
  d.add("step_cuts", step_cuts_);
  d.add("real_time_factor", running() ? rtf_ : 0.0);
  d.add("requested_real_time_factor", params_.real_time_factor);
  d.add("publish_share", publish_share_);
  d.add("publish_wait_share", publish_wait_share_);
  d.add("solver_status", solver_status_);
  d.add("active_contacts", contacts_);
  d.add("pushes", acting_pushes_.size());
  diagnosed_cuts_ = step_cuts_;
}

void SimNode::diagnoseCommands(diagnostic_updater::DiagnosticStatusWrapper& d)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  const uint32_t new_rejections = rejected_ - diagnosed_rejected_;
  using diagnostic_msgs::DiagnosticStatus;
  if (new_rejections > 0)
    d.summaryf(DiagnosticStatus::WARN, "%u rejected since the last report; last: %s", new_rejections,
               last_rejection_.c_str());
  else
    d.summaryf(DiagnosticStatus::OK, "%u accepted, %u rejected", accepted_, rejected_);
  d.add("accepted", accepted_);
  d.add("rejected", rejected_);
  d.add("last_rejection", last_rejection_);
  d.add("last_motion_simulated", last_motion_sim_);
  d.add("last_motion_wall", last_motion_wall_);
  d.add("last_motion_real_time_factor", last_motion_wall_ > 0.0 ? last_motion_sim_ / last_motion_wall_ : 0.0);
  diagnosed_rejected_ = rejected_;
}

void SimNode::diagnosePlanner(diagnostic_updater::DiagnosticStatusWrapper& d)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  using diagnostic_msgs::DiagnosticStatus;
  const std::string state =
      plans_running_ > 0 ? (plan_holds_ > 0 ? "planning (the simulation held)" : "planning") : "idle";
  d.summary(last_plan_ok_ ? DiagnosticStatus::OK : DiagnosticStatus::WARN, state + "; last: " + last_plan_);
  d.add("state", state);
  d.add("requests_answered", plans_answered_);
  d.add("last_answer", last_plan_);
}

ros::Time SimNode::stamp(double t) const
{
  if (params_.publish_clock)
    return ros::Time(stamp_origin_ + t);
  return ros::Time::now();
}

void SimNode::reject(const std::string& what, const std::string& reason)
{
  ++rejected_;
  // a command's text (a name of a megabyte, say) reaches the latched status and the log only cut
  last_rejection_ = core::clipped(what + ": " + reason, 4 * core::kMaxEchoLength);
  int held = 0;
  if (logDue("rejected " + what, held))
    ROS_WARN_STREAM("tensegrity_sim: rejected "
                    << last_rejection_ << " (nothing applied; " << rejected_ << " rejected so far"
                    << (held > 0 ? ", " + std::to_string(held) + " more like it not logged" : std::string()) << ")");
  publishStatus();
}

void SimNode::onActuation(const active_tensegrity::ActuationCommand::ConstPtr& msg)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  const std::string err =
      controller_.setTargets(state_.t, msg->names, msg->targets, msg->max_speeds, msg->max_accelerations,
                             params_.default_speed, params_.default_acceleration);
  if (!err.empty())
  {
    reject("~actuation command", err);
    return;
  }
  ++accepted_;
  ++actuation_epoch_;
  std::ostringstream s;
  for (size_t i = 0; i < msg->names.size(); ++i)
    s << (i ? ", " : "") << core::clipped(msg->names[i]) << " -> " << msg->targets[i] << " m";
  int held = 0;
  if (logDue("actuation", held))
    ROS_INFO_STREAM(
        "tensegrity_sim: actuation at t = "
        << state_.t << " s: " << s.str()
        << (held > 0 ? " (" + std::to_string(held) + " commands since the last one logged)" : std::string()));
  publishStatus();
}

void SimNode::onTrajectory(const trajectory_msgs::JointTrajectory::ConstPtr& msg)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  std::vector<double> times;
  std::vector<std::vector<double>> positions, velocities;
  trajectoryArrays(*msg, times, positions, velocities);
  const std::string err = controller_.setTrajectory(state_.t, msg->joint_names, times, positions, velocities);
  if (!err.empty())
  {
    reject("~trajectory", err);
    return;
  }
  ++accepted_;
  ++actuation_epoch_;
  int held = 0;
  if (logDue("trajectory", held))
    ROS_INFO_STREAM("tensegrity_sim: trajectory of "
                    << msg->points.size() << " points for " << msg->joint_names.size()
                    << " actuators from t = " << state_.t << " s, " << times.back() << " s long"
                    << (held > 0 ? " (" + std::to_string(held) + " since the last one logged)" : std::string()));
  publishStatus();
}

core::Summary SimNode::restart(core::State& s)
{
  controller_.reset(s.u);
  was_moving_ = false;
  const core::Summary init = solver_.initialize(s, [this](double t) { return controller_.values(t); });
  if (init.ok() && finite(s) && params_.adaptive)
    stepper_ = std::make_unique<core::AdaptiveStepper>(solver_, model_.solver);  // a new step-size history
  return init;
}

bool SimNode::onReset(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  // stamps keep increasing across a reset (tf and bags never see time go back)
  stamp_origin_ += state_.t + 1.0 / params_.publish_rate;
  core::State fresh = core::initialState(model_);
  const core::Summary init = restart(fresh);
  if (!init.ok() || !finite(fresh))
  {
    res.success = false;
    res.message = "the initial state is not consistent: " + init.message;
    return true;
  }
  state_ = std::move(fresh);
  ++actuation_epoch_;
  pushes_.clear();
  applyPushes();
  failed_ = false;
  solver_status_ = runState();
  message_ = "reset";
  steps_ = step_cuts_ = 0;
  clear_markers_ = true;
  res.success = true;
  res.message = "reset to the scene's initial state";
  ROS_INFO("tensegrity_sim: reset");
  publishStatus();
  return true;
}

bool SimNode::onPause(std_srvs::SetBool::Request& req, std_srvs::SetBool::Response& res)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  if (!req.data && failed_)
  {
    res.success = false;
    res.message = "the solver failed (" + message_ + "); call ~reset first";
    return true;
  }
  paused_by_user_ = req.data;
  solver_status_ = runState();
  res.success = true;
  res.message = req.data ? "paused" : "running";
  ROS_INFO_STREAM("tensegrity_sim: " << res.message << " at t = " << state_.t << " s");
  publishStatus();
  return true;
}

namespace
{
/// The largest force (N) or torque (N m) a push may have.
constexpr double kMostPush = 1e9;

core::Vec3 vec3(const geometry_msgs::Vector3& v)
{
  return core::Vec3(v.x, v.y, v.z);
}

/// Whether a push's vector is usable, else the reason (naming `what`).
std::string checkPushVector(const core::Vec3& v, const std::string& what, const std::string& unit)
{
  if (!v.allFinite())
    return what + " must be finite, got (" + core::shortestNumber(v.x()) + ", " + core::shortestNumber(v.y()) + ", " +
           core::shortestNumber(v.z()) + ")";
  if (v.norm() > kMostPush)
    return what + " must be at most " + core::shortestNumber(kMostPush) + " " + unit + " in magnitude, got " +
           core::shortestNumber(v.norm());
  return "";
}
}  // namespace

std::string SimNode::wrenchLoads(const std::string& target, const geometry_msgs::Wrench& wrench,
                                 std::vector<core::PointLoad>& loads, std::string& note) const
{
  loads.clear();
  note.clear();
  const core::Vec3 force = vec3(wrench.force), torque = vec3(wrench.torque);
  if (std::string e = checkPushVector(force, "wrench.force", "N"); !e.empty())
    return e;
  if (std::string e = checkPushVector(torque, "wrench.torque", "N m"); !e.empty())
    return e;
  if (target.empty())
    return "target is empty (give a strut, point mass or node of the scene)";
  const int body = model_.findBody(target);
  const int node = body < 0 ? model_.findNode(target) : -1;
  if (body < 0 && node < 0)
    return "target " + core::quoted(target) + " is no strut, point mass or node of the scene";
  const std::string name = "push on " + target;
  if (body >= 0 && model_.bodies[body].kind == core::BodyKind::kStrut)
  {
    const core::Body& b = model_.bodies[body];
    loads.push_back({ name, core::PointRef{ body, core::Vec3::Zero() }, force });
    if (torque.squaredNorm() > 0.0)
    {
      // two opposite forces at the ends, f = (tau x u) / |u|^2 at the end u points to: their moment u x f is the
      // torque's part across the strut
      const core::PointRef end_a{ body, core::Vec3(0.0, 0.0, -0.5 * b.length) };
      const core::PointRef end_b{ body, core::Vec3(0.0, 0.0, 0.5 * b.length) };
      const core::Vec3 u = core::pointPosition(model_, end_b, state_.q) - core::pointPosition(model_, end_a, state_.q);
      const core::Vec3 f = torque.cross(u) / u.squaredNorm();
      loads.push_back({ name, end_b, f });
      loads.push_back({ name, end_a, -f });
      const double along = torque.dot(u.normalized());
      if (std::abs(along) > 1e-12 * torque.norm())
        note = "; the torque's part along the strut (" + core::shortestNumber(along) +
               " N m) is dropped: a strut has no stiffness about its own axis";
    }
    return "";
  }
  if (torque.squaredNorm() > 0.0)
    return "wrench.torque must be zero on " + std::string(body >= 0 ? "point mass " : "node ") + core::quoted(target) +
           " (a point takes a force only), got a torque of " + core::shortestNumber(torque.norm()) + " N m";
  const core::PointRef point = body >= 0 ? core::PointRef{ body, core::Vec3::Zero() } : model_.nodes[node].point;
  if (point.body < 0)
    return "node " + core::quoted(target) + " is fixed: nothing moves it";
  loads.push_back({ name, point, force });
  return "";
}

double SimNode::applyPushes()
{
  const double t = state_.t;
  pushes_.erase(std::remove_if(pushes_.begin(), pushes_.end(),
                               [t](const Push& p)
                               { return std::isfinite(p.end) && p.end - t <= 1e-10 * std::max(1.0, std::abs(p.end)); }),
                pushes_.end());
  std::vector<uint64_t> acting;
  double next_end = std::numeric_limits<double>::infinity();
  for (const Push& p : pushes_)
  {
    acting.push_back(p.id);
    next_end = std::min(next_end, p.end);
  }
  if (acting != acting_pushes_)
  {
    std::vector<core::PointLoad> loads;
    for (const Push& p : pushes_)
      loads.insert(loads.end(), p.loads.begin(), p.loads.end());
    // the forces jump here: the integration restarts from the live state (consistent accelerations)
    const core::Summary restart = solver_.setExternalLoads(std::move(loads), state_);
    acting_pushes_ = std::move(acting);
    if (!restart.ok() && !failed_)
    {
      failed_ = true;
      solver_status_ = core::toString(restart.status);
      message_ = "the pushes changed at t = " + core::shortestNumber(t) + " s: " + restart.message;
      ROS_ERROR_STREAM("tensegrity_sim: " << message_ << "; paused, call ~reset to start again");
    }
  }
  return next_end;
}

bool SimNode::onApplyWrench(active_tensegrity::ApplyWrench::Request& req, active_tensegrity::ApplyWrench::Response& res)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  Push push;
  std::string note;
  std::string err = wrenchLoads(req.target, req.wrench, push.loads, note);
  if (err.empty() && !(req.duration > 0.0 || req.duration == -1.0))
    err = "duration must be > 0 s of simulated time, or -1 (until ~clear_wrenches), got " +
          core::shortestNumber(req.duration);
  if (err.empty() && req.duration > 0.0 && !std::isfinite(state_.t + req.duration))
    err = "duration must be finite, got " + core::shortestNumber(req.duration);
  res.success = err.empty();
  if (!err.empty())
  {
    res.message = "refused: " + err + " (nothing applied)";
    reject("~apply_wrench", err);
    return true;
  }
  push.id = next_push_id_++;
  push.target = req.target;
  push.end = req.duration > 0.0 ? state_.t + req.duration : std::numeric_limits<double>::infinity();
  pushes_.push_back(std::move(push));
  applyPushes();
  ++accepted_;
  std::ostringstream m;
  m << "pushing " << core::quoted(req.target) << " from t = " << state_.t << " s "
    << (req.duration > 0.0 ? "for " + core::shortestNumber(req.duration) + " s" : std::string("until cleared")) << note;
  res.message = m.str();
  ROS_INFO_STREAM("tensegrity_sim: " << res.message);
  publishStatus();
  return true;
}

void SimNode::onWrench(const active_tensegrity::TargetWrench::ConstPtr& msg)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  Push push;
  std::string note;
  const std::string err = wrenchLoads(msg->target, msg->wrench, push.loads, note);
  if (!err.empty())
  {
    reject("~wrench", err);
    return;
  }
  const core::Vec3 force = vec3(msg->wrench.force), torque = vec3(msg->wrench.torque);
  // the same load again: nothing changes (the integration restarts only where the forces jump)
  const bool same =
      std::any_of(pushes_.begin(), pushes_.end(),
                  [&](const Push& p)
                  { return p.standing && p.target == msg->target && p.force == force && p.torque == torque; });
  if (same)
  {
    ++accepted_;
    return;
  }
  pushes_.erase(std::remove_if(pushes_.begin(), pushes_.end(),
                               [&](const Push& p) { return p.standing && p.target == msg->target; }),
                pushes_.end());
  const bool zero = force.squaredNorm() == 0.0 && torque.squaredNorm() == 0.0;
  if (!zero)
  {
    push.id = next_push_id_++;
    push.target = msg->target;
    push.end = std::numeric_limits<double>::infinity();
    push.standing = true;
    push.force = force;
    push.torque = torque;
    pushes_.push_back(std::move(push));
  }
  applyPushes();
  ++accepted_;
  publishStatus();
}

bool SimNode::onClearWrenches(std_srvs::Trigger::Request& /*req*/, std_srvs::Trigger::Response& res)
{
  const std::lock_guard<std::mutex> lock(mutex_);
  const size_t n = pushes_.size();
  pushes_.clear();
  applyPushes();
  res.success = true;
  res.message = "cleared " + std::to_string(n) + (n == 1 ? " push" : " pushes");
  ROS_INFO_STREAM("tensegrity_sim: " << res.message << " at t = " << state_.t << " s");
  publishStatus();
  return true;
}

bool SimNode::onPlan(active_tensegrity::PlanFolding::Request& req, active_tensegrity::PlanFolding::Response& res)
{
  plan(req, res, {});
  return true;
}

template <typename Request, typename Answer>
void SimNode::plan(const Request& req, Answer& res, const planning::PlanControl& control)
{
  namespace ap = active_tensegrity::planning;
  res.executed = false;
  // /diagnostics: a request under way from here, answered on every way out
  class Record
  {
  public:
    Record(SimNode& node, const Answer& answer) : node_(node), answer_(answer)
    {
      const std::lock_guard<std::mutex> lock(node_.mutex_);
      ++node_.plans_running_;
    }
    ~Record()
    {
      const std::lock_guard<std::mutex> lock(node_.mutex_);
      --node_.plans_running_;
      ++node_.plans_answered_;
      const auto status = static_cast<ap::PlanStatus>(answer_.status);
      node_.last_plan_ = std::string(ap::toString(status)) + (answer_.executed ? ", executed" : "");
      node_.last_plan_ok_ = status == ap::PlanStatus::kExactSolution;
    }
    Record(const Record&) = delete;
    Record& operator=(const Record&) = delete;

  private:
    SimNode& node_;
    const Answer& answer_;
  } record(*this, res);
  if (req.allow_contact && !(req.max_contact_force > 0.0))
  {
    res.status = static_cast<uint8_t>(ap::PlanStatus::kInvalidRequest);
    res.message =
        "max_contact_force must be > 0 N when allow_contact is set, got " + core::shortestNumber(req.max_contact_force);
    const std::lock_guard<std::mutex> lock(mutex_);
    int held = 0;
    if (logDue("plan refused", held))
      ROS_WARN_STREAM("tensegrity_sim: ~plan_folding refused: " << res.message);
    return;
  }
  SimParams params;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    params = params_;
  }
  ap::PlanRequest r = planRequest(req, params);
  // the path from the quasi-static equilibrium nearest to the live state (folded, moving) where the actuators
  // come to rest, found within the request's deadline; the verification from the live state itself, under the
  // actuation law in force
  r.relax_start = true;
  core::State live;
  std::unique_ptr<core::ActuationController> law;
  uint64_t epoch = 0;
  // with execute the simulation is held from here to the answer: the trajectory then runs from the state it
  // was planned and verified from (released on every way out)
  class Hold
  {
  public:
    Hold(SimNode& node, bool on) : node_(node), on_(on) {}
    ~Hold()
    {
      if (!on_)
        return;
      const std::lock_guard<std::mutex> lock(node_.mutex_);
      release();
    }
    Hold(const Hold&) = delete;
    Hold& operator=(const Hold&) = delete;
    void take()  // mutex held
    {
      if (!on_)
        return;
      ++node_.plan_holds_;
      if (!node_.failed_)
        node_.solver_status_ = node_.runState();
      node_.publishStatus();
    }
    void release()  // mutex held
    {
      if (!on_)
        return;
      on_ = false;
      --node_.plan_holds_;
      if (!node_.failed_)
        node_.solver_status_ = node_.runState();
      node_.publishStatus();
    }

  private:
    SimNode& node_;
    bool on_;
  } hold(*this, req.execute);
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    live = state_;
    law = std::make_unique<core::ActuationController>(controller_);
    epoch = actuation_epoch_;
    hold.take();
  }
  const ap::PlanResult result = ap::planFolding(model_, live, r, control, law.get());
  fillAnswer(result, res);
  ROS_INFO_STREAM("tensegrity_sim: ~plan_folding: " << planning::toString(result.status) << " ("
                                                    << core::clipped(result.message, 4 * core::kMaxEchoLength) << "), "
                                                    << result.waypoints.size() << " waypoints, "
                                                    << result.equilibrium_solves << " equilibrium solves, "
                                                    << result.planning_time << " s");
  if (!req.execute)
    return;
  std::string not_run;
  if (result.status != ap::PlanStatus::kExactSolution)
    not_run = "not an exact solution";
  else if ((r.verify_dynamics || r.find_speed_limit) && !result.dynamics_within_limits && !req.execute_unverified)
    not_run = std::string("the dynamic verification ") +
              (result.dynamics_verified ? "found the trajectory outside the limits" : "did not complete") +
              " (execute_unverified runs it anyway)";
  if (!not_run.empty())
  {
    res.message += "; not executed: " + not_run;
    return;
  }
  const std::lock_guard<std::mutex> lock(mutex_);
  std::string err;
  if (actuation_epoch_ != epoch)
    err = "the actuation or the state changed while planning (a command, a trajectory, a reset or another plan's "
          "execution): the plan starts from the state the request found";
  else
    err = controller_.setTrajectory(state_.t, result.names, result.times, result.positions, result.velocities);
  if (err.empty())
  {
    res.executed = true;
    ++accepted_;
    ++actuation_epoch_;
    ROS_INFO_STREAM("tensegrity_sim: ~plan_folding: executing from t = " << state_.t << " s, " << result.duration
                                                                         << " s long");
  }
  else
  {
    res.message += "; not executed: " + err;
    reject("~plan_folding execution", err);
  }
  hold.release();  // the simulation runs on (unless paused) with the trajectory in force
}

void SimNode::onPlanGoal(const active_tensegrity::PlanFoldingGoalConstPtr& goal)
{
  planning::PlanControl control;
  control.cancelled = [this] { return plan_action_->isPreemptRequested() || !ros::ok(); };
  control.progress = [this](const planning::PlanProgress& p)
  {
    active_tensegrity::PlanFoldingFeedback f;
    f.elapsed = p.elapsed;
    f.equilibrium_solves = static_cast<uint32_t>(p.equilibrium_solves);
    f.best_height = p.best_height;
    f.best_distance = p.best_distance;
    f.phase = p.phase;
    plan_action_->publishFeedback(f);
  };
  active_tensegrity::PlanFoldingResult res;
  plan(*goal, res, control);
  if (res.cancelled)
    plan_action_->setPreempted(res, res.message);
  else if (res.status == res.EXACT_SOLUTION && (!goal->execute || res.executed))
    plan_action_->setSucceeded(res, res.message);
  else
    plan_action_->setAborted(res, res.message);  // (an exact plan asked to execute that did not: the message says why)
}

void SimNode::onFollowGoal(const active_tensegrity::FollowTrajectoryGoalConstPtr& goal)
{
  using Result = active_tensegrity::FollowTrajectoryResult;
  Result result;
  std::vector<double> times;
  std::vector<std::vector<double>> positions, velocities;
  trajectoryArrays(goal->trajectory, times, positions, velocities);
  const std::vector<std::string>& names = goal->trajectory.joint_names;
  std::string err;
  double t0 = 0.0;
  std::unique_ptr<core::ActuationController> reference;  // the trajectory alone: the desired values
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (!(goal->path_tolerance >= 0.0) || !(goal->goal_tolerance >= 0.0) || !(goal->goal_time_tolerance >= 0.0) ||
        !std::isfinite(goal->goal_time_tolerance))
      err = "path_tolerance, goal_tolerance and goal_time_tolerance must be >= 0 (0 = the default), got " +
            core::shortestNumber(goal->path_tolerance) + ", " + core::shortestNumber(goal->goal_tolerance) + ", " +
            core::shortestNumber(goal->goal_time_tolerance);
    else
      err = controller_.setTrajectory(state_.t, names, times, positions, velocities);
    if (err.empty())
    {
      reference = std::make_unique<core::ActuationController>(controller_);
      t0 = state_.t;
      ++accepted_;
      ++actuation_epoch_;
      publishStatus();
    }
    else
      reject("~follow_trajectory goal", err);
  }
  if (!err.empty())
  {
    result.error_code = Result::INVALID_GOAL;
    result.error_string = err;
    follow_action_->setAborted(result, err);
    return;
  }
  std::vector<int> idx;
  for (const std::string& n : names)
    idx.push_back(reference->index(n));
  const double t_end = t0 + times.back();
  const double goal_tolerance = goal->goal_tolerance > 0.0 ? goal->goal_tolerance : 1e-3;
  const double goal_time = goal->goal_time_tolerance > 0.0 ? goal->goal_time_tolerance : 1.0;
  const auto finish = [&](int code, const std::string& why)
  {
    result.error_code = code;
    result.error_string = why;
    if (code == Result::SUCCESSFUL)
      follow_action_->setSucceeded(result, why);
    else
      follow_action_->setAborted(result, why);
  };
  double publish_rate = 0.0;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    publish_rate = params_.publish_rate;
  }
  ros::WallRate rate(std::min(20.0, publish_rate));
  active_tensegrity::FollowTrajectoryFeedback f;
  f.joint_names = names;
  while (true)
  {
    if (!ros::ok() || follow_action_->isPreemptRequested())
    {
      // hold every named actuator where it is (a ramp to its current value)
      const std::lock_guard<std::mutex> lock(mutex_);
      const core::ActuationValues now = controller_.values(state_.t);
      std::vector<double> here;
      for (int a : idx)
        here.push_back(now[a].value);
      controller_.setTargets(state_.t, names, here, {}, {}, params_.default_speed, params_.default_acceleration);
      ++actuation_epoch_;
      result.error_code = Result::SUCCESSFUL;
      result.error_string = "preempted: the actuators hold where they were";
      follow_action_->setPreempted(result, result.error_string);
      return;
    }
    double t = 0.0;
    bool failed = false;
    f.actual.clear();
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      t = state_.t;
      failed = failed_;
      for (int a : idx)
        f.actual.push_back(state_.u[a].value);
    }
    const core::ActuationValues want = reference->values(t);
    f.sim_time = t;
    f.desired.clear();
    f.error.clear();
    double worst = 0.0;
    size_t worst_i = 0;
    for (size_t i = 0; i < idx.size(); ++i)
    {
      f.desired.push_back(want[idx[i]].value);
      f.error.push_back(f.desired[i] - f.actual[i]);
      if (std::abs(f.error[i]) > worst)
      {
        worst = std::abs(f.error[i]);
        worst_i = i;
      }
    }
    follow_action_->publishFeedback(f);
    if (failed)
      return finish(Result::PATH_TOLERANCE_VIOLATED, "the simulation failed (see ~status); call ~reset");
    if (goal->path_tolerance > 0.0 && t <= t_end && worst > goal->path_tolerance)
      return finish(Result::PATH_TOLERANCE_VIOLATED,
                    "at t = " + core::shortestNumber(t) + " s actuator " + core::quoted(names[worst_i]) + " is " +
                        core::shortestNumber(f.actual[worst_i]) + " m, the trajectory " +
                        core::shortestNumber(f.desired[worst_i]) + " m (path_tolerance " +
                        core::shortestNumber(goal->path_tolerance) + " m)");
    if (t >= t_end)
    {
      double off = 0.0;
      size_t off_i = 0;
      for (size_t i = 0; i < idx.size(); ++i)
        if (std::abs(f.actual[i] - positions.back()[i]) > off)
        {
          off = std::abs(f.actual[i] - positions.back()[i]);
          off_i = i;
        }
      if (off <= goal_tolerance)
        return finish(Result::SUCCESSFUL, "");
      if (t >= t_end + goal_time)
        return finish(Result::GOAL_TOLERANCE_VIOLATED,
                      "actuator " + core::quoted(names[off_i]) + " is " + core::shortestNumber(f.actual[off_i]) +
                          " m, " + core::shortestNumber(off) + " m from its goal " +
                          core::shortestNumber(positions.back()[off_i]) + " m, " + core::shortestNumber(t - t_end) +
                          " s after the trajectory's end (goal_tolerance " + core::shortestNumber(goal_tolerance) +
                          " m)");
    }
    rate.sleep();
  }
}

void SimNode::publishStatus()
{
  active_tensegrity::SimStatus s;
  s.header.stamp = stamp(state_.t);
  s.header.frame_id = params_.frame_id;
  s.sim_time = state_.t;
  s.steps = steps_;
  s.step_cuts = step_cuts_;
  s.real_time_factor = running() ? rtf_ : 0.0;
  s.publish_share = publish_share_;
  s.paused = !running();
  s.solver_status = solver_status_;
  s.message = message_;
  s.commands_accepted = accepted_;
  s.commands_rejected = rejected_;
  s.last_rejection = last_rejection_;
  s.wrenches = static_cast<uint32_t>(acting_pushes_.size());
  status_pub_.publish(s);
}

SimNode::~SimNode()
{
  {
    const std::lock_guard<std::mutex> lock(out_mutex_);
    stop_publishing_ = true;
  }
  out_cv_.notify_all();
  if (publisher_.joinable())
    publisher_.join();
}

double SimNode::send(Outgoing&& out)
{
  std::unique_lock<std::mutex> lock(out_mutex_);
  double waited = 0.0;
  if (outgoing_.size() >= kPublishQueue)
  {
    const WallClock::time_point t0 = WallClock::now();
    out_cv_.wait(lock, [this] { return outgoing_.size() < kPublishQueue || stop_publishing_; });
    waited = seconds(WallClock::now() - t0);
  }
  outgoing_.push_back(std::move(out));
  lock.unlock();
  out_cv_.notify_all();
  return waited;
}

void SimNode::publishLoop()
{
  for (;;)
  {
    Outgoing out;
    {
      std::unique_lock<std::mutex> lock(out_mutex_);
      out_cv_.wait(lock, [this] { return !outgoing_.empty() || stop_publishing_; });
      if (outgoing_.empty())
        return;  // (stopping, and every publication made went out)
      out = std::move(outgoing_.front());
      outgoing_.pop_front();
    }
    out_cv_.notify_all();
    const WallClock::time_point t0 = WallClock::now();
    publish(out);
    const double busy = seconds(WallClock::now() - t0);
    const std::lock_guard<std::mutex> lock(out_mutex_);
    publishing_busy_ += busy;
  }
}

void SimNode::publish(Outgoing& out)
{
  if (out.options)
    builder_.setOptions(*out.options);
  if (out.clear_markers)
  {
    builder_.clearMarkers();
    markers_missed_ = false;  // (the missed ones are of the state before the reset)
  }
  if (out.markers_now)
    next_markers_ = WallClock::time_point::min();
  if (out.kind == Outgoing::Kind::kMissedMarkers)
  {
    if (!markers_missed_)
      return;
    markers_missed_ = false;
    markers_pub_.publish(
        builder_.build(last_published_, last_stamp_, last_have_contacts_ ? &last_contacts_ : nullptr).markers);
    return;
  }
  if (out.publish_clock)
  {
    rosgraph_msgs::Clock c;
    c.clock = out.stamp;
    clock_pub_.publish(c);
  }
  if (out.kind == Outgoing::Kind::kClock)
    return;
  // markers are for rviz, which draws at screen rates: at most marker_rate per wall second (building them with every
  // publication would take a large share of the publishing thread)
  const WallClock::time_point now = WallClock::now();
  const bool markers = out.marker_rate <= 0.0 || now >= next_markers_;
  const std::vector<core::ContactPairState>* contacts = out.have_contacts ? &out.contacts : nullptr;
  const Snapshot snap = builder_.build(out.state, out.stamp, contacts, markers);
  {
    const std::lock_guard<std::mutex> lock(out_mutex_);
    published_contacts_ = snap.contacts.contacts.size();
  }
  tf2_msgs::TFMessage tf;
  tf.transforms = snap.transforms;
  tf_pub_.publish(tf);
  contacts_pub_.publish(snap.contacts);
  cables_pub_.publish(snap.cables);
  struts_pub_.publish(snap.struts);
  actuators_pub_.publish(snap.actuators);
  markers_missed_ = !markers;
  if (markers)
  {
    markers_pub_.publish(snap.markers);
    if (out.marker_rate > 0.0)
      next_markers_ = now + wallSpan(1.0 / out.marker_rate);
  }
  else
  {
    std::swap(last_published_, out.state);
    std::swap(last_contacts_, out.contacts);
    last_have_contacts_ = out.have_contacts;
    last_stamp_ = out.stamp;
  }
}

void SimNode::run()
{
  const double dt = model_.solver.dt;
  const core::ActuationLaw law =
      core::ActuationLaw::writing([this](double t, core::ActuationValues& u) { controller_.values(t, u); });
  publisher_ = std::thread([this] { publishLoop(); });

  // pacing: simulated time since (pace_wall, pace_sim) runs at real_time_factor
  WallClock::time_point pace_wall = WallClock::now();
  double pace_sim = 0.0;
  // real-time factor, publishing share and the stepping's wait for publishing over windows of about a second
  WallClock::time_point window_wall = pace_wall;
  double window_sim = 0.0, window_wait = 0.0;
  double next_publish = 0.0;
  bool was_running = false;
  // whether the markers the last publication went without were asked for since the simulation stopped
  bool missed_asked = false;
  // what goes with the next publication: new marker options, fresh markers after a reset, markers at once
  std::optional<MarkerOptions> options;
  bool clear_markers = false, markers_now = false;
  // with ~max_publish_wall_rate: the wall time before which the data topics do not go again
  WallClock::time_point next_data = WallClock::time_point::min();

  // /diagnostics once a second of wall time (the updater's own period runs on ros::Time, which is simulated time
  // with ~publish_clock: thousands of reports a wall second at real_time_factor 0)
  WallClock::time_point next_diagnostics = WallClock::now();

  while (ros::ok())
  {
    if (WallClock::now() >= next_diagnostics)
    {
      diagnostics_.force_update();  // (takes the mutex itself)
      next_diagnostics = WallClock::now() + std::chrono::seconds(1);
    }
    std::optional<Outgoing> out;
    const auto outgoing = [&](Outgoing::Kind kind)
    {
      out.emplace();
      out->kind = kind;
      out->options = std::move(options);
      options.reset();
      out->clear_markers = std::exchange(clear_markers, false);
      out->markers_now = std::exchange(markers_now, false);
      out->marker_rate = loop_params_.marker_rate;
      out->publish_clock = loop_params_.publish_clock;
    };
    bool idle = false;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      if (loop_params_epoch_ != params_epoch_)
      {
        loop_params_ = params_;
        loop_params_epoch_ = params_epoch_;
        options = loop_params_.markers;
      }
      if (repace_)
      {
        // a new real-time factor: paced from here
        repace_ = false;
        pace_wall = WallClock::now();
        pace_sim = state_.t;
      }
      if (clear_markers_)
      {
        // after a reset: fresh markers, publish at once, pace from the new start
        clear_markers = true;
        clear_markers_ = false;
        next_publish = state_.t;
        was_running = false;
        missed_asked = true;  // (the missed ones are of the state before the reset)
      }
      if (!running())
      {
        was_running = false;
        idle = true;
        if (!missed_asked)
        {
          outgoing(Outgoing::Kind::kMissedMarkers);
          missed_asked = true;
        }
      }
      else
      {
        missed_asked = false;
        if (!was_running)
        {
          // (re)start: pace from here, publish at once (markers too)
          pace_wall = window_wall = WallClock::now();
          markers_now = true;
          pace_sim = window_sim = state_.t;
          window_wait = 0.0;
          {
            const std::lock_guard<std::mutex> out_lock(out_mutex_);
            publishing_busy_ = 0.0;
          }
          next_publish = std::min(next_publish, state_.t);
          was_running = true;
        }
        const double period = 1.0 / loop_params_.publish_rate;
        if (state_.t >= next_publish - 1e-9 * dt)
        {
          next_publish = state_.t + period;
          // (with a wall-rate cap, a publication due before the cap allows is left out)
          const WallClock::time_point now = WallClock::now();
          if (loop_params_.max_publish_wall_rate <= 0.0 || now >= next_data)
          {
            if (loop_params_.max_publish_wall_rate > 0.0)
              next_data = now + wallSpan(1.0 / loop_params_.max_publish_wall_rate);
            outgoing(Outgoing::Kind::kState);
            out->state = state_;
            solver_.formActuatorForces(out->state);  // (the actuators' efforts; a step leaves them unformed)
            out->stamp = stamp(state_.t);
            if (const std::vector<core::ContactPairState>* c = solver_.contactsAt(state_))
            {
              out->contacts = *c;
              out->have_contacts = true;
            }
          }
          else if (loop_params_.publish_clock)
          {
            // /clock goes on at the publish rate (nodes on simulated time need it)
            outgoing(Outgoing::Kind::kClock);
            out->stamp = stamp(state_.t);
          }
        }
        else
          stepOnce(dt, next_publish, law);
      }
    }

    if (out)
    {
      const bool state = out->kind == Outgoing::Kind::kState;
      const double t = out->state.t;
      window_wait += send(std::move(*out));
      const double wall = seconds(WallClock::now() - window_wall);
      if (state && wall >= 1.0)
      {
        double busy = 0.0;
        size_t contacts = 0;
        {
          const std::lock_guard<std::mutex> out_lock(out_mutex_);
          busy = std::exchange(publishing_busy_, 0.0);
          contacts = published_contacts_;
        }
        const std::lock_guard<std::mutex> lock(mutex_);
        rtf_ = (t - window_sim) / wall;
        contacts_ = contacts;
        publish_share_ = busy / wall;
        publish_wait_share_ = window_wait / wall;
        window_wall = WallClock::now();
        window_sim = t;
        window_wait = 0.0;
        publishStatus();
      }
    }
    if (idle)
    {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      continue;
    }
    if (out)
      continue;

    if (loop_params_.real_time_factor > 0.0)
    {
      double t_now = 0.0;
      {
        const std::lock_guard<std::mutex> lock(mutex_);
        t_now = state_.t;
      }
      const WallClock::time_point due = pace_wall + wallSpan((t_now - pace_sim) / loop_params_.real_time_factor);
      if (due > WallClock::now())
        std::this_thread::sleep_until(due);
    }
  }
}

void SimNode::stepOnce(double dt, double next_publish, const core::ActuationLaw& law)
{
  const core::State before = state_;
  const WallClock::time_point wall_before = WallClock::now();
  const double push_end = applyPushes();
  core::Summary s;
  if (stepper_)
  {
    // to the next publish time (or the end of a push), in the steps the error control allows
    const long accepted = stepper_->stats().accepted;
    s = stepper_->advanceTo(state_, std::min(next_publish, push_end), law);
    steps_ += static_cast<uint64_t>(stepper_->stats().accepted - accepted);
  }
  else
  {
    // t = k dt exactly (no drift from summing steps)
    const double t_next = static_cast<double>(steps_ + 1) * dt;
    s = solver_.step(state_, t_next - state_.t, law);
    ++steps_;
    if (s.ok())
      state_.t = t_next;
  }
  step_cuts_ += s.step_cuts;
  if (!s.ok() || !finite(state_))
  {
    // the solver keeps the last good state when a step fails; never publish a non-finite one
    if (!finite(state_))
      state_ = before;
    failed_ = true;
    solver_status_ = s.ok() ? "non_finite" : core::toString(s.status);
    message_ = s.ok() ? "non-finite state" : s.message;
    ROS_ERROR_STREAM("tensegrity_sim: the solver failed at t = " << state_.t << " s (" << solver_status_ << ": "
                                                                 << message_
                                                                 << "); paused at the last good step, call "
                                                                    "~reset to start again");
    publishStatus();
    return;
  }
  const bool moving = controller_.moving(state_.t);
  if (moving && !was_moving_)
  {
    motion_start_sim_ = before.t;
    motion_start_wall_ = wall_before;
  }
  else if (!moving && was_moving_)
  {
    last_motion_sim_ = state_.t - motion_start_sim_;
    last_motion_wall_ = std::chrono::duration<double>(WallClock::now() - motion_start_wall_).count();
  }
  was_moving_ = moving;
}

int runSimNode()
{
  ros::NodeHandle nh, pnh("~");
  SimParams params;
  core::Model model;
  try
  {
    params = loadSimParams(pnh);
    model = core::loadScene(params.scene, params.overrides);
    // the node integrates the scene's dynamics whatever its analysis.type: the contacts evaluated outside the solver
    // (a published state the solver did not end a step in, status rows) are the dynamic ones, damping and friction
    // included
    model.analysis.type = core::AnalysisType::kDynamic;
  }
  catch (const std::exception& e)
  {
    ROS_FATAL_STREAM("tensegrity_sim: " << e.what());
    return 1;
  }
  // command defaults from the scene when not given; every effective value back to the parameter server (where
  // the dynamic_reconfigure server starts from)
  resolveCommandDefaults(params, model);
  writeSimParams(pnh, params);
  ROS_INFO_STREAM("tensegrity_sim: scene '" << model.name << "': " << model.bodies.size() << " bodies, "
                                            << model.cables.size() << " cables, " << model.actuators.size()
                                            << " actuators, " << model.checkedPairCount()
                                            << " checked strut pairs, dt = " << model.solver.dt << " s\n"
                                            << params.describe());
  try
  {
    SimNode node(nh, pnh, params, std::move(model));
    // two threads: a long ~plan_folding call does not hold up commands and the other services
    ros::AsyncSpinner spinner(2);
    spinner.start();
    node.run();
    spinner.stop();
  }
  catch (const std::exception& e)
  {
    ROS_FATAL_STREAM("tensegrity_sim: " << e.what());
    return 1;
  }
  return 0;
}

}  // namespace active_tensegrity::ros_layer
