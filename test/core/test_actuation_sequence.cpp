// actuation.sequence (per-actuator ramps of a dynamic run) and the six-bar robot's roll: the law's values, rates
// and breakpoints against the ramps it is made of, the loader's refusals, and the shipped roll step ending on the
// next cable triangle 0.4 m along +x.
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/scene/scene.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
const std::string kSixBar = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/six_bar.yaml";

std::string sixBarText()
{
  std::ifstream in(kSixBar);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// the scene with its sequence replaced by `sequence` (the lines under `sequence:`)
std::string withSequence(const std::string& sequence, const std::string& analysis = "")
{
  std::string text = sixBarText();
  const size_t a = text.find("  sequence:\n");
  const size_t b = text.find("analysis:", a);
  text.replace(a, b - a, "  sequence:\n" + sequence);
  if (!analysis.empty())
  {
    const size_t c = text.find("analysis:");
    text.replace(c, text.find('\n', c) - c, analysis);
  }
  return text;
}

std::string refusal(const std::string& text)
{
  try
  {
    loadSceneFromString(text, "seq.yaml");
  }
  catch (const SceneError& e)
  {
    return e.what();
  }
  return "accepted";
}
}  // namespace

TEST(ActuationSequence, EachActuatorFollowsItsOwnRampsAndStopsBetweenThem)
{
  const Model m = loadSceneFromString(withSequence("    - {time: 0.5, targets: {C14: 0.4, C3: 0.1}}\n"
                                                   "    - {time: 3.0, targets: {C14: 0.1}}\n"),
                                      "seq.yaml");
  ASSERT_EQ(m.analysis.sequence.size(), 2u);
  const int c14 = m.findActuator("C14"), c3 = m.findActuator("C3"), c1 = m.findActuator("C1");
  // the same ramps built by hand: 0 -> 0.4 from 0.5 s, 0.4 -> 0.1 from 3 s, 0 -> 0.1 from 0.5 s
  RampSchedule up = m.analysis.schedule, down = m.analysis.schedule, small = m.analysis.schedule;
  up.start_time = 0.5;
  up.final_value = 0.4;
  down.start_time = 3.0;
  down.final_value = 0.3;
  small.start_time = 0.5;
  small.final_value = 0.1;
  for (double t : { 0.0, 0.5, 0.55, 1.0, 1.8, 2.9, 3.0, 3.05, 3.6, 4.5, 6.0 })
  {
    const ActuationValues u = scheduledActuation(m, t);
    ASSERT_EQ(u.size(), m.actuators.size());
    const ActuationValue a = t < 3.0 ? up.evaluate(t) : down.evaluate(t);
    const double expected = t < 3.0 ? a.value : 0.4 - a.value;
    const double rate = t < 3.0 ? a.rate : -a.rate;
    EXPECT_NEAR(u[c14].value, expected, 1e-15) << t;
    EXPECT_NEAR(u[c14].rate, rate, 1e-15) << t;
    EXPECT_NEAR(u[c3].value, small.evaluate(t).value, 1e-15) << t;
    EXPECT_EQ(u[c1].value, 0.0) << t;
  }
  EXPECT_NEAR(actuationEndTime(m), down.endTime(), 1e-15);
  // every ramp's corners, once each, in order
  std::vector<double> corners;
  for (const RampSchedule* r : { &up, &down, &small })
    for (double t : r->breakpoints())
      corners.push_back(t);
  std::sort(corners.begin(), corners.end());
  corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
  EXPECT_EQ(actuationBreakpoints(m), corners);
  // the derived duration follows the sequence's end
  EXPECT_NEAR(loadSceneFromString(withSequence("    - {time: 0.5, targets: {C14: 0.4}}\n", "analysis: {type: dynamic}"),
                                  "s")
                  .analysis.duration,
              up.endTime() + 1.0, 1e-12);
}

TEST(ActuationSequence, RefusesOverlapsUnknownNamesOutOfRangeAndAMaxActuation)
{
  const std::string overlap = refusal(withSequence("    - {time: 0.5, targets: {C14: 0.4}}\n"
                                                   "    - {time: 1.0, targets: {C14: 0.0}}\n"));
  EXPECT_NE(overlap.find("actuation.sequence[1].targets.C14"), std::string::npos) << overlap;
  EXPECT_NE(overlap.find("still moving until"), std::string::npos) << overlap;
  const std::string unknown = refusal(withSequence("    - {time: 0.5, targets: {C99: 0.4}}\n"));
  EXPECT_NE(unknown.find("actuation.sequence[0].targets.C99"), std::string::npos) << unknown;
  EXPECT_NE(unknown.find("unknown actuator 'C99'"), std::string::npos) << unknown;
  const std::string range = refusal(withSequence("    - {time: 0.5, targets: {C14: 0.9}}\n"));
  EXPECT_NE(range.find("[0, 0.45], got 0.9"), std::string::npos) << range;
  const std::string order = refusal(withSequence("    - {time: 2.0, targets: {C14: 0.1}}\n"
                                                 "    - {time: 1.0, targets: {C3: 0.1}}\n"));
  EXPECT_NE(order.find("actuation.sequence[1].time"), std::string::npos) << order;
  const std::string nan = refusal(withSequence("    - {time: 0.5, targets: {C14: .nan}}\n"));
  EXPECT_NE(nan.find("actuation.sequence[0].targets.C14"), std::string::npos) << nan;
  const std::string both =
      refusal(withSequence("    - {time: 0.5, targets: {C14: 0.1}}\n",
                           "analysis: {type: dynamic, max_actuation: 0.1, duration: 2.0, output_interval: 0.01}"));
  EXPECT_NE(both.find("analysis.max_actuation"), std::string::npos) << both;
  EXPECT_NE(both.find("not both"), std::string::npos) << both;
  const std::string empty = refusal(withSequence("    []\n"));
  EXPECT_NE(empty.find("actuation.sequence"), std::string::npos) << empty;
}

TEST(SixBarRoll, OnePullOfC14RollsTheRobotOntoTheNextCableTriangleAlongX)
{
  const Model m = loadScene(kSixBar);
  const RunResult r = runAnalysis(m, [](const State&) {});
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  const Eigen::VectorXd& q = r.final_state.q;
  std::vector<std::string> standing;
  Vec3 centre = Vec3::Zero();
  for (const Node& n : m.nodes)
  {
    const Vec3 p = pointPosition(m, n.point, q);
    centre += p / static_cast<double>(m.nodes.size());
    if (p.z() < 0.03)
      standing.push_back(n.name);
  }
  std::printf("[ measured ] standing on %zu nodes, centre moved by (%.4f, %.4f) m, %ld step cuts\n", standing.size(),
              centre.x(), centre.y(), static_cast<long>(r.summary.step_cuts));
  EXPECT_EQ(standing, (std::vector<std::string>{ "N4", "N7", "N10" }));
  EXPECT_GT(centre.x(), 0.35);
  EXPECT_LT(centre.x(), 0.5);
  EXPECT_LT(std::abs(centre.y()), 0.03);
  // at rest again on three ends, carrying the weight
  double weight = 0.0, carried = 0.0;
  for (const Body& b : m.bodies)
    weight += b.mass * 9.81;
  for (const ContactPairState& c : activeContacts(m, r.final_state))
    carried += c.body_b < 0 ? c.normal_force : 0.0;
  EXPECT_NEAR(carried, weight, 0.05 * weight);
}
