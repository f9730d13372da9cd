#include "active_tensegrity/core/solvers/structure_check.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>

#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/linalg/svd.h"
#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::core
{
namespace
{
/// Absolute floor of positive definiteness (N/m): an all-slack structure's roundoff is not a stiffness.
constexpr double kDefinitenessFloor = 1e-9;
/// Relative stretch below which a tension-only element counts as slack.
constexpr double kFreeLengthTolerance = 1e-12;

/// Orthonormal basis of null(a) (columns), from a column-pivoted QR of a^T.
Eigen::MatrixXd nullSpace(const Eigen::MatrixXd& a)
{
  const int n = static_cast<int>(a.cols());
  if (a.rows() == 0 || n == 0)
    return Eigen::MatrixXd::Identity(n, n);
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a.transpose());
  qr.setThreshold(kRankTolerance);
  const int rank = static_cast<int>(qr.rank());
  const Eigen::MatrixXd q = qr.householderQ();
  return q.rightCols(n - rank);
}

/// Orthonormal basis of the orthogonal complement of the orthonormal columns of z in R^n.
Eigen::MatrixXd complement(const Eigen::MatrixXd& z, int n)
{
  if (z.cols() == 0)
    return Eigen::MatrixXd::Identity(n, n);
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(z);
  const Eigen::MatrixXd q = qr.householderQ();
  return q.rightCols(n - z.cols());
}

/// The natural nodes whose displacements define the node metric: the node of every node of the model (-1 for a point
/// of the ground), then every strut end and point mass that no node of the model stands at.
std::vector<int> metricNodes(const NaturalModel& nm)
{
  const Model& model = *nm.model;
  std::vector<int> nodes;
  const auto nodeOf = [&](const PointRef& p)
  {
    if (p.body < 0)
      return -1;
    const int strut = nm.strut_of_body[static_cast<size_t>(p.body)];
    if (strut >= 0)
      return p.local.z() < 0.0 ? nm.struts[static_cast<size_t>(strut)].a : nm.struts[static_cast<size_t>(strut)].b;
    return nm.node_of_body[static_cast<size_t>(p.body)];
  };
  for (const Node& n : model.nodes)
    nodes.push_back(nodeOf(n.point));
  const auto add = [&](int node)
  {
    if (node >= 0 && std::find(nodes.begin(), nodes.end(), node) == nodes.end())
      nodes.push_back(node);
  };
  for (size_t b = 0; b < model.bodies.size(); ++b)
  {
    const int strut = nm.strut_of_body[b];
    if (strut >= 0)
    {
      add(nm.struts[static_cast<size_t>(strut)].a);
      add(nm.struts[static_cast<size_t>(strut)].b);
    }
    else
      add(nm.node_of_body[b]);
  }
  return nodes;
}

ActuationValues actuationOf(const Model& model, const State& state)
{
  return state.u.size() == model.actuators.size() ? state.u : ActuationValues(model.actuators.size());
}

/// The natural coordinates of a state: its own when it carries them (an equilibrium of the statics), else formed
/// from its body poses.
Eigen::VectorXd naturalPositions(const NaturalModel& nm, const State& state)
{
  if (state.natural.x.size() == nm.coordinates && carriesNaturalOf(nm, state))
    return state.natural.x;
  State s = state;
  s.qd.setZero(s.q.size());  // (at rest)
  s.u = actuationOf(*nm.model, state);
  naturalFromBody(nm, s);
  return s.natural.x;
}
}  // namespace

ReducedStructure reduceStructure(const Model& model, const State& state)
{
  if (model.nq > kMaxStructureCoordinates)
    throw std::invalid_argument(std::to_string(model.nq) + " coordinates, more than the limit of " +
                                std::to_string(kMaxStructureCoordinates));
  if (state.q.size() != model.nq)
    throw std::invalid_argument("the state has " + std::to_string(state.q.size()) + " coordinates, the model " +
                                std::to_string(model.nq));
  const NaturalModel nm = buildNaturalModel(model, false);
  const ActuationValues u = actuationOf(model, state);
  const Eigen::VectorXd x = naturalPositions(nm, state);
  const int n = nm.coordinates, rows = static_cast<int>(nm.struts.size() + nm.rows.size());
  NaturalSolver solver(nm, model.solver);
  ReducedStructure out;

  // the forces (the residual at zero multipliers is -F) and the rows' Jacobian G
  solver.assembleStatic(x, Eigen::VectorXd::Zero(rows), u, true);
  const Eigen::VectorXd F = -solver.staticResidual().head(n);
  const Eigen::SparseMatrix<double> g = solver.assembledRows();

  // the node map P (each free node's three coordinates; fixed and driven nodes and the ground none) and the motions
  // the rows allow
  const std::vector<int> nodes = metricNodes(nm);
  const int n_points = static_cast<int>(nodes.size());
  out.node_rows = 3 * static_cast<int>(model.nodes.size());
  std::vector<Eigen::Triplet<double>> entries;
  std::vector<Vec3> position(nodes.size(), Vec3::Zero());
  std::vector<bool> on_body(nodes.size(), false);
  for (int i = 0; i < n_points; ++i)
  {
    if (nodes[i] < 0)
      continue;
    on_body[i] = true;
    position[i] = naturalNodePosition(nm, nodes[i], x, u);
    const int column = nm.nodes[static_cast<size_t>(nodes[i])].column;
    if (column >= 0)
      for (int r = 0; r < 3; ++r)
        entries.emplace_back(3 * i + r, column + r, 1.0);
  }
  out.node_map.resize(3 * n_points, n);
  out.node_map.setFromTriplets(entries.begin(), entries.end());
  const Eigen::MatrixXd n0 = nullSpace(Eigen::MatrixXd(g));  // orthonormal
  const int f = static_cast<int>(n0.cols());

  // orthonormal in the node metric: N = N0 V D^(-1/2) with (P N0)^T (P N0) = V D V^T
  out.basis.resize(n, f);
  if (f > 0)
  {
    const Eigen::MatrixXd pn0 = out.node_map * n0;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(pn0.transpose() * pn0);
    const Eigen::VectorXd d = eig.eigenvalues();
    if (!(d.minCoeff() > kRankTolerance * kRankTolerance * d.maxCoeff()))
      throw std::invalid_argument("a motion the constraints allow moves no node (a body without nodes?)");
    out.basis = n0 * eig.eigenvectors() * d.cwiseSqrt().cwiseInverse().asDiagonal();
  }
  const Eigen::MatrixXd pn = out.node_map * out.basis;

  // the compatibility matrix C N (dl/dx of each tension element: its segments' unit vectors at their free nodes) and
  // its rank
  const int members = static_cast<int>(model.cables.size());
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(members, n);
  for (int i = 0; i < members; ++i)
  {
    const std::vector<int>& points = nm.cable_nodes[static_cast<size_t>(i)];
    for (size_t k = 0; k + 1 < points.size(); ++k)
    {
      const Vec3 d = naturalNodePosition(nm, points[k + 1], x, u) - naturalNodePosition(nm, points[k], x, u);
      const double len = d.norm();
      if (!(len > 0.0))
        continue;
      for (const auto& [node, sign] : { std::make_pair(points[k + 1], 1.0), std::make_pair(points[k], -1.0) })
      {
        const int column = nm.nodes[static_cast<size_t>(node)].column;
        if (column >= 0)
          c.row(i).segment<3>(column) += (sign / len) * d.transpose();
      }
    }
  }
  out.compatibility = c * out.basis;
  Eigen::MatrixXd motions = Eigen::MatrixXd::Identity(f, f);  // null(C N)
  double sigma_max = 0.0;
  if (members > 0 && f > 0)
  {
    const Svd d = svd(out.compatibility, Eigen::ComputeFullV);
    const Eigen::VectorXd& sv = d.singular;
    sigma_max = sv(0);
    out.rank = static_cast<int>((sv.array() > kRankTolerance * sigma_max).count());
    motions = d.v.rightCols(f - out.rank);
  }

  // rigid motions of the whole structure (about the centroid of its moving points), then those the
  // constraints allow (principal angles between the two spaces of node fields at zero) ...
  Eigen::MatrixXd z = Eigen::MatrixXd::Zero(f, 0);
  if (f > 0)
  {
    Vec3 centre = Vec3::Zero();
    int moving = 0;
    for (int i = 0; i < n_points; ++i)
      if (on_body[i])
      {
        centre += position[i];
        ++moving;
      }
    centre /= std::max(1, moving);
    Eigen::MatrixXd w = Eigen::MatrixXd::Zero(3 * n_points, 6);
    for (int i = 0; i < n_points; ++i)
      if (on_body[i])
      {
        w.block<3, 3>(3 * i, 0).setIdentity();
        w.block<3, 3>(3 * i, 3) = -skew(position[i] - centre);
      }
    const Svd fields = jacobiSvd(w, Eigen::ComputeThinU);
    const int k = static_cast<int>((fields.singular.array() > kRankTolerance * fields.singular(0)).count());
    const Svd angles = jacobiSvd(pn.transpose() * fields.u.leftCols(k), Eigen::ComputeThinU);
    const int allowed = static_cast<int>((angles.singular.array() > 1.0 - 1e-8).count());
    const Eigen::MatrixXd z0 = angles.u.leftCols(allowed);
    // ... and of those, the ones that stretch no member (a cable to a ground point may hold them)
    int held = 0;
    Eigen::MatrixXd v = Eigen::MatrixXd::Identity(allowed, allowed);
    if (allowed > 0 && members > 0)
    {
      const Svd stretch = jacobiSvd(out.compatibility * z0, Eigen::ComputeFullV);
      held = static_cast<int>((stretch.singular.array() > kRankTolerance * sigma_max).count());
      v = stretch.v;
    }
    z = z0 * v.rightCols(allowed - held);
  }
  out.rigid = z;

  // the mechanisms: null(C N) without the rigid-body modes
  out.mechanisms = motions;
  if (z.cols() > 0 && motions.cols() > 0)
  {
    const Eigen::MatrixXd b = motions.transpose() * z;
    const Svd d = jacobiSvd(b, Eigen::ComputeFullU);
    const int inside = static_cast<int>((d.singular.array() > 0.5).count());
    out.mechanisms = motions * d.u.rightCols(motions.cols() - inside);
  }

  // the force residual with least-squares multipliers: -F + G^T lambda is minus the part of F in null(G) (the
  // orthogonal complement of the range of G^T), N0 N0^T F with N0 orthonormal
  out.residual = (n0 * (n0.transpose() * F)).lpNorm<Eigen::Infinity>();

  // the tangent stiffness on the manifold, with the state's multipliers (an equilibrium of the statics) or the
  // least-squares ones
  if (state.natural.equilibrium && state.natural.lambda.size() == rows && state.natural.lambda.any() &&
      state.natural.x.size() == n && state.natural.x == x)
    out.lambda = state.natural.lambda;
  else if (rows > 0)
  {
    // normal equations G G^T lambda = G F (sparse): the rows are well conditioned, redundant rows make them singular
    // and send it to the dense solve
    const Eigen::SparseMatrix<double> normal = g * g.transpose();
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(normal);
    if (ldlt.info() == Eigen::Success)
      out.lambda = ldlt.solve(g * F);
    if (out.lambda.size() != rows || !out.lambda.allFinite() ||
        (Eigen::VectorXd(g.transpose() * out.lambda) - F).lpNorm<Eigen::Infinity>() >
            2.0 * out.residual + 1e-9 * (1.0 + F.lpNorm<Eigen::Infinity>()))
      out.lambda = Eigen::MatrixXd(g.transpose()).colPivHouseholderQr().solve(F);
  }
  else
    out.lambda = Eigen::VectorXd();
  solver.assembleStatic(x, out.lambda.size() == rows ? out.lambda : Eigen::VectorXd::Zero(rows), u, true);
  const Eigen::MatrixXd kr = out.basis.transpose() * (solver.assembledMatrix().topLeftCorner(n, n) * out.basis);
  out.stiffness = 0.5 * (kr + kr.transpose());
  return out;
}

namespace
{
/// Eigenvalues of the symmetric a (ascending; empty for an empty a).
Eigen::VectorXd symmetricEigenvalues(const Eigen::MatrixXd& a)
{
  if (a.rows() == 0)
    return Eigen::VectorXd();
  return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(a, Eigen::EigenvaluesOnly).eigenvalues();
}
}  // namespace

Eigen::MatrixXd rigidComplement(const ReducedStructure& r)
{
  return complement(r.rigid, static_cast<int>(r.basis.cols()));
}

StiffnessSpectrum stiffnessSpectrum(const Model& model, const State& state, int max_coordinates)
{
  StiffnessSpectrum out;
  if (model.nq > std::min(max_coordinates, kMaxStructureCoordinates))
    return out;
  try
  {
    const ReducedStructure r = reduceStructure(model, state);
    const Eigen::MatrixXd qc = rigidComplement(r);
    const Eigen::VectorXd k = symmetricEigenvalues(qc.transpose() * r.stiffness * qc);
    out.computed = true;
    if (k.size() == 0)
    {
      out.nearest_zero = std::numeric_limits<double>::quiet_NaN();
      return out;
    }
    out.tolerance = std::max(kDefinitenessTolerance * k.cwiseAbs().maxCoeff(), kDefinitenessFloor);
    Eigen::Index nearest = 0;
    k.cwiseAbs().minCoeff(&nearest);
    out.nearest_zero = k(nearest);
    out.negative = static_cast<int>((k.array() < -out.tolerance).count());
  }
  catch (const std::invalid_argument&)
  {
    out.computed = false;
  }
  return out;
}

StructureReport checkStructure(const Model& model, const State& state)
{
  StructureReport report;
  report.coordinates = model.nq;
  report.tension_members = static_cast<int>(model.cables.size());
  report.struts = static_cast<int>(std::count_if(model.bodies.begin(), model.bodies.end(),
                                                 [](const Body& b) { return b.kind == BodyKind::kStrut; }));
  report.members = report.struts + report.tension_members;
  if (model.nq > kMaxStructureCoordinates)
  {
    report.note = "skipped: " + std::to_string(model.nq) + " coordinates, more than the limit of " +
                  std::to_string(kMaxStructureCoordinates);
    return report;
  }
  const ReducedStructure r = reduceStructure(model, state);
  report.checked = true;
  report.free_coordinates = static_cast<int>(r.basis.cols());
  report.rank = r.rank;
  report.self_stress_states = report.tension_members - r.rank;
  report.rigid_body_modes = static_cast<int>(r.rigid.cols());
  report.mechanisms = static_cast<int>(r.mechanisms.cols());

  // stiffness on the complement of the rigid-body modes, and on the mechanisms
  const Eigen::MatrixXd qc = rigidComplement(r);
  const Eigen::VectorXd kc = symmetricEigenvalues(qc.transpose() * r.stiffness * qc);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  report.smallest_stiffness_eigenvalue = kc.size() ? kc(0) : nan;
  report.largest_stiffness_eigenvalue = kc.size() ? kc(kc.size() - 1) : nan;
  const double scale = kc.size() ? kc.cwiseAbs().maxCoeff() : 0.0;
  const double tol = std::max(kDefinitenessTolerance * scale, kDefinitenessFloor);
  if (report.mechanisms > 0)
    report.prestress_stable = symmetricEigenvalues(r.mechanisms.transpose() * r.stiffness * r.mechanisms)(0) > tol;
  else
    report.prestress_stable = kc.size() == 0 || kc(0) > tol;
  const Eigen::VectorXd kr = symmetricEigenvalues(r.rigid.transpose() * r.stiffness * r.rigid);
  report.smallest_rigid_mode_eigenvalue = kr.size() ? kr(0) : nan;
  if (kr.size() && kr(0) < -tol)
    report.prestress_stable = false;

  // slack elements and the force residual with least-squares multipliers (velocities zero)
  const ActuationValues u = actuationOf(model, state);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(model.nq);
  for (const Cable& c : model.cables)
  {
    // an element at its free length to round-off (lengths from q carry a few ulps) carries nothing either
    const CableState st = evaluateCable(model, c, state.q, zero, u, false);
    if (c.tension_only && (st.slack || st.length - st.rest_length <= kFreeLengthTolerance * st.rest_length))
      report.slack_cables.push_back(c.name);
  }
  report.equilibrium_residual = r.residual;
  return report;
}

double structureSize(const Model& model, const Eigen::VectorXd& q)
{
  if (model.nodes.empty())
    return 0.0;
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Node& n : model.nodes)
  {
    const Vec3 p = pointPosition(model, n.point, q);
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).norm();
}

int freeCoordinates(const Model& model, const Eigen::VectorXd& q)
{
  const NaturalModel nm = buildNaturalModel(model, false);
  State s;
  s.q = q;
  s.qd.setZero(model.nq);
  s.u = ActuationValues(model.actuators.size());
  naturalFromBody(nm, s);
  NaturalSolver solver(nm, model.solver);
  solver.assembleStatic(s.natural.x,
                        Eigen::VectorXd::Zero(static_cast<Eigen::Index>(nm.struts.size() + nm.rows.size())), s.u, true);
  const Eigen::MatrixXd g = solver.assembledRows();
  if (g.rows() == 0 || g.cols() == 0)
    return nm.coordinates;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(g);
  qr.setThreshold(kRankTolerance);
  return nm.coordinates - static_cast<int>(qr.rank());
}

std::vector<std::string> startWarnings(const Model& model_in, const State& state)
{
  std::vector<std::string> warnings;
  // the ground on: a free point mass without a radius falls through it
  if (model_in.ground.enabled)
    for (size_t b = 0; b < model_in.bodies.size(); ++b)
    {
      const int body = static_cast<int>(b);
      const bool touches = std::any_of(model_in.ground_contacts.begin(), model_in.ground_contacts.end(),
                                       [&](const GroundContact& g) { return g.body == body; });
      const bool driven = std::any_of(model_in.constraints.begin(), model_in.constraints.end(),
                                      [&](const Constraint& c) { return c.actuator >= 0 && c.a.body == body; });
      if (model_in.bodies[b].kind == BodyKind::kPointMass && !touches && !driven)
        warnings.push_back("point mass " + quoted(model_in.bodies[b].name) +
                           " has no radius and does not touch the ground (nodes." + model_in.bodies[b].name +
                           ".radius)");
    }
  // a static path that scales its loads starts at its first load factor
  Model scaled;
  if (hasLoadPath(model_in))
  {
    scaled = model_in;
    for (PointLoad& l : scaled.loads)
      l.force *= scaled.analysis.load_factor_start;
  }
  const Model& model = hasLoadPath(model_in) ? scaled : model_in;
  StructureReport report;
  try
  {
    report = checkStructure(model, state);
  }
  catch (const std::invalid_argument& e)
  {
    warnings.push_back(std::string("the structural checks of the start failed: ") + e.what());
    return warnings;
  }
  if (!report.checked)
    return warnings;
  double largest = 0.0;
  for (const Cable& c : model.cables)
    largest =
        std::max(largest, std::abs(evaluateCable(model, c, state.q, state.qd, state.u, model.damping_enabled).tension));
  if (report.equilibrium_residual > 1e-6 * (1.0 + largest))
    warnings.push_back("the start is not in equilibrium: force residual " + shortestNumber(report.equilibrium_residual) +
                       " N (largest member force " + shortestNumber(largest) + " N)");
  if (!report.slack_cables.empty())
  {
    std::string names;
    for (size_t i = 0; i < report.slack_cables.size() && i < 10; ++i)
      names += (i ? ", " : "") + quoted(report.slack_cables[i]);
    if (report.slack_cables.size() > 10)
      names += ", ...";
    warnings.push_back(std::to_string(report.slack_cables.size()) + " of " + std::to_string(report.tension_members) +
                       " tension elements are slack at the start: " + names);
  }
  if (!report.prestress_stable)
    warnings.push_back("the start is not prestress stable: " + std::to_string(report.mechanisms) +
                       " infinitesimal mechanisms, " + std::to_string(report.self_stress_states) +
                       " self-stress states, smallest stiffness eigenvalue " +
                       shortestNumber(report.smallest_stiffness_eigenvalue) + " N/m (tensegrity_run --check)");
  return warnings;
}

}  // namespace active_tensegrity::core
