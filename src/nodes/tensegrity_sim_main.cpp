// tensegrity_sim: the simulator node (docs/ros.md). Everything is in ros_layer::runSimNode().
#include <ros/ros.h>

#include "active_tensegrity/ros/sim_node.h"

int main(int argc, char** argv)
{
  ros::init(argc, argv, "tensegrity_sim");
  return active_tensegrity::ros_layer::runSimNode();
}
