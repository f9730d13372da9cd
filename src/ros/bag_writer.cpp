#include "active_tensegrity/ros/bag_writer.h"

#include <stdexcept>

#include <ros/names.h>
#include <tf2_msgs/TFMessage.h>

#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::ros_layer
{
BagWriter::BagWriter(const std::string& path, const core::Model& model, const std::string& ns,
                     const std::string& frame_id, MarkerOptions markers)
  : builder_(model, frame_id, markers), ns_(checkNamespace(ns)), origin_(ros::WallTime::now().toSec())
{
  bag_.open(path, rosbag::bagmode::Write);
  bag_.setCompression(rosbag::compression::LZ4);
}

std::string BagWriter::checkNamespace(const std::string& ns)
{
  if (ns == "/")
    return "";
  std::string error;
  if (ns.empty() || ns.front() != '/')
    error = "it must be absolute (start with '/')";
  else if (ns.back() == '/')
    error = "it must not end with '/'";
  else if (!ros::names::validate(ns, error))
    error = "it is not a valid ROS graph name: " + error;
  if (!error.empty())
    throw std::invalid_argument("the namespace " + core::quoted(ns) + " cannot prefix topics: " + core::clipped(error));
  return ns;
}

BagWriter::~BagWriter()
{
  close();
}

void BagWriter::close()
{
  if (bag_.isOpen())
    bag_.close();
}

void BagWriter::write(const core::State& state)
{
  const ros::Time stamp(origin_ + state.t);
  const Snapshot snap = builder_.build(state, stamp);
  tf2_msgs::TFMessage tf;
  tf.transforms = snap.transforms;
  bag_.write("/tf", stamp, tf);
  bag_.write(ns_ + "/contacts", stamp, snap.contacts);
  bag_.write(ns_ + "/cables", stamp, snap.cables);
  bag_.write(ns_ + "/struts", stamp, snap.struts);
  bag_.write(ns_ + "/actuators", stamp, snap.actuators);
  bag_.write(ns_ + "/markers", stamp, snap.markers);
  ++written_;
}

}  // namespace active_tensegrity::ros_layer
