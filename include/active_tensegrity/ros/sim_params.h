/// The tensegrity_sim node's parameters: read from its private namespace, validated and logged in
/// one place (docs/ros.md lists them). A bad value is refused with the parameter's name and value.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

#include <ros/node_handle.h>

#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/ros/messages.h"

namespace active_tensegrity::ros_layer
{
/// A parameter that cannot be used: what() names it and its value.
class ParamError : public std::runtime_error
{
public:
  using std::runtime_error::runtime_error;
};

struct SimParams
{
  std::string scene;                      // resolved file path
  std::vector<core::Override> overrides;  // from ~overrides, applied to the scene
  double real_time_factor = 1.0;          // simulated s per wall s; 0 = as fast as possible
  double publish_rate = 50.0;             // Hz of simulated time
  double marker_rate = 30.0;              // ~markers at most this often, Hz of wall time (0: every publication)
  double max_publish_wall_rate = 0.0;     // data topics and tf at most this often, Hz of wall time (0: no cap)
  bool publish_clock = false;             // /clock from the simulation (stamps in simulated time)
  /// the publishers' queue of the data topics and /tf, messages per subscriber: a subscriber that keeps up on
  /// average takes every message when bursts of publications come faster than it takes them
  int queue_size = 1000;
  std::string frame_id = "world";
  /// prefixed to every body's tf frame ("robot_a" gives robot_a/S1); default: the node's namespace without
  /// its leading slash (empty in the root namespace: frames are the bodies' names)
  std::string tf_prefix;
  double default_speed = 0.0;         // m/s for commands without max_speeds (0: the scene's actuation.speed)
  double default_acceleration = 0.0;  // m/s^2 for commands without max_accelerations (0: derived)
  bool start_paused = false;
  /// steps chosen by the scene's error control (solver.error_tolerance, onset_depth, dt_min, dt_max; the
  /// steps land on the publish times); false: fixed steps of solver.dt
  bool adaptive = true;
  MarkerOptions markers;

  /// One line per parameter with its effective value.
  std::string describe() const;
};

/// The parameters that change while the node runs (dynamic_reconfigure, cfg/Sim.cfg), by name.
const std::vector<std::string>& liveParamNames();
/// Why `value` cannot be live parameter `name` (the message names both), or "" when it can.
std::string checkLiveParam(const std::string& name, double value);
/// A live parameter's value in p, and setting it (names from liveParamNames()).
double liveParam(const SimParams& p, const std::string& name);
void setLiveParam(SimParams& p, const std::string& name, double value);

/// A default of 0 (default_speed, default_acceleration) made the scene's: its actuation.speed (else 0.1 m/s)
/// and that over its blend_time (else 0.1 s).
void resolveCommandDefaults(SimParams& params, const core::Model& model);

/// Writes every effective value (defaults included) back to the private namespace: `rosparam list` and
/// `rosparam get` show what the node runs with.
void writeSimParams(ros::NodeHandle& private_nh, const SimParams& p);

/// `package://pkg/rest` -> the package's path + rest (rospack); anything else is returned as is.
/// Throws ParamError when the package is unknown.
std::string resolvePackageUrl(const std::string& url);

/// Reads and checks every parameter (throws ParamError).
SimParams loadSimParams(const ros::NodeHandle& private_nh);

}  // namespace active_tensegrity::ros_layer
