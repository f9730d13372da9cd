// Natural (nodal) coordinates (natural.h): the contact tangents against central differences, the constant mass
// matrix against the rigid strut's kinetic energy, agreement with the body coordinates through contact, refusals.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "active_tensegrity/core/analysis.h"
#include "active_tensegrity/core/natural.h"
#include "active_tensegrity/core/scene.h"
#include "active_tensegrity/core/state.h"

using namespace active_tensegrity::core;

namespace
{
Model scene(const std::string& name, const std::vector<Override>& overrides = {})
{
  return loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name, overrides);
}

using Vec12 = Eigen::Matrix<double, 12, 1>;
using Mat12 = Eigen::Matrix<double, 12, 12>;

// two crossing struts of the tower's first pair, the second pressed into the first by `depth` (m)
void crossing(std::mt19937& rng, double depth, Vec3 r[4], Vec3 v[4])
{
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double half = 0.5 * std::sqrt(0.5 + 0.25 + 0.25);  // (any length: the kernel reads the nodes)
  const Vec3 a = Vec3(1.0, 0.2 * u(rng), 0.1 * u(rng)).normalized(),
             b = Vec3(0.3 * u(rng), 1.0, 0.2 * u(rng)).normalized();
  const Vec3 n = a.cross(b).normalized();
  const Vec3 c1(0.1 * u(rng), 0.1 * u(rng), 0.1 * u(rng));
  const Vec3 c2 = c1 - (0.08 - depth) * n + 0.2 * u(rng) * a;  // radii 0.04 each: gap = -depth
  r[0] = c1 - half * a;
  r[1] = c1 + half * a;
  r[2] = c2 - half * b;
  r[3] = c2 + half * b;
  for (int i = 0; i < 4; ++i)
    v[i] = Vec3(u(rng), u(rng), u(rng));
}

TEST(Natural, ContactTangentsMatchCentralDifferences)
{
  const Model model = scene("tower.yaml", { { "analysis.type", "dynamic" } });
  const NaturalModel nm = buildNaturalModel(model);
  ASSERT_FALSE(nm.pair_slots.empty());
  const int slot = nm.pair_slots[0];
  std::mt19937 rng(7);
  int with_friction = 0, with_cores = 0;
  // sleeves only, and deep enough for the steel cores (the sleeves are 27.5 mm thick each)
  for (const double depth : { 2e-3, 1e-2, 6e-2 })
    for (int trial = 0; trial < 6; ++trial)
    {
      Vec3 r[4], v[4];
      crossing(rng, depth, r, v);
      const double impact_speed = 0.3 + 0.1 * trial;
      Vec12 f;
      Mat12 k, c;
      const ContactPairState st = naturalPairContact(nm, slot, r, v, impact_speed, &f, &k, &c);
      ASSERT_TRUE(st.active);
      ASSERT_GT(st.normal_force, 0.0);
      with_friction += st.friction_force > 0.0;
      with_cores += st.core_penetration > 0.0;
      Mat12 k_fd, c_fd;
      for (int j = 0; j < 24; ++j)
      {
        const double h = 1e-7;
        Vec3 rp[4], rm[4], vp[4], vm[4];
        for (int i = 0; i < 4; ++i)
        {
          rp[i] = rm[i] = r[i];
          vp[i] = vm[i] = v[i];
        }
        (j < 12 ? rp : vp)[(j % 12) / 3](j % 3) += h;
        (j < 12 ? rm : vm)[(j % 12) / 3](j % 3) -= h;
        Vec12 fp, fm;
        naturalPairContact(nm, slot, rp, vp, impact_speed, &fp, nullptr, nullptr);
        naturalPairContact(nm, slot, rm, vm, impact_speed, &fm, nullptr, nullptr);
        (j < 12 ? k_fd : c_fd).col(j % 12) = -(fp - fm) / (2.0 * h);
      }
      EXPECT_LE((k - k_fd).cwiseAbs().maxCoeff(), 1e-5 * k.cwiseAbs().maxCoeff()) << "depth " << depth;
      EXPECT_LE((c - c_fd).cwiseAbs().maxCoeff(), 1e-5 * std::max(1.0, c.cwiseAbs().maxCoeff())) << "depth " << depth;
    }
  EXPECT_GT(with_friction, 0);
  EXPECT_GT(with_cores, 0);
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
  DynamicsSolver solver(model, model.solver);
  const ActuationLaw law = [&model](double t) { return scheduledActuation(model, t); };
  State s = initialState(model);
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
    *impulse_speed = *std::max_element(s.contact_speed.begin(), s.contact_speed.end());
  const Eigen::VectorXd q = naturalToBodyCoordinates(nm, s.x, scheduledActuation(model, s.t));
  std::vector<Vec3> c;
  for (const Body& b : model.bodies)
    c.push_back(q.segment<3>(b.offset));
  return c;
}

TEST(Natural, AgreesWithBodyCoordinatesThroughContact)
{
  // the quadruplex pressed into contact (first touch at 0.29 s, touching again from 0.45 s): the two formulations
  // integrate the same equations (no friction, so spin plays no part) with the same scheme. Each is 4e-5 to 1.3e-4 m
  // off a run at a tenth of the step (tensegrity_bench natural); between them the difference must be far smaller.
  for (const double dt : { 2e-4, 1e-4 })
  {
    const Model model = scene("quadruplex_linear_contact.yaml", { { "solver.integrator", "newmark" },
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
    EXPECT_LT(most, 1e-5) << "dt " << dt;
  }
}

TEST(Natural, RefusesWhatItDoesNotCoverByName)
{
  const Model six_bar = scene("six_bar.yaml");
  try
  {
    buildNaturalModel(six_bar);
    FAIL() << "ground contact accepted";
  }
  catch (const std::invalid_argument& e)
  {
    EXPECT_NE(std::string(e.what()).find("ground contact"), std::string::npos) << e.what();
  }
  const Model tower = scene("tower.yaml", { { "analysis.type", "dynamic" } });
  const NaturalModel nm = buildNaturalModel(tower);
  SolverOptions ga = tower.solver;
  ga.integrator = Integrator::kGeneralizedAlpha;
  EXPECT_THROW(NaturalSolver(nm, ga), std::invalid_argument);
}
}  // namespace
