// Structural diagnostics (core/structure_check): the counts of the equilibrium matrix on prisms whose counts
// follow from Maxwell's rule and their self-stress, stability, slack elements, the force residual off an
// equilibrium against its first-order prediction, and the reduced stiffness against finite differences of the
// potential energy along the constraint manifold; and the SVDs (core/svd) the diagnostics share with form finding.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/statics.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/core/linalg/svd.h"
#include "test_models.h"

using namespace active_tensegrity::test;

namespace
{
std::string scenePath(const std::string& name)
{
  return std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name;
}

std::string sceneText(const std::string& name)
{
  std::ifstream in(scenePath(name));
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// The text of a shipped scene with each `from` replaced by `to` (each must occur).
std::string edited(const std::string& name, const std::vector<std::pair<std::string, std::string>>& edits)
{
  std::string text = sceneText(name);
  for (const auto& [from, to] : edits)
  {
    const size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos)
      text.replace(at, from.size(), to);
  }
  return text;
}

/// The equilibrium of a model at actuation `value` (0: the start), as the statics leave it: with its natural
/// coordinates and multipliers, which these checks read.
State equilibrium(const Model& model, double value = 0.0, int steps = 20)
{
  State s = initialState(model);
  StaticSolver solver(model, model.solver);
  EXPECT_TRUE(solver.solve(s, s.u).ok());
  if (value > 0.0)
  {
    ActuationValues end = s.u;
    for (ActuationValue& u : end)
      u.value = value;
    EXPECT_TRUE(solver.followPath(s, end, steps, [](const State&, const Summary&) {}).ok());
  }
  return s;
}

/// The statics' natural coordinates of a model (the free nodes' positions, no spin rates): the rows Phi, their
/// projection, and the potential energy (cables, springs, gravity, loads, static contact) at rest under u.
struct NaturalProbe
{
  NaturalProbe(const Model& model, const ActuationValues& given)
    : nm(buildNaturalModel(model, false))
    , solver(nm, model.solver)
    , u(given)
    , rows(static_cast<int>(nm.struts.size() + nm.rows.size()))
  {
    for (ActuationValue& a : u)
      a.rate = a.accel = 0.0;
  }
  Eigen::VectorXd positions(const State& s) const
  {
    State c = s;
    if (!(c.natural.x.size() == nm.coordinates && carriesNaturalOf(nm, c)))
      naturalFromBody(nm, c);
    return c.natural.x;
  }
  /// x moved back onto Phi = 0 by Gauss-Newton steps of least norm.
  Eigen::VectorXd project(Eigen::VectorXd x)
  {
    for (int it = 0; it < 20; ++it)
    {
      solver.assembleStatic(x, Eigen::VectorXd::Zero(rows), u, true);
      const Eigen::VectorXd phi = solver.staticResidual().tail(rows);
      if (phi.lpNorm<Eigen::Infinity>() < 1e-15)
        break;
      x -= Eigen::MatrixXd(solver.assembledRows()).completeOrthogonalDecomposition().solve(phi);
    }
    return x;
  }
  double potential(const Eigen::VectorXd& x)
  {
    NaturalState st;
    st.x = x;
    st.v = Eigen::VectorXd::Zero(x.size());
    st.lambda = Eigen::VectorXd::Zero(rows);
    solver.staticContacts(x, u, st.contacts);
    const EnergyPoint e = solver.energyAt(st, u);
    return e.elastic + e.gravity;
  }
  /// The body poses of x (centres, axes; no spin).
  Eigen::VectorXd bodyPoses(const Eigen::VectorXd& x) const
  {
    return naturalToBodyCoordinates(nm, x, u);
  }
  NaturalModel nm;
  NaturalSolver solver;
  ActuationValues u;
  int rows;
};

/// d^2 V / ds^2 at s = 0 along the manifold curve s -> project(x + s N v), by central differences of
/// step h (Richardson-extrapolated from h and 2h).
double energyCurvature(NaturalProbe& probe, const Eigen::VectorXd& x, const Eigen::VectorXd& dx, double h)
{
  const auto v = [&](double t) { return probe.potential(probe.project(x + t * dx)); };
  const double v0 = v(0.0);
  const double d1 = (v(h) - 2.0 * v0 + v(-h)) / (h * h);
  const double d2 = (v(2.0 * h) - 2.0 * v0 + v(-2.0 * h)) / (4.0 * h * h);
  return (4.0 * d1 - d2) / 3.0;
}

/// Checks v^T K_r v against the curvature of the energy along the manifold for the unit vectors of the
/// mechanisms and for random directions, by differences of step h (m of node displacement per unit of v: N is
/// orthonormal in the node metric), to a relative error `tol` (with a floor of 1e-7 of the largest entry of K_r).
void checkCurvature(const Model& model, const State& s, int random_directions, double h = 1e-4, double tol = 1e-5)
{
  const ReducedStructure r = reduceStructure(model, s);
  NaturalProbe probe(model, s.u);
  const Eigen::VectorXd x = probe.positions(s);
  std::mt19937 rng(7);
  std::vector<Eigen::VectorXd> directions;
  for (int k = 0; k < r.mechanisms.cols(); ++k)
    directions.push_back(r.mechanisms.col(k));
  for (int k = 0; k < random_directions; ++k)
    directions.push_back(randomVector(static_cast<int>(r.basis.cols()), 1.0, rng).normalized());
  const double scale = r.stiffness.cwiseAbs().maxCoeff();
  for (const Eigen::VectorXd& v : directions)
  {
    const double exact = v.dot(r.stiffness * v);
    const double fd = energyCurvature(probe, x, r.basis * v, h);
    EXPECT_LT(std::abs(fd - exact) / (std::abs(exact) + 1e-7 * scale), tol)
        << model.name << ": v^T K_r v " << exact << ", finite differences " << fd;
  }
}

std::vector<std::string> names(std::initializer_list<const char*> list)
{
  return std::vector<std::string>(list.begin(), list.end());
}
}  // namespace

// Maxwell's rule for a prism of rigid struts: f free coordinates (5 per free strut: 7 less the norm and the
// spin; 2 per strut pinned at one end), members b, b - r self-stress states, f - r motions, of which the rigid
// ones are no mechanism.

// The SVDs the diagnostics and form finding share: U diag(s) V^T rebuilds the matrix, the singular values
// descend, U and V are orthonormal, thin or full as asked and empty when not asked; BDCSVD past its switch to
// Jacobi (16 columns) agrees with the Jacobi SVD on the singular values.
TEST(Svd, RebuildsTheMatrixWithWhatWasAskedFor)
{
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  for (const auto& [rows, cols] : { std::pair{ 9, 4 }, std::pair{ 4, 9 }, std::pair{ 30, 20 }, std::pair{ 20, 30 } })
  {
    Eigen::MatrixXd a(rows, cols);
    for (Eigen::Index i = 0; i < a.size(); ++i)
      a.data()[i] = uni(rng);
    const int k = std::min(rows, cols);
    const Svd thin = svd(a, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const Svd jacobi = jacobiSvd(a, Eigen::ComputeThinU | Eigen::ComputeThinV);
    for (const Svd* d : { &thin, &jacobi })
    {
      ASSERT_EQ(d->singular.size(), k);
      ASSERT_EQ(d->u.cols(), k);
      ASSERT_EQ(d->v.cols(), k);
      for (int i = 1; i < k; ++i)
        EXPECT_GE(d->singular(i - 1), d->singular(i));
      EXPECT_LT((d->u * d->singular.asDiagonal() * d->v.transpose() - a).norm(), 1e-12 * a.norm());
      EXPECT_LT((d->u.transpose() * d->u - Eigen::MatrixXd::Identity(k, k)).norm(), 1e-12);
      EXPECT_LT((d->v.transpose() * d->v - Eigen::MatrixXd::Identity(k, k)).norm(), 1e-12);
    }
    EXPECT_LT((thin.singular - jacobi.singular).norm(), 1e-12 * a.norm());
    const Svd full_v = svd(a, Eigen::ComputeFullV);
    EXPECT_EQ(full_v.u.size(), 0);
    ASSERT_EQ(full_v.v.rows(), cols);
    ASSERT_EQ(full_v.v.cols(), cols);
    EXPECT_LT((full_v.v.transpose() * full_v.v - Eigen::MatrixXd::Identity(cols, cols)).norm(), 1e-12);
    // the columns past the rank span the null space
    if (cols > rows)
    {
      EXPECT_LT((a * full_v.v.rightCols(cols - rows)).norm(), 1e-12 * a.norm());
    }
    const Svd full_u = jacobiSvd(a, Eigen::ComputeFullU);
    EXPECT_EQ(full_u.v.size(), 0);
    ASSERT_EQ(full_u.u.rows(), rows);
    ASSERT_EQ(full_u.u.cols(), rows);
    EXPECT_LT((full_u.u.transpose() * full_u.u - Eigen::MatrixXd::Identity(rows, rows)).norm(), 1e-12);
  }
}

TEST(StructureCheck, FreePrismHasOneSelfStressOneMechanismAndSixRigidModes)
{
  // without its actuator the prism floats: f = 15, 9 cables, the known self-stress (rank 8), 15 - 8 = 7
  // motions: 6 rigid, 1 infinitesimal mechanism, stiffened by the prestress
  const Model free = loadScene(scenePath("prism.yaml"), { parseOverride("actuators={}") });
  const StructureReport r = checkStructure(free, initialState(free));
  ASSERT_TRUE(r.checked) << r.note;
  EXPECT_EQ(r.coordinates, 21);
  EXPECT_EQ(r.free_coordinates, 15);
  // every member counts: 3 struts and 9 cables (the self-stress states are those of the 9 tension elements)
  EXPECT_EQ(r.members, 12);
  EXPECT_EQ(r.struts, 3);
  EXPECT_EQ(r.tension_members, 9);
  EXPECT_EQ(r.rank, 8);
  EXPECT_EQ(r.self_stress_states, 1);
  EXPECT_EQ(r.rigid_body_modes, 6);
  EXPECT_EQ(r.mechanisms, 1);
  EXPECT_TRUE(r.prestress_stable);
  EXPECT_GT(r.smallest_stiffness_eigenvalue, 0.0);
  EXPECT_TRUE(r.slack_cables.empty());
  // the scene's tensions are given to 13 digits: in equilibrium to that precision of 291 N
  EXPECT_LT(r.equilibrium_residual, 1e-7);

  // the shipped scene's actuator holds T1's height: one translation less, the rest unchanged
  const Model held = loadScene(scenePath("prism.yaml"));
  const StructureReport h = checkStructure(held, initialState(held));
  EXPECT_EQ(h.free_coordinates, 14);
  EXPECT_EQ(h.rigid_body_modes, 5);
  EXPECT_EQ(h.mechanisms, 1);
  EXPECT_EQ(h.self_stress_states, 1);
  EXPECT_TRUE(h.prestress_stable);
}

TEST(StructureCheck, PinnedPrismHasNoRigidModeAndOneMechanism)
{
  // f = 3 x 2; the three top rings and three verticals carry the prism's self-stress (rank 5), and each ring
  // cable between two pins is a self-stress of its own (a zero row): s = 9 - 5 = 4, m = 6 - 5 = 1
  const Model m = loadScene(scenePath("prism_pinned.yaml"));
  const StructureReport r = checkStructure(m, initialState(m));
  EXPECT_EQ(r.free_coordinates, 6);
  EXPECT_EQ(r.members, 12);
  EXPECT_EQ(r.tension_members, 9);
  EXPECT_EQ(r.rank, 5);
  EXPECT_EQ(r.self_stress_states, 4);
  EXPECT_EQ(r.rigid_body_modes, 0);
  EXPECT_EQ(r.mechanisms, 1);
  EXPECT_TRUE(r.prestress_stable);
  EXPECT_GT(r.smallest_stiffness_eigenvalue, 0.0);
  EXPECT_LT(r.equilibrium_residual, 1e-7);
}

TEST(StructureCheck, SlidingVerticalsMakeThreeMechanisms)
{
  // one cable of length V1 + V2 + V3 + const instead of three: its row is the sum of theirs, which the
  // self-stress ties to the top rings' rows (T_ring (R4 + R5 + R6) + T_vert (V1 + V2 + V3) = 0): rank 3 of the
  // four moving rows, s = 7 - 3 = 4, m = 6 - 3 = 3. The prism's stress is super stable (its stress matrix is
  // positive semi-definite, zero only on affine motions, and no affine motion keeps the struts' lengths), so it
  // stiffens every one of the three mechanisms.
  const Model m = loadScene(scenePath("prism_pinned_sliding.yaml"));
  ASSERT_EQ(m.cables.back().points.size(), 6u);
  const StructureReport r = checkStructure(m, initialState(m));
  EXPECT_EQ(r.members, 10);
  EXPECT_EQ(r.struts, 3);
  EXPECT_EQ(r.tension_members, 7);
  EXPECT_EQ(r.rank, 3);
  EXPECT_EQ(r.self_stress_states, 4);
  EXPECT_EQ(r.rigid_body_modes, 0);
  EXPECT_EQ(r.mechanisms, 3);
  EXPECT_TRUE(r.prestress_stable);
  EXPECT_LT(r.equilibrium_residual, 1e-7);
}

TEST(StructureCheck, TooFewMembersLeaveAFiniteMechanism)
{
  // the pinned prism without its verticals, the rings at their free length: the top triangle on three
  // pinned struts has 6 - 3 = 3 degrees of freedom and nothing stiffens them
  const Model m = loadSceneFromString(
      edited("prism_pinned.yaml",
             { { "    prestress: 173.2050807569\n", "" },
               { "  verticals:\n    material: fibreglass\n    radius: 0.0015\n    prestress: 291.2704512527\n    "
                 "members: {V1: [B1, T2], V2: [B2, T3], V3: [B3, T1]}\n",
                 "" },
               { "actuators:\n  tension:\n    cables: [V1, V2, V3]\n    range: [0.0, 0.002]\n", "" } }),
      "rings_only.yaml");
  const StructureReport r = checkStructure(m, initialState(m));
  EXPECT_EQ(r.free_coordinates, 6);
  EXPECT_EQ(r.members, 9);
  EXPECT_EQ(r.tension_members, 6);
  EXPECT_EQ(r.rank, 3);
  EXPECT_EQ(r.self_stress_states, 3);  // the bottom rings, between pins
  EXPECT_EQ(r.rigid_body_modes, 0);
  EXPECT_EQ(r.mechanisms, 3);
  EXPECT_FALSE(r.prestress_stable);
}

TEST(StructureCheck, UnstressedPrismIsNotStableAndListsItsSlackCables)
{
  // every cable at its free length: the same counts as the prestressed prism, but no tension: every element
  // is slack (to round-off), nothing stiffens the mechanism, and nothing is out of balance
  const Model m = loadSceneFromString(edited("prism_pinned.yaml", { { "    prestress: 173.2050807569\n", "" },
                                                                    { "    prestress: 291.2704512527\n", "" } }),
                                      "unstressed.yaml");
  const StructureReport r = checkStructure(m, initialState(m));
  EXPECT_EQ(r.self_stress_states, 4);
  EXPECT_EQ(r.mechanisms, 1);
  EXPECT_FALSE(r.prestress_stable);
  EXPECT_EQ(r.slack_cables, names({ "R1", "R2", "R3", "R4", "R5", "R6", "V1", "V2", "V3" }));
  // a cable at its free length to round-off may count as taut in K_t, with k nn^T but a tension of round-off
  // size: the mechanism stretches no cable, so its stiffness is round-off too
  EXPECT_LT(std::abs(r.smallest_stiffness_eigenvalue), 1e-6);
  EXPECT_LT(r.equilibrium_residual, 1e-6);
}

TEST(StructureCheck, ResidualOffTheEquilibriumIsTheReducedStiffnessTimesTheMove)
{
  // at q* + e N v (back on the manifold) the least-squares residual lies in null(Phi_q) = span(N) and its
  // reduced part N^T r = -N^T F is e K_r v to first order, so r = e N (N^T N)^-1 K_r v + O(e^2)
  const Model m = loadScene(scenePath("prism_pinned.yaml"));
  const State eq = equilibrium(m);
  const ReducedStructure red = reduceStructure(m, eq);
  NaturalProbe probe(m, eq.u);
  const Eigen::VectorXd x = probe.positions(eq);
  std::mt19937 rng(3);
  const Eigen::VectorXd v = randomVector(static_cast<int>(red.basis.cols()), 1.0, rng).normalized();
  const Eigen::MatrixXd& n = red.basis;
  const Eigen::VectorXd per_metre = n * (n.transpose() * n).ldlt().solve(red.stiffness * v);
  for (double e : { 1e-5, 1e-6 })
  {
    State moved = eq;
    moved.natural = NaturalState();  // (the poses of the moved coordinates)
    moved.q = probe.bodyPoses(probe.project(x + e * n * v));
    const StructureReport r = checkStructure(m, moved);
    const double predicted = e * per_metre.lpNorm<Eigen::Infinity>();
    EXPECT_GT(r.equilibrium_residual, 0.0);
    EXPECT_NEAR(r.equilibrium_residual, predicted, 2e-3 * predicted) << "e = " << e;
  }
  EXPECT_LT(checkStructure(m, eq).equilibrium_residual, 1e-8);
}

TEST(StructureCheck, GivenMultipliersAndLeastSquaresOnesGiveTheSameStiffnessAtAnEquilibrium)
{
  const Model m = loadScene(scenePath("quadruplex.yaml"));
  const State eq = equilibrium(m, 0.5, 25);
  State bare = eq;
  bare.natural = NaturalState();  // (its body poses alone: coordinates from q, least-squares multipliers)
  const ReducedStructure given = reduceStructure(m, eq), fitted = reduceStructure(m, bare);
  ASSERT_EQ(given.lambda.size(), eq.natural.lambda.size());
  EXPECT_EQ(given.lambda, eq.natural.lambda);
  // the multipliers fitted to the forces are the equilibrium's (to the size of its residual), and the stiffness is the
  // same: compared by its eigenvalues, as the two bases of null(G), from coordinates that differ by round-off, may
  // differ by a rotation
  ASSERT_EQ(fitted.lambda.size(), given.lambda.size());
  EXPECT_LT((fitted.lambda - given.lambda).lpNorm<Eigen::Infinity>(), 1e-6 * given.lambda.lpNorm<Eigen::Infinity>());
  const Eigen::VectorXd k_given = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(given.stiffness).eigenvalues();
  const Eigen::VectorXd k_fitted = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(fitted.stiffness).eigenvalues();
  ASSERT_EQ(k_given.size(), k_fitted.size());
  EXPECT_LT((k_given - k_fitted).cwiseAbs().maxCoeff(), 1e-6 * k_given.cwiseAbs().maxCoeff());
}

TEST(StructureCheck, ReducedStiffnessIsTheEnergyCurvatureAlongTheManifold)
{
  // pinned prism at its start and with the verticals pulled in; sliding verticals; the quadruplex part way
  // down (actuated nodes: the constraints' curvature enters through the multipliers); the free prism (rigid
  // modes); the tower folded 0.3 m (sliding cables, point masses, guided drives)
  const Model pinned = loadScene(scenePath("prism_pinned.yaml"));
  checkCurvature(pinned, equilibrium(pinned), 6);
  checkCurvature(pinned, equilibrium(pinned, 0.0008, 8), 6);
  const Model sliding = loadScene(scenePath("prism_pinned_sliding.yaml"));
  checkCurvature(sliding, equilibrium(sliding, 0.0008, 8), 6);
  const Model quadruplex = loadScene(scenePath("quadruplex.yaml"));
  checkCurvature(quadruplex, equilibrium(quadruplex, 0.6, 30), 4);
  const Model free = loadScene(scenePath("prism.yaml"), { parseOverride("actuators={}") });
  checkCurvature(free, initialState(free), 6);
  // the tower's fibreglass cables are stretched by only 2.7e-5 to 9.3e-5 m there: steps of 1e-4 m would make
  // them slack (a kink of the energy), steps of 1e-5 m leave the round-off of its 40 J of spring energy
  const Model tower = loadScene(scenePath("tower.yaml"), { parseOverride("contact.enabled=false") });
  checkCurvature(tower, equilibrium(tower, 0.3, 30), 8, 1e-5, 3e-4);
}

TEST(StructureCheck, AboveTheLimitTheCheckIsSkippedAtOnce)
{
  Model big;
  for (int i = 0; i < kMaxStructureCoordinates / 7 + 1; ++i)
    big.bodies.push_back(makeStrut("S" + std::to_string(i), 1.0, 0.01, 7800.0));
  finalizeModel(big);
  ASSERT_GT(big.nq, kMaxStructureCoordinates);
  State s;
  s.q = Eigen::VectorXd::Zero(big.nq);
  const StructureReport r = checkStructure(big, s);
  EXPECT_FALSE(r.checked);
  EXPECT_EQ(r.note, "skipped: " + std::to_string(big.nq) + " coordinates, more than the limit of 3000");
  EXPECT_EQ(r.members, static_cast<int>(big.bodies.size()));  // counted all the same
  EXPECT_EQ(r.struts, r.members);
  EXPECT_THROW(reduceStructure(big, s), std::invalid_argument);
}

TEST(StartWarnings, SayWhatTheStartIsAndNothingForASoundOne)
{
  // the prestressed pinned prism: nothing to say
  EXPECT_TRUE(
      startWarnings(loadScene(scenePath("prism_pinned.yaml")), initialState(loadScene(scenePath("prism_pinned.yaml"))))
          .empty());
  // the tower starts unstressed: all 20 elements slack, 13 mechanisms unstiffened
  const Model tower = loadScene(scenePath("tower.yaml"));
  const std::vector<std::string> t = startWarnings(tower, initialState(tower));
  ASSERT_EQ(t.size(), 2u);
  EXPECT_NE(t[0].find("20 of 20 tension elements are slack"), std::string::npos) << t[0];
  EXPECT_NE(t[1].find("not prestress stable: 13 infinitesimal mechanisms"), std::string::npos) << t[1];
  // a strut dropped under gravity starts out of equilibrium by its weight
  const Model impact = loadScene(scenePath("impact.yaml"));
  const std::vector<std::string> i = startWarnings(impact, initialState(impact));
  ASSERT_FALSE(i.empty());
  EXPECT_NE(i[0].find("not in equilibrium"), std::string::npos) << i[0];
  // and runs carry them in their summaries
  Model short_tower = loadScene(scenePath("tower.yaml"),
                                { parseOverride("analysis.steps=2"), parseOverride("analysis.max_actuation=0.01") });
  const RunResult run = runAnalysis(short_tower, [](const State&) {});
  ASSERT_GE(run.summary.warnings.size(), 2u);
  EXPECT_EQ(run.summary.warnings[0], t[0]);
  EXPECT_EQ(run.summary.warnings[1], t[1]);
}

TEST(StructureCheck, MembersCountEveryStrutAndEveryTensionElement)
{
  // the tower: 16 struts, 8 cables (4 of them sliding, each one member), 8 springs; its 4 driven point masses are
  // bodies, not members (--check's `members` counted the 20 tension elements alone)
  const Model m = loadScene(scenePath("tower.yaml"));
  const StructureReport r = checkStructure(m, initialState(m));
  ASSERT_TRUE(r.checked) << r.note;
  EXPECT_EQ(r.struts, 16);
  EXPECT_EQ(r.tension_members, 20);
  EXPECT_EQ(r.members, 36);
  EXPECT_EQ(r.self_stress_states, r.tension_members - r.rank);
}
