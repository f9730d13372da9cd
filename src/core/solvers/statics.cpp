#include "active_tensegrity/core/solvers/statics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/SparseCholesky>

#include "active_tensegrity/core/solvers/natural.h"
#include "active_tensegrity/core/solvers/structure_check.h"

namespace active_tensegrity::core
{
namespace
{
/// The damped Newton's budget (factorizations) after a failed correction while the increment can still be cut
/// (at most its own, 4 max_iterations).
constexpr int kPathDampedTrials = 15;

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

std::string passedThroughMessage(const Model& model, int pair)
{
  const auto [body_a, body_b] = model.pairBodies(pair);
  return "struts '" + model.bodies[body_a].name + "' and '" + model.bodies[body_b].name + "' passed through each other";
}

ActuationValues blend(const ActuationValues& a, const ActuationValues& b, double w)
{
  ActuationValues u = a;
  for (size_t i = 0; i < u.size(); ++i)
    u[i].value = (1.0 - w) * a[i].value + w * b[i].value;
  return u;
}

/// `sum` failed with `status` and `message`.
Summary failed(Summary sum, SolveStatus status, const std::string& message)
{
  sum.status = status;
  sum.message = message;
  return sum;
}

/// Newton ran out of iterations: `sum` (its residual, the last increment) says so.
Summary notConverged(Summary sum, int max_iterations)
{
  std::ostringstream msg;
  msg << "static Newton did not converge in " << max_iterations << " iterations (last increment " << sum.residual
      << ")";
  return failed(sum, SolveStatus::kMaxIterations, msg.str());
}

ActuationValues atRest(ActuationValues u)
{
  for (ActuationValue& v : u)
    v.rate = v.accel = 0.0;
  return u;
}
}  // namespace

struct StaticSolver::Impl
{
  Impl(const Model& m, const SolverOptions& o)
    : model(m)
    , nm(buildNaturalModel(model, false))
    , solver(nm, o)
    , options(o)
    , n(nm.coordinates)
    , rows(static_cast<int>(nm.struts.size() + nm.rows.size()))
  {
    if (!nm.nodes.empty())
    {
      Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
      for (const NaturalNode& node : nm.nodes)
      {
        lo = lo.cwiseMin(node.position0);
        hi = hi.cwiseMax(node.position0);
      }
      if ((hi - lo).allFinite())
        wander_bound = std::max(2.0, (hi - lo).norm());
    }
    mass_scale = nm.mass.nonZeros() > 0 ? nm.mass.coeffs().cwiseAbs().maxCoeff() : 1.0;
  }

  Model model;  // the natural model points at it
  NaturalModel nm;
  NaturalSolver solver;
  SolverOptions options;
  int n = 0;     // coordinates
  int rows = 0;  // multipliers
  StepTimings timings;
  ActuationValues path_u_start, path_u_end;  // the path being followed: u(w) between them
  double load_start = 1.0, load_end = 1.0;   // ... and the load factor f(w)
  bool arc_length = false;
  // the continuation's tangent factorization (the solver's one factorization, while no other replaced it)
  bool path_factor_valid = false;
  int path_factor_age = 0;  // load increments since it was made
  double path_theta = 0.0;  // largest contraction rate measured with it
  Eigen::VectorXd path_factor_x, path_factor_lambda;
  double path_factor_w = 0.0;
  ActuationValues path_factor_u;
  int path_factor_sign = 0;
  int sign = 0;                 // the path's determinant sign at the last accepted equilibrium (0: none yet)
  double sign_parameter = 0.0;  // the path parameter of the factorization that showed it
  Eigen::VectorXd sign_x;       // ... and the configuration it was made at
  ActuationValues sign_u;
  std::vector<CriticalPoint> critical_points;
  double damped_mu_hint = 0.0;  // the damping at which the last damped Newton first kept a step
  double wander_bound = 2.0;    // the diagonal of the nodes' bounding box at the start, at least 2
  double mass_scale = 1.0;      // the mass matrix's largest entry
  Eigen::VectorXd rhs, dx, fplus, fminus;

  const Eigen::VectorXd& r() const
  {
    return solver.staticResidual();
  }
  void sync()
  {
    const NaturalStats& st = solver.stats();
    timings.forces = st.forces_time;
    timings.contact = st.contact_time + pass_time;
    timings.constraints = st.constraints_time;
    timings.factorization = st.factorization_time;
    timings.solve = solve_time;
    timings.factorizations = st.factorizations;
    timings.analyses = st.analyses;
  }
  void assemble(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, const ActuationValues& u, bool jacobian)
  {
    solver.assembleStatic(x, lambda, u, jacobian);
  }
  void solve(const Eigen::VectorXd& b, Eigen::VectorXd& out)
  {
    const ScopeTimer timer(solve_time);
    solver.solve(b, out);
  }
  double solve_time = 0.0;  // s, in triangular solves
  double pass_time = 0.0;   // s, in the pass-through checks

  /// The natural coordinates the state starts from: its own when it carries this model's, else formed from its body
  /// poses (multipliers zero).
  void start(const State& s, Eigen::VectorXd& x, Eigen::VectorXd& lambda) const
  {
    if (carriesNaturalOf(nm, s) && s.natural.lambda.size() == rows)
    {
      x = s.natural.x;
      lambda = s.natural.lambda;
      return;
    }
    State copy;
    copy.q = s.q;
    copy.qd = Eigen::VectorXd::Zero(s.q.size());
    copy.u = s.u;
    naturalFromBody(nm, copy);
    x = copy.natural.x;
    lambda.setZero(rows);
  }
  /// s becomes the equilibrium (x, lambda) under u: its natural coordinates, their body poses, contacts and
  /// actuator forces.
  void accept(State& s, const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, const ActuationValues& u)
  {
    const bool own =
        carriesNaturalOf(nm, s) && s.natural.frame_spin.size() == static_cast<Eigen::Index>(nm.struts.size());
    NaturalState& a = s.natural;
    if (!own)
    {
      // (the body frames as they are: no spin integrated since)
      a.frame_spin.setZero(static_cast<Eigen::Index>(nm.struts.size()));
      for (const NaturalStrut& st : nm.struts)
        if (st.spin >= 0)
          a.frame_spin(&st - nm.struts.data()) = x(st.spin);
    }
    a.x = x;
    a.lambda = lambda;
    a.v.setZero(n);
    a.a.setZero(n);
    a.qdd.setZero(n);
    a.t = s.t;
    a.touching.clear();
    a.equilibrium = true;
    s.u = atRest(u);
    writeBodyPoses(nm, s);
    solver.staticContacts(x, s.u, a.contacts);
    solver.actuationForces(a, s.u, a.actuator_force);
  }

  ActuationValues pathPoint(double w)
  {
    solver.setLoadFactor(load_start + w * (load_end - load_start));
    return blend(path_u_start, path_u_end, w);
  }

  bool factorizeFull()
  {
    path_factor_valid = false;  // (replaced)
    return solver.factorizeStatic();
  }
  bool factorizePath(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, const ActuationValues& u, double w)
  {
    assemble(x, lambda, u, true);
    const bool ok = r().allFinite() && solver.factorizeStatic();
    path_factor_valid = ok;
    path_factor_age = 0;
    path_theta = 0.0;
    path_factor_x = x;
    path_factor_w = w;
    path_factor_lambda = lambda;
    path_factor_u = u;
    path_factor_sign = ok ? solver.determinantSign() : 0;
    return ok;
  }

  Summary newton(Eigen::VectorXd& x, Eigen::VectorXd& lambda, const ActuationValues& u);
  Summary dampedNewton(Eigen::VectorXd& x, Eigen::VectorXd& lambda, const ActuationValues& u, int max_trials = 0);
  Summary solveFrom(Eigen::VectorXd& x, Eigen::VectorXd& lambda, const ActuationValues& u);
  void parameterDerivative(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, double w, Eigen::VectorXd& out);
  bool pathTangent(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, double w, Eigen::VectorXd& tangent);
  Summary correct(Eigen::VectorXd& x, Eigen::VectorXd& lambda, const ActuationValues& u, double w,
                  double predicted_step);
  void confirmSign(double w);
  void warnCriticalPoints(Summary& summary) const;
  Summary followArcLength(State& s, int steps, const std::function<void(const State&, const Summary&)>& on_step,
                          Eigen::VectorXd tangent, bool have_tangent);
  int passedThrough(const Eigen::VectorXd& x0, const ActuationValues& u0, const Eigen::VectorXd& x1,
                    const ActuationValues& u1)
  {
    const ScopeTimer timer(pass_time);
    return solver.passedThrough(x0, u0, x1, u1);
  }
  /// A body-pose state at (x, u) for the stiffness spectra (multipliers left to structure_check's least squares).
  State bodyState(const Eigen::VectorXd& x, const ActuationValues& u) const
  {
    State b;
    b.q = naturalToBodyCoordinates(nm, x, u);
    b.qd.setZero(b.q.size());
    b.u = u;
    b.natural.x = x;  // (its own coordinates: reduceStructure takes them as they are)
    b.natural.v.setZero(x.size());
    return b;
  }
};

StaticSolver::StaticSolver(const Model& model, const SolverOptions& options)
  : impl_(std::make_unique<Impl>(model, options))
{
}
StaticSolver::~StaticSolver() = default;
StaticSolver::StaticSolver(StaticSolver&&) noexcept = default;
StaticSolver& StaticSolver::operator=(StaticSolver&&) noexcept = default;

const Model& StaticSolver::model() const
{
  return impl_->model;
}

void StaticSolver::setLoadPath(double start, double end)
{
  impl_->load_start = start;
  impl_->load_end = end;
  impl_->solver.setLoadFactor(start);
}

void StaticSolver::setArcLength(bool on)
{
  impl_->arc_length = on;
}

const std::vector<CriticalPoint>& StaticSolver::criticalPoints() const
{
  return impl_->critical_points;
}

const StepTimings& StaticSolver::timings() const
{
  impl_->sync();
  return impl_->timings;
}

Summary StaticSolver::solve(State& s, const ActuationValues& u_in)
{
  Impl& m = *impl_;
  const ScopeTimer timer(m.timings.total);
  const ActuationValues u = atRest(u_in);
  Eigen::VectorXd x, lambda;
  m.start(s, x, lambda);
  const Eigen::VectorXd x0 = x;
  Summary out = m.solveFrom(x, lambda, u);
  // Newton's way to the equilibrium is no motion, but one that passes struts through each other lands where the
  // structure cannot go from the state given
  if (const int crossed = out.ok() ? m.passedThrough(x0, u, x, u) : -1; crossed >= 0)
  {
    out.status = SolveStatus::kPassedThrough;
    out.message =
        "the equilibrium Newton found is on the far side of a contact: " + passedThroughMessage(m.model, crossed) +
        " between the given state and it";
  }
  if (out.ok())
    m.accept(s, x, lambda, u);
  return out;
}

Summary StaticSolver::Impl::solveFrom(Eigen::VectorXd& x, Eigen::VectorXd& lambda, const ActuationValues& u)
{
  Eigen::VectorXd x0 = x, lambda0 = lambda;
  Summary plain = newton(x, lambda, u);
  if (plain.ok() || plain.status == SolveStatus::kNonFinite)
    return plain;
  x = x0;
  lambda = lambda0;
  Summary damped = dampedNewton(x, lambda, u);
  damped.iterations += plain.iterations;
  if (!damped.ok() && plain.status == SolveStatus::kSingular)
  {
    // a mechanism that no load path stiffens: say so, not just "did not converge"
    damped.status = plain.status;
    damped.message = plain.message + "; damped Newton found no equilibrium either";
  }
  return damped;
}

Summary StaticSolver::relax(State& s, const ActuationValues& u_in, long max_steps, const std::function<bool()>& stop)
{
  Impl& m = *impl_;
  const ActuationValues u = atRest(u_in);
  State trial = s;
  Summary first = solve(trial, u);
  if (first.ok())
  {
    s = trial;
    return first;
  }
  // dynamic relaxation: the structure moves under its forces at fixed actuation; whenever its kinetic energy falls
  // (a peak passed) every velocity is set to zero, so the motion only ever runs downhill (without friction, which
  // statics does not have: it could hold the structure where no frictionless equilibrium is)
  Model model = m.model;
  model.contact.friction = 0.0;
  model.solver.adaptive = false;
  const NaturalModel nm = buildNaturalModel(model);
  NaturalSolver dyn(nm, model.solver);
  const ActuationLaw law = ActuationLaw::writing([&u](double, ActuationValues& out) { out = u; });
  Eigen::VectorXd x0, lambda0;
  m.start(s, x0, lambda0);
  NaturalState d;
  d.t = 0.0;
  d.x.setZero(nm.coordinates);
  d.x.head(nm.positions) = x0.head(nm.positions);  // (the positions come first in both; no spin rates here)
  d.v.setZero(nm.coordinates);
  d.a.setZero(nm.coordinates);
  d.qdd.setZero(nm.coordinates);
  d.lambda.setZero(m.rows);
  Summary total = dyn.project(d, u);
  if (total.ok())
    total = dyn.initialize(d, law);
  total.iterations += first.iterations;
  double kinetic_before = 0.0;
  long resets = 0;
  int step_cuts = 0;
  long steps = 0;
  Eigen::VectorXd x = x0, lambda;
  for (long k = 1; k <= max_steps && total.ok(); ++k)
  {
    if (stop && stop())
    {
      total.status = SolveStatus::kMaxIterations;
      total.message = "stopped after " + std::to_string(k - 1) + " steps";
      break;
    }
    steps = k;
    const Summary step = dyn.step(d, m.options.dt, law);
    total.iterations += step.iterations;
    step_cuts += step.step_cuts;
    if (!step.ok())
    {
      total.status = step.status;
      total.message = step.message;
      break;
    }
    const double kinetic = 0.5 * d.v.dot(nm.mass * d.v);
    if (kinetic < kinetic_before)
    {
      // (zero velocities satisfy the velocity constraints at fixed actuation; the accelerations are the step's
      // business)
      d.v.setZero();
      ++resets;
      kinetic_before = 0.0;
    }
    else
      kinetic_before = kinetic;
    if (k % 500 == 0 || k == max_steps)
    {
      x.head(nm.positions) = d.x.head(nm.positions);
      lambda = d.lambda;
      const Summary attempt = m.newton(x, lambda, u);
      total.iterations += attempt.iterations;
      if (attempt.ok())
      {
        m.accept(s, x, lambda, u);
        total.residual = attempt.residual;
        total.step_cuts += step_cuts;
        std::ostringstream msg;
        msg << "found by dynamic relaxation (" << k << " steps, " << resets
            << " velocity resets) after Newton from the given state failed";
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

Summary StaticSolver::Impl::newton(Eigen::VectorXd& x, Eigen::VectorXd& lambda, const ActuationValues& u)
{
  Summary sum;
  int wanders = 0;
  Eigen::VectorXd xt = x, lt = lambda;
  for (int it = 0; it < options.max_iterations; ++it)
  {
    assemble(xt, lt, u, true);
    ++sum.iterations;
    ++timings.newton_iterations;
    if (!r().allFinite())
      return failed(sum, SolveStatus::kNonFinite, "non-finite static residual");
    if (r().lpNorm<Eigen::Infinity>() == 0.0)
    {
      // exactly in equilibrium (e.g. the unstressed start, where the tangent is singular): nothing to do
      x = xt;
      lambda = lt;
      return sum;
    }
    if (!factorizeFull())
    {
      sum.status = SolveStatus::kSingular;
      sum.message = "singular static Jacobian: the scene has a mechanism (a motion no force element or "
                    "constraint resists, e.g. a node held only by slack cables) or a degenerate configuration";
      return sum;
    }
    rhs = -r();
    solve(rhs, dx);
    if (!dx.allFinite())
      return failed(sum, SolveStatus::kNonFinite, "non-finite static Newton increment");
    xt += dx.head(n);
    lt += dx.tail(rows);
    sum.residual = dx.head(n).lpNorm<Eigen::Infinity>();
    if (sum.residual <= options.newton_tolerance)
    {
      x = xt;
      lambda = lt;
      return sum;
    }
    // increments larger than the structure twice: Newton is far outside its region of convergence and the damped
    // Newton takes over (left to run, it wanders through all its iterations, each a factorization)
    if (sum.residual > wander_bound && ++wanders >= 2)
    {
      sum.status = SolveStatus::kMaxIterations;
      std::ostringstream msg;
      msg << "static Newton diverged (an increment of " << sum.residual << " after " << it + 1
          << " iterations, the second larger than the structure's size " << wander_bound << ")";
      sum.message = msg.str();
      return sum;
    }
  }
  return notConverged(sum, options.max_iterations);
}

Summary StaticSolver::Impl::dampedNewton(Eigen::VectorXd& x_io, Eigen::VectorXd& lambda_io, const ActuationValues& u,
                                         int max_trials)
{
  // Levenberg-Marquardt with the mass matrix: (K + mu M) dx. A step is kept only when it lowers the residual (forces
  // plus stiffness-scaled constraint violation). Convergence is judged on plain Newton steps (mu = 0) only, so the
  // equilibrium found is that of the exact equations. This finds equilibria that plain Newton misses: an unstressed
  // structure that is a mechanism until its cables take load, a cable about to go taut, a soft mode along which Newton
  // overshoots.
  // Every trial costs a factorization, so mu moves fast: it starts at a tenth of the damping at which the last damped
  // solve of this solver first kept a step (solves near one another, as the planner's, need about the same damping);
  // it grows by 10, 20, 40 ... after rejected steps, falls by 10 after a kept step, by 100 after one that cut the
  // residual tenfold, and drops to plain Newton (0) after one that cut it a hundredfold (Newton's own region); a
  // rejected plain step goes back to the last damping that was kept.
  Summary sum;
  Eigen::VectorXd x = x_io, lambda = lambda_io;
  // the stiffest element's axial stiffness converts constraint violations to forces (the tangent at the start may
  // miss it: slack cables); a strut's row |r_b - r_a|^2 - L^2 is 2 L times its length's violation
  double k_scale = 1.0;
  for (const Cable& c : model.cables)
    k_scale = std::max(k_scale, c.stiffness);
  double phi_scale = 0.0;  // 1 / (2 L) of the shortest strut, 1 without struts
  for (const NaturalStrut& st : nm.struts)
    phi_scale = std::max(phi_scale, 0.5 / st.length);
  if (phi_scale == 0.0)
    phi_scale = 1.0;
  const auto merit = [&]()
  {
    return r().head(n).lpNorm<Eigen::Infinity>() +
           k_scale *
               std::max(rows > static_cast<int>(nm.struts.size()) ?
                            r().tail(rows - static_cast<int>(nm.struts.size())).lpNorm<Eigen::Infinity>() :
                            0.0,
                        phi_scale *
                            r().segment(n, static_cast<Eigen::Index>(nm.struts.size())).lpNorm<Eigen::Infinity>());
  };
  assemble(x, lambda, u, true);
  k_scale = std::max(k_scale, solver.assembledDiagonal().head(nm.positions).cwiseAbs().maxCoeff());
  const double mu_min = 1e-10 * k_scale / mass_scale, mu_max = 1e6 * k_scale / mass_scale;
  double mu = std::clamp(damped_mu_hint / 10.0, mu_min, mu_max), current = merit();
  double kept_mu = mu, growth = 10.0;
  bool first_kept = true;
  // a residual no larger than the force that the position tolerance makes through the stiffest element
  const double merit_tolerance = options.newton_tolerance * k_scale;
  const int max_iterations = max_trials > 0 ? max_trials : 4 * options.max_iterations;
  for (int it = 0; it < max_iterations; ++it)
  {
    if (current <= merit_tolerance)
    {
      // a residual of the position tolerance times the stiffest element can still be far off the equilibrium along a
      // soft mode (a mechanism's, stiffened only by prestress): plain Newton from here takes it the rest of the way
      Eigen::VectorXd xp = x, lp = lambda;
      const Summary polish = newton(xp, lp, u);
      sum.iterations += polish.iterations;
      if (polish.ok())
      {
        sum.residual = polish.residual;
        x_io = xp;
        lambda_io = lp;
        return sum;
      }
      x_io = x;
      lambda_io = lambda;
      return sum;
    }
    ++sum.iterations;
    ++timings.newton_iterations;
    if (!r().allFinite())
      break;
    if (mu > 0.0)
      solver.addStaticMass(mu);
    const bool factorized = factorizeFull();
    if (factorized)
    {
      rhs = -r();
      solve(rhs, dx);
    }
    bool kept = false;
    double step = 0.0, trial = std::numeric_limits<double>::infinity();
    if (factorized && dx.allFinite())
    {
      const Eigen::VectorXd x_try = x + dx.head(n), lambda_try = lambda + dx.tail(rows);
      step = dx.head(n).lpNorm<Eigen::Infinity>();
      assemble(x_try, lambda_try, u, false);
      trial = r().allFinite() ? merit() : std::numeric_limits<double>::infinity();
      if (trial < current || (mu == 0.0 && step <= options.newton_tolerance))
      {
        kept = true;
        x = x_try;
        lambda = lambda_try;
      }
    }
    if (kept && mu == 0.0 && step <= options.newton_tolerance)
    {
      sum.residual = step;
      x_io = x;
      lambda_io = lambda;
      return sum;
    }
    if (kept)
    {
      if (mu > 0.0)
      {
        kept_mu = mu;
        if (first_kept)
          damped_mu_hint = mu;
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
    assemble(x, lambda, u, true);
  }
  sum.status = SolveStatus::kMaxIterations;
  std::ostringstream msg;
  msg << "static Newton did not converge, plain or damped (" << max_iterations << " damped iterations; residual "
      << current << ")";
  sum.message = msg.str();
  return sum;
}

void StaticSolver::Impl::parameterDerivative(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, double w,
                                             Eigen::VectorXd& out)
{
  // dr/dw at fixed (x, lambda) by central differences: u(w) moves the driven nodes, the driven rows and the cables
  // pulled in, f(w) the loads. The rows are quadratic in u and the loads linear in f, so their differences are exact;
  // the forces are smooth in u, and a pull of 1e-6 m leaves about 1e-12 of them.
  double scale = 0.0;
  for (size_t i = 0; i < path_u_start.size(); ++i)
    scale = std::max(scale, std::abs(path_u_end[i].value - path_u_start[i].value));
  out.setZero(n + rows);
  if (scale == 0.0 && load_start == load_end)
    return;
  const double dw = scale > 0.0 ? std::min(1e-3, 1e-6 / scale) : 1e-3;
  assemble(x, lambda, pathPoint(w + dw), false);
  fplus = r();
  assemble(x, lambda, pathPoint(w - dw), false);
  out = (fplus - r()) / (2.0 * dw);
  pathPoint(w);
}

bool StaticSolver::Impl::pathTangent(const Eigen::VectorXd& x, const Eigen::VectorXd& lambda, double w,
                                     Eigen::VectorXd& tangent)
{
  if (!path_factor_valid)
    return false;
  parameterDerivative(x, lambda, w, fminus);
  rhs = -fminus;
  solve(rhs, tangent);
  return tangent.allFinite();
}

void StaticSolver::Impl::warnCriticalPoints(Summary& summary) const
{
  // one warning each for the first few; a path through a region of many (a mechanism's slack tower) gets one line
  // for the rest
  constexpr size_t kMaxWarnings = 5;
  for (size_t i = 0; i < std::min(critical_points.size(), kMaxWarnings); ++i)
  {
    const CriticalPoint& c = critical_points[i];
    std::ostringstream msg;
    msg << "a critical point (" << c.kind << ") was passed between path parameters " << c.previous_parameter << " and "
        << c.parameter
        << (c.kind == "limit_point" ? ": the path parameter turned back there" :
                                      ": the tangent stiffness changed the sign of its determinant");
    if (c.negative_before >= 0)
      msg << " (reduced stiffness: eigenvalue nearest zero " << c.eigenvalue_before << " -> " << c.eigenvalue_after
          << ", negative eigenvalues " << c.negative_before << " -> " << c.negative_after << ")";
    summary.warnings.push_back(msg.str());
  }
  if (critical_points.size() > kMaxWarnings)
  {
    std::ostringstream more;
    more << "and " << critical_points.size() - kMaxWarnings << " more critical points between path parameters "
         << critical_points[kMaxWarnings].previous_parameter << " and " << critical_points.back().parameter;
    summary.warnings.push_back(more.str());
  }
}

void StaticSolver::Impl::confirmSign(double w)
{
  if (!path_factor_valid || path_factor_sign == 0)
    return;
  if (sign != 0 && path_factor_sign != sign)
  {
    CriticalPoint c;
    c.kind = "bifurcation";
    c.parameter = w;
    c.previous_parameter = sign_parameter;
    c.sign_before = sign;
    c.sign_after = path_factor_sign;
    // the stiffness on both sides (a dense eigenproblem each, at the first kMaxCriticalPointSpectra critical points
    // of a path only)
    const int limit = critical_points.size() < kMaxCriticalPointSpectra ? kMaxCriticalPointCoordinates : 0;
    const StiffnessSpectrum before = stiffnessSpectrum(model, bodyState(sign_x, sign_u), limit);
    const StiffnessSpectrum after = stiffnessSpectrum(model, bodyState(path_factor_x, path_factor_u), limit);
    if (before.computed && after.computed)
    {
      c.eigenvalue_before = before.nearest_zero;
      c.eigenvalue_after = after.nearest_zero;
      c.negative_before = before.negative;
      c.negative_after = after.negative;
    }
    critical_points.push_back(c);
  }
  sign = path_factor_sign;
  sign_parameter = path_factor_w;
  sign_x = path_factor_x;
  sign_u = path_factor_u;
}

Summary StaticSolver::Impl::correct(Eigen::VectorXd& x, Eigen::VectorXd& lambda, const ActuationValues& u, double w,
                                    double predicted_step)
{
  // Modified Newton with the path factorization, rebuilt when it contracts slowly (rate > 0.5), after
  // max_jacobian_age increments, or at every iteration without reuse_jacobian. An iterate is accepted as in
  // dynamics: with a matrix built in this iteration when the increment is within the tolerance; with an older one
  // when the error estimated to be left, theta / (1 - theta) times the scaled increment, is.
  Summary sum;
  const bool reuse = options.reuse_jacobian;
  bool rebuild = !reuse || !path_factor_valid || path_factor_age >= options.max_jacobian_age;
  double previous = -1.0;
  double fresh_step = 0.0;  // the last increment made with a matrix built in its iteration
  int growths = 0;
  for (int it = 0; it < options.max_iterations; ++it)
  {
    const bool build = rebuild;
    ++sum.iterations;
    ++timings.newton_iterations;
    if (build)
    {
      if (!factorizePath(x, lambda, u, w))
      {
        sum.status = r().allFinite() ? SolveStatus::kSingular : SolveStatus::kNonFinite;
        sum.message = r().allFinite() ? "singular static Jacobian" : "non-finite static residual";
        return sum;
      }
      previous = -1.0;
      rebuild = !reuse;
    }
    else
      assemble(x, lambda, u, false);
    if (!r().allFinite())
      return failed(sum, SolveStatus::kNonFinite, "non-finite static residual");
    if (r().lpNorm<Eigen::Infinity>() == 0.0)
      return sum;
    rhs = -r();
    solve(rhs, dx);
    if (!dx.allFinite())
    {
      path_factor_valid = false;
      return failed(sum, SolveStatus::kNonFinite, "non-finite static Newton increment");
    }
    const double tol = options.newton_tolerance;
    const double step = dx.head(n).lpNorm<Eigen::Infinity>();
    // An older matrix whose increment is larger than half the predicted step (on a smooth path the prediction is off
    // by the square of the step), or grows from the last one (diverging), is not trusted: a cable gone taut or slack,
    // a contact begun since the matrix was made, changes the stiffness it lacks, and the increment that such a matrix
    // gives can throw the iterate far off the path. The increment is dropped and the matrix rebuilt where the iterate
    // is.
    if (!build && (step > 0.5 * predicted_step + 100.0 * tol || (previous > 0.0 && step / tol > previous)))
    {
      rebuild = true;
      continue;
    }
    // A fresh matrix whose increment is larger than the whole predicted step: the prediction landed outside Newton's
    // region (a soft mode it overshoots along); the damped Newton of followPath takes over at once.
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
    // convergence; the damped Newton is what finds the equilibrium from here
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
    x += dx.head(n);
    lambda += dx.tail(rows);
    sum.residual = step;
    const double x_part = sum.residual / tol;
    // the multipliers (strut forces over twice their lengths, reactions), relative to their size
    const double lambda_part =
        rows == 0 ? 0.0 : dx.tail(rows).lpNorm<Eigen::Infinity>() / (tol * (1.0 + lambda.lpNorm<Eigen::Infinity>()));
    const double scaled = std::max(x_part, lambda_part);
    bool measured = false;                         // a contraction rate measured in this correction
    if (reuse && previous > 0.0 && scaled > 1e-6)  // (not round-off)
    {
      path_theta = std::max(path_theta, scaled / previous);
      measured = true;
      if (path_theta > 0.5)
        rebuild = true;
    }
    const bool second = previous >= 0.0;
    previous = scaled;
    // A matrix built in this iteration: Newton's own step, the increment is the error measure. An older one: the
    // error left is estimated from its contraction rate theta (floored at 0.05), the largest measured with this
    // matrix, as theta / (1 - theta) times the increment. The rate must have been measured in this correction (or the
    // increment have fallen to round-off): a mode that has softened since the matrix was made contracts slowly from a
    // tiny first increment, and accepting that increment leaves an error that adds up over the increments of a path.
    const double theta = std::max(path_theta, 0.05);
    const bool converged =
        build ? x_part <= 1.0 :
                (measured && theta / (1.0 - std::min(theta, 0.5)) * scaled <= 1.0) || (second && scaled <= 1e-6);
    if (converged)
      return sum;
    if (scaled > 1e12)
      break;  // diverging
  }
  return notConverged(sum, options.max_iterations);
}

Summary StaticSolver::followPath(State& s, const ActuationValues& u_end, int steps,
                                 const std::function<void(const State&, const Summary&)>& on_step)
{
  Impl& m = *impl_;
  const ScopeTimer total_timer(m.timings.total);
  Summary total;
  m.critical_points.clear();
  m.sign = 0;
  m.path_u_start = atRest(s.u);
  m.path_u_end = atRest(u_end);
  Eigen::VectorXd x, lambda;
  m.start(s, x, lambda);
  s.t = 0.0;  // t carries the path parameter
  // a factorization kept from an earlier call is used only at the state it ended in
  if (m.path_factor_valid && (m.path_factor_x.size() != x.size() ||
                              (x - m.path_factor_x).lpNorm<Eigen::Infinity>() > 100.0 * m.options.newton_tolerance))
    m.path_factor_valid = false;
  ActuationValues u_here = m.pathPoint(0.0);
  if (!m.path_factor_valid)
    m.factorizePath(x, lambda, u_here, 0.0);
  m.path_factor_w = 0.0;
  m.sign_parameter = 0.0;
  m.confirmSign(0.0);
  Eigen::VectorXd tangent, tangent_next;
  bool have_tangent = m.pathTangent(x, lambda, 0.0, tangent);
  if (m.arc_length)
  {
    Summary out = m.followArcLength(s, steps, on_step, tangent, have_tangent);
    return out;
  }
  const int n = m.n, rows = m.rows;
  Eigen::VectorXd x_prev = x, lambda_prev = lambda;
  double w_prev = 0.0;
  bool have_previous = false;
  const double floor = 100.0 * m.options.newton_tolerance;
  double w = 0.0;  // path parameter reached
  for (int k = 1; k <= steps; ++k)
  {
    const double w_target = static_cast<double>(k) / steps;
    int cuts = 0;
    while (w < w_target)
    {
      // the increment is the requested one halved `cuts` times; after a success it doubles again (one cut less), and
      // the last piece of a load step lands exactly on its target
      const double dw = std::min(w_target - w, std::ldexp(1.0 / steps, -cuts));
      const double w_next = w_target - (w + dw) <= 1e-9 / steps ? w_target : w + dw;
      const ActuationValues u = m.pathPoint(w_next);
      // predictor: the tangent, else the secant through the last two equilibria, else the last one
      Eigen::VectorXd xt = x, lt = lambda;
      if (have_tangent)
      {
        xt += (w_next - w) * tangent.head(n);
        lt += (w_next - w) * tangent.tail(rows);
      }
      else if (have_previous && w_prev < w)
      {
        const double ratio = (w_next - w) / (w - w_prev);
        xt = x + ratio * (x - x_prev);
        lt = lambda + ratio * (lambda - lambda_prev);
      }
      const Eigen::VectorXd predicted = xt, predicted_lambda = lt;
      Summary attempt = m.correct(xt, lt, u, w_next, (predicted - x).lpNorm<Eigen::Infinity>());
      total.iterations += attempt.iterations;
      if (!attempt.ok())
      {
        // the damped Newton from the prediction (the corrector was plain Newton from there): what a barely stressed
        // mechanism, whose matrix is singular or nearly, needs. Its budget is kPathDampedTrials factorizations while
        // the increment can still be cut, and the full solver (plain, then damped Newton from the last equilibrium)
        // runs only when it cannot.
        const bool last_chance = cuts >= m.options.max_step_cuts;
        xt = predicted;
        lt = predicted_lambda;
        attempt =
            m.dampedNewton(xt, lt, u, last_chance ? 0 : std::min(kPathDampedTrials, 4 * m.options.max_iterations));
        total.iterations += attempt.iterations;
        if (!attempt.ok() && last_chance)
        {
          xt = x;
          lt = lambda;
          attempt = m.solveFrom(xt, lt, u);
          total.iterations += attempt.iterations;
        }
        m.path_factor_valid = false;
      }
      if (attempt.ok())
      {
        const int crossed = m.passedThrough(x, u_here, xt, u);
        if (crossed >= 0)
        {
          attempt.status = SolveStatus::kPassedThrough;
          attempt.message = passedThroughMessage(m.model, crossed);
        }
      }
      bool have_next = false;
      if (attempt.ok())
      {
        if (!m.path_factor_valid)
          m.factorizePath(xt, lt, u, w_next);
        have_next = m.pathTangent(xt, lt, w_next, tangent_next);
        // branch-jump guard: on a smooth path the corrector moves the prediction by O(dw^2); across a kink (a cable
        // going slack or taut, a contact starting) by at most dw times the change of the tangent; a jump to another
        // branch by a distance that does not shrink with dw
        if (have_tangent && jumped(xt, predicted,
                                   (w_next - w) * (tangent.head(n).lpNorm<Eigen::Infinity>() +
                                                   (have_next ? tangent_next.head(n).lpNorm<Eigen::Infinity>() : 0.0)) +
                                       floor,
                                   attempt))
          m.path_factor_valid = false;
      }
      if (attempt.ok())
      {
        x_prev = x;
        lambda_prev = lambda;
        w_prev = w;
        have_previous = true;
        x = xt;
        lambda = lt;
        w = w_next;
        u_here = u;
        cuts = std::max(0, cuts - 1);
        total.residual = attempt.residual;
        ++m.path_factor_age;
        m.confirmSign(w);
        if (have_next)
          tangent.swap(tangent_next);
        have_tangent = have_next;
        continue;
      }
      if (!m.path_factor_valid)
      {
        m.pathPoint(w);
        m.factorizePath(x, lambda, u_here, w);
        have_tangent = m.pathTangent(x, lambda, w, tangent);
      }
      if (++cuts > m.options.max_step_cuts)
      {
        total.status = attempt.status;
        std::ostringstream msg;
        msg << attempt.message << "; load step " << k << " of " << steps << " failed at path parameter " << w_next
            << " after " << m.options.max_step_cuts << " increment cuts";
        total.message = msg.str();
        break;
      }
      ++total.step_cuts;
    }
    if (!total.ok())
      break;
    s.t = w;
    m.accept(s, x, lambda, u_here);
    if (on_step)
      on_step(s, total);
  }
  m.warnCriticalPoints(total);
  return total;
}

Summary StaticSolver::Impl::followArcLength(State& s, int steps,
                                            const std::function<void(const State&, const Summary&)>& on_step,
                                            Eigen::VectorXd tangent, bool have_tangent)
{
  // Pseudo-arc-length continuation (Keller) in (x, w) with the metric <a, b> = a_x . b_x + psi^2 a_w b_w,
  // psi = |dx/dw| at the start (a unit of w weighs as much as the motion it first causes). The unit tangent
  // T ~ (dx/dw, 1) keeps its orientation from step to step (<T_new, T_old> > 0), so the path goes on through a limit
  // point, where w turns back. Each step: predictor (x, w) + ds T; corrector: full Newton on r(z, w) = 0 bordered by
  // the hyperplane <T, (x, w) - (x0, w0)> = ds.
  Summary total;
  if (!have_tangent)
  {
    total.status = SolveStatus::kSingular;
    total.message = "arc-length continuation needs a regular start (the tangent stiffness at the start is singular)";
    return total;
  }
  Eigen::VectorXd x0, lambda0;
  start(s, x0, lambda0);
  const double psi2 = std::max(tangent.head(n).squaredNorm(), 1e-12);
  const auto unit = [&](const Eigen::VectorXd& t, double orientation)
  {
    // (T_x, T_w) with T_x = T_w dx/dw (the multipliers ride along), <T, T> = 1
    const double tw = orientation / std::sqrt(t.head(n).squaredNorm() + psi2);
    return std::make_pair(Eigen::VectorXd(tw * t), tw);
  };
  auto [tx, tw] = unit(tangent, 1.0);
  const double ds_first = std::sqrt(tangent.head(n).squaredNorm() + psi2) / steps;
  const double ds_max = 4.0 * ds_first;
  const double ds_min = std::ldexp(ds_first, -options.max_step_cuts);
  const double floor = 100.0 * options.newton_tolerance;
  const long max_steps = 100L * steps;
  double ds = ds_first;
  double w = 0.0;
  long taken = 0;
  Eigen::VectorXd x = x0, lambda = lambda0, xs = x0, ls = lambda0, da, db, rw;
  ActuationValues u_here = pathPoint(0.0);
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
    x = xs + ds_step * tx.head(n);
    lambda = ls + ds_step * tx.tail(rows);
    double w_it = last ? 1.0 : w + ds_step * tw;
    const Eigen::VectorXd predicted = x;
    Summary attempt;
    attempt.status = SolveStatus::kMaxIterations;
    for (int it = 0; it < options.max_iterations; ++it)
    {
      ++attempt.iterations;
      ++timings.newton_iterations;
      const ActuationValues u = pathPoint(w_it);
      if (!factorizePath(x, lambda, u, w_it))
      {
        attempt.status = r().allFinite() ? SolveStatus::kSingular : SolveStatus::kNonFinite;
        attempt.message = r().allFinite() ? "singular static Jacobian" : "non-finite static residual";
        break;
      }
      rhs = -r();
      solve(rhs, da);
      double dw = 0.0;
      if (!last)
      {
        parameterDerivative(x, lambda, w_it, rw);
        rhs = -rw;
        solve(rhs, db);
        const double g = ds_step - (tx.head(n).dot(x - xs) + psi2 * tw * (w_it - w));
        dw = (g - tx.head(n).dot(da.head(n))) / (tx.head(n).dot(db.head(n)) + psi2 * tw);
        da += dw * db;
      }
      if (!da.allFinite() || !std::isfinite(dw))
      {
        attempt.status = SolveStatus::kNonFinite;
        attempt.message = "non-finite static Newton increment";
        break;
      }
      x += da.head(n);
      lambda += da.tail(rows);
      w_it += dw;
      attempt.residual = da.head(n).lpNorm<Eigen::Infinity>();
      if (attempt.residual <= options.newton_tolerance)
      {
        attempt.status = SolveStatus::kConverged;
        break;
      }
    }
    const ActuationValues u_it = pathPoint(w_it);
    if (attempt.ok())
    {
      const int crossed = passedThrough(xs, u_here, x, u_it);
      if (crossed >= 0)
      {
        attempt.status = SolveStatus::kPassedThrough;
        attempt.message = passedThroughMessage(model, crossed);
      }
    }
    Eigen::VectorXd tangent_next;
    if (attempt.ok())
    {
      // (the tangent at the new equilibrium, from a factorization made there)
      if (!factorizePath(x, lambda, u_it, w_it) || !pathTangent(x, lambda, w_it, tangent_next))
      {
        attempt.status = SolveStatus::kSingular;
        attempt.message = "singular static Jacobian at the new equilibrium";
      }
    }
    std::pair<Eigen::VectorXd, double> next;
    if (attempt.ok())
    {
      next = unit(tangent_next, 1.0);
      if (next.first.head(n).dot(tx.head(n)) + psi2 * next.second * tw < 0.0)
        next = unit(tangent_next, -1.0);
      jumped(x, predicted,
             ds_step * (tx.head(n).lpNorm<Eigen::Infinity>() + next.first.head(n).lpNorm<Eigen::Infinity>()) + floor,
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
            << options.max_step_cuts << " cuts";
        total.message = msg.str();
        break;
      }
      pathPoint(w);
      factorizePath(xs, ls, u_here, w);
      continue;
    }
    total.iterations += attempt.iterations;
    total.residual = attempt.residual;
    // a limit point: the path parameter turned back; the determinant of the tangent changed sign there too
    const size_t known = critical_points.size();
    confirmSign(w_it);
    if (next.second * tw < 0.0)
    {
      if (critical_points.size() > known)
        critical_points.back().kind = "limit_point";
      else
      {
        CriticalPoint c;
        c.kind = "limit_point";
        c.parameter = w_it;
        c.previous_parameter = w;
        critical_points.push_back(c);
      }
    }
    xs = x;
    ls = lambda;
    u_here = u_it;
    w = w_it;
    s.t = w_it;
    accept(s, x, lambda, u_it);
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

double StaticSolver::forceResidual(const State& s)
{
  Impl& m = *impl_;
  Eigen::VectorXd x, lambda;
  m.start(s, x, lambda);
  const ActuationValues u = atRest(s.u);
  // the residual with zero multipliers is -F; G^T lambda for the multipliers that fit F best (the normal equations
  // G G^T lambda = G F, G from the rows' entries of the Jacobian)
  lambda.setZero(m.rows);
  m.assemble(x, lambda, u, true);
  const Eigen::VectorXd force = -m.r().head(m.n);
  const Eigen::SparseMatrix<double> g = m.solver.assembledRows();
  if (g.rows() == 0)
    return force.lpNorm<Eigen::Infinity>();
  const Eigen::SparseMatrix<double> normal = g * g.transpose();
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(normal);
  Eigen::VectorXd fit;
  if (ldlt.info() == Eigen::Success)
    fit = ldlt.solve(g * force);
  if (fit.size() != m.rows || !fit.allFinite())
    fit = Eigen::MatrixXd(g.transpose()).colPivHouseholderQr().solve(force);
  return (Eigen::VectorXd(g.transpose() * fit) - force).lpNorm<Eigen::Infinity>();
}

}  // namespace active_tensegrity::core
