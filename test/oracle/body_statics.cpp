#include "active_tensegrity/oracle/body_kinematics.h"
#include "active_tensegrity/oracle/body_rotation.h"
#include "active_tensegrity/oracle/body_statics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Dense>

#include "active_tensegrity/oracle/body_dynamics.h"
#include "active_tensegrity/core/solvers/structure_check.h"

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
/// The damped Newton's budget (factorizations) after a failed correction while the increment can still be cut
/// (at most its own, 4 max_iterations).
constexpr int kPathDampedTrials = 15;

/// Turns every strut about its own axis so that its spin lock holds exactly (its nodes, on the axis, do
/// not move): a state from dynamics, where friction turns struts about their axes, starts statics on
/// its spin-lock rows.
void unspin(const Model& model, Eigen::VectorXd& q)
{
  for (const Body& b : model.bodies)
  {
    if (b.kind != BodyKind::kStrut)
      continue;
    const Eigen::Quaterniond theta = toEigenQuaternion(q.segment<4>(b.offset + 3));
    const Eigen::Quaterniond p = toEigenQuaternion(model.q0.segment<4>(b.offset + 3)).conjugate() * theta;
    const double n = std::hypot(p.w(), p.z());
    if (!(n > 1e-12))
      continue;  // swung by half a turn: the lock cannot tell the spin
    // (p (x) (c, 0, 0, s))_z = p_w s + p_z c = 0
    const Eigen::Quaterniond turn(p.w() / n, 0.0, 0.0, -p.z() / n);
    q.segment<4>(b.offset + 3) = fromEigenQuaternion(theta * turn);
  }
}

/// The branch-jump guard: refuses (status kBranchJump, with the distances) an equilibrium found further than
/// `allowed` (max norm over the coordinates) from the predicted one. True when refused.
bool jumped(const Eigen::VectorXd& found, const Eigen::VectorXd& predicted, double allowed, Summary& attempt)
{
  const double distance = (found - predicted).lpNorm<Eigen::Infinity>();
  if (distance <= allowed)
    return false;
  attempt.status = SolveStatus::kBranchJump;
  std::ostringstream msg;
  msg << "the equilibrium found lies " << distance << " from the predicted one, more than the " << allowed
      << " the increment allows: a jump to another branch of equilibria";
  attempt.message = msg.str();
  return true;
}

void accept(BodyState& s, const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, const ActuationValues& u)
{
  s.q = q;
  s.lambda = lambda;
  s.u = u;
  s.qd.setZero(q.size());
  s.qdd.setZero(q.size());
  s.acc.setZero(q.size());
}

ActuationValues blend(const ActuationValues& a, const ActuationValues& b, double w)
{
  ActuationValues u = a;
  for (size_t i = 0; i < u.size(); ++i)
    u[i].value = (1.0 - w) * a[i].value + w * b[i].value;
  return u;
}
}  // namespace

BodyStaticSolver::BodyStaticSolver(const Model& model, const SolverOptions& options)
  : system_(model, spinLocks(model))
  , options_(options)
  , jac_(system_.makeMatrix())
  , nbodies_(static_cast<int>(model.bodies.size()))
{
  path_linear_.allowDense(true, true);
  linear_.allowDense(true, true);
  if (!model.nodes.empty())
  {
    Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (const Node& n : model.nodes)
    {
      const Vec3 p = pointPosition(model, n.point, model.q0);
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    if ((hi - lo).allFinite())
      wander_bound_ = std::max(2.0, (hi - lo).norm());
  }
  zero_q_.setZero(system_.nq());
  force_rows_.setZero(system_.nLambda());
  for (size_t c = 0; c < system_.constraints().size(); ++c)
    if (system_.constraints()[c].kind == Constraint::Kind::kPoints)
      force_rows_.segment(system_.constraintRow(static_cast<int>(c)), system_.constraints()[c].rows()).setOnes();
}

void BodyStaticSolver::assemble(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, const ActuationValues& u,
                                bool with_jacobian)
{
  const Eigen::VectorXd& zero = zero_q_;
  BlockSparseMatrix* jac = with_jacobian ? &jac_ : nullptr;
  if (jac)
    jac_.setZero();
  {
    const ScopeTimer timer(timings_.forces);
    system_.appliedForce(q, zero, u, F_, jac, 1.0, 0.0);
  }
  {
    const ScopeTimer timer(timings_.contact);
    system_.contactForce(q, zero, {}, ContactMode::kStatic, F_, jac, 1.0, 0.0);
  }
  const ScopeTimer timer(timings_.constraints);
  system_.constraintForce(q, lambda, cforce_);
  system_.constraintValue(q, u, phi_);
  if (jac)
  {
    system_.addLambdaHessian(q, lambda, jac_, 1.0);
    system_.addConstraintJacobian(q, jac_);
  }
  r_.resize(system_.size());
  r_.head(system_.nq()) = cforce_ - F_;
  r_.tail(system_.nLambda()) = phi_;
}

Summary BodyStaticSolver::solve(BodyState& s, const ActuationValues& u)
{
  s.natural = NaturalState();  // (the dynamics' coordinates, which the equilibrium does not keep)
  if (s.lambda.size() != system_.nLambda())
    s.lambda.conservativeResizeLike(Eigen::VectorXd::Zero(system_.nLambda()));
  unspin(system_.model(), s.q);
  Summary plain = newton(s, u);
  if (plain.ok() || plain.status == SolveStatus::kNonFinite)
    return plain;
  Summary damped = dampedNewton(s, u);
  damped.iterations += plain.iterations;
  if (!damped.ok() && plain.status == SolveStatus::kSingular)
  {
    // a mechanism that no load path stiffens: say so, not just "did not converge"
    damped.status = plain.status;
    damped.message = plain.message + "; damped Newton found no equilibrium either";
  }
  return damped;
}

Summary BodyStaticSolver::relax(BodyState& s, const ActuationValues& u_in, long max_steps,
                                const std::function<bool()>& stop)
{
  ActuationValues u = u_in;
  for (ActuationValue& v : u)
    v.rate = v.accel = 0.0;
  BodyState trial = s;
  Summary first = solve(trial, u);
  if (first.ok())
  {
    s = trial;
    return first;
  }
  // dynamic relaxation: the structure moves under its forces at fixed actuation; whenever its kinetic
  // energy falls (a peak passed) every velocity is set to zero, so the motion only ever runs downhill
  // (without friction, which statics does not have: it could hold the structure where no frictionless
  // equilibrium is)
  Model model = system_.model();
  model.contact.friction = 0.0;
  model.solver.adaptive = false;
  BodyDynamicsSolver dyn(model, model.solver);
  const ActuationLaw law = [u](double) { return u; };
  BodyState d = s;
  unspin(model, d.q);
  d.t = 0.0;
  d.u = u;
  d.qd.setZero(model.nq);
  d.lambda.conservativeResizeLike(Eigen::VectorXd::Zero(model.n_lambda));
  Summary total = dyn.initialize(d, law);
  total.iterations += first.iterations;
  double kinetic_before = 0.0;
  long resets = 0;
  int step_cuts = 0;
  long steps = 0;
  for (long k = 1; k <= max_steps && total.ok(); ++k)
  {
    if (stop && stop())
    {
      total.status = SolveStatus::kMaxIterations;
      total.message = "stopped after " + std::to_string(k - 1) + " steps";
      break;
    }
    steps = k;
    const Summary step = dyn.step(d, options_.dt, law);
    total.iterations += step.iterations;
    step_cuts += step.step_cuts;
    if (!step.ok())
    {
      total.status = step.status;
      total.message = step.message;
      break;
    }
    const double kinetic = system_.kineticEnergy(d.q, d.qd);
    if (kinetic < kinetic_before)
    {
      // (zero velocities satisfy the velocity constraints at fixed actuation; the accelerations are the
      // step's business)
      d.qd.setZero();
      ++resets;
      kinetic_before = 0.0;
    }
    else
      kinetic_before = kinetic;
    if (k % 500 == 0 || k == max_steps)
    {
      trial = d;
      trial.qd.setZero();
      unspin(model, trial.q);
      const Summary attempt = newton(trial, u);
      total.iterations += attempt.iterations;
      if (attempt.ok())
      {
        s = trial;
        total.residual = attempt.residual;
        total.step_cuts += step_cuts;
        std::ostringstream msg;
        msg << "found by dynamic relaxation (" << k << " steps, " << resets
            << " velocity resets) after Newton from the "
            << "given state failed";
        total.warnings.push_back(msg.str());
        return total;
      }
    }
  }
  if (total.ok())
    total.status = SolveStatus::kMaxIterations;
  std::ostringstream msg;
  msg << "no equilibrium at this actuation: Newton from the given state failed (" << first.message << "), and so did "
      << steps << " steps of dynamic relaxation (" << resets << " velocity resets"
      << (total.message.empty() ? std::string() : "; " + total.message) << ")";
  total.message = msg.str();
  return total;
}

bool BodyStaticSolver::factorizeFull()
{
  const ScopeTimer timer(timings_.factorization);
  ++timings_.factorizations;
  const bool ok = linear_.factorize(jac_, nbodies_);
  if (linear_.reduced())
    ++timings_.reduced_factorizations;
  timings_.analyses = path_linear_.analyses() + linear_.analyses();
  return ok;
}

Summary BodyStaticSolver::newton(BodyState& s, const ActuationValues& u)
{
  Summary sum;
  const int nq = system_.nq();
  const int nl = system_.nLambda();
  Eigen::VectorXd q = s.q, lambda = s.lambda;
  lambda.conservativeResizeLike(Eigen::VectorXd::Zero(nl));  // a state from dynamics has no spin-lock rows
  int wanders = 0;
  for (int it = 0; it < options_.max_iterations; ++it)
  {
    assemble(q, lambda, u, true);
    ++sum.iterations;
    ++timings_.newton_iterations;
    if (!r_.allFinite())
    {
      sum.status = SolveStatus::kNonFinite;
      sum.message = "non-finite static residual";
      return sum;
    }
    if (r_.lpNorm<Eigen::Infinity>() == 0.0)
    {
      // exactly in equilibrium (e.g. the unstressed start, where the tangent is singular): nothing to do
      accept(s, q, lambda, u);
      return sum;
    }
    if (!factorizeFull())
    {
      sum.status = SolveStatus::kSingular;
      sum.message = "singular static Jacobian: the scene has a mechanism (a motion no force element or "
                    "constraint resists, e.g. a node held only by slack cables) or a degenerate configuration";
      return sum;
    }
    {
      const ScopeTimer timer(timings_.solve);
      linear_.solve(-r_, dx_);
    }
    if (!dx_.allFinite())
    {
      sum.status = SolveStatus::kNonFinite;
      sum.message = "non-finite static Newton increment";
      return sum;
    }
    q += dx_.head(nq);
    lambda += dx_.tail(nl);
    sum.residual = dx_.head(nq).lpNorm<Eigen::Infinity>();
    if (sum.residual <= options_.newton_tolerance)
    {
      accept(s, q, lambda, u);
      return sum;
    }
    // increments larger than the structure (or than 2, a quaternion's whole range) twice: Newton is far outside
    // its region of convergence and the damped Newton takes over (left to run, it wanders through all its
    // iterations, each a factorization; measured on the tower's plans, it never came back from there)
    if (sum.residual > wander_bound_ && ++wanders >= 2)
    {
      sum.status = SolveStatus::kMaxIterations;
      std::ostringstream msg;
      msg << "static Newton diverged (an increment of " << sum.residual << " after " << it + 1
          << " iterations, the second larger than the structure's size " << wander_bound_ << ")";
      sum.message = msg.str();
      return sum;
    }
  }
  sum.status = SolveStatus::kMaxIterations;
  std::ostringstream msg;
  msg << "static Newton did not converge in " << options_.max_iterations << " iterations (last increment "
      << sum.residual << ")";
  sum.message = msg.str();
  return sum;
}

Summary BodyStaticSolver::dampedNewton(BodyState& s, const ActuationValues& u, int max_trials)
{
  // Levenberg-Marquardt with the mass matrix: (K + mu M) dq. A step is kept only when it lowers the
  // residual (forces plus stiffness-scaled constraint violation). Convergence is judged on plain Newton
  // steps (mu = 0) only, so the equilibrium found is that of the exact equations. This finds equilibria that
  // plain Newton misses: an unstressed structure that is a mechanism until its cables take load, a cable
  // about to go taut, a soft mode along which Newton overshoots.
  // Every trial costs a factorization, so mu moves fast: it starts at a tenth of the damping at which the
  // last damped solve of this solver first kept a step (solves near one another, as the planner's, need
  // about the same damping; measured on the tower's plans, starting from the smallest damping every time
  // spent nine rejected trials per solve climbing to it); it grows by 10, 20, 40 ... after rejected steps,
  // falls by 10 after a kept step, by 100 after one that cut the residual tenfold, and drops to plain
  // Newton (0) after one that cut it a hundredfold (Newton's own region); a rejected plain step goes back
  // to the last damping that was kept.
  Summary sum;
  const int nq = system_.nq();
  const int nl = system_.nLambda();
  Eigen::VectorXd q = s.q, lambda = s.lambda;
  lambda.conservativeResizeLike(Eigen::VectorXd::Zero(nl));
  double m_scale = 1e-12;
  for (const Body& b : system_.model().bodies)
    m_scale = std::max(m_scale, b.mass);
  // the stiffest element's axial stiffness converts constraint violations to forces (the tangent at the
  // start may miss it: slack cables)
  double k_scale = 1.0;
  for (const Cable& c : system_.model().cables)
    k_scale = std::max(k_scale, c.stiffness);
  const auto merit = [&]() { return r_.head(nq).lpNorm<Eigen::Infinity>() + k_scale * phi_.lpNorm<Eigen::Infinity>(); };
  assemble(q, lambda, u, true);
  k_scale = std::max(k_scale, jac_.matrix().diagonal().head(nq).cwiseAbs().maxCoeff());
  const double mu_min = 1e-10 * k_scale / m_scale, mu_max = 1e6 * k_scale / m_scale;
  double mu = std::clamp(damped_mu_hint_ / 10.0, mu_min, mu_max), current = merit();
  double kept_mu = mu, growth = 10.0;
  bool first_kept = true;
  // a residual no larger than the force that the position tolerance makes through the stiffest element
  const double merit_tolerance = options_.newton_tolerance * k_scale;
  const int max_iterations = max_trials > 0 ? max_trials : 4 * options_.max_iterations;
  for (int it = 0; it < max_iterations; ++it)
  {
    if (current <= merit_tolerance)
    {
      accept(s, q, lambda, u);
      return sum;
    }
    ++sum.iterations;
    ++timings_.newton_iterations;
    if (!r_.allFinite())
      break;
    if (mu > 0.0)
      system_.addMass(q, jac_, mu);
    const bool factorized = factorizeFull();
    if (factorized)
    {
      const ScopeTimer timer(timings_.solve);
      linear_.solve(-r_, dx_);
    }
    bool kept = false;
    double step = 0.0, trial = std::numeric_limits<double>::infinity();
    if (factorized && dx_.allFinite())
    {
      const Eigen::VectorXd q_try = q + dx_.head(nq), lambda_try = lambda + dx_.tail(nl);
      step = dx_.head(nq).lpNorm<Eigen::Infinity>();
      assemble(q_try, lambda_try, u, false);
      trial = r_.allFinite() ? merit() : std::numeric_limits<double>::infinity();
      if (trial < current || (mu == 0.0 && step <= options_.newton_tolerance))
      {
        kept = true;
        q = q_try;
        lambda = lambda_try;
      }
    }
    if (kept && mu == 0.0 && step <= options_.newton_tolerance)
    {
      sum.residual = step;
      accept(s, q, lambda, u);
      return sum;
    }
    if (kept)
    {
      if (mu > 0.0)
      {
        kept_mu = mu;
        if (first_kept)
          damped_mu_hint_ = mu;
        first_kept = false;
      }
      const double gain = trial > 0.0 ? current / trial : std::numeric_limits<double>::infinity();
      current = trial;
      growth = 10.0;
      mu = gain >= 100.0 ? 0.0 : mu / (gain >= 10.0 ? 100.0 : 10.0);
      if (mu < mu_min)
        mu = 0.0;
    }
    else if (mu == 0.0)
      mu = std::max(kept_mu, mu_min);
    else
    {
      mu *= growth;
      growth *= 2.0;
      if (mu > mu_max)
        break;
    }
    assemble(q, lambda, u, true);
  }
  sum.status = SolveStatus::kMaxIterations;
  std::ostringstream msg;
  msg << "static Newton did not converge, plain or damped (" << max_iterations << " damped iterations; residual "
      << current << ")";
  sum.message = msg.str();
  return sum;
}

ActuationValues BodyStaticSolver::pathPoint(double w)
{
  system_.setLoadFactor(load_start_ + w * (load_end_ - load_start_));
  return blend(path_u_start_, path_u_end_, w);
}

void BodyStaticSolver::parameterDerivative(const Eigen::VectorXd& q, double w, Eigen::VectorXd& out)
{
  // r = [Phi_q^T lambda - F(q, u, f); Phi(q, u)] with u(w) and the load factor f(w): lambda and contact do
  // not depend on w. Phi is affine in u (a driven row is d.(p_a - p_b) - offset - s) and F in f, so their
  // differences are exact; F (a cable pulled in) is smooth in u, and central differences with a pull of
  // 1e-6 m leave about 1e-12 of it.
  double scale = 0.0;
  for (size_t i = 0; i < path_u_start_.size(); ++i)
    scale = std::max(scale, std::abs(path_u_end_[i].value - path_u_start_[i].value));
  out.setZero(system_.size());
  if (scale == 0.0 && load_start_ == load_end_)
    return;
  const double dw = scale > 0.0 ? std::min(1e-3, 1e-6 / scale) : 1e-3;
  const ScopeTimer timer(timings_.forces);
  const ActuationValues plus = pathPoint(w + dw);
  const ActuationValues minus = pathPoint(w - dw);
  pathPoint(w);
  if (load_start_ == load_end_)
  {
    // at a fixed load factor only the cables pulled in by an actuator that moves along the path depend on w
    // (gravity, the loads and the other cables cancel in the difference): two cable evaluations each instead
    // of two whole force evaluations (on the planner's tower, 4 of 28 cables)
    const Model& model = system_.model();
    fplus_.setZero(system_.nq());
    fminus_.setZero(system_.nq());
    for (const Cable& c : model.cables)
      if (c.actuator >= 0 && path_u_end_[c.actuator].value != path_u_start_[c.actuator].value)
      {
        evaluateCable(model, c, q, zero_q_, plus, model.damping_enabled, &fplus_);
        evaluateCable(model, c, q, zero_q_, minus, model.damping_enabled, &fminus_);
      }
  }
  else
  {
    pathPoint(w + dw);  // the load factor
    system_.appliedForce(q, zero_q_, plus, fplus_, nullptr, 0.0, 0.0);
    pathPoint(w - dw);
    system_.appliedForce(q, zero_q_, minus, fminus_, nullptr, 0.0, 0.0);
    pathPoint(w);
  }
  out.head(system_.nq()) = -(fplus_ - fminus_) / (2.0 * dw);
  system_.constraintValue(q, plus, fplus_, true);
  system_.constraintValue(q, minus, fminus_, true);
  out.tail(system_.nLambda()) = (fplus_ - fminus_) / (2.0 * dw);
}

bool BodyStaticSolver::factorizePath(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, const ActuationValues& u,
                                     double w)
{
  assemble(q, lambda, u, true);
  bool ok = false;
  {
    const ScopeTimer timer(timings_.factorization);
    ok = r_.allFinite() && path_linear_.factorize(jac_, nbodies_);
  }
  ++timings_.factorizations;
  if (path_linear_.reduced())
    ++timings_.reduced_factorizations;
  timings_.analyses = path_linear_.analyses() + linear_.analyses();
  path_factor_valid_ = ok;
  path_factor_age_ = 0;
  path_theta_ = 0.0;
  path_factor_q_ = q;
  path_factor_w_ = w;
  path_factor_lambda_ = lambda;
  path_factor_u_ = u;
  path_factor_sign_ = ok ? path_linear_.determinantSign() : 0;
  return ok;
}

void BodyStaticSolver::warnCriticalPoints(Summary& summary) const
{
  // one warning each for the first few; a path through a region of many (a mechanism's slack tower) gets one line
  // for the rest
  constexpr size_t kMaxWarnings = 5;
  for (size_t i = 0; i < std::min(critical_points_.size(), kMaxWarnings); ++i)
  {
    const CriticalPoint& c = critical_points_[i];
    std::ostringstream msg;
    msg << "a critical point (" << c.kind << ") was passed between path parameters " << c.previous_parameter << " and "
        << c.parameter
        << (c.kind == "limit_point" ? ": the path parameter turned back there" :
                                      ": the tangent stiffness changed the sign of its determinant");
    if (c.negative_before >= 0)
      msg << " (reduced stiffness: eigenvalue nearest zero " << c.eigenvalue_before << " -> " << c.eigenvalue_after
          << " N/m, negative eigenvalues " << c.negative_before << " -> " << c.negative_after << ")";
    summary.warnings.push_back(msg.str());
  }
  if (critical_points_.size() > kMaxWarnings)
  {
    std::ostringstream more;
    more << "and " << critical_points_.size() - kMaxWarnings << " more critical points between path parameters "
         << critical_points_[kMaxWarnings].previous_parameter << " and " << critical_points_.back().parameter;
    summary.warnings.push_back(more.str());
  }
}

void BodyStaticSolver::confirmSign(double w)
{
  if (!path_factor_valid_ || path_factor_sign_ == 0)
    return;
  if (sign_ != 0 && path_factor_sign_ != sign_)
  {
    CriticalPoint c;
    c.kind = "bifurcation";
    c.parameter = w;
    c.previous_parameter = sign_parameter_;
    c.sign_before = sign_;
    c.sign_after = path_factor_sign_;
    // the stiffness on both sides (a dense eigenproblem each, at the first kMaxCriticalPointSpectra
    // critical points of a path only)
    BodyState after;
    after.q = path_factor_q_;
    after.lambda = path_factor_lambda_;
    after.u = path_factor_u_;
    const int limit = critical_points_.size() < kMaxCriticalPointSpectra ? kMaxCriticalPointCoordinates : 0;
    const StiffnessSpectrum before_spectrum = stiffnessSpectrum(system_.model(), sign_state_, limit);
    const StiffnessSpectrum after_spectrum = stiffnessSpectrum(system_.model(), after, limit);
    if (before_spectrum.computed && after_spectrum.computed)
    {
      c.eigenvalue_before = before_spectrum.nearest_zero;
      c.eigenvalue_after = after_spectrum.nearest_zero;
      c.negative_before = before_spectrum.negative;
      c.negative_after = after_spectrum.negative;
    }
    critical_points_.push_back(c);
  }
  sign_ = path_factor_sign_;
  sign_parameter_ = path_factor_w_;
  sign_state_.q = path_factor_q_;
  sign_state_.lambda = path_factor_lambda_;
  sign_state_.u = path_factor_u_;
}

bool BodyStaticSolver::pathTangent(const Eigen::VectorXd& q, double w, Eigen::VectorXd& tangent)
{
  if (!path_factor_valid_)
    return false;
  parameterDerivative(q, w, tangent);
  {
    const ScopeTimer timer(timings_.solve);
    path_linear_.solve(-tangent, dx_);
  }
  tangent = dx_;
  return tangent.allFinite();
}

Summary BodyStaticSolver::correct(Eigen::VectorXd& q, Eigen::VectorXd& lambda, const ActuationValues& u, double w,
                                  double predicted_step)
{
  // Modified Newton with the path factorization, rebuilt when it contracts slowly (rate > 0.5), after
  // max_jacobian_age increments, or at every iteration without reuse_jacobian. An iterate is accepted as in
  // dynamics: with a matrix built in this iteration when the increment is within the tolerance; with an
  // older one when the error estimated to be left, theta / (1 - theta) times the scaled increment, is.
  Summary sum;
  const int nq = system_.nq();
  const int nl = system_.nLambda();
  const bool reuse = options_.reuse_jacobian;
  bool rebuild = !reuse || !path_factor_valid_ || path_factor_age_ >= options_.max_jacobian_age;
  double previous = -1.0;
  double fresh_step = 0.0;  // the last increment made with a matrix built in its iteration
  int growths = 0;
  for (int it = 0; it < options_.max_iterations; ++it)
  {
    const bool build = rebuild;
    ++sum.iterations;
    ++timings_.newton_iterations;
    if (build)
    {
      if (!factorizePath(q, lambda, u, w))
      {
        sum.status = r_.allFinite() ? SolveStatus::kSingular : SolveStatus::kNonFinite;
        sum.message = r_.allFinite() ? "singular static Jacobian" : "non-finite static residual";
        return sum;
      }
      previous = -1.0;
      rebuild = !reuse;
    }
    else
      assemble(q, lambda, u, false);
    if (!r_.allFinite())
    {
      sum.status = SolveStatus::kNonFinite;
      sum.message = "non-finite static residual";
      return sum;
    }
    if (r_.lpNorm<Eigen::Infinity>() == 0.0)
      return sum;
    {
      const ScopeTimer timer(timings_.solve);
      r_ = -r_;
      path_linear_.solve(r_, dx_);
    }
    if (!dx_.allFinite())
    {
      sum.status = SolveStatus::kNonFinite;
      sum.message = "non-finite static Newton increment";
      path_factor_valid_ = false;
      return sum;
    }
    const double tol = options_.newton_tolerance;
    const double step = dx_.head(nq).lpNorm<Eigen::Infinity>();
    // An older matrix whose increment is larger than half the predicted step (on a smooth path the
    // prediction is off by the square of the step), or grows from the last one (diverging), is not trusted:
    // a cable gone taut or slack, a contact begun since the matrix was made, changes the stiffness it lacks,
    // and the increment that such a matrix gives can throw the iterate far off the path (seen on the
    // planner's tower: a first correction 150x the prediction error, then divergence). The increment is
    // dropped and the matrix rebuilt where the iterate is.
    if (!build && (step > 0.5 * predicted_step + 100.0 * tol || (previous > 0.0 && step / tol > previous)))
    {
      rebuild = true;
      continue;
    }
    // A fresh matrix whose increment is larger than the whole predicted step: the prediction landed outside
    // Newton's region (a soft mode it overshoots along). Measured on the tower's plans: the corrector never
    // converged after such an increment (where it did, the first fresh increment was at most 0.66 of the
    // predicted step); it wandered through several more factorizations before giving up. The damped Newton
    // of followPath takes over at once.
    if (build && predicted_step > 0.0 && step > predicted_step + 100.0 * tol)
    {
      sum.status = SolveStatus::kMaxIterations;
      std::ostringstream msg;
      msg << "static Newton overshoots (an increment of " << step << " from a predicted step of " << predicted_step
          << ")";
      sum.message = msg.str();
      return sum;
    }
    // Newton's own increments (fresh matrices) that grew twice: the iterate is not in Newton's region of
    // convergence; the full solver's damped Newton is what finds the equilibrium from here (left to run,
    // this loop wanders through all its iterations, a factorization every other one)
    if (build)
    {
      if (fresh_step > 0.0 && step >= fresh_step && ++growths >= 2)
      {
        sum.status = SolveStatus::kMaxIterations;
        std::ostringstream msg;
        msg << "static Newton diverged (its increment grew twice, to " << step << " after " << it + 1 << " iterations)";
        sum.message = msg.str();
        return sum;
      }
      fresh_step = step;
    }
    q += dx_.head(nq);
    lambda += dx_.tail(nl);
    sum.residual = step;
    const double q_part = sum.residual / tol;
    // the multipliers of joints, pins and driven nodes (forces), relative to their size; those of the
    // quaternion norms and spin locks are not judged (they move no point and feed no output)
    const double lambda_part = nl == 0 ? 0.0 :
                                         (dx_.tail(nl).array() * force_rows_.array()).abs().maxCoeff() /
                                             (tol * (1.0 + (lambda.array() * force_rows_.array()).abs().maxCoeff()));
    const double scaled = std::max(q_part, lambda_part);
    bool measured = false;                         // a contraction rate measured in this correction
    if (reuse && previous > 0.0 && scaled > 1e-6)  // (not round-off)
    {
      path_theta_ = std::max(path_theta_, scaled / previous);
      measured = true;
      if (path_theta_ > 0.5)
        rebuild = true;
    }
    const bool second = previous >= 0.0;
    previous = scaled;
    // A matrix built in this iteration: Newton's own step, the increment is the error measure. An older one:
    // the error left is estimated from its contraction rate theta (floored at 0.05), the largest measured with
    // this matrix, as theta / (1 - theta) times the increment. The rate must have been measured in this
    // correction (or the increment have fallen to round-off): a mode that has softened since the matrix was
    // made contracts slowly from a tiny first increment, and accepting that increment leaves an error that
    // adds up over the increments of a path (seen on the tower, 5e-6 m after 600 increments at tolerance 1e-6)
    const double theta = std::max(path_theta_, 0.05);
    const bool converged =
        build ? q_part <= 1.0 :
                (measured && theta / (1.0 - std::min(theta, 0.5)) * scaled <= 1.0) || (second && scaled <= 1e-6);
    if (converged)
      return sum;
    if (scaled > 1e12)
      break;  // diverging
  }
  sum.status = SolveStatus::kMaxIterations;
  std::ostringstream msg;
  msg << "static Newton did not converge in " << options_.max_iterations << " iterations (last increment "
      << sum.residual << ")";
  sum.message = msg.str();
  return sum;
}

Summary BodyStaticSolver::followPath(BodyState& s, const ActuationValues& u_end, int steps,
                                     const std::function<void(const BodyState&, const Summary&)>& on_step)
{
  const ScopeTimer total_timer(timings_.total);
  Summary total;
  critical_points_.clear();
  s.natural = NaturalState();  // (the dynamics' coordinates, which the path does not keep)
  sign_ = 0;
  path_u_start_ = s.u;
  path_u_end_ = u_end;
  if (s.lambda.size() != system_.nLambda())
    s.lambda.conservativeResizeLike(Eigen::VectorXd::Zero(system_.nLambda()));
  s.t = 0.0;  // t carries the path parameter
  const int nq = system_.nq();
  // a factorization kept from an earlier call is used only at the state it ended in
  if (path_factor_valid_ && (path_factor_q_.size() != nq ||
                             (s.q - path_factor_q_).lpNorm<Eigen::Infinity>() > 100.0 * options_.newton_tolerance))
    path_factor_valid_ = false;
  pathPoint(0.0);
  if (!path_factor_valid_)
    factorizePath(s.q, s.lambda, s.u, 0.0);
  path_factor_w_ = 0.0;
  sign_parameter_ = 0.0;
  confirmSign(0.0);
  Eigen::VectorXd tangent, tangent_next;
  bool have_tangent = pathTangent(s.q, 0.0, tangent);
  if (arc_length_)
    return followArcLength(s, steps, on_step, tangent, have_tangent);
  BodyState previous = s;
  bool have_previous = false;
  const double floor = 100.0 * options_.newton_tolerance;
  double w = 0.0;  // path parameter reached
  for (int k = 1; k <= steps; ++k)
  {
    const double w_target = static_cast<double>(k) / steps;
    int cuts = 0;
    while (w < w_target)
    {
      // the increment is the requested one halved `cuts` times; after a success it doubles again
      // (one cut less), and the last piece of a load step lands exactly on its target
      const double dw = std::min(w_target - w, std::ldexp(1.0 / steps, -cuts));
      const double w_next = w_target - (w + dw) <= 1e-9 / steps ? w_target : w + dw;
      const ActuationValues u = pathPoint(w_next);
      // predictor: the tangent, else the secant through the last two equilibria, else the last one
      BodyState trial = s;
      if (have_tangent)
      {
        trial.q += (w_next - w) * tangent.head(nq);
        trial.lambda += (w_next - w) * tangent.tail(system_.nLambda());
      }
      else if (have_previous && previous.t < s.t)
      {
        const double ratio = (w_next - s.t) / (s.t - previous.t);
        trial.q = s.q + ratio * (s.q - previous.q);
        trial.lambda = s.lambda + ratio * (s.lambda - previous.lambda);
      }
      const Eigen::VectorXd predicted = trial.q;
      trial.u = u;
      Summary attempt = correct(trial.q, trial.lambda, u, w_next, (predicted - s.q).lpNorm<Eigen::Infinity>());
      total.iterations += attempt.iterations;
      if (!attempt.ok())
      {
        // the damped Newton from the prediction (the corrector was plain Newton from there): what a barely
        // stressed mechanism, whose matrix is singular or nearly, needs (measured on the planner: cutting the
        // increment instead is cheaper but loses paths the damped Newton finds). Its budget is
        // kPathDampedTrials factorizations while the increment can still be cut, and the full solver (plain,
        // then damped Newton from the last equilibrium) runs only when it cannot: on the planner's tower
        // plans a damped Newton that had not converged in 15 trials rarely did later (21 of 237 ran on, 37
        // factorizations each, and the full solver after them took 35 more to find 8 equilibria), while the
        // halved increment then succeeded; the budget cut the factorizations per increment by 13 %.
        const bool last_chance = cuts >= options_.max_step_cuts;
        trial = s;
        trial.q = predicted;
        unspin(system_.model(), trial.q);
        attempt = dampedNewton(trial, u, last_chance ? 0 : std::min(kPathDampedTrials, 4 * options_.max_iterations));
        total.iterations += attempt.iterations;
        if (!attempt.ok() && last_chance)
        {
          trial = s;
          attempt = solve(trial, u);
          total.iterations += attempt.iterations;
        }
        path_factor_valid_ = false;
      }
      if (attempt.ok() && system_.model().contact.enabled)
      {
        const ScopeTimer timer(timings_.contact);
        const int crossed = system_.firstPassedThrough(s.q, trial.q);
        if (crossed >= 0)
        {
          attempt.status = SolveStatus::kPassedThrough;
          attempt.message = system_.passedThroughMessage(crossed);
        }
      }
      bool have_next = false;
      if (attempt.ok())
      {
        if (!path_factor_valid_)
          factorizePath(trial.q, trial.lambda, u, w_next);
        have_next = pathTangent(trial.q, w_next, tangent_next);
        // branch-jump guard: on a smooth path the corrector moves the prediction by O(dw^2); across a kink
        // (a cable going slack or taut, a contact starting) by at most dw times the change of the tangent;
        // a jump to another branch by a distance that does not shrink with dw
        if (have_tangent && jumped(trial.q, predicted,
                                   (w_next - w) * (tangent.head(nq).lpNorm<Eigen::Infinity>() +
                                                   (have_next ? tangent_next.head(nq).lpNorm<Eigen::Infinity>() : 0.0)) +
                                       floor,
                                   attempt))
          path_factor_valid_ = false;
      }
      if (attempt.ok())
      {
        previous = s;
        have_previous = true;
        trial.t = w_next;
        s = trial;
        w = w_next;
        cuts = std::max(0, cuts - 1);
        total.residual = attempt.residual;
        ++path_factor_age_;
        confirmSign(w);
        if (have_next)
          tangent.swap(tangent_next);
        have_tangent = have_next;
        continue;
      }
      if (!path_factor_valid_)
      {
        pathPoint(w);
        factorizePath(s.q, s.lambda, s.u, w);
        have_tangent = pathTangent(s.q, w, tangent);
      }
      if (++cuts > options_.max_step_cuts)
      {
        total.status = attempt.status;
        std::ostringstream msg;
        msg << attempt.message << "; load step " << k << " of " << steps << " failed at path parameter " << w_next
            << " after " << options_.max_step_cuts << " increment cuts";
        total.message = msg.str();
        break;
      }
      ++total.step_cuts;
    }
    if (!total.ok())
      break;
    if (on_step)
      on_step(s, total);
  }
  warnCriticalPoints(total);
  return total;
}

Summary BodyStaticSolver::followArcLength(BodyState& s, int steps,
                                          const std::function<void(const BodyState&, const Summary&)>& on_step,
                                          Eigen::VectorXd tangent, bool have_tangent)
{
  // Pseudo-arc-length continuation (Keller) in (q, w) with the metric <a, b> = a_q . b_q + psi^2 a_w b_w,
  // psi = |dq/dw| at the start (a unit of w weighs as much as the motion it first causes). The unit tangent
  // T ~ (dq/dw, 1) keeps its orientation from step to step (<T_new, T_old> > 0), so the path goes on
  // through a limit point, where w turns back. Each step: predictor (q, w) + ds T; corrector: full Newton
  // on r(x, w) = 0 bordered by the hyperplane <T, (q, w) - (q0, w0)> = ds.
  Summary total;
  const int nq = system_.nq();
  const int nl = system_.nLambda();
  if (!have_tangent)
  {
    total.status = SolveStatus::kSingular;
    total.message = "arc-length continuation needs a regular start (the tangent stiffness at the start is singular)";
    return total;
  }
  const double psi2 = std::max(tangent.head(nq).squaredNorm(), 1e-12);
  const auto unit = [&](const Eigen::VectorXd& t, double orientation)
  {
    // (T_x, T_w) with T_x = T_w dx/dw (the multipliers ride along), <T, T> = 1
    const double tw = orientation / std::sqrt(t.head(nq).squaredNorm() + psi2);
    return std::make_pair(Eigen::VectorXd(tw * t), tw);
  };
  auto [tx, tw] = unit(tangent, 1.0);
  const double ds_first = std::sqrt(tangent.head(nq).squaredNorm() + psi2) / steps;
  const double ds_max = 4.0 * ds_first;
  const double ds_min = std::ldexp(ds_first, -options_.max_step_cuts);
  const double floor = 100.0 * options_.newton_tolerance;
  const long max_steps = 100L * steps;
  double ds = ds_first;
  double w = 0.0;
  long taken = 0;
  Eigen::VectorXd q, lambda, da, db, rw;
  while (w < 1.0)
  {
    if (++taken > max_steps)
    {
      total.status = SolveStatus::kMaxIterations;
      std::ostringstream msg;
      msg << "arc-length continuation took " << max_steps << " steps without reaching the end of the path (at path "
          << "parameter " << w << ")";
      total.message = msg.str();
      break;
    }
    // the last step lands on w = 1 by the parameter (when the path is going forward and would pass it)
    const bool last = tw > 0.0 && w + ds * tw >= 1.0;
    const double ds_step = last ? (1.0 - w) / tw : ds;
    q = s.q + ds_step * tx.head(nq);
    lambda = s.lambda + ds_step * tx.tail(nl);
    double w_it = last ? 1.0 : w + ds_step * tw;
    const Eigen::VectorXd predicted = q;
    Summary attempt;
    attempt.status = SolveStatus::kMaxIterations;
    for (int it = 0; it < options_.max_iterations; ++it)
    {
      ++attempt.iterations;
      ++timings_.newton_iterations;
      const ActuationValues u = pathPoint(w_it);
      if (!factorizePath(q, lambda, u, w_it))
      {
        attempt.status = r_.allFinite() ? SolveStatus::kSingular : SolveStatus::kNonFinite;
        attempt.message = r_.allFinite() ? "singular static Jacobian" : "non-finite static residual";
        break;
      }
      {
        const ScopeTimer timer(timings_.solve);
        path_linear_.solve(-r_, da);
      }
      double dw = 0.0;
      if (!last)
      {
        parameterDerivative(q, w_it, rw);
        {
          const ScopeTimer timer(timings_.solve);
          path_linear_.solve(-rw, db);
        }
        const double g = ds_step - (tx.head(nq).dot(q - s.q) + psi2 * tw * (w_it - w));
        dw = (g - tx.head(nq).dot(da.head(nq))) / (tx.head(nq).dot(db.head(nq)) + psi2 * tw);
        da += dw * db;
      }
      if (!da.allFinite() || !std::isfinite(dw))
      {
        attempt.status = SolveStatus::kNonFinite;
        attempt.message = "non-finite static Newton increment";
        break;
      }
      q += da.head(nq);
      lambda += da.tail(nl);
      w_it += dw;
      attempt.residual = da.head(nq).lpNorm<Eigen::Infinity>();
      if (attempt.residual <= options_.newton_tolerance)
      {
        attempt.status = SolveStatus::kConverged;
        break;
      }
    }
    if (attempt.ok() && system_.model().contact.enabled)
    {
      const int crossed = system_.firstPassedThrough(s.q, q);
      if (crossed >= 0)
      {
        attempt.status = SolveStatus::kPassedThrough;
        attempt.message = system_.passedThroughMessage(crossed);
      }
    }
    Eigen::VectorXd tangent_next;
    if (attempt.ok() && !pathTangent(q, w_it, tangent_next))
    {
      attempt.status = SolveStatus::kSingular;
      attempt.message = "singular static Jacobian at the new equilibrium";
    }
    std::pair<Eigen::VectorXd, double> next;
    if (attempt.ok())
    {
      next = unit(tangent_next, 1.0);
      if (next.first.head(nq).dot(tx.head(nq)) + psi2 * next.second * tw < 0.0)
        next = unit(tangent_next, -1.0);
      jumped(q, predicted,
             ds_step * (tx.head(nq).lpNorm<Eigen::Infinity>() + next.first.head(nq).lpNorm<Eigen::Infinity>()) + floor,
             attempt);
    }
    if (!attempt.ok())
    {
      total.iterations += attempt.iterations;
      ds *= 0.5;
      ++total.step_cuts;
      if (ds < ds_min)
      {
        total.status = attempt.status;
        std::ostringstream msg;
        msg << attempt.message << "; arc-length step failed at path parameter " << w << " after "
            << options_.max_step_cuts << " cuts";
        total.message = msg.str();
        break;
      }
      pathPoint(w);
      factorizePath(s.q, s.lambda, s.u, w);
      continue;
    }
    total.iterations += attempt.iterations;
    total.residual = attempt.residual;
    // a limit point: the path parameter turned back; the determinant of the tangent changed sign there too
    const size_t known = critical_points_.size();
    confirmSign(w_it);
    if (next.second * tw < 0.0)
    {
      if (critical_points_.size() > known)
        critical_points_.back().kind = "limit_point";
      else
      {
        CriticalPoint c;
        c.kind = "limit_point";
        c.parameter = w_it;
        c.previous_parameter = w;
        critical_points_.push_back(c);
      }
    }
    s.q = q;
    s.lambda = lambda;
    s.u = pathPoint(w_it);
    s.qd.setZero(nq);
    s.qdd.setZero(nq);
    s.acc.setZero(nq);
    s.t = w_it;
    w = w_it;
    tx = next.first;
    tw = next.second;
    if (attempt.iterations <= 3)
      ds = std::min(ds_max, 1.5 * ds);
    if (on_step)
      on_step(s, total);
    if (last)
      break;
  }
  warnCriticalPoints(total);
  return total;
}

double BodyStaticSolver::forceResidual(const BodyState& s)
{
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(system_.nq());
  system_.appliedForce(s.q, zero, s.u, F_, nullptr, 0.0, 0.0);
  system_.contactForce(s.q, zero, {}, ContactMode::kStatic, F_, nullptr, 0.0, 0.0);
  Eigen::VectorXd lambda = s.lambda;
  if (lambda.size() != system_.nLambda())
    lambda.conservativeResizeLike(Eigen::VectorXd::Zero(system_.nLambda()));
  system_.constraintForce(s.q, lambda, cforce_);
  return (cforce_ - F_).lpNorm<Eigen::Infinity>();
}

}  // namespace active_tensegrity::core
