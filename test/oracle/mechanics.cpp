#include "active_tensegrity/oracle/body_kinematics.h"
#include "active_tensegrity/oracle/body_rotation.h"
#include "active_tensegrity/oracle/mechanics.h"

#include "active_tensegrity/oracle/cable_tangents.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace active_tensegrity::core
{
namespace
{
Mat3 inertiaMatrix(const Body& b)
{
  return b.inertia.asDiagonal();
}
}  // namespace

Mat4 rotationalMass(const Body& body, const Vec4& theta)
{
  const Mat34 l = lMatrix(theta);
  return 4.0 * l.transpose() * inertiaMatrix(body) * l;
}

System::System(const Model& model, std::vector<Constraint> extra_constraints) : model_(model), broad_phase_(model)
{
  constraints_ = model.constraints;
  for (Constraint& c : extra_constraints)
    constraints_.push_back(std::move(c));
  zero_q_ = Eigen::VectorXd::Zero(model.nq);
  for (const Cable& c : model.cables)
  {
    cable_first_.push_back(static_cast<int>(cable_points_.size()));
    for (const PointRef& p : c.points)
      cable_points_.push_back(pointSlot(model, p));
  }
  for (const Constraint& c : constraints_)
    constraintKind(c.kind).check(c);
  constraint_slots_.reserve(constraints_.size());
  for (const Constraint& c : constraints_)
  {
    constraint_slots_.push_back(constraintSlot(model, c, n_lambda_, constraint_tables_));
    n_lambda_ += c.rows();
  }

  std::vector<int> sizes;
  for (const Body& b : model.bodies)
    sizes.push_back(b.nq);
  for (const Constraint& c : constraints_)
    sizes.push_back(c.rows());

  std::vector<std::pair<int, int>> blocks;
  auto couple = [&blocks](int g1, int g2)
  {
    blocks.emplace_back(g1, g2);
    blocks.emplace_back(g2, g1);
  };
  for (const Cable& c : model.cables)
    for (size_t i = 0; i < c.points.size(); ++i)
      for (size_t j = i + 1; j < c.points.size(); ++j)
        if (c.points[i].body >= 0 && c.points[j].body >= 0)
          couple(c.points[i].body, c.points[j].body);
  // strut pairs get their blocks when they first touch (contactForce reserves them): a scene with many
  // checked pairs (`auto` on a large lattice) would otherwise start with a nearly dense matrix
  // a constraint's rows couple to its bodies, and its bodies to each other
  for (size_t i = 0; i < constraints_.size(); ++i)
  {
    const ConstraintBodies cb = constraintKind(constraints_[i].kind).bodies(constraints_[i]);
    for (int x = 0; x < cb.count; ++x)
    {
      couple(constraintGroup(static_cast<int>(i)), cb.body[x]);
      for (int y = x + 1; y < cb.count; ++y)
        couple(cb.body[x], cb.body[y]);
    }
  }
  pattern_.init(sizes, blocks);
}

void System::appliedForce(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const ActuationValues& u,
                          Eigen::VectorXd& F, BlockSparseMatrix* jac, double k_weight, double c_weight) const
{
  F.setZero(model_.nq);
  if (model_.gravity_enabled)
    for (const Body& b : model_.bodies)
      F.segment<3>(b.offset) += b.mass * model_.gravity;
  if (jac)
    for (const Cable& c : model_.cables)
      evaluateCableTangents(model_, c, q, qd, u, model_.damping_enabled, &F, jac, k_weight, c_weight);
  else if (!model_.cables.empty())
  {
    // a residual without tangents: each strut's frame once, then every cable point from it
    frames_.update(model_, q, qd);
    point_sum_.reset(model_);
    for (size_t c = 0; c < model_.cables.size(); ++c)
      evaluateCable(model_.cables[c], &cable_points_[cable_first_[c]], frames_, q, qd, u, model_.damping_enabled,
                    point_sum_, F);
    point_sum_.flush(model_, q, F);
  }
  for (const PointLoad& load : model_.loads)
    addPointForce(load.point, load_factor_ * load.force, q, qd, F, jac, k_weight);
  for (const PointLoad& load : external_loads_)
    addPointForce(load.point, load.force, q, qd, F, jac, k_weight);
}

void System::addPointForce(const PointRef& point, const Vec3& force, const Eigen::VectorXd& q,
                           const Eigen::VectorXd& qd, Eigen::VectorXd& F, BlockSparseMatrix* jac, double k_weight) const
{
  if (point.body < 0)
    return;
  const PointKinematics k = pointKinematics(model_, point, q, qd);
  const Body& b = model_.bodies[k.body];
  F.segment(b.offset, b.nq) += k.jac.leftCols(b.nq).transpose() * force;
  if (jac && b.kind == BodyKind::kStrut)
  {
    // K = -d(B^T f)/dq: only the orientation block, -G(u, f)
    Eigen::Matrix<double, 7, 7> kb = Eigen::Matrix<double, 7, 7>::Zero();
    kb.bottomRightCorner<4, 4>() = -pointHessianTheta(point.local, force);
    jac->add(k.body, k.body, kb, k_weight);
  }
}

void System::contactForce(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const SlotValues& impact_speeds,
                          ContactMode mode, Eigen::VectorXd& F, BlockSparseMatrix* jac, double k_weight,
                          double c_weight) const
{
  if (!model_.anyContact())
    return;
  contactCandidates(q, 0.0, candidates_);
  contactForce(candidates_, q, qd, impact_speeds, mode, F, jac, k_weight, c_weight);
}

void System::contactForce(const std::vector<int>& slots, const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                          const SlotValues& impact_speeds, ContactMode mode, Eigen::VectorXd& F, BlockSparseMatrix* jac,
                          double k_weight, double c_weight) const
{
  contribution_.tangents = jac != nullptr;
  for (int i : slots)
  {
    const double v0 = impact_speeds.empty() ? 0.0 : impact_speeds[i];
    if (evaluateContact(model_, i, q, qd, v0, mode, &contribution_).normal_force <= 0.0)
      continue;
    if (model_.isGroundSlot(i))
    {
      const int body = model_.groundContactOf(i).body;
      const Body& b = model_.bodies[body];
      F.segment(b.offset, b.nq) += contribution_.force.head(b.nq);
      if (!jac)
        continue;
      jac->add(body, body, contribution_.stiffness.topLeftCorner(b.nq, b.nq), k_weight);
      if (c_weight != 0.0 && mode == ContactMode::kDynamic)
        jac->add(body, body, contribution_.damping.topLeftCorner(b.nq, b.nq), c_weight);
      continue;
    }
    const auto [body_a, body_b] = model_.pairBodies(i);
    const Body& a = model_.bodies[body_a];
    const Body& b = model_.bodies[body_b];
    F.segment<7>(a.offset) += contribution_.force.head<7>();
    F.segment<7>(b.offset) += contribution_.force.tail<7>();
    if (!jac)
      continue;
    jac->reserve(body_a, body_b);
    const int g[2] = { body_a, body_b };
    for (int x = 0; x < 2; ++x)
      for (int y = 0; y < 2; ++y)
      {
        jac->add(g[x], g[y], contribution_.stiffness.block<7, 7>(7 * x, 7 * y), k_weight);
        if (c_weight != 0.0 && mode == ContactMode::kDynamic)
          jac->add(g[x], g[y], contribution_.damping.block<7, 7>(7 * x, 7 * y), c_weight);
      }
  }
}

void System::contactCandidates(const Eigen::VectorXd& q, double margin, std::vector<int>& out) const
{
  core::contactCandidates(model_, broad_phase_, q, margin, out);
}

void System::nearContacts(const Eigen::VectorXd& q, double reach, std::vector<int>& out,
                          const SlotValues* known_gap) const
{
  near_slots_.find(model_, broad_phase_, q, reach, out, known_gap);
}

int System::firstPassedThrough(const Eigen::VectorXd& q0, const Eigen::VectorXd& q1) const
{
  broad_phase_.candidates(q1, largestMotion(model_, q0, q1), candidates_);
  return firstPassedThrough(candidates_, q0, q1);
}

int System::firstPassedThrough(const std::vector<int>& slots, const Eigen::VectorXd& q0, const Eigen::VectorXd& q1) const
{
  for (int i : slots)
    if (!model_.isGroundSlot(i) && passedThrough(model_, i, q0, q1))
      return i;
  return -1;
}

std::string System::passedThroughMessage(int pair) const
{
  const auto [body_a, body_b] = model_.pairBodies(pair);
  return "struts '" + model_.bodies[body_a].name + "' and '" + model_.bodies[body_b].name +
         "' passed through each other";
}

void System::addMass(const Eigen::VectorXd& q, BlockSparseMatrix& jac, double weight) const
{
  Eigen::Matrix<double, 7, 7> m = Eigen::Matrix<double, 7, 7>::Zero();
  for (size_t i = 0; i < model_.bodies.size(); ++i)
  {
    const Body& b = model_.bodies[i];
    m.setZero();
    m.topLeftCorner<3, 3>() = b.mass * Mat3::Identity();
    if (b.kind == BodyKind::kStrut)
      m.bottomRightCorner<4, 4>() = rotationalMass(b, thetaOf(q, b));
    jac.add(static_cast<int>(i), static_cast<int>(i), m.topLeftCorner(b.nq, b.nq), weight);
  }
}

void System::inertialForce(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const Eigen::VectorXd& qdd,
                           Eigen::VectorXd& out, BlockSparseMatrix* jac, double m_weight, double k_weight,
                           double c_weight) const
{
  out.setZero(model_.nq);
  if (jac && m_weight != 0.0)
    addMass(q, *jac, m_weight);
  for (size_t i = 0; i < model_.bodies.size(); ++i)
  {
    const Body& b = model_.bodies[i];
    out.segment<3>(b.offset) = b.mass * qdd.segment<3>(b.offset);
    if (b.kind != BodyKind::kStrut)
      continue;
    const Vec4 th = thetaOf(q, b);
    const Vec4 thd = thetaOf(qd, b);
    const Vec4 thdd = thetaOf(qdd, b);
    // M_theta thdd = 4 L^T J L thdd;  Qv = 8 L(thd)^T J L(th) thd (the products without forming L)
    const Vec3 w = b.inertia.cwiseProduct(lTimes(th, thdd));
    const Vec3 z = b.inertia.cwiseProduct(lTimes(th, thd));
    out.segment<4>(b.offset + 3) = 4.0 * lMatrixTransposeTimes(th, w) + 8.0 * lMatrixTransposeTimes(thd, z);
    if (!jac)
      continue;
    const Mat3 J = inertiaMatrix(b);
    const Mat34 l = lMatrix(th);
    const Mat34 ld = lMatrix(thd);
    const Mat34 ldd = lMatrix(thdd);
    Eigen::Matrix<double, 7, 7> blk = Eigen::Matrix<double, 7, 7>::Zero();
    // d(M thdd)/dth = 4 N(w) - 4 L^T J L(thdd);  dQv/dth = -8 L(thd)^T J L(thd)
    blk.bottomRightCorner<4, 4>() =
        k_weight * (4.0 * lTransposeTimes(w) - 4.0 * l.transpose() * J * ldd - 8.0 * ld.transpose() * J * ld);
    // dQv/dthd = 8 (N(z) + L(thd)^T J L(th))
    blk.bottomRightCorner<4, 4>() += c_weight * 8.0 * (lTransposeTimes(z) + ld.transpose() * J * l);
    jac->add(static_cast<int>(i), static_cast<int>(i), blk, 1.0);
  }
}

template <class F>
void System::forEachConstraint(F&& f) const
{
  for (size_t i = 0; i < constraints_.size(); ++i)
  {
    const Constraint& c = constraints_[i];
    f(c, constraintKind(c.kind), constraint_slots_[i].row, constraintGroup(static_cast<int>(i)));
  }
}

void System::constraintValue(const Eigen::VectorXd& q, const ActuationValues& u, Eigen::VectorXd& phi,
                             bool driven_only) const
{
  phi.setZero(n_lambda_);
  for (const ConstraintSlot& c : constraint_slots_)
    if (!driven_only || c.actuator >= 0)
      constraintKind(c.kind).value(c, constraint_tables_, q, u, phi);
}

void System::addConstraintJacobian(const Eigen::VectorXd& q, BlockSparseMatrix& jac) const
{
  forEachConstraint([&](const Constraint& c, const ConstraintKindFunctions& kind, int /*row*/, int group)
                    { kind.addJacobian(model_, c, group, q, jac); });
}

Eigen::MatrixXd System::constraintJacobianDense(const Eigen::VectorXd& q) const
{
  BlockSparseMatrix m = makeMatrix();
  addConstraintJacobian(q, m);
  return Eigen::MatrixXd(m.matrix()).bottomLeftCorner(n_lambda_, model_.nq);
}

void System::constraintForce(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, Eigen::VectorXd& out) const
{
  out.setZero(model_.nq);
  for (const ConstraintSlot& c : constraint_slots_)
    constraintKind(c.kind).addForce(c, constraint_tables_, q, lambda, out);
}

void System::addLambdaHessian(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, BlockSparseMatrix& jac,
                              double weight) const
{
  forEachConstraint([&](const Constraint& c, const ConstraintKindFunctions& kind, int row, int /*group*/)
                    { kind.addLambdaHessian(model_, c, q, lambda.segment(row, c.rows()), jac, weight); });
}

void System::velocityRhs(const ActuationValues& u, Eigen::VectorXd& rhs) const
{
  rhs.setZero(n_lambda_);
  forEachConstraint([&](const Constraint& c, const ConstraintKindFunctions& kind, int row, int /*group*/)
                    { kind.velocityRhs(c, u, rhs.segment(row, c.rows())); });
}

void System::accelerationRhs(const Eigen::VectorXd& q, const Eigen::VectorXd& qd, const ActuationValues& u,
                             Eigen::VectorXd& rhs) const
{
  rhs.setZero(n_lambda_);
  forEachConstraint([&](const Constraint& c, const ConstraintKindFunctions& kind, int row, int /*group*/)
                    { kind.accelerationRhs(model_, c, q, qd, u, rhs.segment(row, c.rows())); });
}

double System::kineticEnergy(const Eigen::VectorXd& q, const Eigen::VectorXd& qd) const
{
  double e = 0.0;
  for (const Body& b : model_.bodies)
  {
    e += 0.5 * b.mass * qd.segment<3>(b.offset).squaredNorm();
    if (b.kind == BodyKind::kStrut)
    {
      const Vec4 thd = thetaOf(qd, b);
      e += 0.5 * thd.dot(rotationalMass(b, thetaOf(q, b)) * thd);
    }
  }
  return e;
}

double System::potentialEnergy(const Eigen::VectorXd& q, const ActuationValues& u) const
{
  double e = 0.0;
  const Eigen::VectorXd& zero = zero_q_;
  if (model_.gravity_enabled)
    for (const Body& b : model_.bodies)
      e -= b.mass * model_.gravity.dot(q.segment<3>(b.offset));
  for (const PointLoad& load : model_.loads)
    e -= load_factor_ * load.force.dot(pointPosition(model_, load.point, q));
  for (const PointLoad& load : external_loads_)
    e -= load.force.dot(pointPosition(model_, load.point, q));
  if (model_.anyContact())
  {
    // only touching slots store energy, and the broad phase at margin 0 finds every one of them
    contactCandidates(q, 0.0, candidates_);
    for (int i : candidates_)
    {
      const ContactPairState st = evaluateContact(model_, i, q, zero, 0.0, ContactMode::kStatic, nullptr);
      e += contactElasticEnergy(model_, st);
    }
  }
  for (const Cable& c : model_.cables)
    e += cablePotentialEnergy(c, evaluateCable(model_, c, q, zero, u, false));
  return e;
}

}  // namespace active_tensegrity::core
