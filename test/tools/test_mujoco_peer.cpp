// The MuJoCo peer (src/tools/mujoco_peer.h) translates our scenes faithfully: the MuJoCo model has our
// bodies, masses, inertias, tendons, joints and pairs; at the initial state every cable has our length and
// tension (sliding cables and the driven segments included) and every actuator our force; the contact is
// the linear law it is documented to be; a free prism falls with g; short runs stay finite.
// MuJoCo's trajectories are compared with ours only where the two model the same thing: a scene on the
// linear contact law (MuJoCo's own), whose impacts MuJoCo must then follow to within its step's error; everywhere
// else the distance is measured, not asserted (tensegrity_bench work-precision --mujoco-dts, docs/benchmarks.md).
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/design/generators.h"
#include "active_tensegrity/core/scene/scene.h"
#include "command.h"
#include "mujoco_peer.h"

namespace at = active_tensegrity::core;
namespace design = active_tensegrity::design;
namespace tools = active_tensegrity::tools;

namespace
{
const std::string kScenes = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/";

at::Model scene(const std::string& file, const std::vector<std::string>& overrides)
{
  std::vector<at::Override> o;
  for (const std::string& kv : overrides)
    o.push_back(at::parseOverride(kv));
  return at::loadScene(kScenes + file, o);
}

// our quantities at the initial state (the solver's consistent start: one short step of the analysis)
at::State initial(const at::Model& model)
{
  at::Model m = model;
  m.analysis.duration = m.solver.dt;
  at::State first;
  bool have = false;
  at::runAnalysis(m,
                  [&](const at::State& s)
                  {
                    if (!have)
                      first = s;
                    have = true;
                  });
  return first;
}

void expectCablesAsOurs(const at::Model& model, tools::MujocoPeer& peer)
{
  const at::State s = at::initialState(model);
  for (size_t i = 0; i < model.cables.size(); ++i)
  {
    const at::CableState ours = at::evaluateCable(model, model.cables[i], s.q, s.qd, s.u, model.damping_enabled);
    EXPECT_NEAR(peer.cableLength(static_cast<int>(i)), ours.length, 1e-12) << model.cables[i].name;
    EXPECT_NEAR(peer.cableTension(static_cast<int>(i)), ours.tension, 1e-9 * (1.0 + ours.tension))
        << model.cables[i].name;
  }
}
}  // namespace

TEST(MujocoPeer, TowerBodiesMassesTendonsJointsAndPairs)
{
  // prestress in the sliding and square cables, so that tensions are compared too
  const at::Model model = scene("tower.yaml", { "analysis.type=dynamic", "cables.sliding.prestress=100",
                                                "cables.squares.prestress=50", "springs.middle.prestress=20" });
  tools::MujocoPeer peer(model, tools::MujocoOptions{});
  const mjModel* m = peer.mujocoModel();
  // 16 struts (the driven bodies B1-B4 move kinematically: no MuJoCo body), 6 dofs each
  EXPECT_EQ(m->nbody, 1 + 16);
  EXPECT_EQ(m->nv, 96);
  double strut_mass = 0.0;
  for (const at::Body& b : model.bodies)
    if (b.kind == at::BodyKind::kStrut)
      strut_mass += b.mass;
  EXPECT_NEAR(peer.totalMass(), strut_mass, 1e-9 * strut_mass);
  // every cable one tendon (the sliding ones end at the pulley G, the driven segment is computed)
  EXPECT_EQ(m->ntendon, 20);
  EXPECT_EQ(m->nu, 20);
  for (size_t i = 0; i < model.cables.size(); ++i)
    EXPECT_EQ(peer.tendonIds(static_cast<int>(i)).size(), 1u) << model.cables[i].name;
  // a sliding cable: one tendon through the four nodes on struts, G's site included
  int l1 = -1;
  for (size_t i = 0; i < model.cables.size(); ++i)
    if (model.cables[i].name == "L1")
      l1 = peer.tendonIds(static_cast<int>(i))[0];
  ASSERT_GE(l1, 0);
  EXPECT_EQ(m->tendon_num[l1], 5);
  // 4 ground pins and 12 strut-to-strut joints; the 16 listed pairs
  EXPECT_EQ(m->neq, 16);
  EXPECT_EQ(peer.pairCount(), 16);
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const at::Body& b = model.bodies[i];
    if (b.kind != at::BodyKind::kStrut)
    {
      EXPECT_EQ(peer.bodyId(static_cast<int>(i)), -1) << b.name;
      continue;
    }
    const int id = peer.bodyId(static_cast<int>(i));
    ASSERT_GT(id, 0) << b.name;
    EXPECT_NEAR(m->body_mass[id], b.mass, 1e-12 * b.mass);
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(m->body_inertia[3 * id + k], b.inertia(k), 1e-12 * b.inertia(k)) << b.name;
    // the capsule: our outer radius, half length
    const int g = m->body_geomadr[id];
    EXPECT_EQ(m->geom_type[g], mjGEOM_CAPSULE);
    EXPECT_NEAR(m->geom_size[3 * g], b.radius(), 1e-15);
    EXPECT_NEAR(m->geom_size[3 * g + 1], 0.5 * b.length, 1e-15);
    // pose: centre and axis as ours
    EXPECT_LT((peer.bodyPosition(static_cast<int>(i)) - model.q0.segment<3>(b.offset)).norm(), 1e-12);
    const at::Mat3 r = at::rotationMatrix(model.q0.segment<4>(b.offset + 3));
    for (int a = 0; a < 3; ++a)
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(peer.mujocoData()->xmat[9 * id + 3 * a + c], r(a, c), 1e-12);
  }
  // lengths and tensions at the start, sliding cables and driven segments included
  expectCablesAsOurs(model, peer);
  // the actuation force at the start: the tension of L1 (B1 does not accelerate yet), as ours
  const at::State s0 = initial(model);
  EXPECT_NEAR(peer.actuationForce(0), at::actuationForce(model, s0, 0), 1e-6 * 100.0);
  EXPECT_NEAR(peer.actuationForce(0), 100.0, 1e-6);
}

TEST(MujocoPeer, QuadruplexPrestressAndDrivenNodesAsOurs)
{
  // gravity on, so that the pins and the drive carry loads at the start
  const at::Model model =
      scene("quadruplex.yaml", { "analysis.type=dynamic", "actuation.speed=0.5", "analysis.max_actuation=0.3",
                                 "gravity.enabled=true", "contact.enabled=true", "analysis.duration=0.05" });
  tools::MujocoPeer peer(model, tools::MujocoOptions{});
  const mjModel* m = peer.mujocoModel();
  // 4 struts; 4 drives, each a light carrier on a slide along the drive and two across
  EXPECT_EQ(m->nbody, 1 + 4 + 4);
  EXPECT_EQ(m->nmocap, 0);
  EXPECT_EQ(m->nv, 4 * 6 + 4 * 3);
  EXPECT_EQ(m->ntendon, 12);
  EXPECT_EQ(m->neq, 4 + 4);  // pins, drives
  EXPECT_EQ(peer.pairCount(), 6);
  double strut_mass = 0.0;
  for (const at::Body& b : model.bodies)
    strut_mass += b.mass;
  EXPECT_NEAR(peer.totalMass() - peer.carrierMass(), strut_mass, 1e-9 * strut_mass);
  EXPECT_LT(peer.carrierMass(), 1e-3 * strut_mass);
  expectCablesAsOurs(model, peer);
  EXPECT_NEAR(peer.cableTension(0), 200.0, 1e-6);  // C1, Table 1's prestress
  // the force holding the top nodes (gravity, prestress) as our multipliers give it; MuJoCo's near-hard
  // equality (impedance 0.9999) and the carriers leave a small difference
  const double ours = at::actuationForce(model, initial(model), 0);
  EXPECT_GT(std::abs(ours), 10.0);
  EXPECT_NEAR(peer.actuationForce(0), ours, 2e-3 * std::abs(ours));
  // a short run stays finite and ends where it should
  for (tools::MujocoIntegrator integrator :
       { tools::MujocoIntegrator::kEuler, tools::MujocoIntegrator::kImplicit, tools::MujocoIntegrator::kRk4 })
  {
    tools::MujocoOptions o;
    o.integrator = integrator;
    o.timestep = 5e-4;
    const tools::MujocoTrace tr = tools::runMujoco(model, o);
    EXPECT_TRUE(tr.ok()) << tools::toString(integrator) << ": " << tr.message;
    EXPECT_EQ(tr.steps, 100);
    ASSERT_FALSE(tr.t.empty());
    EXPECT_NEAR(tr.t.back(), 0.05, 1e-9);
    for (const auto& step : tr.positions)
      for (const at::Vec3& p : step)
        EXPECT_TRUE(p.allFinite());
  }
}

TEST(MujocoPeer, ContactIsTheDocumentedLinearLawWhereverTheStrutsTouch)
{
  // two free rubber-sleeved struts crossing at a right angle, one touched 0.4 m off its centre
  at::Model model;
  model.name = "pair";
  for (int i = 0; i < 2; ++i)
  {
    at::Body b;
    b.name = i == 0 ? "A" : "B";
    b.length = 1.2;
    at::StrutLayer layer;
    layer.material = "rubber";
    layer.outer_radius = 0.04;
    layer.density = 1000.0;
    layer.youngs_modulus = 7.84e6;
    layer.poisson_ratio = 0.47;
    b.layers.push_back(layer);
    b.mass = layer.density * M_PI * 0.04 * 0.04 * b.length;
    const double jt = b.mass * (3.0 * 0.04 * 0.04 + b.length * b.length) / 12.0;
    b.inertia = at::Vec3(jt, jt, 0.5 * b.mass * 0.04 * 0.04);
    model.bodies.push_back(b);
  }
  at::finalizeModel(model);
  model.contact.enabled = true;
  model.contact.friction = 0.0;
  model.contact.restitution = 0.5;
  model.listed_pairs.push_back(at::makeStrutPair(model, 0, 1));
  model.analysis.type = at::AnalysisType::kDynamic;
  const double overlap = 0.004;
  model.q0.setZero(model.nq);
  model.q0.segment<3>(0) = at::Vec3(0.4, 0.0, 0.0);  // A along x: touched at x = 0, 0.4 m off its centre
  model.q0.segment<4>(3) = at::thetaFromZAxis(at::Vec3::UnitX());
  model.q0.segment<3>(7) = at::Vec3(0.0, 0.0, 0.08 - overlap);  // B along y, above
  model.q0.segment<4>(10) = at::thetaFromZAxis(at::Vec3::UnitY());
  tools::MujocoOptions o;
  o.contact_force = 500.0;
  tools::MujocoPeer peer(model, o);
  // the secant of our Hertz law through F*: K90 zeta*^1.5 = F* at zeta* = F* / K_lin
  const double k_lin = peer.contactStiffness(0);
  const double zeta_star = o.contact_force / k_lin;
  EXPECT_NEAR(model.checkedPairList()[0].stiffness90 * std::pow(zeta_star, 1.5), o.contact_force,
              1e-9 * o.contact_force);
  // at rest: F = K_lin r to O(impedance), though the effective mass at x = 0 on A is not A's mass
  EXPECT_NEAR(peer.maxContactForce(), k_lin * overlap, 2e-3 * k_lin * overlap);
  // a linear oscillator with our restitution: zeta = -ln e / sqrt(pi^2 + ln^2 e)
  const double m_red = 0.5 * model.bodies[0].mass;
  const double zeta = -std::log(0.5) / std::sqrt(M_PI * M_PI + std::log(0.5) * std::log(0.5));
  EXPECT_NEAR(peer.contactDamping(0), 2.0 * zeta * std::sqrt(k_lin * m_red), 1e-9 * peer.contactDamping(0));
}

TEST(MujocoPeer, FreePrismFallsWithG)
{
  // the prism without its drive, under gravity: its centre of mass falls as g t^2 / 2 (RK4 is exact for
  // that), the self-stressed cables keep their tensions
  at::Model model = scene("prism.yaml", { "gravity.enabled=true", "analysis.duration=0.2" });
  model.actuators.clear();
  std::vector<at::Constraint> kept;
  for (const at::Constraint& c : model.constraints)
    if (c.actuator < 0)
      kept.push_back(c);
  model.constraints = kept;
  tools::MujocoOptions o;
  o.integrator = tools::MujocoIntegrator::kRk4;
  o.timestep = 1e-3;
  const tools::MujocoTrace tr = tools::runMujoco(model, o);
  ASSERT_TRUE(tr.ok()) << tr.message;
  ASSERT_EQ(tr.positions.size(), tr.t.size());
  const auto centre = [&](size_t k)
  {
    at::Vec3 c = at::Vec3::Zero();
    for (const at::Vec3& p : tr.positions[k])
      c += p / static_cast<double>(tr.positions[k].size());  // three equal struts
    return c;
  };
  const at::Vec3 c0 = centre(0);
  for (size_t k = 0; k < tr.t.size(); ++k)
    EXPECT_NEAR((centre(k) - c0).z(), -0.5 * 9.81 * tr.t[k] * tr.t[k], 1e-9) << "t = " << tr.t[k];
  tools::MujocoPeer peer(model, o);
  for (int k = 0; k < 200; ++k)
    ASSERT_TRUE(peer.step()) << peer.message();
  peer.forward();
  EXPECT_NEAR(peer.cableTension(0), 173.2050807569, 0.02 * 173.2);
  EXPECT_NEAR(peer.cableTension(6), 291.2704512527, 0.02 * 291.3);
}

TEST(MujocoPeer, TowerShortFoldStaysFiniteWithEveryIntegrator)
{
  // a smooth start (the scene's sharp one throws the tower ahead of the pull: the cables go slack)
  const at::Model model = scene("tower.yaml", { "analysis.type=dynamic", "actuation.speed=5",
                                                "actuation.blend_time=0.1", "analysis.duration=0.05" });
  for (tools::MujocoIntegrator integrator :
       { tools::MujocoIntegrator::kEuler, tools::MujocoIntegrator::kImplicit, tools::MujocoIntegrator::kRk4 })
  {
    tools::MujocoOptions o;
    o.integrator = integrator;
    o.timestep = 1e-3;
    const tools::MujocoTrace tr = tools::runMujoco(model, o);
    EXPECT_TRUE(tr.ok()) << tools::toString(integrator) << ": " << tr.message;
    ASSERT_EQ(tr.t.size(), 6u);  // outputs every 0.01 s
    // the pull shortens the tower: the top layer goes down; B1 accelerates and pulls
    EXPECT_LT(tr.heights.back().back(), tr.heights.front().back());
    for (size_t k = 1; k < tr.force.size(); ++k)
      EXPECT_GT(tr.force[k], 0.0) << "t = " << tr.t[k];
    for (const auto& step : tr.positions)
      for (const at::Vec3& p : step)
        EXPECT_TRUE(p.allFinite());
  }
}

TEST(MujocoPeer, UnsupportedConstraintsAreNamed)
{
  at::Model model = scene("quadruplex.yaml", { "analysis.type=dynamic", "actuation.speed=0.5" });
  at::Constraint c;
  c.kind = at::Constraint::Kind::kPoints;
  c.name = "odd";
  c.a = model.nodes[4].point;
  c.b = at::PointRef{ -1, at::Vec3::Zero() };
  c.directions = { at::Vec3::UnitX() };
  c.offsets = { 0.3 };
  model.constraints.push_back(c);
  try
  {
    tools::MujocoPeer peer(model, tools::MujocoOptions{});
    FAIL() << "accepted";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string(e.what()).find("'odd'"), std::string::npos) << e.what();
  }
}

// tensegrity_export --mjcf: the file MuJoCo's own parser (mj_loadXML) loads has the in-memory translation's
// bodies, joints, tendons, actuators, equalities and contact pairs (their solref as compiled here), and a
// peer built from the file runs as the in-memory one, step for step: the quadruplex (driven strut ends) and
// the tower with contact (driven point masses, sliding cables, pairs)
TEST(MujocoPeer, ExportedMjcfLoadsAndRunsAsTheTranslation)
{
  const std::vector<std::pair<std::string, std::vector<std::string>>> cases = {
    { "quadruplex.yaml", { "analysis.type=dynamic", "analysis.duration=0.05", "actuation.speed=0.5" } },
    { "tower.yaml",
      { "analysis.type=dynamic", "actuation.speed=5", "actuation.blend_time=0.1", "analysis.duration=0.05" } },
  };
  for (const auto& [file, overrides] : cases)
  {
    std::string sets;
    for (const std::string& o : overrides)
      sets += " --set " + o;
    const std::string out = active_tensegrity::test::scratchPath("export_" + file + ".xml");
    const active_tensegrity::test::CommandResult r = active_tensegrity::test::runCommand(
        std::string(TENSEGRITY_EXPORT_PATH) + " " + kScenes + file + sets + " --mjcf " + out + " 2>&1");
    ASSERT_EQ(r.code, 0) << file << ": " << r.output;

    const at::Model model = scene(file, overrides);
    tools::MujocoOptions o;
    tools::MujocoPeer memory(model, o);
    char error[1000] = "";
    mjModel* loaded = mj_loadXML(out.c_str(), nullptr, error, sizeof error);
    ASSERT_NE(loaded, nullptr) << file << ": " << error;
    const mjModel* m = memory.mujocoModel();
    EXPECT_EQ(loaded->nbody, m->nbody) << file;
    EXPECT_EQ(loaded->njnt, m->njnt) << file;
    EXPECT_EQ(loaded->ntendon, m->ntendon) << file;
    EXPECT_EQ(loaded->nu, m->nu) << file;
    EXPECT_EQ(loaded->neq, m->neq) << file;
    ASSERT_EQ(loaded->npair, m->npair) << file;
    for (int i = 0; i < 2 * m->npair; ++i)
      EXPECT_NEAR(loaded->pair_solref[i], m->pair_solref[i], 1e-9 * std::abs(m->pair_solref[i])) << file;
    EXPECT_NEAR(loaded->opt.impratio, m->opt.impratio, 1e-9 * m->opt.impratio) << file;
    for (int i = 0; i < m->nbody; ++i)
      EXPECT_EQ(loaded->body_mass[i], m->body_mass[i]) << file << " body " << i;
    mj_deleteModel(loaded);

    o.xml_file = out;
    tools::MujocoPeer from_file(model, o);
    for (int k = 0; k < 50; ++k)
    {
      ASSERT_TRUE(memory.step()) << memory.message();
      ASSERT_TRUE(from_file.step()) << from_file.message();
    }
    memory.forward();
    from_file.forward();
    for (int b = 0; b < static_cast<int>(model.bodies.size()); ++b)
      EXPECT_LT((memory.bodyPosition(b) - from_file.bodyPosition(b)).norm(), 1e-9) << file << " body " << b;
    EXPECT_NEAR(from_file.time(), 0.05, 1e-12);
  }
  // bad arguments, a file that cannot be written
  const auto run = [](const std::string& args)
  { return active_tensegrity::test::runCommand(std::string(TENSEGRITY_EXPORT_PATH) + " " + args + " 2>&1"); };
  const active_tensegrity::test::CommandResult none = run(kScenes + "quadruplex.yaml");
  EXPECT_EQ(none.code, 2);
  EXPECT_NE(none.output.find("no format given (--mjcf OUT.xml)"), std::string::npos) << none.output;
  const active_tensegrity::test::CommandResult integrator =
      run(kScenes + "quadruplex.yaml --mjcf /dev/null --integrator leapfrog");
  EXPECT_EQ(integrator.code, 2);
  EXPECT_NE(integrator.output.find("--integrator: expected euler, implicit or rk4, got 'leapfrog'"), std::string::npos)
      << integrator.output;
  const active_tensegrity::test::CommandResult unwritable = run(kScenes + "quadruplex.yaml --mjcf /nonexistent/q.xml");
  EXPECT_EQ(unwritable.code, 1);
  EXPECT_NE(unwritable.output.find("cannot write '/nonexistent/q.xml'"), std::string::npos) << unwritable.output;
}

TEST(MujocoPeer, TheGroundIsAPlaneWithAPairPerStrutAndEachPairHasItsOwnLaw)
{
  // the six-bar robot: 15 strut pairs and 6 struts on the ground, whose pairs' constants differ by a factor of
  // about 370; MuJoCo's compiler sorts pairs, so each pair's solref must be found by its geoms
  const at::Model model = scene("six_bar.yaml", { "analysis.duration=0.45" });  // before the roll's pull
  tools::MujocoPeer peer(model, tools::MujocoOptions());
  const mjModel_* m = peer.mujocoModel();
  ASSERT_EQ(m->npair, 15 + 6);
  const int ground = mj_name2id(m, mjOBJ_GEOM, "ground");
  ASSERT_GE(ground, 0);
  EXPECT_EQ(m->geom_type[ground], mjGEOM_PLANE);
  int ground_pairs = 0;
  for (int j = 0; j < m->npair; ++j)
  {
    const bool on_ground = m->pair_geom1[j] == ground || m->pair_geom2[j] == ground;
    ground_pairs += on_ground ? 1 : 0;
    // the strut pairs' stiffness (per unit mass) is in the 1e7 range, the ground pairs' in the 1e4 range
    const double k = -m->pair_solref[2 * j];
    if (on_ground)
      EXPECT_LT(k, 1e6) << "pair " << j;
    else
      EXPECT_GT(k, 1e6) << "pair " << j;
  }
  EXPECT_EQ(ground_pairs, 6);
  // standing on the ground it sags a few centimetres and stays put (with other pairs' stiffness on its ground pairs
  // it blew up within 0.13 s)
  const tools::MujocoTrace tr = tools::runMujoco(model, tools::MujocoOptions());
  ASSERT_TRUE(tr.ok()) << tr.message;
  for (const at::Vec3& c : tr.positions.back())
    EXPECT_LT((c - tr.positions.front()[&c - tr.positions.back().data()]).norm(), 0.1);
}

TEST(MujocoPeer, OnTheLinearContactLawMuJoCoFollowsOurImpacts)
{
  // the quadruplex compressed into contact on the linear law (two impacts in 0.4 s): the pairs get
  // its k and c as they are, and MuJoCo's Euler at 0.2 ms stays within 0.2 mm of our generalized-alpha at 0.1 ms
  // (0.01 mm measured) and its peak contact force within 0.5 % of ours (2e-5 measured)
  const at::Model model = scene("quadruplex_linear_contact.yaml",
                                { "analysis.duration=0.4", "solver.dt=1e-4", "solver.newton_tolerance=1e-9" });
  tools::MujocoOptions o;
  o.timestep = 2e-4;
  tools::MujocoPeer peer(model, o);
  for (int i = 0; i < 6; ++i)
  {
    EXPECT_EQ(peer.contactStiffness(i), 1e6);
    EXPECT_EQ(peer.contactDamping(i), 2000.0);
  }
  std::vector<Eigen::VectorXd> ours;
  double peak = 0.0;
  const at::RunResult run = at::runAnalysis(
      model, [&](const at::State& s) { ours.push_back(s.q); }, {},
      [&](const at::State& s)
      {
        for (const at::ContactPairState& c : at::activeContacts(model, s))
          peak = std::max(peak, c.normal_force);
      });
  ASSERT_TRUE(run.summary.ok()) << run.summary.message;
  ASSERT_GT(peak, 1000.0);  // the struts did press into each other
  const tools::MujocoTrace tr = tools::runMujoco(model, o);
  ASSERT_TRUE(tr.ok()) << tr.message;
  ASSERT_EQ(tr.positions.size(), ours.size());
  double distance = 0.0;
  for (size_t k = 0; k < ours.size(); ++k)
    for (size_t b = 0; b < model.bodies.size(); ++b)
      distance = std::max(distance, (tr.positions[k][b] - ours[k].segment<3>(model.bodies[b].offset)).norm());
  std::printf("[ measured ] largest distance %.3g m, peak contact force %.6g N (ours %.6g N)\n", distance, tr.peak,
              peak);
  EXPECT_LT(distance, 2e-4);
  EXPECT_NEAR(tr.peak, peak, 5e-3 * peak);
}

// A run that blows up says so: a five-strut prism pressed into contact at 2 m/s, MuJoCo's implicit integrator at
// 1 ms (the struts fly apart: 3 m off a structure 1.6 m across, contact forces of 4e6 N against 2e5 N, with every
// number finite and no warning from MuJoCo: it said "converged"). Its pins and joints come apart; at 0.25 ms it
// stays together.
TEST(MujocoPeer, ARunThatBlowsUpSaysDiverged)
{
  design::PrismSpec spec;
  spec.struts = 5;
  spec.pinned = true;
  spec.driven = true;
  const at::Model model = at::loadSceneFromString(
      design::prismScene(spec), "prism5",
      { at::parseOverride("analysis.type=dynamic"), at::parseOverride("analysis.max_actuation=0.6"),
        at::parseOverride("actuation.speed=2"), at::parseOverride("analysis.duration=1.5") });
  tools::MujocoOptions o;
  o.integrator = tools::MujocoIntegrator::kImplicit;
  o.timestep = 1e-3;
  o.contact_force = 1.9e5;  // about the fold's peak (the bench's default: the reference's)
  const tools::MujocoTrace blown = tools::runMujoco(model, o);
  std::printf("[ measured ] 1 ms: %s, joint drift %.3g m of a size %.3g m, peak %.3g N: %s\n", blown.status.c_str(),
              blown.joint_drift, blown.size, blown.peak, blown.message.c_str());
  EXPECT_EQ(blown.status, "diverged") << blown.message;
  EXPECT_FALSE(blown.ok());
  EXPECT_NE(blown.message.find("came apart"), std::string::npos) << blown.message;
  o.timestep = 2.5e-4;
  const tools::MujocoTrace sound = tools::runMujoco(model, o);
  std::printf("[ measured ] 0.25 ms: %s, joint drift %.3g m\n", sound.status.c_str(), sound.joint_drift);
  EXPECT_TRUE(sound.ok()) << sound.message;
  EXPECT_LT(sound.joint_drift, 0.01 * sound.size);
  // the free prism at 1 ms with Euler: MuJoCo's own warning of an unstable simulation ("mujoco_failed" before)
  const at::Model free = at::loadSceneFromString(design::prismScene({ 5 }), "prism5_free");
  const tools::MujocoTrace unstable = tools::runMujoco(free, tools::MujocoOptions{});
  EXPECT_EQ(unstable.status, "diverged") << unstable.message;
  EXPECT_NE(unstable.message.find("bad qacc"), std::string::npos) << unstable.message;
}

// A value of the translation that overflows is refused, named, instead of written as "-inf nan" (a contact force
// scale of 1e300 N squares the Hertz stiffness beyond floating point), and tensegrity_export refuses a material
// beyond any solid at the scene's load
TEST(MujocoPeer, ANonFiniteTranslationIsRefusedByName)
{
  const at::Model model =
      scene("quadruplex.yaml", { "analysis.type=dynamic", "actuation.speed=0.5", "contact.enabled=true" });
  tools::MujocoOptions o;
  o.contact_force = 1e300;
  try
  {
    tools::MujocoPeer peer(model, o);
    FAIL() << "accepted";
  }
  catch (const std::invalid_argument& e)
  {
    const std::string what = e.what();
    EXPECT_NE(what.find("the contact of struts 'S"), std::string::npos) << what;
    EXPECT_NE(what.find("is not finite"), std::string::npos) << what;
    EXPECT_NE(what.find("F* = 1e+300 N"), std::string::npos) << what;
  }
  // any other number of the text that overflows: the equality constraints' time constant, twice the step
  tools::MujocoOptions huge_step;
  huge_step.timestep = 1e308;
  try
  {
    tools::MujocoPeer peer(model, huge_step);
    FAIL() << "accepted";
  }
  catch (const std::invalid_argument& e)
  {
    const std::string what = e.what();
    EXPECT_NE(what.find("<connect 'P1.pin'> solref=\"inf 1\" is not finite"), std::string::npos) << what;
  }
  const std::string out = active_tensegrity::test::scratchPath("e1e300.xml");
  const active_tensegrity::test::CommandResult r = active_tensegrity::test::runCommand(
      std::string(TENSEGRITY_EXPORT_PATH) + " " + kScenes +
      "quadruplex.yaml --set analysis.type=dynamic --set actuation.speed=0.5 --set contact.enabled=true --set "
      "materials.steel.youngs_modulus=1e300 --mjcf " +
      out + " 2>&1");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("materials.steel.youngs_modulus: must lie in (0, 1e+14] Pa"), std::string::npos) << r.output;
  EXPECT_FALSE(std::ifstream(out).good()) << "a refused export wrote its file";
}

// a scene whose automatic pairs number more than a million: refused by name and count, not translated into a
// <pair> element each
TEST(MujocoPeer, MoreThanAMillionCheckedPairsAreRefused)
{
  at::Model model;
  std::vector<int> struts;
  for (int i = 0; i < 1500; ++i)
  {
    at::Body b;
    b.name = "S" + std::to_string(i);
    b.kind = at::BodyKind::kStrut;
    b.length = 1.0;
    b.layers = { at::StrutLayer{ "steel", 0.0, 0.01, 7850.0, 2.1e11, 0.3 } };
    b.mass = 1.0;
    model.bodies.push_back(b);
    struts.push_back(i);
  }
  at::finalizeModel(model);
  model.contact.enabled = true;
  model.checkAllStrutPairs(struts, {});
  try
  {
    tools::MujocoPeer peer(model, tools::MujocoOptions{});
    FAIL() << "accepted";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string(e.what()).find("contact.pairs: 1124250 checked strut pairs, more than the 1000000"),
              std::string::npos)
        << e.what();
  }
}

// tensegrity_bench work-precision puts it in the status column: the prism of ARunThatBlowsUpSaysDiverged, whose
// MuJoCo rows at 1 ms said "converged" with a position error of 1.2 to 3 m
TEST(MujocoPeer, WorkPrecisionLabelsADivergedPeerRun)
{
  const std::string scene = active_tensegrity::test::scratchPath("prism5_driven.yaml"),
                    csv = active_tensegrity::test::scratchPath("prism5_wp.csv");
  design::PrismSpec spec;
  spec.struts = 5;
  spec.pinned = true;
  spec.driven = true;
  std::ofstream(scene) << design::prismScene(spec);
  const active_tensegrity::test::CommandResult r = active_tensegrity::test::runCommand(
      std::string(TENSEGRITY_BENCH_PATH) + " work-precision " + scene +
      " --set analysis.type=dynamic --set analysis.max_actuation=0.6 --set actuation.speed=2"
      " --set analysis.duration=1.5 --schemes generalized_alpha --dts 5e-4 --ref-dt 1e-4 --mujoco-dts 1e-3,2.5e-4"
      " --mujoco-integrators implicit --csv " +
      csv + " 2>&1");
  ASSERT_EQ(r.code, 0) << r.output;
  std::ifstream in(csv);
  std::map<std::string, std::string> status;  // "scheme dt" -> status
  for (std::string line; std::getline(in, line);)
  {
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');)
      cells.push_back(cell);
    ASSERT_GE(cells.size(), 4u) << line;
    status[cells[0] + " " + cells[1]] = cells[3];
  }
  EXPECT_EQ(status["mujoco_implicit 0.001"], "diverged") << r.output;
  EXPECT_EQ(status["mujoco_implicit 0.00025"], "converged") << r.output;
  EXPECT_EQ(status["generalized_alpha 0.0005"], "converged") << r.output;
  EXPECT_NE(r.output.find("came apart"), std::string::npos) << r.output;
}
