// tensegrity_topic_meter: a C++ subscriber to tensegrity_sim's data topics and /tf that deserializes every message
// it receives and, when stopped (SIGINT or SIGTERM), prints per topic how many arrived and how many of the node's
// publications it never saw (docs/ros.md, "Measuring the node"). Parameters: ~sim, the node's name (default
// /tensegrity_sim); ~queue_size, the subscribers' queue (default 10000).
#include <csignal>
#include <cstdio>
#include <map>
#include <set>
#include <string>

#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <tf2_msgs/TFMessage.h>
#include <visualization_msgs/MarkerArray.h>

#include "active_tensegrity/CableArray.h"
#include "active_tensegrity/ContactArray.h"
#include "active_tensegrity/StrutArray.h"

namespace
{
volatile std::sig_atomic_t stop = 0;

void onSignal(int /*signal*/)
{
  stop = 1;
}

// per topic: the messages received and the stamps they carried
struct Tally
{
  long messages = 0;
  std::set<ros::Time> stamps;
};

std::map<std::string, Tally> tallies;
std::set<ros::Time> publications;  // every stamp any data topic carried: one per publication of the node

void count(const std::string& topic, const ros::Time& stamp)
{
  Tally& t = tallies[topic];
  ++t.messages;
  t.stamps.insert(stamp);
  publications.insert(stamp);
}
}  // namespace

int main(int argc, char** argv)
{
  ros::init(argc, argv, "tensegrity_topic_meter", ros::init_options::NoSigintHandler);
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  ros::NodeHandle nh, pnh("~");
  std::string sim;
  pnh.param<std::string>("sim", sim, "/tensegrity_sim");
  int queue = 10000;
  pnh.param("queue_size", queue, queue);
  if (sim.empty() || sim.front() != '/' || queue < 1)
  {
    std::fprintf(stderr,
                 "tensegrity_topic_meter: ~sim must be the node's absolute name (got '%s') and ~queue_size "
                 "at least 1 (got %d)\n",
                 sim.c_str(), queue);
    return 2;
  }
  const ros::TransportHints hints = ros::TransportHints().tcpNoDelay();
  // (each callback takes the message deserialized into its type)
  const ros::Subscriber subs[] = {
    nh.subscribe<active_tensegrity::ContactArray>(
        sim + "/contacts", queue, [](const auto& m) { count("contacts", m->header.stamp); }, ros::VoidConstPtr(), hints),
    nh.subscribe<active_tensegrity::CableArray>(
        sim + "/cables", queue, [](const auto& m) { count("cables", m->header.stamp); }, ros::VoidConstPtr(), hints),
    nh.subscribe<active_tensegrity::StrutArray>(
        sim + "/struts", queue, [](const auto& m) { count("struts", m->header.stamp); }, ros::VoidConstPtr(), hints),
    nh.subscribe<sensor_msgs::JointState>(
        sim + "/actuators", queue, [](const auto& m) { count("actuators", m->header.stamp); }, ros::VoidConstPtr(),
        hints),
    nh.subscribe<visualization_msgs::MarkerArray>(
        sim + "/markers", queue, [](const auto& m) { tallies["markers"].messages += m->markers.empty() ? 0 : 1; },
        ros::VoidConstPtr(), hints),
    nh.subscribe<tf2_msgs::TFMessage>(
        "/tf", queue,
        [](const auto& m)
        {
          if (!m->transforms.empty())
            count("tf", m->transforms.front().header.stamp);
        },
        ros::VoidConstPtr(), hints),
  };
  while (!stop && ros::ok())
    ros::getGlobalCallbackQueue()->callAvailable(ros::WallDuration(0.1));
  // the publications seen between the first and the last stamp any topic carried: a topic missed those it lacks
  std::printf("tensegrity_topic_meter: %zu publications of %s seen (distinct stamps on its data topics and /tf)\n",
              publications.size(), sim.c_str());
  for (const auto& [topic, t] : tallies)
  {
    if (topic == "markers")
    {
      std::printf("  %-9s %8ld received (at ~marker_rate, not with every publication)\n", topic.c_str(), t.messages);
      continue;
    }
    long missed = 0;
    if (!t.stamps.empty())
      for (auto it = publications.lower_bound(*t.stamps.begin()); it != publications.end() && *it <= *t.stamps.rbegin();
           ++it)
        missed += t.stamps.count(*it) == 0 ? 1 : 0;
    std::printf("  %-9s %8ld received, %ld missed between its first and last\n", topic.c_str(), t.messages, missed);
  }
  (void)subs;
  return 0;
}
