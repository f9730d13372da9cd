// Form-finding (core/scene/form_finding.h, docs/form_finding.md): the equations' Jacobian against finite
// differences, closed forms (the n-strut prism's twist and force densities, the expanded octahedron's
// proportions, the quadruplex's prestress of paper Table 1), the written scene's own check, and refusals.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/design/form_finding.h"
#include "active_tensegrity/design/generators.h"
#include "active_tensegrity/core/scene/scene.h"

namespace at = active_tensegrity::core;
namespace design = active_tensegrity::design;

namespace
{
std::string readFile(const std::string& path)
{
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

std::string sceneFile(const std::string& name)
{
  return readFile(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name);
}

/// The twist of strut i of a prism form: the angle of Ti about z minus that of Bi, in (-pi, pi].
double strutTwist(const design::FormFindingResult& r, int n, int i)
{
  const at::Vec3& b = r.positions[i];
  const at::Vec3& t = r.positions[n + i];
  return std::remainder(std::atan2(t.y(), t.x()) - std::atan2(b.y(), b.x()), 2.0 * M_PI);
}

const design::FormMember& member(const design::FormFindingResult& r, const std::string& name)
{
  for (const design::FormMember& m : r.members)
    if (m.name == name)
      return m;
  throw std::runtime_error("no member " + name);
}

/// The scene with the position of every node whose line starts with `prefix` ("  T": the top nodes) moved by
/// up to `jitter` m in each direction at random.
std::string jitterNodes(const std::string& yaml, const std::string& prefix, double jitter, unsigned seed)
{
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-jitter, jitter);
  std::istringstream in(yaml);
  std::string out;
  for (std::string line; std::getline(in, line);)
  {
    if (line.rfind(prefix, 0) == 0 && line.find("position: [") != std::string::npos)
    {
      const size_t open = line.find('['), close = line.find(']');
      std::istringstream nums(line.substr(open + 1, close - open - 1));
      double x, y, z;
      char c;
      nums >> x >> c >> y >> c >> z;
      std::ostringstream p;
      p.precision(17);
      p << "[" << x + d(rng) << ", " << y + d(rng) << ", " << z + d(rng) << "]";
      line = line.substr(0, open) + p.str() + line.substr(close + 1);
    }
    out += line + "\n";
  }
  return out;
}

/// A prism a few degrees off its form, its top nodes moved by up to `jitter` m at random.
std::string perturbedPrism(int n, double twist_error, double jitter, unsigned seed, bool pinned = false)
{
  design::PrismSpec spec;
  spec.struts = n;
  spec.twist = design::prismTwist(n) + twist_error;
  spec.pinned = pinned;
  const std::string yaml = design::prismScene(spec);
  return jitter == 0.0 ? yaml : jitterNodes(yaml, "  T", jitter, seed);
}
}  // namespace

// The analytic Jacobian of the equilibrium equations against central differences: tension and force-density
// members, a sliding cable through an inner node, fixed nodes (with and without reactions).
TEST(FormEquations, JacobianMatchesFiniteDifferences)
{
  const design::FormTopology t = design::readFormTopology(sceneFile("prism_pinned_sliding.yaml"), "sliding");
  bool sliding = false;
  for (const design::FormTopology::Member& m : t.members)
    sliding = sliding || m.nodes.size() > 2;
  ASSERT_TRUE(sliding) << "the scene should have a sliding cable";
  ASSERT_GE(t.families.size(), 2u);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> d(-0.05, 0.05);
  for (const bool react : { false, true })
    for (const auto kind : { design::FormEquations::Kind::kTension, design::FormEquations::Kind::kDensity })
    {
      // with reactions: one force density per strut and every strut's length kept (one row each)
      const design::FormEquations eq(t, { { 0, { kind, 150.0 } } }, react, !react, react ? 300.0 : 0.0);
      EXPECT_EQ(eq.equations() - eq.forceRows(), react ? 3 : 0);
      std::vector<at::Vec3> x = t.positions;
      for (at::Vec3& p : x)
        p += at::Vec3(d(rng), d(rng), d(rng));
      Eigen::VectorXd params(eq.parameterNames().size());
      for (Eigen::Index k = 0; k < params.size(); ++k)
        params[k] = 50.0 + 100.0 * std::abs(d(rng)) * (eq.parameterNames()[k].rfind("strut", 0) == 0 ? -1 : 1);
      const Eigen::VectorXd z = eq.pack(x, params);
      const Eigen::MatrixXd j = eq.jacobian(z);
      ASSERT_EQ(j.rows(), eq.equations());
      ASSERT_EQ(j.cols(), eq.unknowns());
      Eigen::MatrixXd fd(j.rows(), j.cols());
      for (Eigen::Index c = 0; c < z.size(); ++c)
      {
        const double h = 1e-6 * std::max(1.0, std::abs(z[c]));
        Eigen::VectorXd zp = z, zm = z;
        zp[c] += h;
        zm[c] -= h;
        fd.col(c) = (eq.residual(zp) - eq.residual(zm)) / (2.0 * h);
      }
      EXPECT_LT((j - fd).cwiseAbs().maxCoeff(), 1e-6 * std::max(1.0, j.cwiseAbs().maxCoeff()))
          << "reactions " << react << ", kind " << static_cast<int>(kind);
      EXPECT_GT(j.cwiseAbs().maxCoeff(), 1.0);
    }
}

// The n-strut class-1 prism, free-standing, from a start 12 degrees off its twist with its top nodes moved at
// random by up to 2 cm: the form's twist is -(90 + 180/n) degrees at every strut and its force densities
// are rings : verticals : struts = 1 : 2 sin(pi/n) : -2 sin(pi/n).
TEST(FormFinding, PrismTwistAndForceDensitiesMatchTheClosedForm)
{
  for (int n = 3; n <= 8; ++n)
  {
    SCOPED_TRACE("n = " + std::to_string(n));
    design::FormFindingOptions o;
    o.tension["rings"] = 100.0;
    const std::string yaml = perturbedPrism(n, 12.0 * M_PI / 180.0, 0.0, 1);
    const design::FormFindingResult r = design::findForm(yaml, "prism", o);
    EXPECT_GT(r.max_move, 0.01);
    for (int i = 0; i < n; ++i)
      EXPECT_NEAR(strutTwist(r, n, i), design::prismTwist(n), 1e-6);
    const design::FormMember& ring = member(r, "R1");
    const design::FormMember& vertical = member(r, "V1");
    const design::FormMember& strut = member(r, "S1");
    const double q_ring = ring.tension / ring.length;
    EXPECT_NEAR(ring.tension, 100.0, 1e-9);
    EXPECT_NEAR(vertical.tension / vertical.length / q_ring, 2.0 * std::sin(M_PI / n), 1e-8);
    EXPECT_NEAR(strut.tension / strut.length / q_ring, -2.0 * std::sin(M_PI / n), 1e-8);
    EXPECT_LT(r.residual, 1e-9);
    // the written scene: in equilibrium at its start, prestress stable, no slack cable
    EXPECT_TRUE(r.check.checked);
    EXPECT_LT(r.check.equilibrium_residual, 1e-6);
    EXPECT_TRUE(r.check.prestress_stable);
    EXPECT_TRUE(r.check.slack_cables.empty());
  }
}

// Random moves of the top nodes break the symmetry of the start; a 4-strut prism then has forms that are not
// regular (its rings are four-bar linkages), and the one found must still be a form: in equilibrium, the held
// and free families uniform, prestress stable, its own check clean.
TEST(FormFinding, AsymmetricStartGivesAValidForm)
{
  for (unsigned seed = 1; seed <= 3; ++seed)
  {
    SCOPED_TRACE("seed " + std::to_string(seed));
    design::FormFindingOptions o;
    o.tension["rings"] = 100.0;
    const design::FormFindingResult r = design::findForm(perturbedPrism(4, 0.1, 0.02, seed), "prism", o);
    EXPECT_LT(r.residual, 1e-9);
    double q_strut = 0.0;
    for (const design::FormMember& m : r.members)
    {
      if (m.family == "rings")
      {
        EXPECT_NEAR(m.tension, 100.0, 1e-9);
      }
      if (m.family == "verticals")
      {
        EXPECT_NEAR(m.tension, member(r, "V1").tension, 1e-9);
      }
      if (m.strut && q_strut == 0.0)
        q_strut = m.tension / m.length;
      if (m.strut)
      {
        EXPECT_NEAR(m.tension / m.length, q_strut, 1e-9 * std::abs(q_strut));
      }
    }
    EXPECT_LT(q_strut, 0.0);
    EXPECT_LT(r.check.equilibrium_residual, 1e-6);
    EXPECT_TRUE(r.check.slack_cables.empty());
  }
}

// The expanded octahedron from a start whose nodes are moved by up to 5 cm (of a 1 m strut), every cable held
// at 100 N: the form's parallel struts are half a strut length apart, every cable is sqrt(6)/4 of a strut
// long, and the force densities are cables : struts = 1 : -1.5.
TEST(FormFinding, ExpandedOctahedronProportions)
{
  design::OctahedronSpec spec;
  const std::string yaml = jitterNodes(design::octahedronScene(spec), "  N", 0.05, 5);
  design::FormFindingOptions o;
  o.tension["cables"] = 100.0;
  const design::FormFindingResult r = design::findForm(yaml, "octahedron", o);
  EXPECT_GT(r.max_move, 0.02);
  double strut_length = 0.0;
  for (const design::FormMember& m : r.members)
    if (m.strut)
      strut_length += m.length / 6.0;
  const design::FormTopology given = design::readFormTopology(yaml, "octahedron");
  double given_length = 0.0;
  for (int k = 0; k < 6; ++k)
    given_length += (given.positions[2 * k + 1] - given.positions[2 * k]).norm() / 6.0;
  EXPECT_NEAR(strut_length, given_length, 1e-12) << "the mean strut length is kept";
  double q_cable = 0.0;
  for (const design::FormMember& m : r.members)
  {
    if (m.strut)
    {
      EXPECT_NEAR(m.length, strut_length, 1e-7);
      continue;
    }
    EXPECT_NEAR(m.tension, 100.0, 1e-9);
    // the octahedron has an infinitesimal mechanism: along it the force residual grows with the square of the
    // distance from the form, so a residual of 1e-15 of the forces leaves the geometry to a few 1e-6
    EXPECT_NEAR(m.length / strut_length, std::sqrt(6.0) / 4.0, 2e-5) << m.name;
    q_cable = m.tension / m.length;
  }
  for (const design::FormMember& m : r.members)
  {
    if (m.strut)
    {
      EXPECT_NEAR(m.tension / m.length / q_cable, -1.5, 3e-5) << m.name;
    }
  }
  // parallel struts (S1 | S2 ...) half a strut length apart: the distance between their midpoints
  for (int k = 0; k < 3; ++k)
  {
    const at::Vec3 mid1 = 0.5 * (r.positions[4 * k] + r.positions[4 * k + 1]);
    const at::Vec3 mid2 = 0.5 * (r.positions[4 * k + 2] + r.positions[4 * k + 3]);
    EXPECT_NEAR((mid1 - mid2).norm() / strut_length, 0.5, 2e-5);
  }
  EXPECT_TRUE(r.check.prestress_stable);
  EXPECT_TRUE(r.check.slack_cables.empty());
}

// Prestress design at the quadruplex's geometry (paper Sec. 6.1, Table 1): with the lower ring at 200 N, the
// self-stress of the free-standing unit gives the upper ring and the bracing 200 sqrt(2) = 282.84 N and the
// struts 200 sqrt(6) = 489.90 N of compression; the written scene is that of config/scenes/quadruplex.yaml.
TEST(FormFinding, QuadruplexPrestressMatchesTable1)
{
  design::FormFindingOptions o;
  o.mode = design::FormFindingMode::kPrestress;
  o.tension["lower"] = 200.0;
  const design::FormFindingResult r = design::findForm(sceneFile("quadruplex.yaml"), "quadruplex", o);
  EXPECT_EQ(r.self_stress_states, 1);
  EXPECT_EQ(r.max_move, 0.0);
  for (const design::FormMember& m : r.members)
  {
    if (m.family == "lower")
      EXPECT_NEAR(m.tension, 200.0, 1e-9);
    else if (m.strut)
      EXPECT_NEAR(m.tension, -200.0 * std::sqrt(6.0), 1e-8) << m.name;
    else
      EXPECT_NEAR(m.tension, 200.0 * std::sqrt(2.0), 1e-8) << m.name;
  }
  EXPECT_LT(r.residual, 1e-9);
  EXPECT_NE(r.scene.find("prestress: 282.84271247461"), std::string::npos) << r.scene;
  // with reactions allowed the lower ring (between pinned nodes) is a self-stress of its own: it cannot set
  // the others, and the upper ring must be given too
  o.supports_react = true;
  EXPECT_THROW(design::findForm(sceneFile("quadruplex.yaml"), "quadruplex", o), design::FormFindingError);
  o.tension["upper"] = 100.0;
  const design::FormFindingResult react = design::findForm(sceneFile("quadruplex.yaml"), "quadruplex", o);
  EXPECT_GT(react.self_stress_states, 1);
  EXPECT_NEAR(member(react, "C9").tension, 100.0, 1e-9);
  EXPECT_NEAR(member(react, "C1").tension, 200.0, 1e-9);
}

// The pinned prism from a start 0.2 rad off its twist: with the strut lengths free the nearest form the
// iterations find is flat (the top falls into the base's plane, where any twist is a form), which is refused;
// with the strut lengths kept the pins stay where they are, the top turns to the prism's twist and the form
// is self-equilibrated (the pins carry nothing).
TEST(FormFinding, PinnedPrismKeepsItsSupportsAndStrutLengths)
{
  design::FormFindingOptions o;
  o.tension["rings"] = 50.0;
  const std::string yaml = perturbedPrism(5, -0.2, 0.0, 1, true);
  try
  {
    design::findForm(yaml, "pinned", o);
    ADD_FAILURE() << "a flat form was accepted";
  }
  catch (const design::FormFindingError& e)
  {
    EXPECT_NE(std::string(e.what()).find("flat"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("--strut-lengths keep"), std::string::npos) << e.what();
  }
  o.keep_strut_lengths = true;
  const design::FormFindingResult r = design::findForm(yaml, "pinned", o);
  const design::FormTopology given = design::readFormTopology(yaml, "pinned");
  for (int i = 0; i < 5; ++i)
  {
    EXPECT_EQ(r.positions[i], given.positions[i]) << "a pinned node moved";
    EXPECT_NEAR(strutTwist(r, 5, i), design::prismTwist(5), 1e-6);
    EXPECT_NEAR(r.members[i].length, (given.positions[5 + i] - given.positions[i]).norm(), 1e-9);
  }
  EXPECT_DOUBLE_EQ(r.scale, 1.0);
  EXPECT_TRUE(r.check.newton_converged);
  EXPECT_LT(r.check.newton_move, 1e-9);
  EXPECT_TRUE(r.check.prestress_stable);
}

// The written scene is a form already: finding its form again moves nothing and keeps every force.
TEST(FormFinding, WrittenSceneIsAFixedPoint)
{
  design::FormFindingOptions o;
  o.tension["rings"] = 100.0;
  const design::FormFindingResult first = design::findForm(perturbedPrism(6, 0.05, 0.0, 1), "prism", o);
  const design::FormFindingResult again = design::findForm(first.scene, "again", o);
  EXPECT_LT(again.max_move, 1e-9);
  EXPECT_LE(again.iterations, 1);
  for (size_t e = 0; e < first.members.size(); ++e)
    EXPECT_NEAR(again.members[e].tension, first.members[e].tension, 1e-8);
}

// Without a held family the scene's first prestress is held; with force densities held, every member of a
// family has the same force density and a family whose members differ in tension is split.
TEST(FormFinding, ForceDensitiesAndSplitFamilies)
{
  design::FormFindingOptions o;
  const design::FormFindingResult held = design::findForm(perturbedPrism(3, 0.1, 0.0, 1), "prism", o);
  EXPECT_NEAR(member(held, "R1").tension, 100.0, 1e-9);
  ASSERT_FALSE(held.notes.empty());
  o.force_density["rings"] = 200.0;
  o.force_density["verticals"] = 200.0 * std::sqrt(3.0);
  const design::FormFindingResult fdm = design::findForm(perturbedPrism(3, 0.1, 0.03, 2), "prism", o);
  for (const design::FormMember& m : fdm.members)
  {
    if (m.family == "rings")
    {
      EXPECT_NEAR(m.tension / m.length, 200.0, 1e-9);
    }
  }
  EXPECT_TRUE(fdm.check.slack_cables.empty());
  EXPECT_LT(fdm.check.equilibrium_residual, 1e-6);
}

TEST(FormFinding, RefusesWhatItCannotDo)
{
  const std::string prism = perturbedPrism(3, 0.0, 0.0, 1);
  const auto message = [&](const std::string& yaml, const design::FormFindingOptions& o)
  {
    try
    {
      design::findForm(yaml, "x.yaml", o);
    }
    catch (const design::FormFindingError& e)
    {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  design::FormFindingOptions o;
  o.tension["ringz"] = 1.0;
  EXPECT_NE(message(prism, o).find("no cable or spring family 'ringz'"), std::string::npos) << message(prism, o);
  EXPECT_NE(message(prism, o).find("'rings'"), std::string::npos);
  o = {};
  o.tension["rings"] = -1.0;
  EXPECT_NE(message(prism, o).find("must be positive"), std::string::npos);
  o = {};
  o.tension["rings"] = 1.0;
  o.force_density["rings"] = 1.0;
  EXPECT_NE(message(prism, o).find("held already"), std::string::npos);
  o = {};
  o.mode = design::FormFindingMode::kPrestress;
  EXPECT_NE(message(prism, o).find("needs a target"), std::string::npos);
  o.force_density["rings"] = 1.0;
  EXPECT_NE(message(prism, o).find("not force densities"), std::string::npos);
  // a geometry that is no form: the prism 30 degrees off its twist has no self-stress
  o = {};
  o.mode = design::FormFindingMode::kPrestress;
  o.tension["rings"] = 100.0;
  EXPECT_NE(message(perturbedPrism(3, 0.5, 0.0, 1), o).find("no state of self-stress"), std::string::npos);
  // iterations run out
  o = {};
  o.tension["rings"] = 100.0;
  o.max_iterations = 1;
  EXPECT_NE(message(perturbedPrism(3, 0.3, 0.0, 1), o).find("did not converge in 1 iterations"), std::string::npos);
  // the scene itself is refused by the loader, with its message
  EXPECT_THROW(design::findForm("name: x\nnodes: {}\n", "x.yaml", {}), at::SceneError);
}

// Form-finding knows no strut thickness: a form whose struts overlap (here struts thicker than their spacing)
// is written, with the overlapping pairs in the check and a note
TEST(FormFinding, OverlappingStrutsAreNamed)
{
  design::PrismSpec spec;
  spec.struts = 3;
  spec.pinned = true;
  spec.driven = true;  // contact between every pair of struts
  spec.strut_radius = 0.3;
  design::FormFindingOptions o;
  o.tension["rings"] = 50.0;
  const design::FormFindingResult r = design::findForm(design::prismScene(spec), "thick", o);
  ASSERT_EQ(r.check.overlapping.size(), 3u);
  EXPECT_EQ(r.check.overlapping[0].rfind("S1-S2 (gap -", 0), 0u) << r.check.overlapping[0];
  bool noted = false;
  for (const std::string& n : r.notes)
    noted = noted || n.find("struts overlap in the form") != std::string::npos;
  EXPECT_TRUE(noted);
  spec.strut_radius = 0.012;  // the same form with thin struts: nothing overlaps
  EXPECT_TRUE(design::findForm(design::prismScene(spec), "thin", o).check.overlapping.empty());
}

// The pinned prism whose verticals are one sliding cable running inside two hollow struts: its given
// geometry is a form (the pins carry nothing), but the cable inside S2 and S3 adds to their compression
// only, so one force density for every strut cannot hold it (refused, naming --struts free); with a force
// density per strut nothing moves and the cable keeps the scene's tension
TEST(FormFinding, SlidingCableInsideStrutsNeedsTheirOwnForceDensities)
{
  design::FormFindingOptions o;
  try
  {
    design::findForm(sceneFile("prism_pinned_sliding.yaml"), "sliding", o);
    ADD_FAILURE() << "a form with uniform struts";
  }
  catch (const design::FormFindingError& e)
  {
    EXPECT_NE(std::string(e.what()).find("--struts free"), std::string::npos) << e.what();
  }
  o.uniform_struts = false;
  const design::FormFindingResult r = design::findForm(sceneFile("prism_pinned_sliding.yaml"), "sliding", o);
  EXPECT_LT(r.max_move, 1e-9);
  EXPECT_NEAR(member(r, "V").tension, 291.2704512527, 1e-6);
  // the struts the cable runs inside carry its tension on top of S1's compression
  EXPECT_NEAR(member(r, "S2").tension - member(r, "S1").tension, -member(r, "V").tension, 1e-6);
  EXPECT_TRUE(r.check.prestress_stable);
}

// What the scene's layout gave and the form changed, named with both values: a two-stage tower whose stages
// overlap by 0.3 m, its middle ring moved up onto the lower stage's top (the overlap to 0)
TEST(FormChanges, TheOverlapOfTwoStagesAndTheOtherLayoutParameters)
{
  const std::string yaml = R"(name: tower2
materials:
  alu: {youngs_modulus: 70.0e9, density: 2700.0}
  fib: {youngs_modulus: 73.0e9, density: 2450.0}
nodes:
  B1: {position: [0.5, 0.0, 0.0], fixed: true}
  B2: {position: [-0.25, 0.4330127, 0.0], fixed: true}
  B3: {position: [-0.25, -0.4330127, 0.0], fixed: true}
  T1: {position: [-0.4330127, 0.25, 1.0]}
  T2: {position: [0.0, -0.5, 1.0]}
  T3: {position: [0.4330127, 0.25, 1.0]}
  M1: {position: [0.25, 0.4330127, 0.7]}
  M2: {position: [-0.5, 0.0, 0.7]}
  M3: {position: [0.25, -0.4330127, 0.7]}
  U1: {position: [-0.4330127, -0.25, 1.7]}
  U2: {position: [0.4330127, -0.25, 1.7]}
  U3: {position: [0.0, 0.5, 1.7]}
struts:
  radius: 0.01
  material: alu
  members: {S1: [B1, T1], S2: [B2, T2], S3: [B3, T3], R1: [M1, U1], R2: [M2, U2], R3: [M3, U3]}
cables:
  rings:
    material: fib
    radius: 0.001
    prestress: 100
    members: {b1: [B1, B2], b2: [B2, B3], b3: [B3, B1], t1: [U1, U2], t2: [U2, U3], t3: [U3, U1]}
  verticals:
    material: fib
    radius: 0.001
    members: {v1: [B1, T2], v2: [B2, T3], v3: [B3, T1], v4: [M1, U2], v5: [M2, U3], v6: [M3, U1]}
  saddle:
    material: fib
    radius: 0.001
    members: {s1: [T1, M1], s2: [T2, M2], s3: [T3, M3], s4: [T1, M2], s5: [T2, M3], s6: [T3, M1]}
analysis: {type: static, steps: 10}
)";
  const design::FormTopology t = design::readFormTopology(yaml, "tower2");
  EXPECT_TRUE(design::formChanges(t, t.positions).empty());
  std::vector<at::Vec3> x = t.positions;
  for (size_t i = 0; i < x.size(); ++i)
    if (t.node_names[i][0] == 'M')
      x[i].z() += 0.3;
  const std::vector<std::string> changes = design::formChanges(t, x);
  const auto has = [&](const std::string& text)
  { return std::find(changes.begin(), changes.end(), text) != changes.end(); };
  std::string all;
  for (const std::string& c : changes)
    all += c + "\n";
  EXPECT_TRUE(
      has("overlap of stage 'S1', 'S2', 'S3' (z 0 to 1 m) and stage 'R1', 'R2', 'R3' (z 0.7 to 1.7 m): 0.3 m in "
          "the scene, 0 m in the form"))
      << all;
  EXPECT_TRUE(has("height of stage 'R1', 'R2', 'R3' (z 0.7 to 1.7 m): 1 m in the scene, 0.7 m in the form")) << all;
  EXPECT_TRUE(has("length of strut 'R1': 1.39033 m in the scene, 1.1929 m in the form")) << all;
  // the structure's height, the lower stage and the rings' radii did not change: not named
  EXPECT_EQ(all.find("height (the nodes' z extent)"), std::string::npos) << all;
  EXPECT_EQ(all.find("stage 'S1', 'S2', 'S3' (z 0 to 1 m): "), std::string::npos) << all;
  EXPECT_EQ(all.find("radius"), std::string::npos) << all;
  // a ring that is no longer level, a ring turned (the stage's twist) and widened
  x = t.positions;
  x[t.node_names.size() - 1].z() += 0.05;  // U3
  for (size_t i = 0; i < x.size(); ++i)
    if (t.node_names[i][0] == 'T')
      x[i] = at::Vec3(1.2 * x[i].x(), 1.2 * x[i].y(), x[i].z());
  all.clear();
  for (const std::string& c : design::formChanges(t, x))
    all += c + "\n";
  EXPECT_NE(all.find("flatness of the level of nodes 'U1', 'U2', 'U3' (z = 1.7 m): its nodes at one height in the "
                     "scene, spread over z 1.7 to 1.75 m in the form"),
            std::string::npos)
      << all;
  EXPECT_NE(all.find("radius of the level of nodes 'T1', 'T2', 'T3' (z = 1 m): 0.5 m in the scene, 0.6 m in the form"),
            std::string::npos)
      << all;
}
