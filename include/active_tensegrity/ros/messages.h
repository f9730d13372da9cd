/// Core state -> ROS messages: the one conversion the node (live topics) and tensegrity_run --bag
/// (a bag written without a master) share, so that both carry the same frames, topics and markers.
/// No physics here: everything is read from the core (contacts, cable states, actuation forces).
#pragma once

#include <string>
#include <vector>

#include <geometry_msgs/TransformStamped.h>
#include <ros/time.h>
#include <sensor_msgs/JointState.h>
#include <visualization_msgs/MarkerArray.h>

#include "active_tensegrity/CableArray.h"
#include "active_tensegrity/StrutArray.h"
#include "active_tensegrity/ContactArray.h"
#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::ros_layer
{
/// How markers are drawn (docs/ros.md explains each).
struct MarkerOptions
{
  /// contact arrows: length = force * scale (m per N; 4e-3: 250 N per metre), tail at the contact
  /// point of the strut the force acts on. Normal forces yellow, friction forces cyan, on both struts.
  double contact_force_scale = 4e-3;
  /// cable colour: blue (0 N) to red (>= this tension, N); 0 = the largest tension of the moment
  double cable_tension_scale = 0.0;
  double cable_width = 0.01;  // m (line width of taut cables; slack ones are drawn thinner, grey)
  double strut_alpha = 0.7;   // strut opacity (arrows at contacts start inside the struts' surfaces)
};

/// Everything published for one state at one stamp.
struct Snapshot
{
  std::vector<geometry_msgs::TransformStamped> transforms;
  active_tensegrity::ContactArray contacts;
  active_tensegrity::CableArray cables;
  active_tensegrity::StrutArray struts;
  sensor_msgs::JointState actuators;
  visualization_msgs::MarkerArray markers;
};

class MessageBuilder
{
public:
  /// tf frames: frame_id the parent, each body's frame bodyFrame(model, body, tf_prefix).
  MessageBuilder(const core::Model& model, std::string frame_id, MarkerOptions options, std::string tf_prefix = "");

  /// All messages for `state` stamped `stamp`. Markers of contacts that ended since the previous
  /// call with markers are deleted (the builder remembers which arrows it drew). `contacts`: the state's active
  /// contacts when the caller has them (core::DynamicsSolver::contactsAt), else null and they are searched for
  /// here. With `markers` false the snapshot's markers stay empty (their building is most of a snapshot's cost).
  Snapshot build(const core::State& state, const ros::Time& stamp,
                 const std::vector<core::ContactPairState>* contacts = nullptr, bool markers = true);
  /// Forget the drawn arrows (after a reset) and delete every marker on the next build.
  void clearMarkers();

  const std::string& frameId() const
  {
    return frame_id_;
  }
  /// The drawing options from the next build on (the node's live parameters).
  void setOptions(const MarkerOptions& options)
  {
    options_ = options;
  }

private:
  void addMarkers(const core::State& state, const std::vector<core::ContactPairState>& contacts,
                  const std::vector<core::CableState>& cables, const ros::Time& stamp,
                  visualization_msgs::MarkerArray& out);

  const core::Model& model_;
  std::string frame_id_;
  MarkerOptions options_;
  std::string tf_prefix_;
  std::vector<int> arrow_shown_;  // the contact slots whose normal and friction arrows were drawn last time (ascending)
  core::Vec3 ground_centre_;      // the ground slab's centre: under the bodies' mean start position
  bool clear_all_ = true;
};

/// The tf frame of a body: its name as given in the scene, after `tf_prefix` and a slash when there is one.
std::string bodyFrame(const core::Model& model, int body, const std::string& tf_prefix = "");

}  // namespace active_tensegrity::ros_layer
