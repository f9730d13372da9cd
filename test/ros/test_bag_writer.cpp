// The ROS layer without a master: MessageBuilder's frames and markers against the scene's geometry,
// contact arrows drawn and deleted, and tensegrity_run --bag read back with the rosbag API.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "../tools/command.h"
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <tf2_msgs/TFMessage.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/ros/messages.h"

namespace at = active_tensegrity::core;
namespace rl = active_tensegrity::ros_layer;

namespace
{
std::string scene(const std::string& name)
{
  return std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name;
}

int run(const std::string& args, std::string& output)
{
  const active_tensegrity::test::CommandResult r =
      active_tensegrity::test::runCommand(std::string(TENSEGRITY_RUN_PATH) + " " + args + " 2>&1");
  output += r.output;
  return r.code;
}

at::Vec3 vec(const geometry_msgs::Point& p)
{
  return at::Vec3(p.x, p.y, p.z);
}

int countNs(const visualization_msgs::MarkerArray& m, const std::string& ns, int action)
{
  int n = 0;
  for (const auto& k : m.markers)
    n += (k.ns == ns && k.action == action) ? 1 : 0;
  return n;
}
}  // namespace

TEST(MessageBuilder, FramesAndStrutCylindersSitOnTheScenesNodes)
{
  const at::Model model = at::loadScene(scene("tower.yaml"));
  const at::State state = at::initialState(model);
  rl::MessageBuilder builder(model, "world", rl::MarkerOptions());
  const rl::Snapshot snap = builder.build(state, ros::Time(100.0));
  ASSERT_EQ(snap.transforms.size(), model.bodies.size());
  std::map<std::string, const visualization_msgs::Marker*> cylinders;
  for (const auto& m : snap.markers.markers)
    if (m.ns == "struts")
      cylinders[model.bodies[m.id].name] = &m;
  EXPECT_EQ(snap.markers.markers.front().action, visualization_msgs::Marker::DELETEALL);
  int struts = 0;
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const at::Body& b = model.bodies[i];
    const geometry_msgs::TransformStamped& t = snap.transforms[i];
    EXPECT_EQ(t.child_frame_id, b.name);
    EXPECT_EQ(t.header.frame_id, "world");
    EXPECT_EQ(t.header.stamp, ros::Time(100.0));
    if (b.kind != at::BodyKind::kStrut)
      continue;
    ++struts;
    // the frame's z axis is the strut axis: centre +- L/2 z lands on the strut's end nodes
    const Eigen::Quaterniond rot(t.transform.rotation.w, t.transform.rotation.x, t.transform.rotation.y,
                                 t.transform.rotation.z);
    const at::Vec3 c(t.transform.translation.x, t.transform.translation.y, t.transform.translation.z);
    const at::Vec3 half = 0.5 * b.length * (rot * at::Vec3::UnitZ());
    double best_a = 1e9, best_b = 1e9;
    const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq);
    for (const at::Node& n : model.nodes)
    {
      const at::Vec3 p = at::pointPosition(model, n.point, state.q);
      best_a = std::min(best_a, (p - (c + half)).norm());
      best_b = std::min(best_b, (p - (c - half)).norm());
    }
    EXPECT_LT(best_a, 1e-9) << b.name;
    EXPECT_LT(best_b, 1e-9) << b.name;
    // the marker: a cylinder of the real size at the same pose
    ASSERT_TRUE(cylinders.count(b.name)) << b.name;
    const visualization_msgs::Marker& m = *cylinders[b.name];
    EXPECT_EQ(m.type, visualization_msgs::Marker::CYLINDER);
    EXPECT_DOUBLE_EQ(m.scale.x, 2.0 * b.radius());
    EXPECT_DOUBLE_EQ(m.scale.z, b.length);
    EXPECT_LT((vec(m.pose.position) - c).norm(), 1e-12);
  }
  EXPECT_EQ(struts, 16);
  // cables: one line per segment (the sliding ones have several), all slack in the unstressed tower
  size_t segments = 0;
  for (const at::Cable& c : model.cables)
    segments += c.points.size() - 1;
  EXPECT_EQ(snap.cables.cables.size(), model.cables.size());
  size_t drawn = 0;
  for (const auto& m : snap.markers.markers)
    if ((m.ns == "cables" || m.ns == "slack_cables") && m.action == visualization_msgs::Marker::ADD)
      drawn += m.points.size() / 2;
  EXPECT_EQ(drawn, segments);
  EXPECT_EQ(snap.actuators.name.size(), 4u);
  EXPECT_TRUE(snap.contacts.contacts.empty());
  // a second build does not clear everything again
  EXPECT_EQ(countNs(builder.build(state, ros::Time(101.0)).markers, "", visualization_msgs::Marker::DELETEALL), 0);
}

TEST(MessageBuilder, ContactArrowsAreDrawnAndDeletedWhenTheContactEnds)
{
  at::Model model = at::loadScene(scene("tower.yaml"), { at::parseOverride("analysis.type=dynamic"),
                                                         at::parseOverride("analysis.duration=1.6"),
                                                         at::parseOverride("analysis.output_interval=0.1") });
  const at::RunResult folded = at::runAnalysis(model, [](const at::State&) {});
  ASSERT_TRUE(folded.summary.ok()) << folded.summary.message;
  const std::vector<at::ContactPairState> contacts = at::activeContacts(model, folded.final_state);
  ASSERT_FALSE(contacts.empty());
  rl::MarkerOptions opt;
  opt.contact_force_scale = 2e-3;
  rl::MessageBuilder builder(model, "world", opt);
  const rl::Snapshot with = builder.build(folded.final_state, ros::Time(10.0));
  ASSERT_EQ(with.contacts.contacts.size(), contacts.size());
  // normal-force arrows on both struts: from the contact point, length F_N * scale along -+n
  for (size_t i = 0; i < contacts.size(); ++i)
  {
    const at::ContactPairState& c = contacts[i];
    const active_tensegrity::Contact& m = with.contacts.contacts[i];
    EXPECT_DOUBLE_EQ(m.normal_force, c.normal_force);
    const visualization_msgs::Marker* arrow = nullptr;
    for (const auto& k : with.markers.markers)
      if (k.ns == "contact_forces" && k.id == 4 * c.pair)
        arrow = &k;
    ASSERT_NE(arrow, nullptr);
    EXPECT_LT((vec(arrow->points[0]) - c.point_a).norm(), 1e-12);
    EXPECT_LT((vec(arrow->points[1]) - (c.point_a + opt.contact_force_scale * c.normal_force * c.normal)).norm(), 1e-12);
  }
  // back to the unfolded state: every arrow drawn before is deleted, once
  const rl::Snapshot without = builder.build(at::initialState(model), ros::Time(11.0));
  EXPECT_EQ(countNs(without.markers, "contact_forces", visualization_msgs::Marker::DELETE),
            4 * static_cast<int>(contacts.size()));
  EXPECT_EQ(countNs(without.markers, "contact_forces", visualization_msgs::Marker::ADD), 0);
  const rl::Snapshot again = builder.build(at::initialState(model), ros::Time(12.0));
  EXPECT_EQ(countNs(again.markers, "contact_forces", visualization_msgs::Marker::DELETE), 0);
  // given the contacts (the node passes those the solver evaluated at the step's end), the builder takes them
  // instead of searching
  std::vector<at::ContactPairState> given = contacts;
  given[0].normal_force *= 2.0;
  const rl::Snapshot taken = builder.build(folded.final_state, ros::Time(13.0), &given);
  ASSERT_EQ(taken.contacts.contacts.size(), given.size());
  EXPECT_DOUBLE_EQ(taken.contacts.contacts[0].normal_force, given[0].normal_force);
}

TEST(TensegrityRunBag, WritesEveryTopicPerOutputStepInSimulatedTime)
{
  const std::string bag_path = active_tensegrity::test::scratchPath("tensegrity_run_tower.bag");
  const std::string csv = active_tensegrity::test::scratchPath("tensegrity_run_tower_bag.csv");
  std::string out;
  // the quasi-static fold past the contact onset (0.638 m): 70 load steps of 0.01 m
  const int code = run(scene("tower.yaml") + " --set analysis.max_actuation=0.7 --set analysis.steps=70 --out " + csv +
                           " --bag " + bag_path,
                       out);
  ASSERT_EQ(code, 0) << out;
  EXPECT_NE(out.find("wrote 71 states to " + bag_path), std::string::npos) << out;

  rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
  rosbag::View view(bag);
  std::map<std::string, int> count;
  std::map<std::string, ros::Time> last;
  std::set<std::string> frames;
  double last_max_force = 0.0;
  for (const rosbag::MessageInstance& m : view)
  {
    const std::string topic = m.getTopic();
    ++count[topic];
    if (last.count(topic))
    {
      EXPECT_GT(m.getTime(), last[topic]) << topic;
      // statics: t is the path parameter, 1/70 per load step
      EXPECT_NEAR((m.getTime() - last[topic]).toSec(), 1.0 / 70.0, 1e-6) << topic;
    }
    last[topic] = m.getTime();
    if (auto tf = m.instantiate<tf2_msgs::TFMessage>())
      for (const auto& t : tf->transforms)
      {
        frames.insert(t.child_frame_id);
        EXPECT_EQ(t.header.stamp, m.getTime());
      }
    if (auto c = m.instantiate<active_tensegrity::ContactArray>())
    {
      last_max_force = 0.0;
      for (const auto& k : c->contacts)
        last_max_force = std::max(last_max_force, k.normal_force);
    }
  }
  for (const char* topic : { "/tf", "/tensegrity_sim/contacts", "/tensegrity_sim/cables", "/tensegrity_sim/struts",
                             "/tensegrity_sim/actuators", "/tensegrity_sim/markers" })
    EXPECT_EQ(count[topic], 71) << topic;
  EXPECT_EQ(frames.size(), 20u);  // 16 struts and B1-B4
  // the bag's contact forces are the CSV's: last row's max_normal_force
  std::ifstream in(csv);
  std::string header, row, line;
  std::getline(in, header);
  while (std::getline(in, line))
    row = line;
  size_t col = 0;
  for (size_t pos = 0, k = 0; pos != std::string::npos; pos = header.find(',', pos + 1), ++k)
    if (header.compare(pos == 0 ? 0 : pos + 1, 16, "max_normal_force") == 0)
      col = k;
  ASSERT_GT(col, 0u);
  std::stringstream ss(row);
  std::string cell;
  for (size_t k = 0; k <= col; ++k)
    std::getline(ss, cell, ',');
  EXPECT_GT(last_max_force, 0.0);
  EXPECT_NEAR(last_max_force, std::stod(cell), 1e-8 * last_max_force);

  // a bag that cannot be written is refused before any simulation
  std::string bad_out;
  EXPECT_EQ(run(scene("tower.yaml") + " --bag /no/such/dir/x.bag", bad_out), 1);
  EXPECT_NE(bad_out.find("cannot write the bag '/no/such/dir/x.bag'"), std::string::npos) << bad_out;
}

TEST(MessageBuilder, GroundContactsNameTheGroundAndTheGroundIsDrawn)
{
  // the six-bar robot after 0.5 s on its triangle: three strut ends on the ground, with their arrows, and the
  // ground's slab at its height
  const at::Model model = at::loadScene(scene("six_bar.yaml"));
  at::State state = at::initialState(model);
  at::DynamicsSolver solver(model, model.solver);
  const at::ActuationLaw still = [&](double) { return at::ActuationValues(model.actuators.size()); };
  ASSERT_TRUE(solver.initialize(state, still).ok());
  for (int k = 0; k < 500; ++k)
    ASSERT_TRUE(solver.step(state, model.solver.dt, still).ok());
  ASSERT_TRUE(solver.formActuatorForces(state));  // (the actuators' efforts the message carries)
  rl::MessageBuilder builder(model, "world", rl::MarkerOptions());
  const rl::Snapshot snap = builder.build(state, ros::Time(100.0));
  std::set<std::string> on_ground;
  for (const auto& c : snap.contacts.contacts)
  {
    ASSERT_EQ(c.strut_b, "ground");
    on_ground.insert(c.strut_a);
    EXPECT_DOUBLE_EQ(c.point_b.z, 0.0);
    EXPECT_DOUBLE_EQ(c.normal.z, 1.0);
    EXPECT_GT(c.normal_force, 0.0);
  }
  EXPECT_EQ(on_ground, (std::set<std::string>{ "S2", "S4", "S6" }));
  EXPECT_EQ(countNs(snap.markers, "ground", visualization_msgs::Marker::ADD), 1);
  // per contact the normal force on the strut and on the ground (and friction while it is above the drawing floor)
  EXPECT_GE(countNs(snap.markers, "contact_forces", visualization_msgs::Marker::ADD), 6);
}
