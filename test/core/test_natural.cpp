// Natural (nodal) coordinates (natural.h): the contact tangents against central differences, the constant mass
// matrix against the rigid strut's kinetic energy, agreement with the body coordinates through contact, refusals.
#include <gtest/gtest.h>

#include <cstdio>
#include <random>
#include <string>

#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/oracle/body_statics.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/oracle/body_dynamics.h"
#include "active_tensegrity/oracle/energy_meter.h"
#include "test_models.h"

using namespace active_tensegrity::core;
using active_tensegrity::test::freeStrutModel;
using active_tensegrity::test::trapezoidalOptions;

namespace
{
// the first actuator's force at s under u (NaturalSolver::actuationForces)
double firstActuatorForce(NaturalSolver& solver, const NaturalState& s, const ActuationValues& u)
{
  std::vector<double> forces;
  solver.actuationForces(s, u, forces);
  return forces.at(0);
}

Model scene(const std::string& name, const std::vector<Override>& overrides = {})
{
  return loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name, overrides);
}

using Vec14 = Eigen::Matrix<double, 14, 1>;
using Mat14 = Eigen::Matrix<double, 14, 14>;

// two crossing struts, the second pressed into the first by `depth` (m; radii 0.04 each)
NaturalContactInput crossing(std::mt19937& rng, double depth)
{
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double half = 0.55;
  const Vec3 a = Vec3(1.0, 0.2 * u(rng), 0.1 * u(rng)).normalized();
  const Vec3 b = Vec3(0.3 * u(rng), 1.0, 0.2 * u(rng)).normalized();
  const Vec3 n = a.cross(b).normalized();
  const Vec3 c1(0.1 * u(rng), 0.1 * u(rng), 0.1 * u(rng));
  const Vec3 c2 = c1 - (0.08 - depth) * n + 0.2 * u(rng) * a;
  NaturalContactInput in;
  in.r[0] = c1 - half * a;
  in.r[1] = c1 + half * a;
  in.r[2] = c2 - half * b;
  in.r[3] = c2 + half * b;
  for (int i = 0; i < 4; ++i)
    in.v[i] = Vec3(u(rng), u(rng), u(rng));
  in.spin[0] = 5.0 * u(rng);
  in.spin[1] = 5.0 * u(rng);
  return in;
}

// K and C of contact k at `in` against central differences of its force (positions, velocities, spin rates)
void expectTangentsMatch(const NaturalModel& nm, const NaturalContactSlot& k, const NaturalContactInput& in,
                         double impact_speed, ContactPairState* state)
{
  Vec14 f;
  Mat14 kk, cc;
  *state = naturalContact(nm, k, in, impact_speed, &f, &kk, &cc);
  Mat14 k_fd = Mat14::Zero(), c_fd = Mat14::Zero();
  for (int j = 0; j < 26; ++j)
  {
    const double h = 1e-7;
    NaturalContactInput p = in, m = in;
    if (j < 12)
    {
      p.r[j / 3](j % 3) += h;
      m.r[j / 3](j % 3) -= h;
    }
    else if (j < 24)
    {
      p.v[(j - 12) / 3]((j - 12) % 3) += h;
      m.v[(j - 12) / 3]((j - 12) % 3) -= h;
    }
    else
    {
      p.spin[j - 24] += h;
      m.spin[j - 24] -= h;
    }
    Vec14 fp, fm;
    naturalContact(nm, k, p, impact_speed, &fp, nullptr, nullptr);
    naturalContact(nm, k, m, impact_speed, &fm, nullptr, nullptr);
    const Vec14 d = -(fp - fm) / (2.0 * h);
    if (j < 12)
      k_fd.col(j) = d;
    else
      c_fd.col(j - 12) = d;  // (velocities to columns 0-11, the spin rates to 12-13)
  }
  EXPECT_LE((kk - k_fd).cwiseAbs().maxCoeff(), 1e-5 * std::max(1.0, kk.cwiseAbs().maxCoeff()));
  EXPECT_LE((cc - c_fd).cwiseAbs().maxCoeff(), 1e-5 * std::max(1.0, cc.cwiseAbs().maxCoeff()));
}

TEST(Natural, ContactTangentsMatchCentralDifferences)
{
  const Model model = scene("tower.yaml", { { "analysis.type", "dynamic" } });
  const NaturalModel nm = buildNaturalModel(model);
  std::vector<int> pairs;
  model.checkedPairList(&pairs);
  ASSERT_FALSE(pairs.empty());
  const NaturalContactSlot pair = naturalContactSlot(nm, pairs[0]);
  ASSERT_GE(nm.struts[0].spin, 0) << "the tower has strut friction: spin rates";
  std::mt19937 rng(7);
  int with_friction = 0, with_cores = 0;
  // sleeves only, and deep enough for the steel cores (the sleeves are 27.5 mm thick each)
  for (const double depth : { 2e-3, 1e-2, 6e-2 })
    for (int trial = 0; trial < 6; ++trial)
    {
      const NaturalContactInput in = crossing(rng, depth);
      ContactPairState st;
      // (an impact speed of 3 m/s or more keeps the Lankarani-Nikravesh factor 1 + D zeta_dot above 0.3 for any
      // of these velocities: every sample pushes)
      expectTangentsMatch(nm, pair, in, 3.0 + 0.5 * trial, &st);
      ASSERT_TRUE(st.active);
      ASSERT_GT(st.normal_force, 0.0);
      with_friction += st.friction_force > 0.0;
      with_cores += st.core_penetration > 0.0;
    }
  EXPECT_GT(with_friction, 0);
  EXPECT_GT(with_cores, 0);
}

TEST(Natural, GroundTangentsMatchCentralDifferences)
{
  // the six-bar's spheres at the strut ends on the ground, with friction at their lowest points
  const Model model = scene("six_bar.yaml");
  const NaturalModel nm = buildNaturalModel(model);
  ASSERT_FALSE(nm.ground_contacts.empty());
  const NaturalContactSlot k = nm.ground_contacts[0];
  ASSERT_EQ(k.slot, model.pairSlots());
  ASSERT_EQ(naturalContactSlot(nm, k.slot).nodes[0], k.nodes[0]);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int with_friction = 0;
  for (int trial = 0; trial < 12; ++trial)
  {
    NaturalContactInput in;
    const Vec3 axis = Vec3(u(rng), u(rng), 0.5 + 0.5 * std::abs(u(rng))).normalized();
    const double length = nm.struts[k.struts[0]].length;
    const int end = k.sphere_end;
    const Vec3 sphere(u(rng), u(rng), model.ground_contacts[0].radius - 1e-3 * (1.0 + std::abs(u(rng))));
    in.r[end] = sphere;
    in.r[1 - end] = sphere + (end == 0 ? 1.0 : -1.0) * length * axis;
    for (int i = 0; i < 2; ++i)
      in.v[i] = Vec3(u(rng), u(rng), u(rng));
    in.spin[0] = 5.0 * u(rng);
    ContactPairState st;
    expectTangentsMatch(nm, k, in, 0.5, &st);
    ASSERT_TRUE(st.active);
    with_friction += st.friction_force > 0.0;
  }
  EXPECT_GT(with_friction, 0);
}

TEST(Natural, ForceTangentsMatchCentralDifferences)
{
  // the six-bar's prestressed, damped springs (pulled in by their actuators) and its spinning struts' gyroscopic
  // couples, away from its start
  const Model model = scene("six_bar.yaml");
  const NaturalModel nm = buildNaturalModel(model);
  ASSERT_GE(nm.struts[0].spin, 0);
  NaturalSolver solver(nm, model.solver);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  NaturalState s = naturalInitialState(nm);
  Eigen::VectorXd x = s.x, v(nm.coordinates);
  for (int i = 0; i < nm.coordinates; ++i)
  {
    if (i < nm.positions)
      x(i) += 0.01 * uni(rng);
    v(i) = (i < nm.positions ? 0.5 : 20.0) * uni(rng);
  }
  ActuationValues u(model.actuators.size());
  for (ActuationValue& a : u)
  {
    a.value = 0.05 * (1.0 + uni(rng));
    a.rate = 0.2 * uni(rng);
  }
  Eigen::VectorXd f, fp, fm;
  Eigen::MatrixXd k, c;
  solver.appliedForces(x, v, u, f, &k, &c);
  Eigen::MatrixXd k_fd(nm.coordinates, nm.coordinates), c_fd(nm.coordinates, nm.coordinates);
  const double h = 1e-7;
  for (int j = 0; j < nm.coordinates; ++j)
  {
    Eigen::VectorXd xp = x, xm = x, vp = v, vm = v;
    xp(j) += h;
    xm(j) -= h;
    solver.appliedForces(xp, v, u, fp, nullptr, nullptr);
    solver.appliedForces(xm, v, u, fm, nullptr, nullptr);
    k_fd.col(j) = -(fp - fm) / (2.0 * h);
    vp(j) += h;
    vm(j) -= h;
    solver.appliedForces(x, vp, u, fp, nullptr, nullptr);
    solver.appliedForces(x, vm, u, fm, nullptr, nullptr);
    c_fd.col(j) = -(fp - fm) / (2.0 * h);
  }
  EXPECT_GT(c.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_GT(c.rightCols(nm.coordinates - nm.positions).cwiseAbs().maxCoeff(), 0.0) << "gyroscopic: the spin columns";
  EXPECT_LE((k - k_fd).cwiseAbs().maxCoeff(), 1e-5 * k.cwiseAbs().maxCoeff());
  EXPECT_LE((c - c_fd).cwiseAbs().maxCoeff(), 1e-5 * c.cwiseAbs().maxCoeff());
}

TEST(Natural, StaticJacobianMatchesCentralDifferences)
{
  // the static residual's Jacobian [K + sum lambda_k Phi_k'', G^T; G, 0] against central differences of the residual
  // in the positions and the multipliers: the tower folded 1.2 m (its sliding cables over the joints, struts in
  // contact, driven bodies) and the quadruplex part way down, each moved a little off its path
  for (const auto& [name, pull] : { std::pair{ "tower.yaml", 1.2 }, std::pair{ "quadruplex.yaml", 0.9 } })
  {
    const Model model = scene(name);
    StaticSolver statics(model, model.solver);
    State st = initialState(model);
    ASSERT_TRUE(statics.solve(st, st.u).ok());
    ActuationValues end = st.u;
    for (ActuationValue& a : end)
      a.value = pull;
    ASSERT_TRUE(statics.followPath(st, end, 60, {}).ok()) << name;
    const NaturalModel nm = buildNaturalModel(model, false);  // (statics' coordinates: no spin rates)
    ASSERT_EQ(st.natural.x.size(), nm.coordinates);
    NaturalSolver solver(nm, model.solver);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> uni(-1.0, 1.0);
    Eigen::VectorXd x = st.natural.x, lambda = st.natural.lambda;
    for (int i = 0; i < nm.positions; ++i)
      x(i) += 1e-4 * uni(rng);
    for (Eigen::Index i = 0; i < lambda.size(); ++i)
      lambda(i) *= 1.0 + 0.01 * uni(rng);
    solver.assembleStatic(x, lambda, st.u, true);
    const Eigen::MatrixXd j = solver.assembledMatrix();
    const int n = nm.coordinates, m = static_cast<int>(lambda.size());
    Eigen::MatrixXd fd = Eigen::MatrixXd::Zero(n + m, n + m);
    const double h = 1e-7;
    for (int c = 0; c < n + m; ++c)
    {
      if (c >= nm.positions && c < n)
        continue;  // (the spin entries: no residual)
      Eigen::VectorXd xp = x, xm = x, lp = lambda, lm = lambda;
      if (c < n)
      {
        xp(c) += h;
        xm(c) -= h;
      }
      else
      {
        lp(c - n) += h;
        lm(c - n) -= h;
      }
      solver.assembleStatic(xp, lp, st.u, false);
      const Eigen::VectorXd rp = solver.staticResidual();
      solver.assembleStatic(xm, lm, st.u, false);
      fd.col(c) = (rp - solver.staticResidual()) / (2.0 * h);
    }
    const Eigen::MatrixXd jp = j.topLeftCorner(nm.positions, nm.positions),
                          fp = fd.topLeftCorner(nm.positions, nm.positions);
    EXPECT_LE((jp - fp).cwiseAbs().maxCoeff(), 1e-6 * jp.cwiseAbs().maxCoeff()) << name << ": K + sum lambda Phi''";
    EXPECT_LE((j.bottomLeftCorner(m, nm.positions) - fd.bottomLeftCorner(m, nm.positions)).cwiseAbs().maxCoeff(), 1e-6)
        << name << ": G";
    EXPECT_LE((j.topRightCorner(nm.positions, m) - fd.topRightCorner(nm.positions, m)).cwiseAbs().maxCoeff(), 1e-6)
        << name << ": G^T";
    std::vector<ContactPairState> touching;
    solver.staticContacts(x, st.u, touching);
    if (std::string(name) == "tower.yaml")
    {
      EXPECT_FALSE(touching.empty()) << "the fold's struts in contact";
    }
  }
}

TEST(Natural, MassMatrixGivesTheRigidStrutsKineticEnergy)
{
  // a free strut: 1/2 v^T M v = 1/2 m |v_c|^2 + 1/2 J_t |w|^2 for every motion that keeps its length
  const Model model = scene("prism.yaml");
  const NaturalModel nm = buildNaturalModel(model);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const NaturalStrut& s : nm.struts)
  {
    const NaturalNode& a = nm.nodes[s.a];
    const NaturalNode& b = nm.nodes[s.b];
    if (a.column < 0 || b.column < 0)
      continue;
    const Body& body = model.bodies[s.body];
    const Vec3 axis = (b.position0 - a.position0);
    const Vec3 vc(u(rng), u(rng), u(rng));
    Vec3 w(u(rng), u(rng), u(rng));
    w -= w.dot(axis) / axis.squaredNorm() * axis;  // no spin: the coordinates have none
    Eigen::VectorXd v = Eigen::VectorXd::Zero(nm.coordinates);
    v.segment<3>(a.column) = vc + w.cross(-0.5 * axis);
    v.segment<3>(b.column) = vc + w.cross(0.5 * axis);
    const double natural = 0.5 * v.dot(nm.mass * v);
    const double rigid = 0.5 * body.mass * vc.squaredNorm() + 0.5 * body.inertia.x() * w.squaredNorm();
    EXPECT_NEAR(natural, rigid, 1e-12 * rigid) << body.name;
  }
}

// the strut centres of a run to t_end, each formulation at fixed steps of dt
std::vector<Vec3> centresBody(const Model& model, double t_end)
{
  BodyDynamicsSolver solver(model, model.solver);
  const ActuationLaw law = [&model](double t) { return scheduledActuation(model, t); };
  BodyState s = bodyInitialState(model);
  EXPECT_TRUE(solver.initialize(s, law).ok());
  while (s.t < t_end - 1e-12)
  {
    const double t1 = s.t + model.solver.dt;
    EXPECT_TRUE(solver.step(s, model.solver.dt, law).ok());
    s.t = t1;
  }
  std::vector<Vec3> c;
  for (const Body& b : model.bodies)
    c.push_back(s.q.segment<3>(b.offset));
  return c;
}

std::vector<Vec3> centresNatural(const Model& model, double t_end, double* impulse_speed = nullptr)
{
  const NaturalModel nm = buildNaturalModel(model);
  NaturalSolver solver(nm, model.solver);
  const ActuationLaw law = [&model](double t) { return scheduledActuation(model, t); };
  NaturalState s = naturalInitialState(nm);
  EXPECT_TRUE(solver.initialize(s, law).ok());
  EXPECT_TRUE(solver.advanceTo(s, t_end, law).ok());
  if (impulse_speed)
  {
    *impulse_speed = 0.0;
    for (const NaturalTouch& c : s.touching)
      *impulse_speed = std::max(*impulse_speed, c.speed);
  }
  const Eigen::VectorXd q = naturalToBodyCoordinates(nm, s.x, scheduledActuation(model, s.t));
  std::vector<Vec3> c;
  for (const Body& b : model.bodies)
    c.push_back(q.segment<3>(b.offset));
  return c;
}

TEST(Natural, AgreesWithBodyCoordinatesThroughContact)
{
  // the quadruplex pressed into contact (first touch at 0.29 s, touching again from 0.45 s): the two formulations
  // integrate the same equations (no friction, so spin plays no part) with the same scheme, Newmark or the scene's
  // generalized-alpha. Each is 4e-5 to 1.3e-4 m off a run at a tenth of the step (tensegrity_bench natural); between
  // them the difference must be far smaller.
  for (const char* integrator : { "newmark", "generalized_alpha" })
    for (const double dt : { 2e-4, 1e-4 })
    {
      const Model model = scene("quadruplex_linear_contact.yaml", { { "solver.integrator", integrator },
                                                                    { "solver.dt", std::to_string(dt) },
                                                                    { "solver.newton_tolerance", "1e-10" } });
      double speed = 0.0;
      const std::vector<Vec3> body = centresBody(model, 0.5), natural = centresNatural(model, 0.5, &speed);
      EXPECT_GT(speed, 0.0) << "in contact at the end";
      double most = 0.0, moved = 0.0;
      for (size_t i = 0; i < body.size(); ++i)
      {
        most = std::max(most, (body[i] - natural[i]).norm());
        moved = std::max(moved, (body[i] - model.q0.segment<3>(model.bodies[i].offset)).norm());
      }
      EXPECT_GT(moved, 0.1);
      EXPECT_LT(most, 1e-5) << integrator << " dt " << dt;
    }
}

TEST(Natural, ActuationForcesAgreeWithBodyCoordinatesAndTheDrivenBodysBalance)
{
  // the quadruplex's unguided top nodes (a driven row's multiplier in both formulations): the force agrees with the
  // body coordinates' along the path into contact (the two paths agree to 1e-8 m)
  {
    const Model model =
        scene("quadruplex_linear_contact.yaml",
              { { "solver.integrator", "newmark" }, { "solver.dt", "2e-4" }, { "solver.newton_tolerance", "1e-10" } });
    const ActuationLaw law = [&model](double t) { return scheduledActuation(model, t); };
    BodyDynamicsSolver body(model, model.solver);
    BodyState bs = bodyInitialState(model);
    ASSERT_TRUE(body.initialize(bs, law).ok());
    const NaturalModel nm = buildNaturalModel(model);
    NaturalSolver natural(nm, model.solver);
    NaturalState ns = naturalInitialState(nm);
    ASSERT_TRUE(natural.initialize(ns, law).ok());
    for (const double t_end : { 0.3, 0.6, 1.0 })
    {
      while (bs.t < t_end - 1e-12)
      {
        const double t1 = bs.t + model.solver.dt;
        ASSERT_TRUE(body.step(bs, model.solver.dt, law).ok());
        bs.t = t1;
        ASSERT_TRUE(natural.tryStep(ns, model.solver.dt, law).ok());
      }
      const double fb = bodyActuationForce(model, bs, 0);
      const double fn = firstActuatorForce(natural, ns, scheduledActuation(model, ns.t));
      EXPECT_GT(std::abs(fb), 1000.0);
      EXPECT_NEAR(fn, fb, 1e-5 * std::abs(fb)) << "at " << t_end << " s";
    }
  }
  // the tower's guided driven bodies (a reaction in the natural coordinates): the 1 kg body B1 hangs on cable L1, whose
  // last segment runs straight up to the pulley G1, and is pulled down (d = -z), so the drive holds T - m g + m a_d
  // (gravity on here; the scene has none); the fold's paths depend on round-off, so it is checked against the run's
  // own tension
  {
    const Model model = scene("tower.yaml", { { "analysis.type", "dynamic" }, { "gravity.enabled", "true" } });
    ASSERT_TRUE(model.gravity_enabled);
    const ActuationLaw law = [&model](double t) { return scheduledActuation(model, t); };
    const NaturalModel nm = buildNaturalModel(model);
    NaturalSolver natural(nm, model.solver);
    NaturalState ns = naturalInitialState(nm);
    ASSERT_TRUE(natural.initialize(ns, law).ok());
    int cable = -1;
    for (size_t k = 0; k < model.cables.size(); ++k)
      if (model.cables[k].name == "L1")
        cable = static_cast<int>(k);
    ASSERT_GE(cable, 0);
    const std::vector<int>& nodes = nm.cable_nodes[static_cast<size_t>(cable)];
    int taut = 0;
    for (const double t_end : { 0.5, 1.0, 1.5, 2.0, 2.5 })
    {
      ASSERT_TRUE(natural.advanceTo(ns, t_end, law).ok());
      const ActuationValues u = scheduledActuation(model, ns.t);
      double l = 0.0, rate = 0.0;
      for (size_t i = 0; i + 1 < nodes.size(); ++i)
      {
        const Vec3 d = naturalNodePosition(nm, nodes[i + 1], ns.x, u) - naturalNodePosition(nm, nodes[i], ns.x, u);
        l += d.norm();
        rate += d.normalized().dot(naturalNodeVelocity(nm, nodes[i + 1], ns.v, u) -
                                   naturalNodeVelocity(nm, nodes[i], ns.v, u));
      }
      const double tension = cableLaw(model.cables[static_cast<size_t>(cable)], l, rate, u, true).tension;
      const Vec3 last =
          naturalNodePosition(nm, nodes[nodes.size() - 2], ns.x, u) - naturalNodePosition(nm, nodes.back(), ns.x, u);
      ASSERT_LT(last.normalized().cross(Vec3::UnitZ()).norm(), 1e-9) << "the last segment runs straight up";
      const double expected = tension + 1.0 * model.gravity.z() + 1.0 * u[0].accel;
      EXPECT_NEAR(firstActuatorForce(natural, ns, u), expected, 1e-9 * std::max(1.0, tension))
          << "at " << t_end << " s";
      taut += tension > 1.0;
    }
    EXPECT_GT(taut, 0) << "the pull cable is taut at some of the instants";
  }
}

namespace
{
// the energy account of a natural-coordinate run at fixed steps (or adaptive ones): actuator work, contact and damper
// dissipation and the integrator's own, summed by the trapezoidal rule over the accepted steps
struct NaturalAccount
{
  double work = 0.0, contact = 0.0, damping = 0.0, numerical = 0.0, most_gain = 0.0;
  EnergyPoint start, end;
  NaturalStats stats;
};

NaturalAccount naturalAccount(const Model& model, double t_end)
{
  const NaturalModel nm = buildNaturalModel(model);
  NaturalSolver solver(nm, model.solver);
  const ActuationLaw law = [&model](double t) { return scheduledActuation(model, t); };
  NaturalState s = naturalInitialState(nm);
  EXPECT_TRUE(solver.initialize(s, law).ok());
  NaturalAccount a;
  a.start = solver.energyAt(s, scheduledActuation(model, s.t));
  EnergyPoint last = a.start;
  double last_t = s.t;
  const Summary r = solver.advanceTo(s, t_end, law,
                                     [&](const NaturalState& e)
                                     {
                                       const EnergyPoint p = solver.energyAt(e, scheduledActuation(model, e.t));
                                       const double h = e.t - last_t;
                                       a.work += 0.5 * h * (last.actuator_power + p.actuator_power);
                                       a.contact += 0.5 * h * (last.contact_power + p.contact_power);
                                       a.damping += 0.5 * h * (last.damping_power + p.damping_power);
                                       const double d = stepNumericalDissipation(last, p, h);
                                       a.numerical += d;
                                       a.most_gain = std::max(a.most_gain, -d);
                                       last = p;
                                       last_t = e.t;
                                     });
  EXPECT_TRUE(r.ok()) << r.message;
  a.end = last;
  a.stats = solver.stats();
  return a;
}
}  // namespace

TEST(Natural, EnergyAccountAgreesWithBodyCoordinatesAndCloses)
{
  // the linear-law quadruplex driven into contact (driven rows): at the start the prestress's elastic energy is the
  // body coordinates'; over the run the actuators' work is the body coordinates' and the integrator's own share
  // vanishes with the step (as EnergyAccount.ClosesAsTheStepShrinks has it for the body coordinates)
  Model model = scene("quadruplex_linear_contact.yaml");
  {
    const BodyState bs = bodyInitialState(model);
    const System system(model);
    const EnergyPoint body = energyPoint(system, bs, {});
    const NaturalModel nm = buildNaturalModel(model);
    NaturalSolver solver(nm, model.solver);
    const NaturalState ns = naturalInitialState(nm);
    const EnergyPoint natural = solver.energyAt(ns, scheduledActuation(model, 0.0));
    ASSERT_GT(body.elastic, 1.0);
    EXPECT_NEAR(natural.elastic, body.elastic, 1e-12 * body.elastic);
    EXPECT_EQ(natural.kinetic, 0.0);
    EXPECT_EQ(natural.gravity, 0.0);
  }
  double numerical[2], work[2];
  const double steps[2] = { 1e-4, 2.5e-5 };
  for (int i = 0; i < 2; ++i)
  {
    model.solver.dt = steps[i];
    const NaturalAccount a = naturalAccount(model, model.analysis.duration);
    numerical[i] = a.numerical;
    work[i] = a.work;
    EXPECT_GT(a.contact, 0.01 * a.work);
    EXPECT_EQ(a.damping, 0.0);
    std::printf("[ measured ] natural, dt %g s: actuator work %.6f J, contact %.6f J, numerical %.3e J\n", steps[i],
                a.work, a.contact, a.numerical);
  }
  EXPECT_GT(work[0], 1000.0);
  EXPECT_NEAR(work[0], work[1], 1e-3 * work[1]);
  EXPECT_LT(std::abs(numerical[1]), 0.1 * std::abs(numerical[0]));
  EXPECT_LT(std::abs(numerical[1]), 1e-6 * work[1]);
  model.solver.dt = 1e-4;
  const RunResult body = runAnalysis(model, [](const State&) {});
  ASSERT_TRUE(body.summary.ok());
  EXPECT_NEAR(work[0], body.energy.actuator_work, 1e-4 * body.energy.actuator_work);
}

TEST(Natural, DrivenBodiesWorkClosesTheTowersAccount)
{
  // the tower folded by its guided driven bodies (their reactions' power), generalized-alpha with little numerical
  // damping: the drives' work, less what friction and the contacts take, is what the structure gains, to the
  // integrator's share (a drive power of the wrong sign would leave twice the work unaccounted for)
  const Model model = scene("tower.yaml", { { "analysis.type", "dynamic" },
                                            { "solver.integrator", "generalized_alpha" },
                                            { "solver.rho_infinity", "0.95" },
                                            { "solver.dt", "1e-4" } });
  const NaturalAccount a = naturalAccount(model, 2.5);
  const double gained = a.end.total() - a.start.total();
  std::printf("[ measured ] tower: drives' work %.4f J, contact %.4f J, gained %.4f J, numerical %.3e J\n", a.work,
              a.contact, gained, a.numerical);
  ASSERT_GT(std::abs(a.work), 100.0);
  EXPECT_LT(std::abs(a.numerical), 0.02 * std::abs(a.work));
}

TEST(Natural, AdaptiveStepsRefuseWhatGainsEnergy)
{
  // the linear-law quadruplex into contact with a loose error tolerance: the error control alone takes steps through
  // the stiff contact that gain energy; the energy check halves them
  Model model =
      scene("quadruplex_linear_contact.yaml", { { "solver.adaptive", "true" }, { "solver.error_tolerance", "1e-2" } });
  const NaturalAccount checked = naturalAccount(model, model.analysis.duration);
  model.solver.energy_tolerance = 1e9;
  const NaturalAccount unchecked = naturalAccount(model, model.analysis.duration);
  std::printf("[ measured ] adaptive, tolerance 1e-2: refused for energy %ld, largest gain in a step %.3e J (without "
              "the check %.3e J)\n",
              checked.stats.rejected_energy, checked.most_gain, unchecked.most_gain);
  EXPECT_GT(checked.stats.rejected_energy, 0);
  EXPECT_EQ(unchecked.stats.rejected_energy, 0);
  EXPECT_LT(checked.most_gain, unchecked.most_gain);
}

TEST(Natural, StaticPathsAgreeWithBodyCoordinates)
{
  // the quadruplex compressed to its ultimate configuration (no contact) and the tower folded with contact: the path
  // of equilibria of StaticSolver (natural coordinates, no spin locks) against the body coordinates'
  // BodyStaticSolver.
  // The quadruplex agrees at every load step, its actuation force too; the unprestressed tower starts as a mechanism
  // (its first equilibria are not unique), and its fold ends where the body coordinates' does.
  for (const char* name : { "quadruplex.yaml", "tower.yaml" })
  {
    const Model model = scene(name);
    const int steps = model.analysis.steps;
    BodyStaticSolver body(model, model.solver);
    BodyState bs = bodyInitialState(model);
    ASSERT_TRUE(body.solve(bs, bs.u).ok());
    ActuationValues u_end = bs.u;
    for (ActuationValue& v : u_end)
      v.value = model.analysis.max_actuation;
    std::vector<Eigen::VectorXd> body_path;
    ASSERT_TRUE(
        body.followPath(bs, u_end, steps, [&](const State& s, const Summary&) { body_path.push_back(s.q); }).ok());
    StaticSolver natural(model, model.solver);
    State ns = initialState(model);
    ASSERT_TRUE(natural.solve(ns, ns.u).ok());
    EXPECT_TRUE(ns.natural.equilibrium);
    std::vector<Eigen::VectorXd> natural_path;
    const Summary r =
        natural.followPath(ns, u_end, steps, [&](const State& s, const Summary&) { natural_path.push_back(s.q); });
    ASSERT_TRUE(r.ok()) << name << ": " << r.message;
    ASSERT_EQ(natural_path.size(), body_path.size()) << name;
    const auto difference = [&](size_t k)
    {
      double most = 0.0;
      for (const Body& b : model.bodies)
        most = std::max(most, (natural_path[k].segment<3>(b.offset) - body_path[k].segment<3>(b.offset)).norm());
      return most;
    };
    if (std::string(name) == "quadruplex.yaml")
    {
      for (size_t k = 0; k < body_path.size(); ++k)
        ASSERT_LT(difference(k), 1e-9) << "load step " << k + 1;
      const double fb = bodyActuationForce(model, bs, 0), fn = actuationForce(model, ns, 0);
      EXPECT_GT(std::abs(fb), 100.0);
      EXPECT_NEAR(fn, fb, 1e-8 * std::abs(fb));
    }
    else
      EXPECT_LT(difference(body_path.size() - 1), 1e-8) << name << " at the end of the fold";
  }
}

TEST(Natural, GeneralizedAlphaConvergesAtSecondOrder)
{
  // the prism turned and released: generalized-alpha's position error against a run at a sixteenth of the step falls
  // about four times per halving
  const auto run = [](double dt)
  {
    const Model model = scene("prism_released.yaml", { { "solver.integrator", "generalized_alpha" },
                                                       { "solver.dt", std::to_string(dt) },
                                                       { "solver.newton_tolerance", "1e-12" } });
    return centresNatural(model, 0.2);
  };
  const std::vector<Vec3> fine = run(2.5e-5 / 4.0);
  double previous = 0.0;
  for (const double dt : { 1e-4, 5e-5 })
  {
    const std::vector<Vec3> c = run(dt);
    double most = 0.0;
    for (size_t i = 0; i < c.size(); ++i)
      most = std::max(most, (c[i] - fine[i]).norm());
    EXPECT_GT(most, 0.0);
    if (previous > 0.0)
    {
      EXPECT_GT(previous / most, 3.0) << "dt " << dt;
      EXPECT_LT(previous / most, 5.5) << "dt " << dt;
    }
    previous = most;
  }
}

TEST(Natural, SpinningStrutKeepsItsAngularMomentum)
{
  // a free strut tumbling and spinning with no force: its angular momentum J_t w_perp + J_a w_s e is constant (the
  // gyroscopic couple turns the transverse rotation as the axis moves), its spin rate too, and the trapezoidal rule
  // keeps the energy (both to about 1e-9 here; without the gyroscopic couple the momentum is off by 2.5 N m s)
  Model model = freeStrutModel("S", 1.2, 0.05, 2700.0, Vec3(1.0, 0.3, 0.2).normalized());
  model.contact.enabled = true;  // (friction: the struts get spin rates)
  model.contact.friction = 0.3;
  const NaturalModel nm = buildNaturalModel(model);
  const NaturalStrut& st = nm.struts[0];
  ASSERT_GE(st.spin, 0);
  const double jt = model.bodies[0].inertia.x(), ja = model.bodies[0].inertia.z();
  NaturalState s = naturalInitialState(nm);
  const Vec3 u0 = s.x.segment<3>(nm.nodes[st.b].column) - s.x.segment<3>(nm.nodes[st.a].column);
  const Vec3 w = Vec3(0.0, 0.0, 3.0) - Vec3(0.0, 0.0, 3.0).dot(u0) / u0.squaredNorm() * u0;  // transverse
  s.v.segment<3>(nm.nodes[st.b].column) = w.cross(0.5 * u0);
  s.v.segment<3>(nm.nodes[st.a].column) = w.cross(-0.5 * u0);
  s.v(st.spin) = 40.0;
  const auto momentum = [&](const NaturalState& z)
  {
    const Vec3 u = z.x.segment<3>(nm.nodes[st.b].column) - z.x.segment<3>(nm.nodes[st.a].column);
    const Vec3 ud = z.v.segment<3>(nm.nodes[st.b].column) - z.v.segment<3>(nm.nodes[st.a].column);
    return Vec3(jt * u.cross(ud) / (st.length * st.length) + ja * z.v(st.spin) * u / st.length);
  };
  const auto energy = [&](const NaturalState& z) { return 0.5 * z.v.dot(nm.mass * z.v); };
  const Vec3 h0 = momentum(s);
  const double e0 = energy(s);
  SolverOptions o = trapezoidalOptions(1e-4, 1e-12);
  o.reuse_jacobian = false;  // (Newton's own errors out of the measure: the formulation and the scheme alone)
  NaturalSolver solver(nm, o);
  const ActuationLaw law = [](double) { return ActuationValues{}; };
  ASSERT_TRUE(solver.initialize(s, law).ok());
  ASSERT_TRUE(solver.advanceTo(s, 1.0, law).ok());
  const Vec3 u1 = s.x.segment<3>(nm.nodes[st.b].column) - s.x.segment<3>(nm.nodes[st.a].column);
  EXPECT_GT((u1.normalized() - u0.normalized()).norm(), 0.5) << "the axis turned";
  EXPECT_NEAR(s.v(st.spin), 40.0, 1e-9);
  EXPECT_LT((momentum(s) - h0).norm(), 1e-7 * h0.norm());
  EXPECT_NEAR(energy(s), e0, 1e-7 * e0);
}

TEST(Natural, PushedFreeStrutGainsTheImpulseAndKeepsItsLength)
{
  // a free strut along x without gravity, pushed at its +L/2 end by a constant force for 0.3 s: the trapezoidal rule
  // gives the momentum F t and the centre F t^2 / (2 m) exactly (the restart makes the accelerations consistent with
  // the push), the length stays, and the velocity stays once the push is off
  const Model m = freeStrutModel("A", 1.0, 0.02, 7800.0, Vec3::UnitX());
  SolverOptions options = trapezoidalOptions(1e-3, 1e-12);
  const NaturalModel nm = buildNaturalModel(m);
  NaturalSolver solver(nm, options);
  const ActuationLaw law = [](double) { return ActuationValues(); };
  NaturalState s = naturalInitialState(nm);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  const Vec3 force(3.0, -2.0, 5.0);
  ASSERT_TRUE(solver.setExternalLoads({ PointLoad{ "push", PointRef{ 0, Vec3(0.0, 0.0, 0.5) }, force } }, s, law).ok());
  // a push off the axis is refused by name, and the one in force stays
  const NaturalState before = s;
  try
  {
    solver.setExternalLoads({ PointLoad{ "side", PointRef{ 0, Vec3(0.01, 0.0, 0.2) }, force } }, s, law);
    ADD_FAILURE() << "a push off the strut's axis was taken";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string(e.what()).find("load side"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("strut A"), std::string::npos) << e.what();
  }
  EXPECT_EQ(s.x, before.x);
  EXPECT_EQ(s.a, before.a);
  const NaturalStrut& st = nm.struts[0];
  const auto centre = [&](const Eigen::VectorXd& x)
  { return 0.5 * (x.segment<3>(nm.nodes[st.a].column) + x.segment<3>(nm.nodes[st.b].column)); };
  const Vec3 c0 = centre(s.x);
  const double h = 1e-3;
  for (int k = 0; k < 300; ++k)
    ASSERT_TRUE(solver.tryStep(s, h, law).ok());
  ASSERT_NEAR(s.t, 0.3, 1e-12);
  const double mass = m.bodies[0].mass;
  const Vec3 momentum = mass * centre(s.v);
  EXPECT_LT((momentum - force * s.t).norm(), 1e-9 * force.norm() * s.t) << momentum.transpose();
  EXPECT_LT((centre(s.x) - c0 - 0.5 * force / mass * s.t * s.t).norm(), 1e-9);
  const Vec3 u = s.x.segment<3>(nm.nodes[st.b].column) - s.x.segment<3>(nm.nodes[st.a].column);
  EXPECT_NEAR(u.norm(), 1.0, 1e-10);
  EXPECT_LT(u.normalized().dot(Vec3::UnitX()), 0.999) << "the end's push turns the strut";
  ASSERT_TRUE(solver.setExternalLoads({}, s, law).ok());
  const Vec3 v = centre(s.v);
  for (int k = 0; k < 50; ++k)
    ASSERT_TRUE(solver.tryStep(s, h, law).ok());
  EXPECT_LT((centre(s.v) - v).norm(), 1e-12);
}

TEST(Natural, AStepThroughAStrutIsCutNotAcceptedOrFailsNamingThePair)
{
  // strut B 0.5 mm above strut A and across it, falling at 30 m/s, with 5 ms steps: the first try jumps through
  // (the 4 cm struts meet within 1.4 ms). With cuts allowed the step is cut until the contact catches it and B ends
  // above A moving up; with none, the step fails as passed_through naming both struts, and the state stays.
  Model m;
  m.name = "crossing";
  m.bodies.push_back(active_tensegrity::test::makeStrut("A", 1.0, 0.02, 7800.0));
  m.bodies.push_back(active_tensegrity::test::makeStrut("B", 1.0, 0.02, 7800.0));
  for (Body& b : m.bodies)
  {
    b.layers.back().youngs_modulus = 2.0e8;
    b.layers.back().poisson_ratio = 0.3;
  }
  finalizeModel(m);
  m.contact.enabled = true;
  m.contact.restitution = 0.5;
  m.listed_pairs.push_back(makeStrutPair(m, 0, 1));
  m.q0.setZero(m.nq);
  m.q0.segment<4>(3) = thetaFromZAxis(Vec3::UnitX());
  m.q0.segment<3>(7) = Vec3(0.0, 0.0, 0.0405);
  m.q0.segment<4>(10) = thetaFromZAxis(Vec3::UnitY());
  const NaturalModel nm = buildNaturalModel(m);
  const ActuationLaw law = [](double) { return ActuationValues(); };
  const NaturalStrut& b = nm.struts[static_cast<size_t>(nm.strut_of_body[1])];
  const NaturalStrut& a = nm.struts[static_cast<size_t>(nm.strut_of_body[0])];
  const auto height = [&](const NaturalState& s, const NaturalStrut& st)
  { return 0.5 * (s.x(nm.nodes[st.a].column + 2) + s.x(nm.nodes[st.b].column + 2)); };
  for (const int cuts : { 16, 0 })
  {
    SolverOptions o = trapezoidalOptions(5e-3, 1e-13);
    o.max_step_cuts = cuts;
    NaturalSolver solver(nm, o);
    NaturalState s = naturalInitialState(nm);
    for (const int node : { b.a, b.b })
      s.v.segment<3>(nm.nodes[node].column) = Vec3(0.0, 0.0, -30.0);
    ASSERT_TRUE(solver.initialize(s, law).ok());
    if (cuts == 0)
    {
      const NaturalState before = s;
      const Summary r = solver.advanceTo(s, 5e-3, law);
      EXPECT_EQ(r.status, SolveStatus::kPassedThrough);
      EXPECT_NE(r.message.find("'A'"), std::string::npos) << r.message;
      EXPECT_NE(r.message.find("'B'"), std::string::npos) << r.message;
      EXPECT_EQ(s.x, before.x);
      EXPECT_EQ(s.t, before.t);
      continue;
    }
    const Summary r = solver.advanceTo(s, 2e-2, law);
    ASSERT_TRUE(r.ok()) << r.message;
    EXPECT_GT(r.step_cuts, 0);
    EXPECT_GT(height(s, b), height(s, a)) << "B is still above A";
    const double rising = 0.5 * (s.v(nm.nodes[b.a].column + 2) + s.v(nm.nodes[b.b].column + 2));
    EXPECT_GT(rising, 0.0) << "and moving up after the rebound";
  }
}

TEST(Natural, RefusesWhatItDoesNotCover)
{
  // a joint of two struts whose ends start apart, and a cable to a point along a strut: no node is both, and the
  // refusal names the element
  try
  {
    buildNaturalModel(active_tensegrity::test::mixedModel());
    FAIL() << "the mixed model was accepted";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string(e.what()).find("joint"), std::string::npos) << e.what();
  }
  Model cable = active_tensegrity::test::freeStrutModel("S", 1.0, 0.02, 2700.0, Vec3::UnitZ());
  cable.cables.push_back(active_tensegrity::test::makeCable("mid", PointRef{ 0, Vec3(0.0, 0.0, 0.1) },
                                                            PointRef{ -1, Vec3(1.0, 0.0, 0.0) }, 100.0, 0.5, 0.0));
  try
  {
    buildNaturalModel(cable);
    FAIL() << "a cable at the middle of a strut was accepted";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string(e.what()).find("cable mid"), std::string::npos) << e.what();
  }
  // a cable to a point of the ground: a fixed node of its own
  Model anchored = active_tensegrity::test::freeStrutModel("S", 1.0, 0.02, 2700.0, Vec3::UnitZ());
  anchored.cables.push_back(active_tensegrity::test::makeCable("tie", PointRef{ 0, Vec3(0.0, 0.0, 0.5) },
                                                               PointRef{ -1, Vec3(1.0, 0.0, 0.5) }, 100.0, 0.5, 0.0));
  const NaturalModel nm = buildNaturalModel(anchored);
  ASSERT_EQ(nm.cable_nodes[0].size(), 2u);
  EXPECT_EQ(nm.nodes[nm.cable_nodes[0][1]].kind, NaturalNode::Kind::kFixed);
  EXPECT_EQ(nm.coordinates, 6);
}
}  // namespace
