// Cables against struts (core/outputs/observables.h, minimumCableStrutGap and cableStrutCrossings): the gap of a cable
// segment from a strut against its closed form (above, through and beside the strut), the struts a cable meets
// at its nodes left out, sliding cables segment by segment, the CSV column, and the run's warning naming the
// cable and the strut.
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/csv.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/scene/scene.h"

using namespace active_tensegrity::core;

namespace
{
// strut S (radius 2 cm) along x from A to B; a cable across it in y at height z above its axis, from P to Q;
// a sliding cable from A over R to Q (it meets S at A); B held by two cables, one of which can be pulled in
// (the strut settles about 25 cm below at the start and rises with the pull)
std::string scene(double z, bool pull = false)
{
  return std::string(R"(name: crossing
materials:
  steel: {youngs_modulus: 210.0e9, poisson_ratio: 0.3, density: 7850.0}
  cord: {youngs_modulus: 1.0e9, density: 1000.0}
nodes:
  A: {position: [0.0, 0.0, 0.0], fixed: true}
  B: {position: [1.0, 0.0, 0.0]}
  P: {position: [0.5, -0.5, )") +
         std::to_string(z) + R"(], fixed: true}
  Q: {position: [0.5, 0.5, )" +
         std::to_string(z) + R"(], fixed: true}
  R: {position: [0.3, 0.4, 0.5], fixed: true}
  T: {position: [1.0, 0.0, 1.0], fixed: true}
  U: {position: [1.0, -1.0, 0.0], fixed: true}
struts:
  material: steel
  radius: 0.02
  members: {S: [A, B]}
cables:
  cords:
    material: cord
    radius: 0.002
    prestress: 10.0
    members: {across: [P, Q], sliding: [A, R, Q], hold: [B, T], side: [B, U]}
)" +
         (pull ? R"(actuators:
  pull: {cables: [hold], range: [0.0, 0.5]}
analysis:
  type: static
  max_actuation: 0.04
  steps: 4
)" :
                 R"(analysis:
  type: static
  max_actuation: 0.0
  steps: 1
)");
}
}  // namespace

TEST(CableStrutGap, AboveThroughAndBesideTheStrutAgainstTheClosedForm)
{
  for (double z : { 0.5, 0.05, 0.01, -0.005 })
  {
    const Model m = loadSceneFromString(scene(z), "crossing.yaml");
    const CableStrutGap g = minimumCableStrutGap(m, m.q0);
    // 'across' passes |z| above or below S's axis; 'sliding' meets S at A (left out), its second segment from
    // R (0.3, 0.4, 0.5) to Q stays far; 'hold' and 'side' end at B (left out)
    ASSERT_GE(g.cable, 0) << z;
    EXPECT_EQ(m.cables[g.cable].name, "across") << z;
    EXPECT_EQ(m.bodies[g.strut].name, "S");
    EXPECT_EQ(g.segment, 0);
    EXPECT_NEAR(g.gap, std::abs(z) - 0.02, 1e-6) << z;  // the scene's positions are printed to 6 decimals
    const std::vector<CableStrutGap> through = cableStrutCrossings(m, m.q0);
    EXPECT_EQ(through.size(), std::abs(z) < 0.02 ? 1u : 0u) << z;
  }
}

TEST(CableStrutGap, StrutsACableMeetsAtItsNodesAreLeftOutTheirNeighboursNot)
{
  const Model m = loadSceneFromString(scene(0.5), "crossing.yaml");
  for (const Cable& c : m.cables)
  {
    ASSERT_EQ(c.point_struts.size(), c.points.size()) << c.name;
    // 'sliding' starts at A, 'hold' and 'side' at B: S's ends; every cable ends at a node without a strut
    const bool at_strut = c.name == "sliding" || c.name == "hold" || c.name == "side";
    EXPECT_EQ(c.point_struts.front().size(), at_strut ? 1u : 0u) << c.name;
    EXPECT_EQ(c.point_struts.back().size(), 0u) << c.name;
  }
  // without the loader's lists the point's own body is left out: the same answer
  Model bare = m;
  for (Cable& c : bare.cables)
    c.point_struts.clear();
  EXPECT_EQ(minimumCableStrutGap(bare, bare.q0).gap, minimumCableStrutGap(m, m.q0).gap);
}

TEST(CableStrutGap, TheRunWritesTheColumnAndWarnsOnceNamingTheCableAndTheStrut)
{
  const Model m = loadSceneFromString(scene(0.01, true), "crossing.yaml");
  const std::vector<std::string> cols = csvColumns(m);
  const size_t col = std::find(cols.begin(), cols.end(), "min_cable_strut_gap") - cols.begin();
  ASSERT_LT(col, cols.size());
  int rows = 0, through = 0;
  const RunResult r = runAnalysis(m,
                                  [&](const State& s)
                                  {
                                    const std::vector<double> row = csvRow(m, s);
                                    EXPECT_EQ(row[col], minimumCableStrutGap(m, s.q).gap);
                                    through += row[col] < 0.0 ? 1 : 0;
                                    ++rows;
                                  });
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  EXPECT_EQ(rows, 5);
  EXPECT_GE(through, 2);  // the strut rises through the cable as 'hold' is pulled in
  int warned = 0;
  for (const std::string& w : r.summary.warnings)
    if (w.find("runs through strut") != std::string::npos)
    {
      ++warned;
      EXPECT_NE(w.find("cable 'across' runs through strut 'S'"), std::string::npos) << w;
      EXPECT_NE(w.find("path parameter 0 "), std::string::npos) << w;  // first seen at the start
    }
  EXPECT_EQ(warned, 1);  // once, though several output steps have it
  // clear of the strut: no warning
  const Model clear = loadSceneFromString(scene(0.5, true), "crossing.yaml");
  for (const std::string& w : runAnalysis(clear, [](const State&) {}).summary.warnings)
    EXPECT_EQ(w.find("runs through"), std::string::npos) << w;
}
