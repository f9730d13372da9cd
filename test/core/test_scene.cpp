// Scene loading (core/scene): the shipped quadruplex, command-line overrides, and a table of broken
// scenes, each refused with a SceneError that names the key and the offending value or name.
#include <algorithm>
#include <cmath>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <ostream>
#include <set>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/oracle/mechanics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/core/base/text.h"

using namespace active_tensegrity::core;

namespace
{
const std::string kQuadruplex = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/quadruplex.yaml";

// a small valid scene: two fixed feet, three struts (S3 joins the tops of S1 and S2), cables, springs
// to a point mass, one actuator; the broken scenes below are edits of it
const std::string kMini = R"(name: mini
materials:
  steel: {youngs_modulus: 210.0e9, poisson_ratio: 0.3, density: 7850.0}
  cord: {youngs_modulus: 1.0e7, density: 1000.0}
nodes:
  A: {position: [0.0, 0.0, 0.0], fixed: true}
  B: {position: [1.0, 0.0, 0.0], fixed: true}
  C: {position: [0.0, 0.8, 1.0]}
  D: {position: [1.0, 0.2, 1.0]}
  M: {position: [0.5, 0.5, 1.5], mass: 0.2}
struts:
  material: steel
  radius: 0.02
  members:
    S1: [A, D]
    S2: [B, C]
    S3: [C, D]
cables:
  cords:
    material: cord
    radius: 0.005
    prestress: 50.0
    members: {C1: [A, C], C2: [B, D]}
springs:
  holders:
    stiffness: 500.0
    prestress: 10.0
    members: {K1: [C, M], K2: [D, M]}
actuators:
  lift:
    nodes: [M]
    direction: [0.0, 0.0, -1.0]
    range: [0.0, 0.5]
analysis:
  type: static
  max_actuation: 0.3
  steps: 10
)";

const std::map<std::string, Vec3> kMiniPositions = { { "A", Vec3(0.0, 0.0, 0.0) },
                                                     { "B", Vec3(1.0, 0.0, 0.0) },
                                                     { "C", Vec3(0.0, 0.8, 1.0) },
                                                     { "D", Vec3(1.0, 0.2, 1.0) },
                                                     { "M", Vec3(0.5, 0.5, 1.5) } };

struct Edit
{
  std::string from;
  std::string to;
};

// kMini with the edits applied in turn; each `from` must occur exactly once, so a stale edit fails
// here rather than silently testing the valid scene
std::string edited(const std::vector<Edit>& edits)
{
  std::string yaml = kMini;
  for (const Edit& e : edits)
  {
    const size_t at = yaml.find(e.from);
    if (at == std::string::npos || yaml.find(e.from, at + 1) != std::string::npos)
    {
      ADD_FAILURE() << "edit target must occur exactly once in the scene: '" << e.from << "'";
      continue;
    }
    yaml.replace(at, e.from.size(), e.to);
  }
  return yaml;
}

// loading must throw a SceneError whose key() is `key` and whose message holds every needle
::testing::AssertionResult refused(const std::function<void()>& load, const std::string& key,
                                   const std::vector<std::string>& needles)
{
  try
  {
    load();
  }
  catch (const SceneError& e)
  {
    const std::string what = e.what();
    if (e.key() != key)
      return ::testing::AssertionFailure() << "key '" << e.key() << "', expected '" << key << "' in: " << what;
    if (what.find(key) == std::string::npos)
      return ::testing::AssertionFailure() << "the message does not name the key '" << key << "': " << what;
    for (const std::string& n : needles)
      if (what.find(n) == std::string::npos)
        return ::testing::AssertionFailure() << "the message lacks '" << n << "': " << what;
    return ::testing::AssertionSuccess() << what;
  }
  catch (const std::exception& e)
  {
    return ::testing::AssertionFailure() << "threw a non-SceneError: " << e.what();
  }
  return ::testing::AssertionFailure() << "loaded without complaint";
}

const Cable& cableNamed(const Model& model, const std::string& name)
{
  for (const Cable& c : model.cables)
    if (c.name == name)
      return c;
  throw std::runtime_error("no cable " + name);
}

Vec3 nodePosition(const Model& model, const std::string& name, const Eigen::VectorXd& q)
{
  const int i = model.findNode(name);
  EXPECT_GE(i, 0) << name;
  return pointPosition(model, model.nodes.at(i).point, q);
}

// |Phi(q0, u)| with every actuator at `value`
Eigen::VectorXd constraintsAt(const Model& model, double value)
{
  const System sys(model);
  ActuationValues u(model.actuators.size());
  for (ActuationValue& v : u)
    v.value = value;
  Eigen::VectorXd phi;
  sys.constraintValue(model.q0, u, phi);
  return phi;
}
}  // namespace

// ---------------------------------------------------------------------------------------------------
// the shipped quadruplex (Kan et al. 2019, Table 1)

TEST(QuadruplexScene, LoadsWithTheCountsOfTable1)
{
  const Model m = loadScene(kQuadruplex);
  EXPECT_EQ(m.name, "quadruplex");
  EXPECT_EQ(m.source, kQuadruplex);
  int struts = 0;
  for (const Body& b : m.bodies)
    struts += b.kind == BodyKind::kStrut;
  EXPECT_EQ(struts, 4);
  EXPECT_EQ(m.bodies.size(), 4u);  // no point masses
  EXPECT_EQ(m.nq, 28);
  EXPECT_EQ(m.nodes.size(), 8u);
  EXPECT_EQ(m.cables.size(), 12u);
  ASSERT_EQ(m.actuators.size(), 1u);
  EXPECT_EQ(m.actuators[0].name, "top");
  EXPECT_EQ(m.actuators[0].constraints.size(), 4u);
  EXPECT_DOUBLE_EQ(m.actuators[0].max_value, 1.8);
  EXPECT_EQ(m.checkedPairList().size(), 6u);
  EXPECT_EQ(m.analysis.type, AnalysisType::kStatic);
  EXPECT_DOUBLE_EQ(m.analysis.max_actuation, 1.72);
  EXPECT_EQ(m.analysis.steps, 172);
  EXPECT_DOUBLE_EQ(m.solver.newton_tolerance, 1e-10);
  EXPECT_EQ(m.solver.max_iterations, 30);
  EXPECT_EQ(m.solver.max_step_cuts, 12);
  EXPECT_DOUBLE_EQ(m.ground_level, 0.0);
  EXPECT_EQ(m.height_nodes.size(), 4u);
  int rows = 0;
  for (const Constraint& c : m.constraints)
    rows += c.rows();
  EXPECT_EQ(m.n_lambda, rows);
}

TEST(QuadruplexScene, StrutMassAndInertiaAreThoseOfASolidSteelCylinder)
{
  const Model m = loadScene(kQuadruplex);
  const double r = 0.05, length = std::sqrt(1.5);
  const double mass = 7850.0 * M_PI * r * r * length;
  for (const Body& b : m.bodies)
  {
    SCOPED_TRACE(b.name);
    EXPECT_NEAR(b.length, length, 1e-12);
    EXPECT_NEAR(b.radius(), r, 1e-15);
    EXPECT_NEAR(b.mass, mass, 1e-10 * mass);
    EXPECT_NEAR(b.inertia.x(), mass * (3.0 * r * r + length * length) / 12.0, 1e-10 * mass);
    EXPECT_NEAR(b.inertia.y(), mass * (3.0 * r * r + length * length) / 12.0, 1e-10 * mass);
    EXPECT_NEAR(b.inertia.z(), mass * r * r / 2.0, 1e-10 * mass);
    ASSERT_EQ(b.layers.size(), 1u);
    EXPECT_EQ(b.layers[0].material, "steel");
    EXPECT_DOUBLE_EQ(b.layers[0].youngs_modulus, 210.0e9);
  }
}

TEST(QuadruplexScene, CableRestLengthsGiveTheTablePrestress)
{
  const Model m = loadScene(kQuadruplex);
  const double ea = 7.84e6 * M_PI * 0.01 * 0.01;
  const Eigen::VectorXd qd = Eigen::VectorXd::Zero(m.nq);
  // one cable of each family: lower (l = 1), upper and bracing (l = sqrt(1/2))
  const std::vector<std::tuple<std::string, double, double>> cases = { { "C1", 1.0, 200.0 },
                                                                       { "C5", std::sqrt(0.5), 282.84 },
                                                                       { "C9", std::sqrt(0.5), 282.84 } };
  for (const auto& [name, l, tension] : cases)
  {
    SCOPED_TRACE(name);
    const Cable& c = cableNamed(m, name);
    const double l0 = l / (1.0 + tension / ea);
    EXPECT_NEAR(c.rest_length, l0, 1e-12);
    EXPECT_NEAR(c.stiffness, ea / l0, 1e-9 * ea);
    EXPECT_NEAR(c.area, M_PI * 1e-4, 1e-15);
    EXPECT_TRUE(c.tension_only);
    // physics: the cable carries exactly its prestress in the initial configuration
    const CableState s = evaluateCable(m, c, m.q0, qd, {}, false);
    EXPECT_NEAR(s.length, l, 1e-12);
    EXPECT_NEAR(s.tension, tension, 1e-9 * tension);
  }
}

TEST(QuadruplexScene, InitialConfigurationPlacesEveryNodeAndSatisfiesEveryConstraint)
{
  const Model m = loadScene(kQuadruplex);
  const std::map<std::string, Vec3> positions = { { "P1", Vec3(0.5, 0.5, 0.0) },   { "P2", Vec3(-0.5, 0.5, 0.0) },
                                                  { "P3", Vec3(-0.5, -0.5, 0.0) }, { "P4", Vec3(0.5, -0.5, 0.0) },
                                                  { "P5", Vec3(0.5, 0.0, 0.5) },   { "P6", Vec3(0.0, 0.5, 0.5) },
                                                  { "P7", Vec3(-0.5, 0.0, 0.5) },  { "P8", Vec3(0.0, -0.5, 0.5) } };
  for (const auto& [name, p] : positions)
    EXPECT_LT((nodePosition(m, name, m.q0) - p).norm(), 1e-12) << name;
  EXPECT_LT(constraintsAt(m, 0.0).lpNorm<Eigen::Infinity>(), 1e-12);
}

TEST(QuadruplexScene, ChecksEveryPairOfStrutsOnce)
{
  const Model m = loadScene(kQuadruplex);
  std::set<std::pair<int, int>> seen;
  for (const StrutPair& p : m.checkedPairList())
  {
    EXPECT_LT(p.body_a, p.body_b);
    EXPECT_TRUE(seen.insert({ p.body_a, p.body_b }).second);
  }
  EXPECT_EQ(seen.size(), 6u);  // C(4, 2): no two struts of the quadruplex share a node
}

// ---------------------------------------------------------------------------------------------------
// overrides

TEST(SceneOverride, StrutRadiusChangesRadiusAndMass)
{
  const Model m = loadScene(kQuadruplex, { parseOverride("struts.radius=0.06") });
  const double mass = 7850.0 * M_PI * 0.06 * 0.06 * std::sqrt(1.5);
  for (const Body& b : m.bodies)
  {
    EXPECT_DOUBLE_EQ(b.radius(), 0.06) << b.name;
    EXPECT_NEAR(b.mass, mass, 1e-10 * mass) << b.name;
  }
}

TEST(SceneOverride, AnalysisMaxActuationAndSteps)
{
  const Model m =
      loadScene(kQuadruplex, { parseOverride("analysis.max_actuation=1.0"), parseOverride("analysis.steps=50") });
  EXPECT_DOUBLE_EQ(m.analysis.max_actuation, 1.0);
  EXPECT_DOUBLE_EQ(m.analysis.schedule.final_value, 1.0);
  EXPECT_EQ(m.analysis.steps, 50);
  // the rest of the scene is untouched
  EXPECT_EQ(m.cables.size(), 12u);
  EXPECT_DOUBLE_EQ(m.bodies[0].radius(), 0.05);
}

TEST(SceneOverride, LaterOverrideWins)
{
  const Model m = loadScene(kQuadruplex, { parseOverride("analysis.steps=50"), parseOverride("analysis.steps=7") });
  EXPECT_EQ(m.analysis.steps, 7);
}

TEST(SceneOverride, OptionalSectionAbsentFromTheFileCanBeSet)
{
  // the quadruplex has a solver section but no solver.newmark map
  const Model m = loadScene(kQuadruplex, { parseOverride("solver.newmark.gamma=0.55") });
  EXPECT_DOUBLE_EQ(m.solver.newmark_gamma, 0.55);
}

TEST(SceneOverride, MisspeltKeyIsRefusedByName)
{
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride("struts.radiuss=0.1") }); }, "struts.radiuss",
                      { kQuadruplex, "unknown key" }));
}

TEST(SceneOverride, PathIntoNothingIsRefused)
{
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride("nosuch.key=1") }); }, "nosuch", { "unknown key" }));
  EXPECT_TRUE(
      refused([] { loadScene(kQuadruplex, { parseOverride("struts.foo.bar=1") }); }, "struts.foo", { "unknown key" }));
  // through a scalar
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride("struts.radius.x=1") }); }, "struts.radius.x",
                      { "'radius' is not a map" }));
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride("struts..radius=1") }); }, "struts..radius",
                      { "malformed" }));
}

TEST(SceneOverride, BadValuesAreRefusedLikeBadFileValues)
{
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride("struts.radius=[1,") }); }, "struts.radius",
                      { "cannot parse", "'[1,'" }));
  EXPECT_TRUE(
      refused([] { loadScene(kQuadruplex, { parseOverride("struts.radius=abc") }); }, "struts.radius", { "'abc'" }));
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride("struts.radius=-0.06") }); }, "struts.radius",
                      { "'-0.06'" }));
}

TEST(ParseOverride, SplitsAtTheFirstEquals)
{
  const Override o = parseOverride("analysis.type=a=b");
  EXPECT_EQ(o.key, "analysis.type");
  EXPECT_EQ(o.value, "a=b");
  const Override empty = parseOverride("struts.radius=");
  EXPECT_EQ(empty.key, "struts.radius");
  EXPECT_EQ(empty.value, "");
}

TEST(ParseOverride, RefusesTextWithoutKeyOrEquals)
{
  EXPECT_TRUE(refused([] { parseOverride("noequals"); }, "noequals", { "key=value" }));
  EXPECT_TRUE(refused([] { parseOverride("=0.1"); }, "=0.1", { "key=value" }));
  EXPECT_THROW(parseOverride(""), SceneError);
}

// ---------------------------------------------------------------------------------------------------
// a small valid scene

TEST(MiniScene, Loads)
{
  const Model m = loadSceneFromString(kMini, "mini.yaml");
  EXPECT_EQ(m.source, "mini.yaml");
  ASSERT_EQ(m.bodies.size(), 4u);  // three struts, then the point mass at M
  EXPECT_EQ(m.bodies[3].kind, BodyKind::kPointMass);
  EXPECT_DOUBLE_EQ(m.bodies[3].mass, 0.2);
  EXPECT_EQ(m.nq, 3 * 7 + 3);
  EXPECT_EQ(m.nodes.size(), 5u);
  EXPECT_EQ(m.cables.size(), 4u);
  EXPECT_DOUBLE_EQ(cableNamed(m, "K1").stiffness, 500.0);
  ASSERT_EQ(m.actuators.size(), 1u);
  EXPECT_EQ(m.actuators[0].constraints.size(), 1u);
  // two pins, two joints (C: S2-S3, D: S1-S3), one actuated row, three norms
  EXPECT_EQ(m.n_lambda, 3 + 3 + 3 + 3 + 1 + 3);
  // S3 shares a node with each of the others: only S1-S2 is checked
  ASSERT_EQ(m.checkedPairList().size(), 1u);
  EXPECT_EQ(m.bodies[m.checkedPairList()[0].body_a].name, "S1");
  EXPECT_EQ(m.bodies[m.checkedPairList()[0].body_b].name, "S2");
}

TEST(MiniScene, AutoPairsLeaveOutEveryPairAtACommonNode)
{
  // three struts meeting at C (the loader joins the first to each other one, not the second to the
  // third) and a fourth apart: auto checks only the pairs with the fourth
  const std::string yaml = R"(name: star
materials:
  steel: {youngs_modulus: 210.0e9, density: 7850.0}
nodes:
  A: {position: [0.0, 0.0, 0.0], fixed: true}
  B: {position: [1.0, 0.0, 0.0], fixed: true}
  E: {position: [0.0, 1.0, 0.0], fixed: true}
  C: {position: [0.4, 0.4, 1.0]}
  F: {position: [2.0, 2.0, 0.0], fixed: true}
  G: {position: [2.0, 2.0, 1.0], fixed: true}
struts:
  material: steel
  radius: 0.02
  members: {S1: [A, C], S2: [B, C], S3: [E, C], S4: [F, G]}
contact:
  pairs: auto
analysis: {type: dynamic, duration: 0.01}
)";
  const Model m = loadSceneFromString(yaml, "star.yaml");
  std::set<std::pair<std::string, std::string>> pairs;
  for (const StrutPair& p : m.checkedPairList())
    pairs.insert({ m.bodies[p.body_a].name, m.bodies[p.body_b].name });
  const std::set<std::pair<std::string, std::string>> expected = { { "S1", "S4" }, { "S2", "S4" }, { "S3", "S4" } };
  EXPECT_EQ(pairs, expected);
}

TEST(MiniScene, CablesAndSpringsCarryTheirPrestressInitially)
{
  // cables: l0 = l / (1 + T / EA), k = EA / l0; springs: l0 = l - T / k
  const Model m = loadSceneFromString(kMini, "mini.yaml");
  const Eigen::VectorXd qd = Eigen::VectorXd::Zero(m.nq);
  const double ea = 1.0e7 * M_PI * 0.005 * 0.005;
  const std::vector<std::tuple<std::string, std::string, std::string, double>> cases = {
    { "C1", "A", "C", 50.0 }, { "C2", "B", "D", 50.0 }, { "K1", "C", "M", 10.0 }, { "K2", "D", "M", 10.0 }
  };
  for (const auto& [name, a, b, tension] : cases)
  {
    SCOPED_TRACE(name);
    const Cable& c = cableNamed(m, name);
    const double l = (kMiniPositions.at(a) - kMiniPositions.at(b)).norm();
    const bool spring = name[0] == 'K';
    EXPECT_NEAR(c.rest_length, spring ? l - tension / 500.0 : l / (1.0 + tension / ea), 1e-12);
    EXPECT_NEAR(c.stiffness, spring ? 500.0 : ea / c.rest_length, 1e-9);
    const CableState s = evaluateCable(m, c, m.q0, qd, {}, false);
    EXPECT_NEAR(s.length, l, 1e-12);
    EXPECT_NEAR(s.tension, tension, 1e-9 * tension);
  }
}

TEST(MiniScene, FreeFloatingSceneLoadsForADynamicAnalysisOnly)
{
  // no fixed node: refused for statics (see the table below), accepted for dynamics with the ground level
  // at the lowest node
  const Model m = loadSceneFromString(edited({ { "[0.0, 0.0, 0.0], fixed: true}", "[0.0, 0.0, -0.2]}" },
                                               { "[1.0, 0.0, 0.0], fixed: true}", "[1.0, 0.0, 0.0]}" },
                                               { "type: static", "type: dynamic" },
                                               { "analysis:", "actuation: {speed: 0.1}\nanalysis:" } }),
                                      "floating.yaml");
  EXPECT_EQ(m.analysis.type, AnalysisType::kDynamic);
  EXPECT_DOUBLE_EQ(m.analysis.schedule.speed, 0.1);
  EXPECT_DOUBLE_EQ(m.analysis.schedule.final_value, 0.3);
  EXPECT_DOUBLE_EQ(m.ground_level, -0.2);
  EXPECT_LT(constraintsAt(m, 0.0).lpNorm<Eigen::Infinity>(), 1e-12);
}

TEST(MiniScene, InitialConfigurationSatisfiesEveryConstraint)
{
  const Model m = loadSceneFromString(kMini, "mini.yaml");
  for (const auto& [name, p] : kMiniPositions)
    EXPECT_LT((nodePosition(m, name, m.q0) - p).norm(), 1e-12) << name;
  const Eigen::VectorXd phi = constraintsAt(m, 0.0);
  ASSERT_EQ(phi.size(), m.n_lambda);
  EXPECT_LT(phi.lpNorm<Eigen::Infinity>(), 1e-12) << phi.transpose();
  // the check can see a violation: with the actuator at 0.1 exactly its row is off, by -0.1
  const Eigen::VectorXd moved = constraintsAt(m, 0.1);
  EXPECT_NEAR(moved.lpNorm<Eigen::Infinity>(), 0.1, 1e-12);
  EXPECT_NEAR(moved.sum(), -0.1, 1e-12);
}

TEST(MiniScene, VerticalStrutsPointingUpAndDownSatisfyTheirConstraints)
{
  // S4 runs from E straight down to F, S5 from G straight up to F (q0 orientation along -z and +z)
  const Model m =
      loadSceneFromString(edited({ { "  M: {", "  E: {position: [2.0, 0.0, 2.0]}\n"
                                               "  F: {position: [2.0, 0.0, 1.0]}\n"
                                               "  G: {position: [2.0, 0.0, 0.0], fixed: true}\n"
                                               "  M: {" },
                                   { "    S3: [C, D]\n", "    S3: [C, D]\n    S4: [E, F]\n    S5: [G, F]\n" } }),
                          "vertical.yaml");
  EXPECT_LT((nodePosition(m, "E", m.q0) - Vec3(2.0, 0.0, 2.0)).norm(), 1e-12);
  EXPECT_LT((nodePosition(m, "F", m.q0) - Vec3(2.0, 0.0, 1.0)).norm(), 1e-12);
  EXPECT_LT((nodePosition(m, "G", m.q0) - Vec3(2.0, 0.0, 0.0)).norm(), 1e-12);
  EXPECT_LT(constraintsAt(m, 0.0).lpNorm<Eigen::Infinity>(), 1e-12);
}

// ---------------------------------------------------------------------------------------------------
// broken scenes: each must be refused naming the key and the bad value (or name)

struct BadScene
{
  std::string name;
  std::vector<Edit> edits;
  std::string key;                   // SceneError::key()
  std::vector<std::string> needles;  // in what(), besides the file and the key
};

std::ostream& operator<<(std::ostream& os, const BadScene& b)
{
  return os << b.name;
}

const std::string kAnalysis = "analysis:\n  type: static\n  max_actuation: 0.3\n  steps: 10\n";

const std::vector<BadScene> kBadScenes = {
  { "MissingAnalysis", { { kAnalysis, "" } }, "analysis", { "missing required key" } },
  { "MissingStrutMaterial", { { "  material: steel\n", "" } }, "struts.material", { "missing required key" } },
  { "RadiusNotANumber", { { "radius: 0.02", "radius: \"abc\"" } }, "struts.radius", { "expected a number", "'abc'" } },
  { "NegativeRadius", { { "radius: 0.02", "radius: -0.02" } }, "struts.radius", { "positive", "'-0.02'" } },
  { "NegativePrestress", { { "prestress: 50.0", "prestress: -50.0" } }, "cables.cords.prestress", { "'-50.0'" } },
  { "NanRadius", { { "radius: 0.02", "radius: .nan" } }, "struts.radius", { "finite", "'.nan'" } },
  { "InfinitePosition", { { "[0.0, 0.8, 1.0]", "[0.0, 0.8, .inf]" } }, "nodes.C.position", { "finite", "'.inf'" } },
  { "PositionWithTwoNumbers", { { "[0.0, 0.8, 1.0]", "[0.0, 0.8]" } }, "nodes.C.position", { "three numbers" } },
  { "UnknownNodeInStrut", { { "S2: [B, C]", "S2: [B, X]" } }, "struts.members.S2", { "unknown node", "'X'" } },
  { "UnknownNodeInCable", { { "C1: [A, C]", "C1: [A, X]" } }, "cables.cords.members.C1", { "unknown node", "'X'" } },
  { "StrutOnOneNodeTwice", { { "S3: [C, D]", "S3: [C, C]" } }, "struts.members.S3", { "'C'", "twice" } },
  { "CableNamedLikeAStrut", { { "C2: [B, D]", "S2: [B, D]" } }, "cables.cords.members.S2", { "duplicate", "'S2'" } },
  { "ZeroLengthStrut", { { "[1.0, 0.2, 1.0]", "[0.0, 0.0, 0.0]" } }, "struts.members.S1", { "zero length" } },
  { "ZeroMassStrut", { { "density: 7850.0", "density: 0.0" } }, "struts.material", { "zero mass", "'S1'" } },
  { "UnknownStrutMaterial", { { "material: steel\n", "material: stele\n" } }, "struts.material", { "'stele'" } },
  { "UnknownCableMaterial", { { "material: cord", "material: rope" } }, "cables.cords.material", { "'rope'" } },
  { "PoissonRatioOutOfRange",
    { { "poisson_ratio: 0.3", "poisson_ratio: 0.5" } },
    "materials.steel.poisson_ratio",
    { "0.5" } },
  { "UnknownTopLevelKey", { { kAnalysis, kAnalysis + "gravty: {enabled: true}\n" } }, "gravty", { "unknown key" } },
  { "UnknownNestedKey",
    { { "C: {position: [0.0, 0.8, 1.0]}", "C: {position: [0.0, 0.8, 1.0], fixd: true}" } },
    "nodes.C.fixd",
    { "unknown key" } },
  { "UnknownAnalysisType", { { "type: static", "type: quasi_static" } }, "analysis.type", { "'quasi_static'" } },
  { "StepsNotAnInteger", { { "steps: 10", "steps: 2.5" } }, "analysis.steps", { "integer", "'2.5'" } },
  { "DynamicWithoutSpeed", { { "type: static", "type: dynamic" } }, "actuation", { "speed" } },
  { "NewmarkGammaBelowHalf",
    { { kAnalysis, kAnalysis + "solver:\n  newmark: {gamma: 0.4}\n" } },
    "solver.newmark.gamma",
    { "0.4", "at least 0.5" } },
  { "MinStepAboveMaxStep",
    { { kAnalysis, kAnalysis + "solver: {adaptive: true, dt_min: 0.1, dt_max: 0.01}\n" } },
    "solver.dt_min",
    { "0.1", "dt_max" } },
  { "NegativeErrorTolerance",
    { { kAnalysis, kAnalysis + "solver: {adaptive: true, error_tolerance: -1.0e-5}\n" } },
    "solver.error_tolerance",
    { "positive", "-1" } },
  { "UnknownIntegrator",
    { { kAnalysis, kAnalysis + "solver: {integrator: euler}\n" } },
    "solver.integrator",
    { "'euler'" } },
  { "NoFixedNode",
    { { "fixed: true}\n  B", "fixed: false}\n  B" }, { "fixed: true}\n  C", "fixed: false}\n  C" } },
    "analysis.type",
    { "static", "fixed node" } },
  { "FixedNodeWithMass",
    { { "[0.0, 0.0, 0.0], fixed: true}", "[0.0, 0.0, 0.0], fixed: true, mass: 1.0}" } },
    "nodes.A.mass",
    { "fixed" } },
  { "NodeAttachedToNothing",
    { { "  M: {", "  Z: {position: [2.0, 2.0, 2.0]}\n  M: {" } },
    "nodes.Z",
    { "attached to nothing" } },
  { "ActuatedFixedNode", { { "nodes: [M]", "nodes: [A]" } }, "actuators.lift.nodes", { "'A'", "fixed" } },
  { "ActuatedNodeTwice", { { "nodes: [M]", "nodes: [M, M]" } }, "actuators.lift.nodes", { "'M'", "twice" } },
  { "CablePulledTwiceByOneActuator",
    { { "actuators:\n  lift:\n    nodes: [M]\n    direction: [0.0, 0.0, -1.0]\n", "actuators:\n  lift:\n    cables: "
                                                                                  "[C2, C2]\n" } },
    "actuators.lift.cables",
    { "'C2'", "twice" } },
  { "HeightNodeTwice",
    { { kAnalysis, kAnalysis + "outputs:\n  height_nodes: [C, D, C]\n" } },
    "outputs.height_nodes",
    { "'C'", "twice" } },
  { "ActuatedUnknownNode", { { "nodes: [M]", "nodes: [Q]" } }, "actuators.lift.nodes", { "'Q'" } },
  { "ActuatorWithoutDirection",
    { { "direction: [0.0, 0.0, -1.0]", "direction: [0.0, 0.0, 0.0]" } },
    "actuators.lift.direction",
    { "zero vector" } },
  { "ActuatorRangeBelowZero", { { "range: [0.0, 0.5]", "range: [0.0, -0.5]" } }, "actuators.lift.range", { "-0.5" } },
  { "MaxActuationBeyondActuatorRange",
    { { "max_actuation: 0.3", "max_actuation: 0.9" } },
    "analysis.max_actuation",
    { "'lift'", "0.9" } },
  { "ContactPairWithUnknownStrut",
    { { kAnalysis, kAnalysis + "contact:\n  pairs: [[S1, S9]]\n" } },
    "contact.pairs",
    { "'S9'" } },
  { "ContactPairWithItself",
    { { kAnalysis, kAnalysis + "contact:\n  pairs: [[S1, S1]]\n" } },
    "contact.pairs",
    { "S1, S1" } },
  { "RestitutionAboveOne",
    { { kAnalysis, kAnalysis + "contact:\n  restitution: 1.5\n" } },
    "contact.restitution",
    { "[0, 1]", "1.5" } },
  { "NegativeFriction",
    { { kAnalysis, kAnalysis + "contact:\n  friction: -0.1\n" } },
    "contact.friction",
    { "negative", "-0.1" } },
  { "SlipVelocityBelowStickVelocity",
    { { kAnalysis, kAnalysis + "contact:\n  stick_velocity: 0.01\n  slip_velocity: 0.005\n" } },
    "contact.slip_velocity",
    { "stick_velocity", "0.005" } },
  { "CrossingAngleOfNinetyDegrees",
    { { kAnalysis, kAnalysis + "contact:\n  min_crossing_angle: 90\n" } },
    "contact.min_crossing_angle",
    { "90" } },
  { "ContactSwitchNotABoolean",
    { { kAnalysis, kAnalysis + "contact:\n  enabled: maybe\n" } },
    "contact.enabled",
    { "true or false", "maybe" } },
  { "PrestressAndRestLength",
    { { "prestress: 50.0", "prestress: 50.0\n    rest_length: 1.0" } },
    "cables.cords.rest_length",
    { "prestress" } },
  { "SpringPrestressBeyondItsLength",
    { { "prestress: 10.0", "prestress: 1000.0" } },
    "springs.holders.prestress",
    { "'K1'", "rest length" } },
  { "LoadOnFixedNode",
    { { kAnalysis, kAnalysis + "loads:\n  push: {node: A, force: [0.0, 0.0, -1.0]}\n" } },
    "loads.push.node",
    { "'A'", "fixed" } },
  // the message names the limit (struts.radius) but not the bad core radius: see the test report
  { "CoreWiderThanStrut",
    { { "  radius: 0.02\n", "  radius: 0.02\n  core: {material: steel, radius: 0.03}\n" } },
    "struts.core.radius",
    { "smaller than struts.radius" } },
};

class BadSceneTest : public ::testing::TestWithParam<BadScene>
{
};

TEST_P(BadSceneTest, IsRefusedNamingKeyAndValue)
{
  const BadScene& b = GetParam();
  const std::string yaml = edited(b.edits);
  ASSERT_NE(yaml, kMini);
  std::vector<std::string> needles = b.needles;
  needles.push_back("bad.yaml: ");  // the file comes first
  EXPECT_TRUE(refused([&] { loadSceneFromString(yaml, "bad.yaml"); }, b.key, needles)) << yaml;
}

INSTANTIATE_TEST_SUITE_P(Scene, BadSceneTest, ::testing::ValuesIn(kBadScenes),
                         [](const ::testing::TestParamInfo<BadScene>& info) { return info.param.name; });

TEST(BadScene, TheUneditedSceneLoads)
{
  // the control for the table above: every refusal comes from its edit
  EXPECT_NO_THROW(loadSceneFromString(kMini, "bad.yaml"));
}

TEST(BadScene, YamlSyntaxErrorNamesTheFileAndTheLine)
{
  const std::string broken = "C: {position: [0.0, 0.8, 1.0}";  // the ']' is missing
  const std::string yaml = edited({ { "C: {position: [0.0, 0.8, 1.0]}", broken } });
  const size_t at = yaml.find(broken);
  const int line = 1 + static_cast<int>(std::count(yaml.begin(), yaml.begin() + at, '\n'));
  EXPECT_TRUE(refused([&] { loadSceneFromString(yaml, "bad.yaml"); }, "",
                      { "bad.yaml: ", "YAML syntax error", "line " + std::to_string(line) }));
}

TEST(BadScene, SceneThatIsNotAMap)
{
  EXPECT_TRUE(refused([] { loadSceneFromString("[1, 2, 3]", "list.yaml"); }, "", { "list.yaml", "YAML map" }));
  EXPECT_TRUE(refused([] { loadSceneFromString("", "empty.yaml"); }, "", { "empty.yaml", "YAML map" }));
  EXPECT_TRUE(refused(
      [] {
        loadSceneFromString(edited({ { "  M: {", "  M: 7\n  N: {" } }), "bad.yaml");
      },
      "nodes.M", { "expected a map", "'7'" }));
}

TEST(BadScene, MissingFileIsNamed)
{
  const std::string path = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/no_such_scene.yaml";
  EXPECT_TRUE(refused([&] { loadScene(path); }, "", { path, "cannot open" }));
}

TEST(ContactSettings, KeysReachTheModelAndPairsGetTheirStiffness)
{
  const Model m = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/quadruplex.yaml",
                            { { "contact.enabled", "true" },
                              { "contact.restitution", "0.5" },
                              { "contact.friction", "0.1" },
                              { "contact.stick_velocity", "0.002" },
                              { "contact.slip_velocity", "0.04" },
                              { "contact.min_crossing_angle", "5" },
                              { "contact.min_impact_speed", "0.01" } });
  EXPECT_TRUE(m.contact.enabled);
  EXPECT_EQ(m.contact.restitution, 0.5);
  EXPECT_EQ(m.contact.friction, 0.1);
  EXPECT_EQ(m.contact.stick_velocity, 0.002);
  EXPECT_EQ(m.contact.slip_velocity, 0.04);
  EXPECT_NEAR(m.contact.min_crossing_angle, 5.0 * M_PI / 180.0, 1e-15);
  EXPECT_EQ(m.contact.min_impact_speed, 0.01);
  // steel on steel (E 210 GPa, nu 0.31), r = 0.05 m: K90 = 4/3 E* sqrt(r)
  const double estar = 210e9 / (2.0 * (1.0 - 0.31 * 0.31));
  ASSERT_EQ(m.checkedPairList().size(), 6u);
  for (const StrutPair& p : m.checkedPairList())
    EXPECT_NEAR(p.stiffness90, 4.0 / 3.0 * estar * std::sqrt(0.05), 1e-6 * p.stiffness90);
}

TEST(SceneFiles, EveryShippedSceneLoadsAndStartsConsistent)
{
  int n = 0;
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes"))
  {
    if (entry.path().extension() != ".yaml")
      continue;
    ++n;
    const Model m = loadScene(entry.path().string());
    EXPECT_FALSE(m.bodies.empty()) << entry.path();
    const State s = initialState(m);
    EXPECT_TRUE(s.q.allFinite()) << entry.path();
    // the joints hold at the start: every constraint row is satisfied by the initial configuration
    const System sys(m);
    Eigen::VectorXd phi;
    sys.constraintValue(s.q, s.u, phi);
    EXPECT_LT(phi.lpNorm<Eigen::Infinity>(), 1e-9) << entry.path();
  }
  EXPECT_GE(n, 5);  // quadruplex, tower, prism, masts, parallel, and whatever comes
}

// ---------------------------------------------------------------------------------------------------
// bounds on what a scene may ask for, repeated keys, and messages that stay readable

const std::string kDynamic = "analysis:\n  type: dynamic\n  max_actuation: 0.3\n  duration: 0.1\n";

// kMini as a dynamic run (actuation speed 0.1 m/s), with `extra` appended
std::string dynamicMini(const std::string& extra = "")
{
  return edited({ { kAnalysis, "actuation: {speed: 0.1}\n" + kDynamic + extra } });
}

TEST(SceneBounds, EveryIntegerKeyIsBounded)
{
  const std::vector<std::tuple<std::string, std::string, std::string>> cases = {
    { "solver.max_iterations", "1073741824", "at most 1000" },  // 4 x 2^30 overflowed an int in statics
    { "solver.max_step_cuts", "1e9", "at most 60" },
    { "solver.max_jacobian_age", "3e9", "at most 1000000" },
    { "analysis.steps", "2147483648", "at most 10000000" },
    { "solver.max_step_cuts", "-1", "at least 0" },
    { "analysis.modes", "1e9", "at most 1000" },
    { "analysis.modes", "0", "at least 1" },
  };
  for (const auto& [key, value, needle] : cases)
  {
    const std::string set = key + "=" + value;  // (a lambda may not capture a structured binding before C++20)
    EXPECT_TRUE(refused([&set] { loadSceneFromString(kMini, "mini.yaml", { parseOverride(set) }); }, key,
                        { needle, "'" + value + "'" }))
        << key;
  }
  // the bounds themselves load
  const Model m = loadSceneFromString(
      kMini, "mini.yaml", { parseOverride("solver.max_iterations=1000"), parseOverride("solver.max_step_cuts=60") });
  EXPECT_EQ(m.solver.max_iterations, 1000);
  EXPECT_EQ(m.solver.max_step_cuts, 60);
}

TEST(SceneBounds, TimeStepsBeyondTheBoundAreRefusedWithTheNumbers)
{
  // 0.1 s / 1e-300 s would overflow the step counter (it ran no step and said converged)
  EXPECT_TRUE(refused([] { loadSceneFromString(dynamicMini(), "mini.yaml", { parseOverride("solver.dt=1e-300") }); },
                      "solver.dt", { "solver.dt_min = 1e-07", "1e-300" }));
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(dynamicMini(), "mini.yaml",
                            { parseOverride("solver.dt=1e-9"), parseOverride("solver.dt_min=1e-12"),
                              parseOverride("analysis.duration=1000") });
      },
      "solver.dt", { "1000 s", "1e-09 s", "1e+12 time steps", "1e+08" }));
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(dynamicMini(), "mini.yaml",
                            { parseOverride("solver.adaptive=true"), parseOverride("analysis.duration=1e300") });
      },
      "solver.dt_max", { "1e+300 s", "0.01 s", "1e+08" }));
  // the smallest step bounds dt in every scene (the node steps static scenes in time too); a static run
  // does not step in time, so its number of steps does not bound dt
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("solver.dt=1e-300") }); },
                      "solver.dt", { "solver.dt_min = 1e-07", "1e-300" }));
  EXPECT_NO_THROW(loadSceneFromString(kMini, "mini.yaml",
                                      { parseOverride("solver.dt=1e-300"), parseOverride("solver.dt_min=1e-300") }));
}

TEST(SceneBounds, OutputIntervalBelowTheSmallestStepIsRefused)
{
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(dynamicMini(), "mini.yaml",
                            { parseOverride("solver.adaptive=true"),
                              parseOverride("analysis.output_interval=1e-300") });
      },
      "analysis.output_interval", { "dt_min = 1e-07", "1e-300" }));
  EXPECT_TRUE(refused([]
                      { loadSceneFromString(dynamicMini(), "mini.yaml", { parseOverride("analysis.duration=1e-9") }); },
                      "analysis.duration", { "dt_min", "1e-09" }));
  EXPECT_NO_THROW(loadSceneFromString(dynamicMini(), "mini.yaml", { parseOverride("analysis.output_interval=1e-7") }));
}

TEST(SceneBounds, NothingFreeToMoveIsRefused)
{
  // every node fixed and no strut, for both analyses (a dynamic one crashed in the sparse LU, a static one
  // wrote -inf heights)
  const std::string still = R"(name: still
materials:
  cord: {youngs_modulus: 1.0e7}
nodes:
  A: {position: [0.0, 0.0, 0.0], fixed: true}
  B: {position: [1.0, 0.0, 0.0], fixed: true}
struts: {material: cord, radius: 0.01, members: {}}
cables:
  c: {material: cord, radius: 0.001, members: {C1: [A, B]}}
)";
  EXPECT_TRUE(refused([&] { loadSceneFromString(still + "analysis: {type: static}\n", "still.yaml"); },
                      "struts.members", { "nothing to simulate" }));
  EXPECT_TRUE(refused([&] { loadSceneFromString(still + "analysis: {type: dynamic, duration: 1}\n", "still.yaml"); },
                      "struts.members", { "nothing to simulate" }));
}

TEST(SceneBounds, AStrutPinnedAtBothEndsMeasuresTheHeightOfItsNodes)
{
  // no free node: the height is that of all nodes (finite), not of an empty set (-inf)
  const Model m = loadSceneFromString(
      edited({ { "  C: {position: [0.0, 0.8, 1.0]}", "  C: {position: [0.0, 0.8, 1.0], fixed: true}" },
               { "  D: {position: [1.0, 0.2, 1.0]}", "  D: {position: [1.0, 0.2, 1.0], fixed: true}" },
               { "  M: {position: [0.5, 0.5, 1.5], mass: 0.2}\n", "" },
               { "springs:\n  holders:\n    stiffness: 500.0\n    prestress: 10.0\n    members: {K1: [C, M], K2: [D, "
                 "M]}\n",
                 "" },
               { "actuators:\n  lift:\n    nodes: [M]\n    direction: [0.0, 0.0, -1.0]\n    range: [0.0, 0.5]\n", "" },
               { "  max_actuation: 0.3\n", "" } }),
      "pinned.yaml");
  EXPECT_EQ(m.height_nodes.size(), m.nodes.size());
}

// "line N" of the n-th (1-based) line of `yaml` that holds `needle`
std::string lineOf(const std::string& yaml, const std::string& needle, int nth = 1)
{
  size_t at = std::string::npos;
  for (int k = 0; k < nth; ++k)
    at = yaml.find(needle, at == std::string::npos ? 0 : at + 1);
  EXPECT_NE(at, std::string::npos) << needle;
  return "line " + std::to_string(1 + std::count(yaml.begin(), yaml.begin() + static_cast<long>(at), '\n'));
}

TEST(SceneKeys, ARepeatedKeyIsRefusedWithBothLines)
{
  // a repeated node (the first one won, shifting every height) and a second members block (dropped)
  const std::string node_twice = edited({ { "  M: {", "  A: {position: [0.0, 0.0, -1.0], fixed: true}\n  M: {" } });
  EXPECT_TRUE(refused([&] { loadSceneFromString(node_twice, "bad.yaml"); }, "nodes.A",
                      { "repeated key", lineOf(node_twice, "  A: {"), lineOf(node_twice, "  A: {", 2) }));
  const std::string members_twice =
      edited({ { "    members: {C1: [A, C], C2: [B, D]}\n",
                 "    members: {C1: [A, C], C2: [B, D]}\n    members: {C3: [A, D]}\n" } });
  EXPECT_TRUE(refused([&] { loadSceneFromString(members_twice, "bad.yaml"); }, "cables.cords.members",
                      { "repeated key", lineOf(members_twice, "members: {C1"), lineOf(members_twice, "members: {C3") }));
  // in a flow map, and at the top level
  const std::string in_flow = edited({ { "density: 7850.0}", "density: 7850.0, density: 1.0}" } });
  EXPECT_TRUE(refused([&] { loadSceneFromString(in_flow, "bad.yaml"); }, "materials.steel.density",
                      { "repeated key", lineOf(in_flow, "density: 1.0}") }));
  const std::string top = kMini + "name: again\n";
  EXPECT_TRUE(refused([&] { loadSceneFromString(top, "bad.yaml"); }, "name",
                      { "repeated key", "line 1 ", lineOf(top, "name: again") }));
}

TEST(SceneKeys, ASecondYamlDocumentIsRefused)
{
  const std::string two = kMini + "---\nname: other\n";
  EXPECT_TRUE(refused([&] { loadSceneFromString(two, "two.yaml"); }, "",
                      { "two.yaml", "a second YAML document starts on", lineOf(two, "---") }));
}

TEST(SceneKeys, AKeyThatIsNotANameIsRefusedWithItsLine)
{
  const std::string yaml = edited({ { "materials:\n", "materials:\n  [a, b]: 1\n" } });
  EXPECT_TRUE(refused([&] { loadSceneFromString(yaml, "bad.yaml"); }, "materials",
                      { "expected names as keys", "[a, b]", lineOf(yaml, "[a, b]") }));
  const std::string null_key = kMini + ":\n";
  EXPECT_TRUE(
      refused([&] { loadSceneFromString(null_key, "bad.yaml"); }, "",
              { "got the key null", "line " + std::to_string(std::count(kMini.begin(), kMini.end(), '\n') + 1) }));
}

TEST(SceneKeys, StrayFlowTokensEndInARefusal)
{
  // yaml-cpp's LoadAll yields empty documents for ever on a lone ','
  for (const std::string& text : { std::string(","), kMini + ",\n", std::string("]") })
    EXPECT_THROW(loadSceneFromString(text, "stray.yaml"), SceneError) << text;
}

TEST(SceneKeys, AliasedNodesAreCheckedOnce)
{
  // YAML aliases share nodes: nine levels of ten references each reach a billion leaves through a few
  // dozen nodes; the repeated-key check visits each node once (else this test would not end)
  std::string nested = "[&a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]";
  for (int level = 1; level <= 9; ++level)
  {
    nested += ", &a" + std::to_string(level) + " [";
    for (int k = 0; k < 10; ++k)
      nested += (k ? ", *a" : "*a") + std::to_string(level - 1);
    nested += "]";
  }
  nested += "]";
  EXPECT_TRUE(refused([&] { loadSceneFromString(kMini + "description: " + nested + "\n", "alias.yaml"); },
                      "description", { "non-empty string" }));
}

TEST(SceneOverride, AKeyEndingInADotIsRefused)
{
  // "analysis.duration." was taken as analysis.duration
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride("analysis.duration.=0.001") }); },
                      "analysis.duration.", { "malformed" }));
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride(".analysis=1") }); }, ".analysis", { "malformed" }));
}

TEST(SceneOverride, ABadValueIsBlamedOnTheCommandLine)
{
  try
  {
    loadScene(kQuadruplex, { parseOverride("struts.radius=-0.06") });
    FAIL() << "loaded";
  }
  catch (const SceneError& e)
  {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind("--set struts.radius=-0.06 (on " + kQuadruplex + "): struts.radius: ", 0), 0u) << what;
  }
  // a key the file set and no override touched is still blamed on the file
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(edited({ { "radius: 0.02", "radius: -0.02" } }), "mini.yaml",
                            { parseOverride("analysis.steps=5") });
      },
      "struts.radius", { "mini.yaml: struts.radius" }));
}

TEST(SceneMessages, NumbersArePrintedInTheirShortestExactForm)
{
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("solver.newmark.gamma=0.4999") }); },
                      "solver.newmark.gamma", { "got 0.4999" }));
  EXPECT_TRUE(
      refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("materials.steel.poisson_ratio=-1e-9") }); },
              "materials.steel.poisson_ratio", { "got -1e-09" }));
  // the six-decimal form would have printed 0.500000 and -0.000000
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("solver.newmark.beta=0.3") }); },
                      "solver.newmark.beta", { "= 0.3025", "got 0.3" }));
}

TEST(SceneMessages, LongValuesAreCut)
{
  const std::string huge(1000 * 1000, 'x');
  try
  {
    loadSceneFromString(kMini, "mini.yaml", { parseOverride("struts.radius=" + huge) });
    FAIL() << "loaded";
  }
  catch (const SceneError& e)
  {
    const std::string what = e.what();
    EXPECT_LT(what.size(), 1000u);
    EXPECT_NE(what.find("(1000000 bytes)"), std::string::npos) << what;
  }
  try
  {
    loadSceneFromString(edited({ { "S2: [B, C]", "S2: [B, " + huge + "]" } }), "mini.yaml");
    FAIL() << "loaded";
  }
  catch (const SceneError& e)
  {
    EXPECT_LT(std::string(e.what()).size(), 1000u);
    EXPECT_NE(std::string(e.what()).find("unknown node 'xxx"), std::string::npos);
  }
  // a key that is a long text (found by libFuzzer: a multi-line plain scalar as a material's name, missing
  // its required keys, gave a 4 kB message)
  try
  {
    loadSceneFromString(
        edited({ { "materials:\n", "materials:\n  " + std::string(1000, 'k') + ": {density: 1.0}\n" } }), "mini.yaml");
    FAIL() << "loaded";
  }
  catch (const SceneError& e)
  {
    EXPECT_LT(std::string(e.what()).size(), 1000u) << e.what();
    EXPECT_NE(std::string(e.what()).find("(1000 bytes)"), std::string::npos) << e.what();
  }
}

TEST(SceneMessages, TheRealCauseOfAMasslessStrutIsNamed)
{
  // a radius of 1e-200 m: r^2 underflows; the density is fine
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("struts.radius=1e-200") }); },
                      "struts.radius", { "1e-200", "area of 0" }));
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("struts.radius=1e200") }); },
                      "struts.radius", { "1e+200", "area of inf" }));
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("cables.cords.radius=1e-170") }); },
                      "cables.cords.radius", { "1e-170" }));
}

TEST(SceneMessages, MessagesQuoteTheBadValue)
{
  EXPECT_TRUE(refused(
      [] {
        loadSceneFromString(edited({ { "S3: [C, D]", "S3: [C, D, A]" } }), "mini.yaml");
      },
      "struts.members.S3", { "expected two node names [from, to], got [C, D, A]" }));
  EXPECT_TRUE(refused(
      [] {
        loadSceneFromString(edited({ { "[1.0, 0.2, 1.0]", "[0.0, 0.0, 0.0]" } }), "mini.yaml");
      },
      "struts.members.S1", { "zero length", "'A' at [0, 0, 0]", "'D' at [0, 0, 0]" }));
}

TEST(SceneModal, TheModalKeysLoad)
{
  // a modal analysis needs no actuation travel (its modes are then about the start) and no fixed node (a
  // floating structure has its rigid-body modes at 0 Hz)
  const Model m = loadSceneFromString(edited({ { "type: static", "type: modal\n  modes: 4" },
                                               { "  max_actuation: 0.3\n", "" },
                                               { "fixed: true}\n  B", "fixed: false}\n  B" },
                                               { "fixed: true}\n  C", "fixed: false}\n  C" } }),
                                      "modal.yaml");
  EXPECT_EQ(m.analysis.type, AnalysisType::kModal);
  EXPECT_EQ(m.analysis.modes, 4);
  EXPECT_EQ(m.analysis.max_actuation, 0.0);
  EXPECT_EQ(loadSceneFromString(kMini, "mini.yaml").analysis.modes, 10);
}

TEST(SceneModal, BadModalInputIsRefusedNamingKeyAndValue)
{
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(kMini, "mini.yaml",
                            { parseOverride("analysis.type=modal"), parseOverride("analysis.modes=.nan") });
      },
      "analysis.modes", { "finite", "'.nan'" }));
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(kMini, "mini.yaml",
                            { parseOverride("analysis.type=modal"), parseOverride("analysis.modes=2.5") });
      },
      "analysis.modes", { "integer", "'2.5'" }));
  // every node fixed: each strut pinned at both ends, nothing to vibrate (7 coordinates, 6 + 1 + 1 rows each)
  const std::string pinned =
      edited({ { "  C: {position: [0.0, 0.8, 1.0]}", "  C: {position: [0.0, 0.8, 1.0], fixed: true}" },
               { "  D: {position: [1.0, 0.2, 1.0]}", "  D: {position: [1.0, 0.2, 1.0], fixed: true}" },
               { "  M: {position: [0.5, 0.5, 1.5], mass: 0.2}\n", "" },
               { "springs:\n  holders:\n    stiffness: 500.0\n    prestress: 10.0\n    members: {K1: [C, M], K2: [D, "
                 "M]}\n",
                 "" },
               { "actuators:\n  lift:\n    nodes: [M]\n    direction: [0.0, 0.0, -1.0]\n    range: [0.0, 0.5]\n", "" },
               { "  max_actuation: 0.3\n", "" } });
  EXPECT_NO_THROW(loadSceneFromString(pinned, "pinned.yaml"));
  EXPECT_TRUE(refused([&] { loadSceneFromString(pinned, "pinned.yaml", { parseOverride("analysis.type=modal") }); },
                      "analysis.type",
                      { "--set analysis.type=modal (on pinned.yaml)", "leave free", "every node", "'modal'" }));
  // the dense analysis is bounded: 1001 point masses, 3003 coordinates
  std::string extra;
  for (int i = 0; i < 1001; ++i)
    extra += "  G" + std::to_string(i) + ": {position: [" + std::to_string(i) + ".0, 5.0, 0.0], mass: 1.0}\n";
  const std::string many = edited({ { "  M: {", extra + "  M: {" } });
  EXPECT_NO_THROW(loadSceneFromString(many, "many.yaml"));
  EXPECT_TRUE(refused([&] { loadSceneFromString(many, "many.yaml", { parseOverride("analysis.type=modal") }); },
                      "analysis.type", { "at most 3000 coordinates", "has 3027", "'modal'" }));
}

TEST(SceneLoading, TwentyThousandNodesLoad)
{
  // the loader indexes names and keys (its time grew with the square of the node count); the run time is
  // measured by `tensegrity_bench load`
  std::string extra;
  for (int i = 0; i < 20000; ++i)
    extra += "  G" + std::to_string(i) + ": {position: [" + std::to_string(i) + ".0, 5.0, 0.0], fixed: true}\n";
  const Model m = loadSceneFromString(edited({ { "  M: {", extra + "  M: {" } }), "many.yaml");
  EXPECT_EQ(m.nodes.size(), 20005u);
  EXPECT_EQ(m.findNode("G19999"), 4 + 19999);
  EXPECT_EQ(m.findNode("M"), 4 + 20000);
}

TEST(SceneBounds, LoadPathKeysAreCheckedAgainstTheAnalysis)
{
  const std::string tripod = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/test/scenes/snap_tripod.yaml";
  EXPECT_NO_THROW(loadScene(tripod, { parseOverride("analysis.arc_length=true") }));
  EXPECT_TRUE(refused([&] { loadScene(tripod, { parseOverride("analysis.load_factor=[0, 1, 2]") }); },
                      "analysis.load_factor", { "two numbers", "[0, 1, 2]" }));
  EXPECT_TRUE(refused([&] { loadScene(tripod, { parseOverride("analysis.load_factor=[0, .nan]") }); },
                      "analysis.load_factor", { "finite", ".nan" }));
  EXPECT_TRUE(refused([&] { loadScene(tripod, { parseOverride("analysis.load_factor=[0, 1e9]") }); },
                      "analysis.load_factor", { "[-1e6, 1e6]", "1e+09" }));
  // a path with no loads to scale, and keys of static paths on a dynamic analysis
  EXPECT_TRUE(refused([] { loadScene(kQuadruplex, { parseOverride("analysis.load_factor=[0, 1]") }); },
                      "analysis.load_factor", { "no loads" }));
  EXPECT_TRUE(
      refused([] { loadSceneFromString(dynamicMini(), "mini.yaml", { parseOverride("analysis.arc_length=true") }); },
              "analysis.arc_length", { "static paths only" }));
}

TEST(MessageNumbers, ComputedValuesAreRoundedUserValuesExact)
{
  using active_tensegrity::core::roundedNumber;
  using active_tensegrity::core::shortestNumber;
  const double ramp_end = 0.09999999999999999;  // a ramp of 0.02 m at 0.4 m/s with 0.05 s blends, as computed
  EXPECT_EQ(shortestNumber(ramp_end), "0.09999999999999999");
  EXPECT_EQ(roundedNumber(ramp_end), "0.1");
  EXPECT_EQ(roundedNumber(41245957.1234, 6), "41246000");
  EXPECT_EQ(roundedNumber(-2.5e-300), "-2.5e-300");
  EXPECT_EQ(roundedNumber(std::nan("")), "nan");
  EXPECT_EQ(roundedNumber(-HUGE_VAL), "-inf");
}

TEST(SceneBounds, ATimeStepLongerThanTheRunIsRefusedWithBoth)
{
  // it ran no step at all and said converged
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(dynamicMini(), "mini.yaml",
                            { parseOverride("analysis.duration=0.003"), parseOverride("solver.dt=1e7") });
      },
      "solver.dt", { "--set solver.dt=1e7", "time step 1e+07 s", "analysis.duration 0.003 s" }));
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(dynamicMini(), "mini.yaml",
                            { parseOverride("analysis.duration=0.003"), parseOverride("solver.dt=0.004"),
                              parseOverride("solver.adaptive=true") });
      },
      "solver.dt", { "first step 0.004 s", "analysis.duration 0.003 s" }));
  // a derived duration is named as such
  EXPECT_TRUE(refused(
      []
      {
        loadSceneFromString(edited({ { kAnalysis, "actuation: {speed: 0.1}\nanalysis:\n  type: dynamic\n  "
                                                  "max_actuation: 0.3\n  settle_time: 0.5\n" } }),
                            "mini.yaml", { parseOverride("solver.dt=10") });
      },
      "solver.dt", { "(derived) 3.5 s" }));
  // a step as long as the run, and any step of a static path, load
  EXPECT_NO_THROW(loadSceneFromString(dynamicMini(), "mini.yaml", { parseOverride("solver.dt=0.1") }));
  EXPECT_NO_THROW(loadSceneFromString(kMini, "mini.yaml", { parseOverride("solver.dt=10") }));
}

TEST(SceneBounds, TolerancesLieInTheirRanges)
{
  const std::vector<std::tuple<std::string, std::string, std::string, std::string>> cases = {
    { "solver.newton_tolerance", "1e300", "(0, 0.001] m", "got '1e300'" },
    { "solver.newton_tolerance", "0.002", "(0, 0.001] m", "got '0.002'" },
    { "solver.newton_tolerance", "0", "(0, 0.001] m", "got '0'" },
    { "solver.error_tolerance", "1", "(0, 0.01] m", "got '1'" },
    { "solver.onset_depth", "1e9", "(0, 0.01] m", "got '1e9'" },
    { "solver.newmark.gamma", "2", "at most 1", "got 2" },
    { "solver.newmark.beta", "1e300", "[0.3025, 1]", "got 1e+300" },
    { "materials.steel.youngs_modulus", "1e300", "(0, 1e+14] Pa", "got '1e300'" },
    { "materials.steel.density", "1e6", "[0, 1e+05] kg/m^3", "got '1e6'" },
    { "contact.friction", "1e300", "[0, 10]", "got '1e300'" },
  };
  for (const auto& [key, value, range, got] : cases)
  {
    const std::string set = key + "=" + value;
    EXPECT_TRUE(
        refused([&set] { loadSceneFromString(kMini, "mini.yaml", { parseOverride(set) }); }, key, { range, got }))
        << set;
  }
  // the bounds themselves load
  const Model m = loadSceneFromString(
      kMini, "mini.yaml",
      { parseOverride("solver.newton_tolerance=1e-3"), parseOverride("solver.error_tolerance=1e-2"),
        parseOverride("solver.onset_depth=1e-2"), parseOverride("solver.newmark={gamma: 1, beta: 1}"),
        parseOverride("materials.steel.youngs_modulus=1e14"), parseOverride("materials.steel.density=1e5"),
        parseOverride("contact.friction=10") });
  EXPECT_EQ(m.solver.newton_tolerance, 1e-3);
  EXPECT_EQ(m.solver.error_tolerance, 1e-2);
  EXPECT_EQ(m.contact.friction, 10.0);
}

TEST(SceneOverride, AValueIsHeldToTheRulesOfTheFile)
{
  // a repeated key inside a --set value (the first one was kept silently)
  EXPECT_TRUE(refused([]
                      { loadSceneFromString(kMini, "mini.yaml", { parseOverride("struts={radius: 1, radius: 2}") }); },
                      "struts.radius",
                      { "--set struts={radius: 1, radius: 2} (on mini.yaml)", "repeated key", "column 2",
                        "column 13 of the --set value" }));
  EXPECT_TRUE(
      refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("materials.steel={a: {b: 1, b: 2}}") }); },
              "materials.steel.a.b", { "repeated key" }));
  // a second document in a value (only the first was read)
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("struts.radius=0.05\n---\n1") }); },
                      "struts.radius", { "second YAML document", "line 2" }));
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("name=a\n--- b") }); }, "name",
                      { "second YAML document" }));
  // what looks like them but is not: '---' inside a text, the same key in two maps
  EXPECT_EQ(loadSceneFromString(kMini, "mini.yaml", { parseOverride("name=a --- b") }).name, "a --- b");
  EXPECT_NO_THROW(
      loadSceneFromString(kMini, "mini.yaml", { parseOverride("gravity={enabled: true, vector: [0, 0, 1]}") }));
}

TEST(SceneKeys, AMisspeltKeyIsNamedWithItsNearMatch)
{
  // a required key misspelt: the typo is named, not only the missing key
  EXPECT_TRUE(refused(
      [] {
        loadSceneFromString(edited({ { "radius: 0.02", "radious: 0.02" } }), "mini.yaml");
      },
      "struts.radious", { "unknown key", "did you mean 'radius'?", "the required key struts.radius is missing" }));
  // an optional one, from the command line and in the file
  EXPECT_TRUE(refused([] { loadSceneFromString(kMini, "mini.yaml", { parseOverride("solver.newton_tolerence=1e-6") }); },
                      "solver.newton_tolerence", { "unknown key", "did you mean 'newton_tolerance'?" }));
  EXPECT_TRUE(refused(
      [] {
        loadSceneFromString(edited({ { "  steps: 10", "  stpes: 10" } }), "mini.yaml");
      },
      "analysis.stpes", { "did you mean 'steps'?" }));
  // nothing near: no guess
  EXPECT_TRUE(refused(
      [] {
        loadSceneFromString(edited({ { "radius: 0.02", "thickness: 0.02" } }), "mini.yaml");
      },
      "struts.radius", { "missing required key" }));
  try
  {
    loadSceneFromString(kMini, "mini.yaml", { parseOverride("solver.frobnicate=1") });
    FAIL() << "loaded";
  }
  catch (const SceneError& e)
  {
    EXPECT_EQ(std::string(e.what()).find("did you mean"), std::string::npos) << e.what();
  }
}

TEST(MessageText, EditDistanceAndNearestMatch)
{
  EXPECT_EQ(editDistance("radious", "radius"), 1u);
  EXPECT_EQ(editDistance("stpes", "steps"), 1u);  // a swap of neighbours
  EXPECT_EQ(editDistance("", "abc"), 3u);
  EXPECT_EQ(editDistance("kitten", "sitting"), 3u);
  EXPECT_EQ(nearestMatch("radious", { "material", "radius", "members" }), "radius");
  EXPECT_EQ(nearestMatch("dt", { "dt_min", "dt_max" }), "");
  EXPECT_EQ(nearestMatch("mas", { "mass", "radius" }), "mass");
  EXPECT_EQ(nearestMatch("radius", { "radius" }), "");
}

TEST(SceneFiles, OnlyRegularFilesOfBoundedSizeAreRead)
{
  // /dev/zero was read without end (std::bad_alloc)
  EXPECT_TRUE(refused([] { loadScene("/dev/zero"); }, "", { "/dev/zero", "not a regular file (a device)", "64 MiB" }));
  const std::string dir = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes";
  EXPECT_TRUE(refused([&] { loadScene(dir); }, "", { dir, "is a directory" }));
  // a sparse file of 64 MiB and a byte
  const std::filesystem::path big = std::filesystem::path(::testing::TempDir()) / "active_tensegrity_big_scene.yaml";
  {
    std::ofstream(big.string()) << "name: big\n";
  }
  std::filesystem::resize_file(big, kMaxSceneBytes + 1);
  EXPECT_TRUE(refused([&] { loadScene(big.string()); }, "", { "67108865 bytes", "64 MiB" }));
  std::filesystem::remove(big);
  EXPECT_TRUE(refused([] { loadSceneFromString(std::string(kMaxSceneBytes + 1, ' '), "big.yaml"); }, "",
                      { "big.yaml", "67108865 bytes" }));
  EXPECT_EQ(readSceneFile(kQuadruplex).substr(0, 1), "#");
}
