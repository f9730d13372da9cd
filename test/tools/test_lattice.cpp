// The quadruplex-cell lattices of `tensegrity_bench lattice` (src/tools/lattice.cpp): they load with the
// expected counts, check the intended strut pairs, start with every constraint satisfied and in equilibrium,
// and a small one runs dynamically; the command refuses bad arguments by name.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <set>
#include <tuple>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "command.h"

#include "active_tensegrity/core/model/actuation_schedule.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/oracle/mechanics.h"
#include "cli.h"
#include "lattice.h"

namespace at = active_tensegrity::core;
namespace tl = active_tensegrity::tools;

namespace
{
at::Model lattice(int nx, int ny, tl::LatticePairs pairs = tl::LatticePairs::kAuto)
{
  tl::LatticeOptions o;
  o.nx = nx;
  o.ny = ny;
  o.pairs = pairs;
  return at::loadSceneFromString(tl::quadruplexLatticeYaml(o), "lattice");
}

// the lattice's dynamic fold (bracings pulled in) over `duration` seconds
at::Model folding(int nx, int ny, double duration)
{
  tl::LatticeOptions o;
  o.nx = nx;
  o.ny = ny;
  o.duration = duration;
  return at::loadSceneFromString(tl::quadruplexLatticeYaml(o), "lattice");
}

// both end points of every strut at q0 (world)
std::vector<std::pair<at::Vec3, at::Vec3>> strutEnds(const at::Model& m)
{
  std::vector<std::pair<at::Vec3, at::Vec3>> ends;
  for (const at::Body& b : m.bodies)
  {
    const at::Vec3 r = m.q0.segment<3>(b.offset);
    const at::Vec3 axis = at::rotationMatrix(m.q0.segment<4>(b.offset + 3)).col(2);
    ends.push_back({ r - 0.5 * b.length * axis, r + 0.5 * b.length * axis });
  }
  return ends;
}

// pairs of struts that share no end point, found from the geometry (not from the generator's names)
std::set<std::pair<int, int>> pairsSharingNoNode(const at::Model& m)
{
  const auto ends = strutEnds(m);
  const auto same = [](const at::Vec3& a, const at::Vec3& b) { return (a - b).norm() < 1e-9; };
  std::set<std::pair<int, int>> out;
  for (size_t i = 0; i < ends.size(); ++i)
    for (size_t j = i + 1; j < ends.size(); ++j)
    {
      const auto& [a0, a1] = ends[i];
      const auto& [b0, b1] = ends[j];
      if (!same(a0, b0) && !same(a0, b1) && !same(a1, b0) && !same(a1, b1))
        out.insert({ static_cast<int>(i), static_cast<int>(j) });
    }
  return out;
}

std::set<std::pair<int, int>> checked(const at::Model& m)
{
  std::set<std::pair<int, int>> out;
  for (const at::StrutPair& p : m.checkedPairList())
    out.insert({ std::min(p.body_a, p.body_b), std::max(p.body_a, p.body_b) });
  return out;
}

// cell (i, j) of a strut from its name S<i>_<j>_<k>
std::pair<int, int> cellOf(const std::string& name)
{
  int i = -1, j = -1, k = -1;
  EXPECT_EQ(std::sscanf(name.c_str(), "S%d_%d_%d", &i, &j, &k), 3) << name;
  return { i, j };
}
}  // namespace

TEST(Lattice, LoadsWithFourStrutsPerCellAndTheExpectedCables)
{
  for (const auto& [nx, ny] : { std::pair{ 1, 1 }, std::pair{ 1, 2 }, std::pair{ 2, 3 } })
  {
    const at::Model m = lattice(nx, ny);
    EXPECT_EQ(m.bodies.size(), static_cast<size_t>(4 * nx * ny)) << nx << "x" << ny;
    for (const at::Body& b : m.bodies)
      EXPECT_EQ(b.kind, at::BodyKind::kStrut);
    // upper and bracing: 8 per cell; ties between neighbouring cells
    const size_t ties = (nx - 1) * ny + nx * (ny - 1);
    EXPECT_EQ(m.cables.size(), static_cast<size_t>(8 * nx * ny) + ties) << nx << "x" << ny;
    ASSERT_EQ(m.actuators.size(), 1u);
    EXPECT_EQ(m.actuators[0].cables.size(), static_cast<size_t>(4 * nx * ny));  // every bracing
    EXPECT_EQ(m.analysis.type, at::AnalysisType::kDynamic);
    EXPECT_TRUE(m.contact.enabled);
  }
}

TEST(Lattice, NeighbouringCellsShareTheirGroundCorners)
{
  // 2 x 2 cells: 9 ground corners; the middle one carries a strut of each cell (four struts, joined)
  const at::Model m = lattice(2, 2);
  const auto ends = strutEnds(m);
  int at_middle = 0;
  for (const auto& [foot, top] : ends)
  {
    EXPECT_NEAR(foot.z(), 0.0, 1e-12);
    EXPECT_NEAR(top.z(), 0.5, 1e-12);
    at_middle += (foot - at::Vec3(1.0, 1.0, 0.0)).norm() < 1e-9 ? 1 : 0;
  }
  EXPECT_EQ(at_middle, 4);
}

TEST(Lattice, AllListsEveryPairOfStrutsThatShareNoNodeOnce)
{
  for (const auto& [nx, ny] : { std::pair{ 1, 1 }, std::pair{ 2, 2 }, std::pair{ 3, 3 } })
  {
    const at::Model m = lattice(nx, ny, tl::LatticePairs::kAll);
    const auto expected = pairsSharingNoNode(m);
    EXPECT_EQ(checked(m), expected) << nx << "x" << ny;
    EXPECT_EQ(m.checkedPairList().size(), expected.size()) << "a pair listed twice";
  }
  EXPECT_EQ(lattice(1, 1, tl::LatticePairs::kAll).checkedPairList().size(), 6u);  // one quadruplex: all six pairs
}

TEST(Lattice, AutoChecksEveryPairOfStrutsThatShareNoNode)
{
  for (const auto& [nx, ny] : { std::pair{ 1, 1 }, std::pair{ 1, 3 }, std::pair{ 3, 3 } })
  {
    const at::Model m = lattice(nx, ny, tl::LatticePairs::kAuto);
    const auto expected = pairsSharingNoNode(m);
    // exactly those: at a corner where four struts meet, the pairs the loader did not join directly
    // share the node too (they touch there by construction and must not be checked)
    EXPECT_EQ(checked(m), expected) << nx << "x" << ny;
  }
}

TEST(Lattice, NearListsOnlyPairsOfTheSameOrAdjacentCells)
{
  const at::Model m = lattice(3, 3, tl::LatticePairs::kNear);
  const auto all = pairsSharingNoNode(m);
  std::set<std::pair<int, int>> expected;
  for (const auto& [a, b] : all)
  {
    const auto [ia, ja] = cellOf(m.bodies[a].name);
    const auto [ib, jb] = cellOf(m.bodies[b].name);
    if (std::abs(ia - ib) <= 1 && std::abs(ja - jb) <= 1)
      expected.insert({ a, b });
  }
  EXPECT_EQ(checked(m), expected);
  EXPECT_EQ(m.checkedPairList().size(), expected.size()) << "a pair listed twice";
  EXPECT_LT(expected.size(), all.size());  // on 3 x 3 some cells are not adjacent
  // a single cell: the same six pairs as auto
  EXPECT_EQ(lattice(1, 1, tl::LatticePairs::kNear).checkedPairList().size(), 6u);
}

TEST(Lattice, StartsWithEveryConstraintSatisfiedAndInEquilibrium)
{
  for (const auto& [nx, ny] : { std::pair{ 1, 1 }, std::pair{ 2, 3 } })
  {
    at::Model m = lattice(nx, ny);
    const at::State s = at::initialState(m);
    const at::System sys(m);
    Eigen::VectorXd phi;
    sys.constraintValue(s.q, s.u, phi);
    ASSERT_EQ(phi.size(), m.n_lambda);
    EXPECT_LT(phi.lpNorm<Eigen::Infinity>(), 1e-12) << nx << "x" << ny;
    // the prestress balances: the best multipliers leave no force residual (cables carry ~280 N)
    m.analysis.type = at::AnalysisType::kStatic;
    at::StaticSolver statics(m, m.solver);
    EXPECT_LT(statics.forceResidual(s), 1e-6) << nx << "x" << ny;
  }
  // and the check can fail: with less prestress in the upper cables the top nodes are pulled outward
  at::Model off = at::loadSceneFromString(tl::quadruplexLatticeYaml({}), "lattice",
                                          { at::parseOverride("cables.upper.prestress=100") });
  off.analysis.type = at::AnalysisType::kStatic;
  at::StaticSolver statics_off(off, off.solver);
  EXPECT_GT(statics_off.forceResidual(at::initialState(off)), 10.0);
}

TEST(Lattice, SmallLatticeRunsDynamicStepsToConvergence)
{
  tl::LatticeOptions o;
  o.nx = 1;
  o.ny = 2;
  o.duration = 0.02;  // 20 steps of 1 ms
  const at::Model m = at::loadSceneFromString(tl::quadruplexLatticeYaml(o), "lattice");
  bool finite = true;
  const at::RunResult r = at::runAnalysis(
      m, [](const at::State&) {}, {},
      [&finite](const at::State& s)
      { finite = finite && s.q.allFinite() && s.qd.allFinite() && s.natural.lambda.allFinite(); });
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  EXPECT_TRUE(finite);
  EXPECT_GE(r.solver_steps, 20);
  EXPECT_NEAR(r.final_state.t, 0.02, 1e-12);
  // the bracings are being pulled in (in the 50 ms start blend: less than speed * t) and the tops come down
  EXPECT_GT(r.final_state.u[0].value, 0.0);
  EXPECT_LT(r.final_state.u[0].value, 0.04);
  EXPECT_LT(at::structureHeight(m, r.final_state.q), 0.5);
}

TEST(Lattice, StaticPivotsServeModifiedNewtonAsExactFactorsWould)
{
  // 48 struts, a sparse Newton matrix: modified Newton's matrices are factorized with static pivots (the constraint rows
  // shifted), full Newton's refined to round-off. Each passes its check (A 1 solved near 1), every step converges in
  // about as many iterations as with exact factors, and the fold's nodes end where full Newton at every iteration
  // puts them, to within the Newton tolerance's reach (through contact)
  at::Model m = folding(4, 3, 0.3);
  const at::NaturalModel nm = at::buildNaturalModel(m);
  ASSERT_GT(nm.coordinates + static_cast<int>(nm.struts.size() + nm.rows.size()), 160) << "a sparse Newton matrix";
  const auto fold = [&](bool reuse)
  {
    at::SolverOptions options = m.solver;
    options.reuse_jacobian = reuse;
    at::NaturalSolver solver(nm, options);
    const at::ActuationLaw law = [&m](double t) { return at::scheduledActuation(m, t); };
    at::NaturalState s = at::naturalInitialState(nm);
    EXPECT_TRUE(solver.initialize(s, law).ok());
    size_t touching = 0;
    const at::Summary r =
        solver.advanceTo(s, m.analysis.duration, law,
                         [&touching](const at::NaturalState& e) { touching = std::max(touching, e.touching.size()); });
    EXPECT_TRUE(r.ok()) << r.message;
    return std::tuple{ s, solver.stats(), touching };
  };
  const auto [modified, modified_stats, touching] = fold(true);
  const auto [full, full_stats, full_touching] = fold(false);
  (void)full_touching;
  std::printf("[ measured ] static pivots: modified Newton %ld of %ld factorizations, %.2f iterations per step; full "
              "Newton %ld of %ld, %.2f; nodes %.1e m apart\n",
              modified_stats.static_pivots, modified_stats.factorizations,
              static_cast<double>(modified_stats.iterations) / modified_stats.steps, full_stats.static_pivots,
              full_stats.factorizations, static_cast<double>(full_stats.iterations) / full_stats.steps,
              (modified.x - full.x).head(nm.positions).lpNorm<Eigen::Infinity>());
  EXPECT_GT(touching, 4u) << "the fold brings struts into contact";
  EXPECT_GT(modified_stats.static_pivots, 0);
  EXPECT_EQ(modified_stats.static_pivot_refusals, 0);
  EXPECT_EQ(full_stats.static_pivot_refusals, 0);
  EXPECT_LT(static_cast<double>(modified_stats.iterations) / modified_stats.steps, 3.0);
  EXPECT_LT((modified.x - full.x).head(nm.positions).lpNorm<Eigen::Infinity>(), 1e-5);
}

TEST(Lattice, NaturalCoordinatesKeepEveryTouchingPairInTheirList)
{
  // 24 struts (276 pairs: listed through the broad phase) folding into contact: at every step's end the pairs the
  // natural coordinates' solver remembers as touching are exactly those of every checked pair whose gap is negative
  const at::Model m = folding(3, 2, 0.3);
  ASSERT_GT(m.checkedPairCount(), 64);
  const at::NaturalModel nm = at::buildNaturalModel(m);
  at::NaturalSolver solver(nm, m.solver);
  const at::ActuationLaw law = [&m](double t) { return at::scheduledActuation(m, t); };
  at::NaturalState s = at::naturalInitialState(nm);
  ASSERT_TRUE(solver.initialize(s, law).ok());
  std::vector<int> pairs;
  m.checkedPairList(&pairs);
  int steps = 0, most_touching = 0;
  bool same = true;
  const at::Summary r = solver.advanceTo(
      s, m.analysis.duration, law,
      [&](const at::NaturalState& e)
      {
        const at::ActuationValues u = at::scheduledActuation(m, e.t);
        std::vector<int> brute, kept;
        for (const int slot : pairs)
        {
          const at::NaturalContactSlot c = at::naturalContactSlot(nm, slot);
          if (at::naturalContact(nm, c, at::naturalContactInput(nm, c, e.x, e.v, u), 0.0, nullptr, nullptr, nullptr).gap <
              0.0)
            brute.push_back(slot);
        }
        for (const at::NaturalTouch& t : e.touching)
        {
          kept.push_back(t.slot);
          same = same && t.speed > 0.0;
        }
        same = same && kept == brute;
        most_touching = std::max(most_touching, static_cast<int>(kept.size()));
        ++steps;
      });
  ASSERT_TRUE(r.ok()) << r.message;
  EXPECT_TRUE(same);
  EXPECT_GT(steps, 100);
  EXPECT_GT(most_touching, 4) << "the fold brings struts into contact";
}

TEST(LatticeSizes, LadderComesCloseToTheTargets)
{
  const std::vector<int> targets = { 10, 20, 50, 100, 200, 500 };
  const auto sizes = tl::standardLatticeSizes();
  ASSERT_EQ(sizes.size(), targets.size());
  for (size_t i = 0; i < sizes.size(); ++i)
  {
    EXPECT_LE(sizes[i].nx, sizes[i].ny);
    EXPECT_LE(sizes[i].ny, 2 * sizes[i].nx);
    EXPECT_LE(std::abs(sizes[i].struts() - targets[i]), 0.25 * targets[i]) << targets[i];
  }
  EXPECT_EQ(tl::latticeCellsFor(100).struts(), 100);
  EXPECT_EQ(tl::latticeCellsFor(4).struts(), 4);
}

#ifdef TENSEGRITY_BENCH_PATH
namespace
{
// a shipped scene's path (the tests run from anywhere)
std::string scenePath(const std::string& name)
{
  return std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name;
}

// exit status and output (stdout and stderr) of tensegrity_bench with the arguments
std::pair<int, std::string> bench(const std::string& args)
{
  const active_tensegrity::test::CommandResult r =
      active_tensegrity::test::runCommand(std::string(TENSEGRITY_BENCH_PATH) + " " + args + " 2>&1");
  return { r.code, r.output };
}
}  // namespace

TEST(LatticeCommand, RefusesBadArgumentsByNameAndValue)
{
  for (const auto& [args, text] : { std::pair<std::string, std::string>{ "--pairs far", "'far'" },
                                    { "--struts 10,x", "'x'" },
                                    { "--repeat 0", "--repeat" },
                                    { "--duration -1", "'-1'" },
                                    { "--bogus", "'--bogus'" },
                                    { "--set contact.nope=1", "contact.nope" } })
  {
    const auto [status, out] = bench("lattice " + args);
    EXPECT_EQ(status, 2) << args << ": " << out;
    EXPECT_NE(out.find(text), std::string::npos) << args << ": " << out;
  }
}

// the other subcommands' arguments: refused before anything runs (a mistyped --quick used to start the full
// stress run, minutes long; --repeat 0 and "5x" were taken as 1 and 5)
TEST(BenchCommand, RefusesBadArgumentsByNameAndValue)
{
  for (const auto& [args, text] :
       { std::pair<std::string, std::string>{ "stress --quik", "'--quik'" },
         { "stress --quick --quick", "'--quick'" },
         { "stress --quick 1", "'1'" },
         { "steps config/scenes/prism.yaml --repeat 0", "--repeat: expected a positive integer, got '0'" },
         { "contact-pair --repeat 5x", "'5x'" },
         { "broad-phase --repeat abc", "'abc'" },
         { "broad-phase --bogus", "'--bogus'" },
         { "natural " + scenePath("prism.yaml") + " --dts 0", "'0'" },
         { "natural " + scenePath("prism.yaml") + " --tols 1e-5,x", "'x'" },
         { "natural " + scenePath("prism.yaml") + " --bogus", "'--bogus'" },
         { "natural " + scenePath("prism.yaml") + " --set analysis.type=modal", "dynamic and static analyses" },
         { "natural", "no scene" } })
  {
    const auto [status, out] = bench(args);
    EXPECT_EQ(status, 2) << args << ": " << out;
    EXPECT_NE(out.find(text), std::string::npos) << args << ": " << out;
  }
}

TEST(NaturalCommand, ComparesAStaticPathAtEveryLoadStep)
{
  // the quadruplex's compression in 43 load steps: both formulations' paths, which agree
  const auto [status, out] = bench("natural " + scenePath("quadruplex.yaml") + " --set analysis.steps=43 --repeat 1");
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("body converged (43 equilibria), natural converged (43 equilibria)"), std::string::npos) << out;
  const size_t at = out.find("largest strut-centre difference over the path: ");
  ASSERT_NE(at, std::string::npos) << out;
  const double difference =
      std::stod(out.substr(at + std::string("largest strut-centre difference over the path: ").size()));
  EXPECT_LT(difference, 1e-8) << out;
}

TEST(NaturalCommand, WorkPrecisionRunsTheNaturalSchemesWhenNamed)
{
  // 0.35 s of the linear-law quadruplex (its first touch at 0.29 s): a row per step and tolerance, converged; the
  // natural schemes are not run unless named
  const std::string scene = scenePath("quadruplex_linear_contact.yaml") + " --set analysis.duration=0.35 --ref-dt 1e-4";
  const auto [status, out] = bench("work-precision " + scene +
                                   " --schemes natural_generalized_alpha,adaptive_natural_generalized_alpha --dts "
                                   "1e-3 --tols 1e-5");
  ASSERT_EQ(status, 0) << out;
  for (const char* row : { "natural_generalized_alpha,0.001,0,converged,", "adaptive_natural_generalized_alpha," })
    EXPECT_NE(out.find(row), std::string::npos) << row << "\n" << out;
  const auto [plain_status, plain] = bench("work-precision " + scene + " --schemes generalized_alpha --dts 1e-3");
  ASSERT_EQ(plain_status, 0) << plain;
  EXPECT_EQ(plain.find("natural"), std::string::npos) << plain;
}

TEST(LatticeCommand, PrintsARowPerSizeAndTheExponent)
{
  const auto [status, out] = bench("lattice --struts 4,8 --duration 0.005 --repeat 1 --pairs near");
  ASSERT_EQ(status, 0) << out;
  EXPECT_NE(out.find("converged"), std::string::npos) << out;
  EXPECT_NE(out.find("fitted exponent"), std::string::npos) << out;
}
#endif

TEST(CommandLine, PositiveNumbersAreReadWholeOrRefusedByNameAndValue)
{
  namespace tl = active_tensegrity::tools;
  EXPECT_EQ(tl::parsePositive<int>("--repeat", "3"), 3);
  EXPECT_DOUBLE_EQ(tl::parsePositive<double>("--ref-dt", "2.5e-5"), 2.5e-5);
  EXPECT_EQ(tl::parsePositiveList("--dts", "1e-3,5e-4"), (std::vector<double>{ 1e-3, 5e-4 }));
  for (const char* bad : { "", "x", "1e-3x", "-1", "0", "nan", "inf" })
    EXPECT_THROW(tl::parsePositive<double>("--dts", bad), tl::BadArgument) << bad;
  for (const char* bad : { "3.5", "0", "-2", "2x" })
    EXPECT_THROW(tl::parsePositive<int>("--repeat", bad), tl::BadArgument) << bad;
  EXPECT_THROW(tl::parsePositiveList("--dts", "1e-3,,5e-4"), tl::BadArgument);
  try
  {
    tl::parsePositive<double>("--mujoco-dts", "1e-3x");
    FAIL() << "no exception";
  }
  catch (const tl::BadArgument& e)
  {
    EXPECT_EQ(std::string(e.what()), "--mujoco-dts: expected a positive number, got '1e-3x'");
  }
}

TEST(Lattice, ModifiedNewtonFollowsFullNewtonOnALargeLattice)
{
  // 48 struts (a sparse Newton matrix): modified Newton keeps its factorization across steps, full Newton makes one
  // per iteration. Over 500 steps of 0.2 ms with the bracings pulled in, the two stay within a small multiple of the
  // Newton tolerance of each other.
  at::Model m = folding(3, 4, 0.1);
  ASSERT_GT(m.nq + m.n_lambda, 400);
  m.solver.newton_tolerance = 1e-8;
  const auto run = [&m](bool reuse)
  {
    at::Model copy = m;
    copy.solver.reuse_jacobian = reuse;
    return at::runAnalysis(
        copy, [](const at::State&) {}, {}, [](const at::State&) {});
  };
  const at::RunResult modified = run(true);
  const at::RunResult full = run(false);
  ASSERT_TRUE(modified.summary.ok()) << modified.summary.message;
  ASSERT_TRUE(full.summary.ok()) << full.summary.message;
  ASSERT_EQ(modified.final_state.t, full.final_state.t);
  EXPECT_LT(modified.timings.factorizations, full.timings.factorizations / 10);
  EXPECT_EQ(full.timings.factorizations, full.timings.newton_iterations);
  const double distance = (modified.final_state.q - full.final_state.q).lpNorm<Eigen::Infinity>();
  EXPECT_LT(distance, 1e-6);
  std::printf("[ measured ] 48-strut lattice, 500 steps: modified Newton (%ld factorizations, %ld iterations) against "
              "full Newton (%ld): %.2e\n",
              modified.timings.factorizations, modified.timings.newton_iterations, full.timings.factorizations,
              distance);
}

TEST(Lattice, ModifiedNewtonFollowsFullNewtonThroughContact)
{
  // 8 struts: the bracings fold the lattice into contact from about 0.26 s. Contact amplifies the differences the
  // tolerance allows, down to a floor that no tolerance removes (runs at 1e-12 end about 1e-8 m apart: rounding moves
  // the step a contact begins in), so over 0.4 s each tolerance's distance to full Newton is held to ten tolerances
  // or that floor's band, whichever is larger (measured 2.5e-6, 2.0e-8, 1.3e-8, 1.3e-8 m at 1e-6, 1e-8, 1e-10, 1e-12)
  const at::Model m = folding(1, 2, 0.4);
  int touched = 0;
  const auto run = [&m, &touched](bool reuse, double tolerance)
  {
    at::Model copy = m;
    copy.solver.reuse_jacobian = reuse;
    copy.solver.newton_tolerance = tolerance;
    return at::runAnalysis(
        copy, [](const at::State&) {}, {},
        [&](const at::State& s) { touched = std::max(touched, static_cast<int>(at::activeContacts(m, s).size())); });
  };
  for (double tolerance : { 1e-6, 1e-8, 1e-10, 1e-12 })
  {
    const at::RunResult modified = run(true, tolerance);
    const at::RunResult full = run(false, tolerance);
    ASSERT_TRUE(modified.summary.ok()) << modified.summary.message;
    ASSERT_TRUE(full.summary.ok()) << full.summary.message;
    EXPECT_LT(modified.timings.factorizations, full.timings.factorizations);
    const double distance = (modified.final_state.q - full.final_state.q).lpNorm<Eigen::Infinity>();
    std::printf("[ measured ] 8-strut lattice through contact, tolerance %.0e: %ld factorizations, %ld Newton "
                "iterations (full Newton %ld); distance to full Newton %.2e\n",
                tolerance, modified.timings.factorizations, modified.timings.newton_iterations,
                full.timings.newton_iterations, distance);
    EXPECT_LT(distance, std::max(10.0 * tolerance, 1e-6)) << "tolerance " << tolerance;
  }
  EXPECT_GT(touched, 0);
}

// The numbered pairs of `pairs: auto` are the listed pairs of every two struts sharing no node, in the same slots:
// the fold through contact gives the same bits either way
TEST(Lattice, NumberedPairsFoldAsTheSamePairsListed)
{
  tl::LatticeOptions o;
  o.nx = 1;
  o.ny = 2;
  o.duration = 0.4;
  const at::Model numbered = at::loadSceneFromString(tl::quadruplexLatticeYaml(o), "numbered");
  o.pairs = tl::LatticePairs::kAll;
  const at::Model listed = at::loadSceneFromString(tl::quadruplexLatticeYaml(o), "listed");
  ASSERT_TRUE(numbered.all_strut_pairs);
  ASSERT_FALSE(listed.all_strut_pairs);
  std::vector<int> slots;
  const std::vector<at::StrutPair> pairs = numbered.checkedPairList(&slots);
  ASSERT_EQ(pairs.size(), listed.listed_pairs.size());
  for (bool adaptive : { false, true })
  {
    int touched = 0;
    const auto run = [&](const at::Model& m)
    {
      at::Model copy = m;
      copy.solver.adaptive = adaptive;
      std::vector<std::pair<int, int>> seen;  // bodies of every active contact of every step
      const at::RunResult r = at::runAnalysis(
          copy, [](const at::State&) {}, {},
          [&](const at::State& s)
          {
            for (const at::ContactPairState& c : at::activeContacts(copy, s))
              seen.emplace_back(c.body_a, c.body_b);
          });
      touched = std::max(touched, static_cast<int>(seen.size()));
      return std::make_pair(r, seen);
    };
    const auto [a, seen_a] = run(numbered);
    const auto [b, seen_b] = run(listed);
    ASSERT_TRUE(a.summary.ok()) << a.summary.message;
    ASSERT_TRUE(b.summary.ok()) << b.summary.message;
    EXPECT_GT(touched, 0);
    EXPECT_EQ(seen_a, seen_b) << "adaptive " << adaptive;
    EXPECT_EQ(a.solver_steps, b.solver_steps);
    EXPECT_TRUE(a.final_state.q == b.final_state.q) << "adaptive " << adaptive;
    EXPECT_TRUE(a.final_state.qd == b.final_state.qd) << "adaptive " << adaptive;
  }
}

// 2500 cells, 10 000 struts: every two that share no node checked, none of the 50 million pairs stored; the
// minimum gap through the broad phase is the one between neighbouring cells' struts
TEST(Lattice, TenThousandStrutsLoadWithoutAPairList)
{
  const at::Model m = lattice(50, 50);
  ASSERT_EQ(m.bodies.size(), 10000u);
  EXPECT_TRUE(m.all_strut_pairs);
  EXPECT_TRUE(m.listed_pairs.empty());
  EXPECT_EQ(m.pairSlots(), 10000 * 9999 / 2);
  // struts sharing a node: a cell's four meet pairwise at the top, the ground corners join up to four cells
  long sharing = 0;
  std::map<std::tuple<long, long, long>, int> at_node;
  for (const auto& [foot, top] : strutEnds(m))
    for (const at::Vec3& p : { foot, top })
      ++at_node[{ std::lround(p.x() * 1e6), std::lround(p.y() * 1e6), std::lround(p.z() * 1e6) }];
  for (const auto& [node, count] : at_node)
    sharing += static_cast<long>(count) * (count - 1) / 2;
  EXPECT_EQ(m.checkedPairCount(), 10000L * 9999 / 2 - sharing);
  double near = std::numeric_limits<double>::infinity();
  const at::Model one = lattice(2, 2);  // the same gaps between cells as any two neighbours
  for (int slot = 0; slot < one.pairSlots(); ++slot)
    if (one.isCheckedPair(slot))
      near = std::min(near, at::contactGeometry(one, slot, one.q0).gap);
  EXPECT_NEAR(at::minimumGap(m, m.q0), near, 1e-12);
}

TEST(Lattice, RattlingContactConvergesOnEveryPath)
{
  // 48 struts run on past the fold into the struts' rattling contact, where the touching pairs change at nearly every
  // step. The rattling is chaotic: each processor and build follows its own path, and how often the matrix is rebuilt
  // is that path's (printed); what every path must give is a converged run whose steps need few iterations and whose
  // constraints hold.
  const at::Model m = folding(3, 4, 0.6);
  ASSERT_TRUE(m.solver.reuse_jacobian);
  const at::RunResult r = at::runAnalysis(
      m, [](const at::State&) {}, {}, [](const at::State&) {});
  ASSERT_TRUE(r.summary.ok()) << r.summary.message;
  std::printf("[ measured ] 3x4 lattice, 0.6 s: %ld factorizations, %.2f Newton iterations per step, %d step cuts\n",
              r.timings.factorizations, static_cast<double>(r.summary.iterations) / r.solver_steps,
              r.summary.step_cuts);
  EXPECT_LT(static_cast<double>(r.summary.iterations) / r.solver_steps, 0.5 * m.solver.max_iterations);
  EXPECT_LE(r.summary.step_cuts, r.solver_steps / 20);
  EXPECT_TRUE(r.final_state.q.allFinite());
  Eigen::VectorXd phi;
  at::System(m).constraintValue(r.final_state.q, r.final_state.u, phi);
  EXPECT_LT(phi.lpNorm<Eigen::Infinity>(), 1e-8);
}
