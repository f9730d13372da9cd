/// Writes what tensegrity_sim would publish (tf, contacts, cables, struts, actuators, markers) for states of
/// a batch run into a bag, without a master (rosbag C++ API), so that a tensegrity_run result can be
/// watched in rviz through playback.launch. Message times and stamps are origin + simulated time.
#pragma once

#include <memory>
#include <string>

#include <rosbag/bag.h>

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/ros/messages.h"

namespace active_tensegrity::ros_layer
{
class BagWriter
{
public:
  /// Opens (truncates) `path`; topics are <ns>/contacts etc., as the node named <ns> publishes them.
  /// Throws std::invalid_argument when `ns` is not a valid namespace (checkNamespace) and
  /// rosbag::BagException when the file cannot be written.
  BagWriter(const std::string& path, const core::Model& model, const std::string& ns = "/tensegrity_sim",
            const std::string& frame_id = "world", MarkerOptions markers = MarkerOptions());
  ~BagWriter();

  /// Writes every topic for `state` at origin + state.t (states must come in time order).
  void write(const core::State& state);
  int written() const
  {
    return written_;
  }
  void close();

  /// `ns` when it is an absolute ROS graph name ("/tensegrity_sim", "/robot/sim"), "" for the root "/";
  /// else throws std::invalid_argument quoting it and saying why.
  static std::string checkNamespace(const std::string& ns);

private:
  rosbag::Bag bag_;
  MessageBuilder builder_;
  std::string ns_;
  double origin_;
  int written_ = 0;
};

}  // namespace active_tensegrity::ros_layer
