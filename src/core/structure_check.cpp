#include "active_tensegrity/core/structure_check.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>

#include "active_tensegrity/core/analysis.h"
#include "active_tensegrity/core/cable.h"
#include "active_tensegrity/core/constraints.h"
#include "active_tensegrity/core/kinematics.h"
#include "active_tensegrity/core/mechanics.h"
#include "active_tensegrity/core/svd.h"
#include "active_tensegrity/core/text.h"

namespace active_tensegrity::core
{
std::vector<Constraint> spinLocks(const Model& model)
{
  std::vector<Constraint> locks;
  for (size_t i = 0; i < model.bodies.size(); ++i)
  {
    const Body& b = model.bodies[i];
    if (b.kind != BodyKind::kStrut)
      continue;
    Constraint c;
    c.kind = Constraint::Kind::kSpinLock;
    c.name = b.name + ".spin_lock";
    c.body = static_cast<int>(i);
    c.coefficients = spinLockCoefficients(model.q0.segment<4>(b.offset + 3));
    locks.push_back(c);
  }
  return locks;
}

Eigen::VectorXd leastSquaresMultipliers(const System& system, const Eigen::VectorXd& q, const ActuationValues& u)
{
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(system.nq());
  Eigen::VectorXd F;
  system.appliedForce(q, zero, u, F, nullptr, 0.0, 0.0);
  system.contactForce(q, zero, {}, ContactMode::kStatic, F, nullptr, 0.0, 0.0);
  const Eigen::MatrixXd jt = system.constraintJacobianDense(q).transpose();
  return jt.colPivHouseholderQr().solve(F);
}

namespace
{
/// Absolute floor of positive definiteness (N/m): an all-slack structure's roundoff is not a stiffness.
constexpr double kDefinitenessFloor = 1e-9;
/// Relative stretch below which a tension-only element counts as slack.
constexpr double kFreeLengthTolerance = 1e-12;

/// One spin lock per strut about its axis at q (statics' locks refer to the model's initial orientation).
std::vector<Constraint> spinLocksAt(const Model& model, const Eigen::VectorXd& q)
{
  std::vector<Constraint> locks = spinLocks(model);
  for (Constraint& c : locks)
    c.coefficients = spinLockCoefficients(thetaOf(q, model.bodies[c.body]));
  return locks;
}

/// Orthonormal basis of null(a) (columns), from a column-pivoted QR of a^T.
Eigen::MatrixXd nullSpace(const Eigen::MatrixXd& a)
{
  const int n = static_cast<int>(a.cols());
  if (a.rows() == 0)
    return Eigen::MatrixXd::Identity(n, n);
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a.transpose());
  qr.setThreshold(kRankTolerance);
  const int rank = static_cast<int>(qr.rank());
  const Eigen::MatrixXd q = qr.householderQ();
  return q.rightCols(n - rank);
}

/// Phi_q of a system at q (n_lambda x nq), sparse.
Eigen::SparseMatrix<double> constraintJacobian(const System& system, const Eigen::VectorXd& q)
{
  BlockSparseMatrix m = system.makeMatrix();
  m.setZero();
  system.addConstraintJacobian(q, m);
  const int nq = system.nq();
  std::vector<Eigen::Triplet<double>> entries;
  const Eigen::SparseMatrix<double>& s = m.matrix();
  for (int k = 0; k < s.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(s, k); it; ++it)
      if (it.row() >= nq && it.col() < nq && it.value() != 0.0)
        entries.emplace_back(static_cast<int>(it.row()) - nq, static_cast<int>(it.col()), it.value());
  Eigen::SparseMatrix<double> out(system.nLambda(), nq);
  out.setFromTriplets(entries.begin(), entries.end());
  return out;
}

/// null(Phi_q) in two stages, so that the dense work is on the rows that couple bodies only: each body's own
/// rows (its norm and spin lock, pins and drives on it alone) give a small local basis T_b of its coordinates;
/// the coupling rows Phi_g (ball joints) are then taken on the product of the local bases, A = Phi_g T.
struct MotionSpace
{
  std::vector<Eigen::MatrixXd> local;  // T_b, nq_b x t_b, orthonormal columns
  std::vector<int> offset;             // first column of T_b in T
  Eigen::MatrixXd coupling;            // A = Phi_g T
  int size = 0;                        // columns of T

  /// N0 = T Z for a basis Z of null(A) (orthonormal when Z is: T's blocks are).
  Eigen::MatrixXd expand(const Model& model, const Eigen::MatrixXd& z) const
  {
    Eigen::MatrixXd n0 = Eigen::MatrixXd::Zero(model.nq, z.cols());
    for (size_t b = 0; b < local.size(); ++b)
      n0.middleRows(model.bodies[b].offset, local[b].rows()) = local[b] * z.middleRows(offset[b], local[b].cols());
    return n0;
  }
};

MotionSpace motionSpace(const Model& model, const System& system, const Eigen::SparseMatrix<double>& phi_q)
{
  // each row: the body it alone acts on, or -1 (coupling) and then its row among the coupling rows
  const int n_rows = static_cast<int>(phi_q.rows());
  std::vector<int> row_body(n_rows, -1), coupling_row(n_rows, -1);
  int n_coupling = 0;
  for (size_t c = 0; c < system.constraints().size(); ++c)
  {
    const Constraint& con = system.constraints()[c];
    const ConstraintBodies bodies = constraintKind(con.kind).bodies(con);
    for (int k = 0; k < con.rows(); ++k)
    {
      const int row = system.constraintRow(static_cast<int>(c)) + k;
      if (bodies.count == 1)
        row_body[row] = bodies.body[0];
      else
        coupling_row[row] = n_coupling++;
    }
  }
  std::vector<int> col_body(model.nq);
  for (size_t b = 0; b < model.bodies.size(); ++b)
    for (int i = 0; i < model.bodies[b].nq; ++i)
      col_body[model.bodies[b].offset + i] = static_cast<int>(b);

  // local bases from each body's own rows
  std::vector<Eigen::MatrixXd> own(model.bodies.size());
  std::vector<std::vector<int>> own_rows(model.bodies.size());
  for (int r = 0; r < n_rows; ++r)
    if (row_body[r] >= 0)
      own_rows[row_body[r]].push_back(r);
  for (size_t b = 0; b < model.bodies.size(); ++b)
    own[b] = Eigen::MatrixXd::Zero(own_rows[b].size(), model.bodies[b].nq);
  for (int k = 0; k < phi_q.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(phi_q, k); it; ++it)
    {
      const int b = row_body[it.row()];
      if (b < 0)
        continue;
      const auto at = std::find(own_rows[b].begin(), own_rows[b].end(), static_cast<int>(it.row()));
      own[b](at - own_rows[b].begin(), it.col() - model.bodies[b].offset) += it.value();
    }
  MotionSpace m;
  for (size_t b = 0; b < model.bodies.size(); ++b)
  {
    m.local.push_back(nullSpace(own[b]));
    m.offset.push_back(m.size);
    m.size += static_cast<int>(m.local.back().cols());
  }
  // the coupling rows on T
  m.coupling = Eigen::MatrixXd::Zero(n_coupling, m.size);
  for (int k = 0; k < phi_q.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(phi_q, k); it; ++it)
    {
      const int g = coupling_row[it.row()];
      if (g < 0)
        continue;
      const int b = col_body[it.col()];
      if (m.local[b].cols() == 0)
        continue;  // a body with no motion of its own (and Eigen's row() of an empty matrix offsets a null pointer)
      m.coupling.row(g).segment(m.offset[b], m.local[b].cols()) +=
          it.value() * m.local[b].row(it.col() - model.bodies[b].offset);
    }
  return m;
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

/// The material points whose displacements define the node metric: every node of the model, then every strut
/// end and point mass that no node on a body stands at (models built in code need not name them).
std::vector<PointRef> metricPoints(const Model& model, const Eigen::VectorXd& q)
{
  std::vector<PointRef> points;
  std::vector<Vec3> placed;
  for (const Node& n : model.nodes)
  {
    points.push_back(n.point);
    if (n.point.body >= 0)
      placed.push_back(pointPosition(model, n.point, q));
  }
  for (size_t b = 0; b < model.bodies.size(); ++b)
  {
    const Body& body = model.bodies[b];
    std::vector<Vec3> locals;
    if (body.kind == BodyKind::kStrut)
      locals = { Vec3(0.0, 0.0, -0.5 * body.length), Vec3(0.0, 0.0, 0.5 * body.length) };
    else
      locals = { Vec3::Zero() };
    for (const Vec3& local : locals)
    {
      const PointRef ref{ static_cast<int>(b), local };
      const Vec3 p = pointPosition(model, ref, q);
      const bool known = std::any_of(placed.begin(), placed.end(),
                                     [&](const Vec3& x) { return (x - p).norm() <= 1e-9 * (1.0 + p.norm()); });
      if (!known)
      {
        points.push_back(ref);
        placed.push_back(p);
      }
    }
  }
  return points;
}

/// Adds dir^T B_P (the derivative of dir . p along q) into row.
void addPointGradient(const Model& model, const PointKinematics& k, const Vec3& dir, Eigen::RowVectorXd& row)
{
  if (k.body < 0)
    return;
  row.segment(model.bodies[k.body].offset, k.nq) += dir.transpose() * k.jac.leftCols(k.nq);
}

/// dl/dq of a cable (sum over its segments; a zero-length segment contributes nothing).
Eigen::RowVectorXd lengthGradient(const Model& model, const Cable& cable, const Eigen::VectorXd& q,
                                  const Eigen::VectorXd& zero)
{
  Eigen::RowVectorXd row = Eigen::RowVectorXd::Zero(model.nq);
  std::vector<PointKinematics> kin(cable.points.size());
  for (size_t j = 0; j < cable.points.size(); ++j)
    pointKinematics(model, cable.points[j], q, zero, false, kin[j]);
  for (size_t s = 0; s + 1 < kin.size(); ++s)
  {
    const Vec3 d = kin[s + 1].p - kin[s].p;
    const double len = d.norm();
    if (!(len > 0.0))
      continue;
    const Vec3 n = d / len;
    addPointGradient(model, kin[s + 1], n, row);
    addPointGradient(model, kin[s], -n, row);
  }
  return row;
}

ActuationValues actuationOf(const Model& model, const State& state)
{
  return state.u.size() == model.actuators.size() ? state.u : ActuationValues(model.actuators.size());
}

/// The applied and static contact forces at (q, u), velocities zero; with jac, K = -dF/dq added into it.
void staticForce(const System& system, const Eigen::VectorXd& q, const ActuationValues& u, Eigen::VectorXd& F,
                 BlockSparseMatrix* jac)
{
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(system.nq());
  system.appliedForce(q, zero, u, F, jac, 1.0, 0.0);
  system.contactForce(q, zero, {}, ContactMode::kStatic, F, jac, 1.0, 0.0);
}

ReducedStructure reduce(const Model& model, const State& state, const System& system, const ActuationValues& u)
{
  const int nq = model.nq;
  const Eigen::VectorXd& q = state.q;
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(nq);
  ReducedStructure out;

  // the node map P and the motions the constraints allow
  const std::vector<PointRef> points = metricPoints(model, q);
  const int n_points = static_cast<int>(points.size());
  out.node_rows = 3 * static_cast<int>(model.nodes.size());
  std::vector<Eigen::Triplet<double>> entries;
  for (int i = 0; i < n_points; ++i)
  {
    const PointKinematics k = pointKinematics(model, points[i], q, zero, false);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < k.nq; ++c)
        entries.emplace_back(3 * i + r, model.bodies[k.body].offset + c, k.jac(r, c));
  }
  out.node_map.resize(3 * n_points, nq);
  out.node_map.setFromTriplets(entries.begin(), entries.end());
  const Eigen::SparseMatrix<double> phi_q = constraintJacobian(system, q);
  const MotionSpace space = motionSpace(model, system, phi_q);
  const Eigen::MatrixXd n0 = space.expand(model, nullSpace(space.coupling));  // orthonormal
  const int f = static_cast<int>(n0.cols());

  // orthonormal in the node metric: N = N0 V D^(-1/2) with (P N0)^T (P N0) = V D V^T
  out.basis.resize(nq, f);
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

  // the compatibility matrix C N and its rank
  const int members = static_cast<int>(model.cables.size());
  Eigen::MatrixXd c(members, nq);
  for (int i = 0; i < members; ++i)
    c.row(i) = lengthGradient(model, model.cables[i], q, zero);
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
    for (const PointRef& p : points)
      if (p.body >= 0)
      {
        centre += pointPosition(model, p, q);
        ++moving;
      }
    centre /= std::max(1, moving);
    Eigen::MatrixXd w = Eigen::MatrixXd::Zero(3 * n_points, 6);
    for (int i = 0; i < n_points; ++i)
      if (points[i].body >= 0)
      {
        w.block<3, 3>(3 * i, 0).setIdentity();
        w.block<3, 3>(3 * i, 3) = -skew(pointPosition(model, points[i], q) - centre);
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

  // the force residual with least-squares multipliers: -F + Phi_q^T lambda is minus the part of F in
  // null(Phi_q) (the orthogonal complement of the range of Phi_q^T), N0 N0^T F with N0 orthonormal
  BlockSparseMatrix jac = system.makeMatrix();
  jac.setZero();
  Eigen::VectorXd F;
  staticForce(system, q, u, F, &jac);
  out.residual = (n0 * (n0.transpose() * F)).lpNorm<Eigen::Infinity>();

  // the tangent stiffness on the manifold, with the state's multipliers or the least-squares ones
  if (state.lambda.size() == system.nLambda() && state.lambda.any())
    out.lambda = state.lambda;
  else
  {
    // normal equations Phi_q Phi_q^T lambda = Phi_q F (sparse): the rows are well conditioned, redundant
    // rows make them singular and send it to the dense solve below
    const Eigen::SparseMatrix<double> normal = phi_q * phi_q.transpose();
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(normal);
    if (ldlt.info() == Eigen::Success)
      out.lambda = ldlt.solve(phi_q * F);
    // a consistent system (F less its residual lies in the range of Phi_q^T): else the dense solve
    Eigen::VectorXd reaction;
    if (out.lambda.size() == system.nLambda() && out.lambda.allFinite())
      system.constraintForce(q, out.lambda, reaction);
    if (reaction.size() == 0 ||
        (reaction - F).lpNorm<Eigen::Infinity>() > 2.0 * out.residual + 1e-9 * (1.0 + F.lpNorm<Eigen::Infinity>()))
      out.lambda = leastSquaresMultipliers(system, q, u);
  }
  system.addLambdaHessian(q, out.lambda, jac, 1.0);
  const Eigen::MatrixXd kr = out.basis.transpose() * (coordinateBlock(jac, nq) * out.basis);
  out.stiffness = 0.5 * (kr + kr.transpose());
  return out;
}

/// Eigenvalues of the symmetric a (ascending; empty for an empty a).
Eigen::VectorXd symmetricEigenvalues(const Eigen::MatrixXd& a)
{
  if (a.rows() == 0)
    return Eigen::VectorXd();
  return Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(a, Eigen::EigenvaluesOnly).eigenvalues();
}
}  // namespace

Eigen::SparseMatrix<double> coordinateBlock(const BlockSparseMatrix& m, int nq)
{
  std::vector<Eigen::Triplet<double>> entries;
  const Eigen::SparseMatrix<double>& s = m.matrix();
  for (int k = 0; k < s.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(s, k); it; ++it)
      if (it.row() < nq && it.col() < nq)
        entries.emplace_back(static_cast<int>(it.row()), static_cast<int>(it.col()), it.value());
  Eigen::SparseMatrix<double> out(nq, nq);
  out.setFromTriplets(entries.begin(), entries.end());
  return out;
}

Eigen::MatrixXd rigidComplement(const ReducedStructure& r)
{
  return complement(r.rigid, static_cast<int>(r.basis.cols()));
}

ReducedStructure reduceStructure(const Model& model, const State& state)
{
  if (model.nq > kMaxStructureCoordinates)
    throw std::invalid_argument(std::to_string(model.nq) + " coordinates, more than the limit of " +
                                std::to_string(kMaxStructureCoordinates));
  if (state.q.size() != model.nq)
    throw std::invalid_argument("the state has " + std::to_string(state.q.size()) + " coordinates, the model " +
                                std::to_string(model.nq));
  const System system(model, spinLocksAt(model, state.q));
  return reduce(model, state, system, actuationOf(model, state));
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
    const CableState st = evaluateCable(model, c, state.q, zero, u, false, nullptr, nullptr, 0.0, 0.0);
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
  const System system(model, spinLocksAt(model, q));
  const MotionSpace space = motionSpace(model, system, constraintJacobian(system, q));
  if (space.coupling.rows() == 0)
    return space.size;
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(space.coupling);
  qr.setThreshold(kRankTolerance);
  return space.size - static_cast<int>(qr.rank());
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
  for (const CableState& c : cableStates(model, state))
    largest = std::max(largest, std::abs(c.tension));
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
