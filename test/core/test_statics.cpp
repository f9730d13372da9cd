// Statics: the quadruplex of paper Sec. 6.1 (config/scenes/quadruplex.yaml, docs/scenes.md) without contact.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/oracle/body_statics.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
Model quadruplex(const std::vector<Override>& overrides = {})
{
  return loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/quadruplex.yaml", overrides);
}

struct PathPoint
{
  double v, force, height;
  Eigen::VectorXd q;
};

std::vector<PathPoint> runPath(const Model& model)
{
  std::vector<PathPoint> path;
  const RunResult r =
      runAnalysis(model,
                  [&](const State& s) {
                    path.push_back({ s.u[0].value, actuationForce(model, s, 0), structureHeight(model, s.q), s.q });
                  });
  EXPECT_TRUE(r.summary.ok()) << r.summary.message;
  return path;
}
}  // namespace

TEST(Quadruplex, PrestressedGeometryIsInEquilibrium)
{
  const Model model = quadruplex();
  EXPECT_EQ(model.n_lambda, 4 * 3 + 4 + 4);  // ground pins, quaternion norms, actuated top nodes
  EXPECT_EQ(bodyInitialState(model).lambda.size(), model.n_lambda);
  const System sys(model);
  EXPECT_EQ(sys.nLambda(), model.n_lambda);
  const Eigen::VectorXd lambda = leastSquaresMultipliers(sys, model.q0);
  Eigen::VectorXd F, cf;
  sys.appliedForce(model.q0, Eigen::VectorXd::Zero(model.nq), {}, F, nullptr, 0, 0);
  sys.constraintForce(model.q0, lambda, cf);
  EXPECT_LT((cf - F).lpNorm<Eigen::Infinity>() / 200.0, 1e-8);  // relative to the smallest prestress

  // the actuators carry nothing at v = 0: the multipliers of the driven nodes' rows, and the statics' own forces
  for (const int c : model.actuators[0].constraints)
  {
    int row = 0;
    for (int i = 0; i < c; ++i)
      row += model.constraints[i].rows();
    EXPECT_NEAR(lambda(row), 0.0, 1e-8);
  }
  State s = initialState(model);
  ASSERT_TRUE(StaticSolver(model, model.solver).solve(s, s.u).ok());
  EXPECT_NEAR(actuationForce(model, s, 0), 0.0, 1e-8);

  // the cables meeting at a top node balance a strut force of 489.89 N along the strut (Table 1)
  const int p5 = model.findNode("P5");
  const int strut = model.nodes[p5].point.body;
  Vec3 pull = Vec3::Zero();
  for (const Cable& c : model.cables)
  {
    const PointRef& ca = c.points.front();
    const PointRef& cb = c.points.back();
    const bool at_a = ca.body == strut && ca.local == model.nodes[p5].point.local;
    const bool at_b = cb.body == strut && cb.local == model.nodes[p5].point.local;
    if (!at_a && !at_b)
      continue;
    const CableState cs = evaluateCable(model, c, model.q0, Eigen::VectorXd::Zero(model.nq), {}, false);
    const Vec3 pa = pointPosition(model, ca, model.q0);
    const Vec3 pb = pointPosition(model, cb, model.q0);
    pull += cs.tension * (at_a ? (pb - pa) : (pa - pb)).normalized();
  }
  const Vec3 axis = rotationMatrix(model.q0.segment<4>(model.bodies[strut].offset + 3)).col(2);
  EXPECT_NEAR(pull.norm(), 489.89, 0.01);
  EXPECT_NEAR(std::abs(pull.normalized().dot(axis)), 1.0, 1e-9);

  // Newton starts converged
  StaticSolver solver(model, model.solver);
  State s0 = initialState(model);
  const Summary r = solver.solve(s0, s0.u);
  EXPECT_TRUE(r.ok()) << r.message;
  EXPECT_LT((s0.q - model.q0).lpNorm<Eigen::Infinity>(), 1e-9);
}

TEST(Quadruplex, PathWithoutContactRisesSoftensStiffensAndReachesTheUltimateConfiguration)
{
  const Model model = quadruplex();
  const std::vector<PathPoint> path = runPath(model);
  ASSERT_EQ(path.size(), 173u);  // v = 0, 0.01, ..., 1.72
  EXPECT_NEAR(path.back().v, 1.72, 1e-12);

  // rises from zero
  EXPECT_NEAR(path.front().force, 0.0, 1e-6);
  EXPECT_GT(path[5].force, path[1].force);
  EXPECT_GT(path[1].force, 0.0);
  // softens: a peak, then the force falls (snap-through region, where displacement control holds it)
  size_t peak = 0;
  for (size_t i = 0; i < 60; ++i)
    if (path[i].force > path[peak].force)
      peak = i;
  EXPECT_GT(peak, 5u);
  EXPECT_LT(peak, 40u);
  EXPECT_LT(path[50].force, 0.5 * path[peak].force);
  // stiffens again and diverges at the ultimate configuration: struts vertical at v = 0.5 + sqrt(1.5)
  EXPECT_GT(path.back().force, 100.0 * path[peak].force);
  const double slope_late = path[172].force - path[171].force;
  const double slope_earlier = path[160].force - path[159].force;
  EXPECT_GT(slope_late, 10.0 * slope_earlier);
  for (const Body& b : model.bodies)
    EXPECT_GT(std::abs(rotationMatrix(path.back().q.segment<4>(b.offset + 3))(2, 2)), 0.99) << b.name;
  EXPECT_NEAR(path.back().height, 0.5 - 1.72, 1e-9);
}

TEST(Quadruplex, PathIsAntisymmetricAboutTheFlatConfiguration)
{
  // the configuration at top height -h mirrors the one at +h through the ground plane, so the
  // vertical actuation force flips sign: F(0.5 + x) = -F(0.5 - x)
  const std::vector<PathPoint> path = runPath(quadruplex());
  for (int i = 0; i <= 50; i += 5)
    EXPECT_NEAR(path[50 + i].force, -path[50 - i].force, 1e-6 * (1.0 + std::abs(path[50 - i].force)))
        << "x = " << 0.01 * i;
}

TEST(Quadruplex, StrutsMeetBeforeTheStructureIsFlat)
{
  // paper: without contact the struts pass through each other before v = 0.5 m
  const Model model = quadruplex();
  const std::vector<PathPoint> path = runPath(model);
  EXPECT_GT(minimumGap(model, path.front().q), 0.0);
  bool overlap = false;
  for (const PathPoint& p : path)
    if (p.v < 0.5 && minimumGap(model, p.q) < 0.0)
      overlap = true;
  EXPECT_TRUE(overlap);
  // a thicker strut meets earlier
  auto first_contact = [](const Model& m)
  {
    for (const PathPoint& p : runPath(m))
      if (minimumGap(m, p.q) < 0.0)
        return p.v;
    return 99.0;
  };
  EXPECT_LT(first_contact(quadruplex({ { "struts.radius", "0.08" } })),
            first_contact(quadruplex({ { "struts.radius", "0.04" } })));
}

TEST(Statics, LargeIncrementIsCutAndReachesTheSameEquilibrium)
{
  const Model model = quadruplex();
  SolverOptions few = model.solver;
  few.max_iterations = 6;  // one increment of 0.9 m needs more: it has to be cut
  StaticSolver solver(model, few);
  State coarse = initialState(model);
  ASSERT_TRUE(solver.solve(coarse, coarse.u).ok());
  const Summary r = solver.followPath(coarse, { ActuationValue{ 0.9, 0, 0 } }, 1, {});
  ASSERT_TRUE(r.ok()) << r.message;
  // plain Newton cannot do it in 6 iterations: the increment was cut or the damped Newton took over
  EXPECT_GT(r.iterations, few.max_iterations);

  State fine = initialState(model);
  ASSERT_TRUE(solver.solve(fine, fine.u).ok());
  ASSERT_TRUE(solver.followPath(fine, { ActuationValue{ 0.9, 0, 0 } }, 90, {}).ok());
  // (the nodes: each path carries the struts' body frames along its own arcs)
  for (const Node& n : model.nodes)
    EXPECT_LT((pointPosition(model, n.point, coarse.q) - pointPosition(model, n.point, fine.q)).norm(), 1e-8) << n.name;
  EXPECT_NEAR(actuationForce(model, coarse, 0), actuationForce(model, fine, 0), 1e-6);
  EXPECT_LT(solver.forceResidual(fine), 1e-6);
}

TEST(Statics, MechanismIsReportedNotHidden)
{
  // a mass on a frictionless rail (held in y and z), pushed along the rail: no equilibrium exists.
  // (Unloaded, a loose structure is in a neutral equilibrium wherever it is: that is accepted, as for the
  // unstressed tower at its start; slack cables that a load makes taut are found by the damped Newton.)
  Model model;
  model.name = "rail";
  model.bodies.push_back(makePointMass("M", 1.0));
  finalizeModel(model);
  Constraint rail = pointConstraint("rail", PointRef{ 0, Vec3::Zero() }, PointRef{ -1, Vec3::Zero() });
  rail.directions = { Vec3::UnitY(), Vec3::UnitZ() };
  rail.offsets = { 0.0, 0.0 };
  model.constraints.push_back(rail);
  model.loads.push_back(PointLoad{ "push", PointRef{ 0, Vec3::Zero() }, Vec3(10.0, 0.0, 0.0) });
  finalizeModel(model);
  model.q0 = Eigen::Vector3d::Zero();
  StaticSolver solver(model, model.solver);
  State s = initialState(model);
  const Summary r = solver.solve(s, s.u);
  EXPECT_EQ(r.status, SolveStatus::kSingular);
  EXPECT_NE(r.message.find("mechanism"), std::string::npos) << r.message;
  EXPECT_TRUE(s.q.allFinite());
}

// ---------------------------------------------------------------------------------------------------
// the quadruplex with strut contact (paper Sec. 6.1, Fig. 10-11)

namespace
{
struct ContactPath
{
  std::vector<double> v, force, gap;
  std::vector<int> contacts;
  double onset = -1.0;  // first v with a contact
};

ContactPath contactPath(double radius, double max_v, int steps, bool contact = true)
{
  const Model model = quadruplex({ { "struts.radius", std::to_string(radius) },
                                   { "contact.enabled", contact ? "true" : "false" },
                                   { "analysis.max_actuation", std::to_string(max_v) },
                                   { "analysis.steps", std::to_string(steps) } });
  ContactPath p;
  const RunResult r = runAnalysis(model,
                                  [&](const State& s)
                                  {
                                    const int n = static_cast<int>(activeContacts(model, s).size());
                                    if (n > 0 && p.onset < 0.0)
                                      p.onset = s.u[0].value;
                                    p.v.push_back(s.u[0].value);
                                    p.force.push_back(actuationForce(model, s, 0));
                                    p.gap.push_back(minimumGap(model, s.q));
                                    p.contacts.push_back(n);
                                  });
  EXPECT_TRUE(r.summary.ok()) << r.summary.message;
  return p;
}
}  // namespace

TEST(QuadruplexContact, OnsetComesLaterForThinnerStrutsAndStiffensThePath)
{
  // 1 mm load steps to v = 0.3 m, Rs = 4, 6, 8 cm
  const ContactPath free = contactPath(0.06, 0.3, 300, false);
  double previous_onset = 1.0;
  for (double radius : { 0.04, 0.06, 0.08 })
  {
    const ContactPath p = contactPath(radius, 0.3, 300);
    ASSERT_GT(p.onset, 0.0) << radius;
    // the onset is where the no-contact path first overlaps, within a load step
    const ContactPath ghost = contactPath(radius, 0.3, 300, false);
    size_t first_overlap = 0;
    while (first_overlap < ghost.gap.size() && ghost.gap[first_overlap] >= 0.0)
      ++first_overlap;
    EXPECT_NEAR(p.onset, ghost.v[first_overlap], 1.5e-3) << radius;
    EXPECT_LT(p.onset, previous_onset) << "thicker struts touch earlier";
    previous_onset = p.onset;
    for (size_t i = 0; i < p.v.size(); ++i)
    {
      // before contact the path is the no-contact one; 0.1 m after onset the force is far above it
      if (p.v[i] < p.onset - 1e-9)
      {
        EXPECT_NEAR(p.force[i], free.force[i], 1e-6 * (1.0 + std::abs(free.force[i]))) << radius << " v " << p.v[i];
      }
      if (p.v[i] > p.onset + 0.1)
      {
        EXPECT_GT(p.force[i], 5.0 * free.force[i]) << radius << " v " << p.v[i];
      }
      // Hertz keeps the overlap a tiny fraction of the radius (steel: tens of micrometres)
      EXPECT_GT(p.gap[i], -0.005 * radius) << radius << " v " << p.v[i];
    }
  }
}

TEST(Statics, EquilibriumFromAFoldedDynamicState)
{
  // the tower folded dynamically (0.5 m/s, contact with friction) to a pull of 1.7 m and stopped there
  // mid-motion: statics finds the equilibrium at that actuation from the moving state (its struts spun
  // about their axes by friction), the one the quasi-static fold reaches
  const std::string path = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/tower.yaml";
  const Model model = loadScene(path, { { "analysis.type", "dynamic" },
                                        { "analysis.max_actuation", "1.7" },
                                        { "analysis.duration", "3.6" },
                                        { "actuation.speed", "0.5" } });
  const RunResult run = runAnalysis(model, [](const State&) {});
  ASSERT_TRUE(run.summary.ok()) << run.summary.message;
  const Model statics = loadScene(path, { { "analysis.max_actuation", "1.7" }, { "analysis.steps", "340" } });
  const RunResult fold = runAnalysis(statics, [](const State&) {});
  ASSERT_TRUE(fold.summary.ok()) << fold.summary.message;

  State start = run.final_state;
  ASSERT_GT(start.qd.lpNorm<Eigen::Infinity>(), 1e-3);  // moving
  StaticSolver solver(statics, statics.solver);
  const Summary eq = solver.relax(start, start.u);
  ASSERT_TRUE(eq.ok()) << eq.message;
  EXPECT_EQ(start.qd.lpNorm<Eigen::Infinity>(), 0.0);
  EXPECT_LT(solver.forceResidual(start), 1e-3);
  std::cerr << "[ measured ] tower at pull 1.7 m: dynamic fold height " << structureHeight(model, run.final_state.q)
            << " m, relaxed " << structureHeight(model, start.q) << " m, quasi-static fold "
            << structureHeight(model, fold.final_state.q) << " m\n";
  EXPECT_NEAR(structureHeight(model, start.q), structureHeight(model, fold.final_state.q), 1e-6);
  for (const Node& n : model.nodes)
    EXPECT_LT((pointPosition(model, n.point, start.q) - pointPosition(model, n.point, fold.final_state.q)).norm(), 1e-5)
        << n.name;
}

TEST(Statics, RelaxationFindsAnEquilibriumWhereNewtonFails)
{
  // the tower folded quasi-statically to a pull of 0.8 m (struts in contact), every body then thrown up to 5 cm off
  // (twelve throws): where Newton's equilibrium lies beyond struts it would pass through each other (or Newton fails),
  // dynamic relaxation brings the tower to rest in an equilibrium. Which one is the throw's basin: the fold's own, or
  // another 0.2-0.4 m from it with the struts resting on each other otherwise; a throw near the basins' boundary goes
  // either way with the processor's rounding, so each relaxed state is checked as an equilibrium (Newton from it stays
  // put), not as a particular one. (Cores of 1 um: thrown into each other, struts of the real 12.5 mm cores are
  // pushed apart by them.)
  const std::string path = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/tower.yaml";
  const Model model = loadScene(
      path, { { "analysis.max_actuation", "0.8" }, { "analysis.steps", "160" }, { "struts.core.radius", "0.000001" } });
  const RunResult fold = runAnalysis(model, [](const State&) {});
  ASSERT_TRUE(fold.summary.ok()) << fold.summary.message;
  const auto thrown = [&](double amplitude, unsigned seed)
  {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> push(-amplitude, amplitude);
    State s = fold.final_state;
    s.natural = NaturalState();  // (a caller's poses)
    for (const Body& b : model.bodies)
      for (int k = 0; k < 3; ++k)
        s.q(b.offset + k) += push(rng);
    return s;
  };
  const auto farthest = [&](const State& a, const State& b)
  {
    double most = 0.0;
    for (const Node& n : model.nodes)
      most = std::max(most, (pointPosition(model, n.point, a.q) - pointPosition(model, n.point, b.q)).norm());
    return most;
  };
  StaticSolver solver(model, model.solver);
  int relaxed = 0, at_fold = 0;
  for (unsigned seed = 1; seed <= 12; ++seed)
  {
    State s = thrown(0.05, seed);
    State plain = s;
    const Summary newton = solver.solve(plain, s.u);
    if (newton.ok())
      continue;  // (Newton's own equilibrium, reached without passing struts through each other)
    ++relaxed;
    const Summary eq = solver.relax(s, s.u);
    ASSERT_TRUE(eq.ok()) << "throw " << seed << ": " << eq.message;
    ASSERT_EQ(eq.warnings.size(), 1u);
    EXPECT_NE(eq.warnings[0].find("dynamic relaxation"), std::string::npos) << eq.warnings[0];
    EXPECT_EQ(s.qd.lpNorm<Eigen::Infinity>(), 0.0);
    EXPECT_LT(solver.forceResidual(s), 1e-3) << "throw " << seed;
    // an equilibrium: Newton from it converges where it is
    State again = s;
    const Summary held = solver.solve(again, s.u);
    EXPECT_TRUE(held.ok()) << "throw " << seed << ": " << held.message;
    EXPECT_LT(farthest(again, s), 1e-8) << "throw " << seed;
    const double from_fold = farthest(s, fold.final_state);
    at_fold += from_fold < 1e-5;
    std::cerr << "[ measured ] throw " << seed << ": Newton " << newton.message.substr(0, 60) << "...; "
              << eq.warnings[0] << "; the farthest node " << from_fold << " m from the fold's equilibrium\n";
  }
  std::cerr << "[ measured ] " << relaxed << " of 12 throws relaxed, " << at_fold
            << " of them to the fold's equilibrium\n";
  EXPECT_GT(relaxed, 0) << "no throw left Newton without an equilibrium: the test checks nothing";
}

TEST(Statics, RelaxationThatFindsNothingSaysSo)
{
  // thrown 20 cm off, the tower does not settle within 300 relaxation steps, nor within 50 when its caller
  // stops it: a status and a message, and the state left as it was (cores of 0.1 mm, as above)
  const std::string path = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/tower.yaml";
  const Model model = loadScene(
      path, { { "analysis.max_actuation", "0.8" }, { "analysis.steps", "160" }, { "struts.core.radius", "0.000001" } });
  const RunResult fold = runAnalysis(model, [](const State&) {});
  ASSERT_TRUE(fold.summary.ok()) << fold.summary.message;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> push(-0.2, 0.2);
  State s = fold.final_state;
  for (const Body& b : model.bodies)
    for (int k = 0; k < 3; ++k)
      s.q(b.offset + k) += push(rng);
  const State before = s;
  StaticSolver solver(model, model.solver);
  const Summary eq = solver.relax(s, s.u, 300);
  EXPECT_FALSE(eq.ok());
  EXPECT_NE(eq.message.find("300 steps of dynamic relaxation"), std::string::npos) << eq.message;
  EXPECT_EQ(s.q, before.q);
  // stopped by its caller after 50 steps (a planner's deadline): the same, sooner
  int polls = 0;
  const Summary stopped = solver.relax(s, s.u, 300, [&polls] { return ++polls > 50; });
  EXPECT_FALSE(stopped.ok());
  EXPECT_EQ(polls, 51);
  EXPECT_NE(stopped.message.find("50 steps of dynamic relaxation ("), std::string::npos) << stopped.message;
  EXPECT_NE(stopped.message.find("stopped after 50 steps"), std::string::npos) << stopped.message;
  EXPECT_EQ(s.q, before.q);
}

namespace
{
/// The snap-through tripod (test/scenes/snap_tripod.yaml): rows of (load factor, apex height).
struct TripodRun
{
  RunResult result;
  std::vector<std::pair<double, double>> rows;
};

TripodRun runTripod(bool arc_length, std::vector<Override> overrides = {})
{
  overrides.push_back({ "analysis.arc_length", arc_length ? "true" : "false" });
  const Model model = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/test/scenes/snap_tripod.yaml", overrides);
  TripodRun run;
  run.result = runAnalysis(model, [&](const State& s)
                           { run.rows.emplace_back(loadFactor(model, s), structureHeight(model, s.q)); });
  return run;
}

/// The load (N, downwards) that holds the apex at height z: P = 3 k z (L0 / L - 1).
double tripodLoad(double z)
{
  const double k = 1000.0, a = 1.0, l0 = std::sqrt(1.0 + 0.2 * 0.2);
  return 3.0 * k * z * (l0 / std::hypot(a, z) - 1.0);
}

/// The apex's vertical stiffness at height z, -dP/dz = 3 k (z^2 L0 / L^3 - (L0 / L - 1)): zero at the limit
/// points, where the load is largest.
double tripodVerticalStiffness(double z)
{
  const double k = 1000.0, a = 1.0, l0 = std::sqrt(1.0 + 0.2 * 0.2), l = std::hypot(a, z);
  return 3.0 * k * (z * z * l0 / (l * l * l) - (l0 / l - 1.0));
}

/// The height in [lo, hi] where the tripod holds the load p (bisection; P monotonic there).
double tripodHeight(double p, double lo, double hi)
{
  const double sign = tripodLoad(hi) > tripodLoad(lo) ? 1.0 : -1.0;
  for (int i = 0; i < 200; ++i)
  {
    const double mid = 0.5 * (lo + hi);
    (sign * (tripodLoad(mid) - p) > 0.0 ? hi : lo) = mid;
  }
  return 0.5 * (lo + hi);
}
}  // namespace

TEST(CriticalPoints, CarryTheReducedStiffnessOnBothSidesOnItsClosedForm)
{
  // the tripod's arc-length path passes two limit points; on each side of each, the reduced stiffness's
  // eigenvalue nearest zero is the apex's vertical stiffness -dP/dz at the bracketing equilibrium (the
  // lateral stiffness is about 1500 N/m there), and the count of negative eigenvalues goes 0 -> 1 over the
  // first (the rising branch turns unstable) and 1 -> 0 over the mirror one
  const Model model = loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/test/scenes/snap_tripod.yaml");
  StaticSolver solver(model, model.solver);
  solver.setLoadPath(0.0, 1.0);
  solver.setArcLength(true);
  State s = initialState(model);
  ASSERT_TRUE(solver.followPath(s, {}, 40, {}).ok());
  const std::vector<CriticalPoint>& points = solver.criticalPoints();
  ASSERT_EQ(points.size(), 2u);
  const double z_star = std::sqrt(std::pow(std::sqrt(1.04), 2.0 / 3.0) - 1.0);
  // (z range of the equilibrium before, of the one after) for each point, from the path's shape
  const std::pair<double, double> before[2] = { { z_star, 0.2 }, { -z_star, 0.0 } };
  const std::pair<double, double> after[2] = { { 0.0, z_star }, { -0.4, -z_star } };
  for (size_t i = 0; i < 2; ++i)
  {
    const CriticalPoint& c = points[i];
    SCOPED_TRACE(i);
    EXPECT_EQ(c.kind, "limit_point");
    EXPECT_EQ(c.negative_before, i == 0 ? 0 : 1);
    EXPECT_EQ(c.negative_after, i == 0 ? 1 : 0);
    const double zb = tripodHeight(10.0 * c.previous_parameter, before[i].first, before[i].second);
    const double za = tripodHeight(10.0 * c.parameter, after[i].first, after[i].second);
    std::cerr << "[ measured ] limit point " << i << ": eigenvalue " << c.eigenvalue_before << " (closed form "
              << tripodVerticalStiffness(zb) << ") -> " << c.eigenvalue_after << " (" << tripodVerticalStiffness(za)
              << ") N/m\n";
    EXPECT_NEAR(c.eigenvalue_before, tripodVerticalStiffness(zb), 1e-3);
    EXPECT_NEAR(c.eigenvalue_after, tripodVerticalStiffness(za), 1e-3);
    EXPECT_GT(c.eigenvalue_before * (i == 0 ? 1.0 : -1.0), 0.0);
    EXPECT_LT(c.eigenvalue_after * (i == 0 ? 1.0 : -1.0), 0.0);
  }
}

TEST(ArcLength, PassesTheLimitPointsOfASnapThroughOnItsClosedForm)
{
  // the load factor stepped: the path stops at the limit point (0.45287: P* = 4.5287 N of the 10 N load),
  // never "converged" past it
  const TripodRun stepped = runTripod(false);
  EXPECT_FALSE(stepped.result.summary.ok());
  ASSERT_FALSE(stepped.rows.empty());
  EXPECT_LT(stepped.rows.back().first, 0.4529);
  EXPECT_GT(stepped.rows.back().first, 0.42);

  // arc length: over the first limit point (0.45287, z* = 0.11471 m), down through the flat state, the
  // mirror limit point (-0.45287) and on to the full load with the apex below the ground
  const TripodRun arc = runTripod(true);
  ASSERT_TRUE(arc.result.summary.ok()) << arc.result.summary.message;
  const double z_star = std::sqrt(std::pow(std::sqrt(1.04), 2.0 / 3.0) - 1.0);
  const double p_star = tripodLoad(z_star);
  EXPECT_NEAR(p_star, 4.5287211, 1e-6);
  double highest = -1.0, lowest = 1.0;
  for (const auto& [f, z] : arc.rows)
  {
    EXPECT_NEAR(10.0 * f, tripodLoad(z), 1e-6) << "load factor " << f << ", height " << z;
    if (z > 0.0)
      highest = std::max(highest, f);  // on the rising branch
    lowest = std::min(lowest, f);
  }
  EXPECT_EQ(arc.rows.back().first, 1.0);
  EXPECT_LT(arc.rows.back().second, -0.2);  // past the inverted, unstressed state
  // the extreme load factors reached are the limit points, to within a step's curvature
  EXPECT_NEAR(highest, p_star / 10.0, 2e-3);
  EXPECT_NEAR(lowest, -p_star / 10.0, 2e-3);
  ASSERT_EQ(arc.result.summary.warnings.size(), 2u);
  for (const std::string& w : arc.result.summary.warnings)
    EXPECT_NE(w.find("limit_point"), std::string::npos) << w;
}

TEST(BranchJumpGuard, RefusesTheSnapToTheInvertedBranch)
{
  // load steps of 0.2 with three cuts: the increment from 0.4 towards 0.6 passes the limit point (0.45287),
  // and Newton converges on the inverted branch 0.32 m away (the apex below the ground). The guard refuses
  // it at every cut: status branch_jump, the path stopped on its branch, never "converged"
  const TripodRun run = runTripod(false, { { "analysis.steps", "5" }, { "solver.max_step_cuts", "3" } });
  EXPECT_EQ(run.result.summary.status, SolveStatus::kBranchJump) << run.result.summary.message;
  EXPECT_NE(run.result.summary.message.find("jump to another branch"), std::string::npos);
  ASSERT_FALSE(run.rows.empty());
  for (const auto& [f, z] : run.rows)
  {
    EXPECT_GT(z, 0.1);  // on the rising branch only
    EXPECT_NEAR(10.0 * f, tripodLoad(z), 1e-6);
  }
  EXPECT_NEAR(run.rows.back().first, 0.4, 1e-12);
}

TEST(Statics, NewtonFarFromConvergenceHandsOverEarly)
{
  // the first part of the tower's fold in increments of 0.02 m, each from the last equilibrium (as a planner
  // extends its tree), and in 140 steps: the barely stressed tower is nearly a mechanism, the corrector's and
  // plain Newton's iterates are thrown metres away, and the damped Newton finds the equilibria. Newton stops
  // once two of its increments exceed the structure (its nodes' bounding box; 2 for quaternions), and the
  // corrector once Newton's own increments grew twice, instead of wandering through all their iterations,
  // each a factorization: measured before those exits, 391 and 1362 factorizations, and the same equilibria.
  // (The two paths end 1-6 mm apart: this barely stressed tower has equilibria that close.)
  const std::string path = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/tower.yaml";
  const Model model = loadScene(path);
  const std::vector<double> direction = { 0.015701794729357385, 0.019205326546770034, 0.017895051304021577, 0.02 };
  const auto pulled = [&](double k)
  {
    ActuationValues u = initialState(model).u;
    for (size_t i = 0; i < direction.size(); ++i)
      u[i].value = k * direction[i];
    return u;
  };
  StaticSolver solver(model, model.solver);
  State s = initialState(model);
  const int increments = 7;
  for (int k = 1; k <= increments; ++k)
    ASSERT_TRUE(solver.followPath(s, pulled(k), 1, {}).ok()) << "increment " << k;
  const long factorizations = solver.timings().factorizations;
  StaticSolver fine_solver(model, model.solver);
  State fine = initialState(model);
  ASSERT_TRUE(fine_solver.followPath(fine, pulled(increments), 20 * increments, {}).ok());
  std::cerr << "[ measured ] " << factorizations << " factorizations in " << increments << " increments ("
            << fine_solver.timings().factorizations << " on the fine path of " << 20 * increments << ")\n";
  EXPECT_LE(factorizations, 300);
  EXPECT_LE(fine_solver.timings().factorizations, 1000);
  // equilibria within the damped Newton's acceptance: a force residual of the order of the tolerance times
  // the stiffest element
  double k_max = 0.0;
  for (const Cable& c : model.cables)
    k_max = std::max(k_max, c.stiffness);
  for (const auto& [solved, state] : { std::make_pair(&solver, &s), std::make_pair(&fine_solver, &fine) })
    EXPECT_LT(solved->forceResidual(*state), 10.0 * model.solver.newton_tolerance * k_max);
}

TEST(QuadruplexContact, OnTheLinearLawTheActuationWorkIsTheStoredEnergy)
{
  // the static path into contact on the linear law (k = 1 MN/m): every contact's force is k zeta, and the
  // actuator's work along the path (trapezoid over 1 mm steps) is the rise of the potential energy, cables'
  // and contacts' k zeta^2 / 2 (a contact energy inconsistent with its force would break the balance)
  const Model model = quadruplex({ { "contact.enabled", "true" },
                                   { "contact.law", "linear" },
                                   { "contact.stiffness", "1e6" },
                                   { "analysis.max_actuation", "0.4" },
                                   { "analysis.steps", "400" } });
  const System sys(model);
  std::vector<double> v, force, energy;
  double contact_energy = 0.0;
  const RunResult r = runAnalysis(model,
                                  [&](const State& s)
                                  {
                                    v.push_back(s.u[0].value);
                                    force.push_back(actuationForce(model, s, 0));
                                    energy.push_back(sys.potentialEnergy(s.q, s.u));
                                    double e = 0.0;
                                    for (const ContactPairState& c : activeContacts(model, s))
                                    {
                                      EXPECT_NEAR(c.normal_force, 1e6 * c.penetration, 1e-9 * c.normal_force);
                                      e += contactElasticEnergy(model, c);
                                    }
                                    contact_energy = e;
                                  });
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  ASSERT_GT(contact_energy, 1.0);  // the struts press each other at the end
  double work = 0.0;
  for (size_t i = 1; i < v.size(); ++i)
    work += 0.5 * (force[i] + force[i - 1]) * (v[i] - v[i - 1]);
  const double rise = energy.back() - energy.front();
  std::printf("[ measured ] actuation work %.6f J, potential energy rise %.6f J (contact %.6f J)\n", work, rise,
              contact_energy);
  EXPECT_NEAR(work, rise, 5e-4 * std::abs(rise));
}
