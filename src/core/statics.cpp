#include "active_tensegrity/core/statics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Dense>

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

namespace
{
void accept(State& s, const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, const ActuationValues& u)
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

StaticSolver::StaticSolver(const Model& model, const SolverOptions& options)
  : system_(model, spinLocks(model)), options_(options), jac_(system_.makeMatrix())
{
}

void StaticSolver::assemble(const Eigen::VectorXd& q, const Eigen::VectorXd& lambda, const ActuationValues& u,
                            bool with_jacobian)
{
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(system_.nq());
  BlockSparseMatrix* jac = with_jacobian ? &jac_ : nullptr;
  if (jac)
    jac_.setZero();
  system_.appliedForce(q, zero, u, F_, jac, 1.0, 0.0);
  system_.contactForce(q, zero, {}, ContactMode::kStatic, F_, jac, 1.0, 0.0);
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

Summary StaticSolver::solve(State& s, const ActuationValues& u)
{
  if (s.lambda.size() != system_.nLambda())
    s.lambda.conservativeResizeLike(Eigen::VectorXd::Zero(system_.nLambda()));
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

Summary StaticSolver::newton(State& s, const ActuationValues& u)
{
  Summary sum;
  const int nq = system_.nq();
  const int nl = system_.nLambda();
  Eigen::VectorXd q = s.q, lambda = s.lambda;
  for (int it = 0; it < options_.max_iterations; ++it)
  {
    assemble(q, lambda, u, true);
    ++sum.iterations;
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
    if (!linear_.factorize(jac_.matrix()))
    {
      sum.status = SolveStatus::kSingular;
      sum.message = "singular static Jacobian: the scene has a mechanism (a motion no force element or "
                    "constraint resists, e.g. a node held only by slack cables) or a degenerate configuration";
      return sum;
    }
    linear_.solve(-r_, dx_);
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
  }
  sum.status = SolveStatus::kMaxIterations;
  std::ostringstream msg;
  msg << "static Newton did not converge in " << options_.max_iterations << " iterations (last increment "
      << sum.residual << ")";
  sum.message = msg.str();
  return sum;
}

Summary StaticSolver::dampedNewton(State& s, const ActuationValues& u)
{
  // Levenberg-Marquardt with the mass matrix: (K + mu M) dq. A step is kept only when it lowers the
  // residual (forces plus stiffness-scaled constraint violation); mu shrinks after a kept step and
  // grows after a rejected one. Convergence is judged on plain Newton steps (mu = 0) only, so the
  // equilibrium found is that of the exact equations. This finds equilibria that plain Newton misses:
  // an unstressed structure that is a mechanism until its cables take load, a cable about to go taut.
  Summary sum;
  const int nq = system_.nq();
  const int nl = system_.nLambda();
  Eigen::VectorXd q = s.q, lambda = s.lambda;
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
  double mu = mu_min, current = merit();
  // a residual no larger than the force that the position tolerance makes through the stiffest element
  const double merit_tolerance = options_.newton_tolerance * k_scale;
  const int max_iterations = 4 * options_.max_iterations;
  for (int it = 0; it < max_iterations; ++it)
  {
    if (current <= merit_tolerance)
    {
      accept(s, q, lambda, u);
      return sum;
    }
    ++sum.iterations;
    if (!r_.allFinite())
      break;
    if (mu > 0.0)
      system_.addMass(q, jac_, mu);
    const bool factorized = linear_.factorize(jac_.matrix());
    if (factorized)
      linear_.solve(-r_, dx_);
    bool kept = false;
    double step = 0.0;
    if (factorized && dx_.allFinite())
    {
      const Eigen::VectorXd q_try = q + dx_.head(nq), lambda_try = lambda + dx_.tail(nl);
      step = dx_.head(nq).lpNorm<Eigen::Infinity>();
      assemble(q_try, lambda_try, u, false);
      const double trial = r_.allFinite() ? merit() : std::numeric_limits<double>::infinity();
      if (trial < current || (mu == 0.0 && step <= options_.newton_tolerance))
      {
        kept = true;
        q = q_try;
        lambda = lambda_try;
        current = trial;
      }
    }
    if (kept && mu == 0.0 && step <= options_.newton_tolerance)
    {
      sum.residual = step;
      accept(s, q, lambda, u);
      return sum;
    }
    if (kept)
      mu = mu > mu_min ? mu / 10.0 : 0.0;
    else
    {
      mu = mu == 0.0 ? mu_min : 10.0 * mu;
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

Summary StaticSolver::followPath(State& s, const ActuationValues& u_end, int steps,
                                 const std::function<void(const State&, const Summary&)>& on_step)
{
  Summary total;
  const ActuationValues u_start = s.u;
  s.t = 0.0;  // t carries the path parameter
  State previous = s;
  bool have_previous = false;
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
      const ActuationValues u = blend(u_start, u_end, w_next);
      // secant predictor from the last two equilibria, then a plain warm start
      State trial = s;
      Summary attempt;
      attempt.status = SolveStatus::kMaxIterations;
      if (have_previous && previous.t < s.t)
      {
        const double ratio = (w_next - s.t) / (s.t - previous.t);
        trial.q = s.q + ratio * (s.q - previous.q);
        trial.lambda = s.lambda + ratio * (s.lambda - previous.lambda);
        attempt = solve(trial, u);
        total.iterations += attempt.iterations;
      }
      if (!attempt.ok())
      {
        trial = s;
        attempt = solve(trial, u);
        total.iterations += attempt.iterations;
      }
      if (attempt.ok() && system_.model().contact.enabled)
      {
        const int crossed = system_.firstPassedThrough(s.q, trial.q);
        if (crossed >= 0)
        {
          attempt.status = SolveStatus::kPassedThrough;
          attempt.message = system_.passedThroughMessage(crossed);
        }
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
        continue;
      }
      if (++cuts > options_.max_step_cuts)
      {
        total.status = attempt.status;
        std::ostringstream msg;
        msg << attempt.message << "; load step " << k << " of " << steps << " failed at path parameter " << w_next
            << " after " << options_.max_step_cuts << " increment cuts";
        total.message = msg.str();
        return total;
      }
      ++total.step_cuts;
    }
    if (on_step)
      on_step(s, total);
  }
  return total;
}

double StaticSolver::forceResidual(const State& s)
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

Eigen::VectorXd leastSquaresMultipliers(const System& system, const Eigen::VectorXd& q, const ActuationValues& u)
{
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(system.nq());
  Eigen::VectorXd F;
  system.appliedForce(q, zero, u, F, nullptr, 0.0, 0.0);
  system.contactForce(q, zero, {}, ContactMode::kStatic, F, nullptr, 0.0, 0.0);
  const Eigen::MatrixXd jt = system.constraintJacobianDense(q).transpose();
  return jt.colPivHouseholderQr().solve(F);
}

}  // namespace active_tensegrity::core
