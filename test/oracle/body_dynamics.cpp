#include "active_tensegrity/oracle/body_contact.h"
#include "active_tensegrity/oracle/body_dynamics.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

#include "active_tensegrity/core/solvers/adaptive.h"
#include "active_tensegrity/core/base/text.h"

namespace active_tensegrity::core
{
namespace
{
/// Modified Newton keeps a factorization built for a step within this relative change of h.
constexpr double kReuseStepChange = 0.2;
/// The smallest contraction rate modified Newton assumes when it estimates the error left in an iterate.
constexpr double kRateFloor = 0.05;
constexpr int kFreshStartsLeast = 2;
constexpr int kFreshStartsMost = 64;
// Small systems, where a factorization costs about a residual: Newton matrices of at most this many unknowns (the
// six-bar robot's 48, not the tower's 200). Fresh starts there (dense ones); body blocks only above (on a small
// system they double the Newton iterations)
constexpr int kSmallSystem = 64;
/// Exact factorizations with the one-body rows eliminated (ReducedLinearSolver) above kSmallSystem and up to
/// this many unknowns (the dense LU's range; above it the static pivots and the sparse LU of the whole matrix):
/// it pays where many one-body rows are eliminated (the tower's 200 unknowns leave 120), not on a small system.
constexpr int kReducedMost = 400;
/// With fixed steps, a body-block matrix that contracted at first and slowed later is rebuilt at the iterate
/// (not distrusted) when the iterate moved this many Newton tolerances since the matrix was built (the sum of
/// the position increments): far enough for the matrix, not the body blocks, to be what is off.
constexpr double kRebuildMoved = 100.0;

/// Whether two vectors hold the same bits (memcmp: Eigen's == compares coefficient by coefficient).
bool sameBits(const Eigen::VectorXd& a, const Eigen::VectorXd& b)
{
  return a.size() == b.size() &&
         (a.size() == 0 || std::memcmp(a.data(), b.data(), static_cast<size_t>(a.size()) * sizeof(double)) == 0);
}

/// Orders contacts by their slot (as activeContacts gives them).
void sortBySlot(std::vector<ContactPairState>& contacts)
{
  const auto by_slot = [](const ContactPairState& a, const ContactPairState& b) { return a.pair < b.pair; };
  // (the near slots come in slot order nearly always: std::sort would still move the large states around)
  if (!std::is_sorted(contacts.begin(), contacts.end(), by_slot))
    std::sort(contacts.begin(), contacts.end(), by_slot);
}

/// Gives the linear solver back the approximate-factorization setting it had when made (an attempt that
/// suspends the approximate methods has many returns).
class ApproximateSetting
{
public:
  explicit ApproximateSetting(SparseLinearSolver& linear) : linear_(linear), allowed_(linear.approximateAllowed()) {}
  ~ApproximateSetting()
  {
    linear_.allowApproximate(allowed_);
  }
  ApproximateSetting(const ApproximateSetting&) = delete;
  ApproximateSetting& operator=(const ApproximateSetting&) = delete;

private:
  SparseLinearSolver& linear_;
  bool allowed_;
};
}  // namespace

BodyDynamicsSolver::BodyDynamicsSolver(const Model& model, const SolverOptions& options)
  : system_(model), options_(options), jac_(system_.makeMatrix())
{
  linear_.allowDense(true);
  reduced_.allowDense(true);
  use_reduced_ = system_.size() > kSmallSystem && system_.size() <= kReducedMost;
  // the approximate static-pivot factorization is for modified Newton only (its contraction test)
  linear_.allowStaticPivot(options.reuse_jacobian);
  if (options.reuse_jacobian && system_.size() > kSmallSystem)
  {
    std::vector<int> body_sizes;
    for (const Body& b : model.bodies)
      body_sizes.push_back(b.nq);
    linear_.allowBodyBlocks(body_sizes);
  }
  for (const Body& b : model.bodies)
    mass_scale_ = std::max(mass_scale_, b.mass);
  if (options.integrator == Integrator::kNewmark)
    coef_ = { options.newmark_gamma, options.newmark_beta, 0.0, 0.0 };
  else
  {
    const double rho = options.rho_infinity;
    const double am = (2.0 * rho - 1.0) / (rho + 1.0);
    const double af = rho / (rho + 1.0);
    const double gamma = 0.5 + af - am;
    coef_ = { gamma, 0.25 * (gamma + 0.5) * (gamma + 0.5), am, af };
  }
}

void BodyDynamicsSolver::predict(const BodyState& s, double h, const Eigen::VectorXd& qdd_new, Eigen::VectorXd& q,
                                 Eigen::VectorXd& qd, Eigen::VectorXd& acc) const
{
  const auto& c = coef_;
  // (1 - am) a_{n+1} + am a_n = (1 - af) qdd_{n+1} + af qdd_n
  acc = ((1.0 - c.alpha_f) * qdd_new + c.alpha_f * s.qdd - c.alpha_m * s.acc) / (1.0 - c.alpha_m);
  q = s.q + h * s.qd + h * h * ((0.5 - c.beta) * s.acc + c.beta * acc);
  qd = s.qd + h * ((1.0 - c.gamma) * s.acc + c.gamma * acc);
}

void BodyDynamicsSolver::residualAndJacobian(const BodyState& s, double h, const ActuationValues& u,
                                             const Eigen::VectorXd& qdd_new, const Eigen::VectorXd& lambda_new,
                                             Eigen::VectorXd& r, BlockSparseMatrix* jac)
{
  prepareContact(s, h);
  residual(s, h, u, qdd_new, lambda_new, r, jac);
}

void BodyDynamicsSolver::prepareContact(const BodyState& s, double h)
{
  const ScopeTimer timer(timings_.contact);
  const Model& model = system_.model();
  // (only the near slots' speeds are read, and findNearContacts sets each of them)
  if (step_speeds_.size() != model.contactSlots())
    step_speeds_.reset(model.contactSlots(), model.contact.min_impact_speed);
  start_at_end_ = atEnd(s);
  near_.clear();
  if (!model.anyContact())
    return;
  // how far any body point can move in this step, from the speeds and accelerations at its start
  // (doubled: a margin; a strut's end moves at most |c'| + (l/2) |a'| with |a'| <= 2 |Theta'|)
  double reach = 0.0;
  for (const Body& b : model.bodies)
  {
    double speed = s.qd.segment<3>(b.offset).norm(), acc = s.acc.segment<3>(b.offset).norm();
    if (b.kind == BodyKind::kStrut)
    {
      speed += b.length * s.qd.segment<4>(b.offset + 3).norm();
      acc += b.length * s.acc.segment<4>(b.offset + 3).norm();
    }
    reach = std::max(reach, speed * h + acc * h * h);
  }
  findNearContacts(s, std::max(2.0 * reach, kNearFloor));
}

void BodyDynamicsSolver::findNearContacts(const BodyState& s, double motion)
{
  const Model& model = system_.model();
  near_motion_ = motion;
  // (at the last accepted step's end, the gaps evaluated there: most of the kept slots' narrow phase)
  system_.nearContacts(s.q, motion, near_, start_at_end_ ? &end_gap_ : nullptr);
  // the slots the last accepted step evaluated at its end, which is this start: their approach rates
  const bool at_end = start_at_end_;
  for (int i : near_)
  {
    const double memory = i < s.contact_speed.size() ? s.contact_speed[i] : 0.0;
    if (memory > 0.0)
      step_speeds_.set(i, memory);
    else if (at_end && !std::isnan(end_rate_[i]))
      step_speeds_.set(i, std::max(end_rate_[i], model.contact.min_impact_speed));
    else
    {
      const ContactPairState st = evaluateContact(model, i, s.q, s.qd, 0.0, ContactMode::kDynamic, nullptr);
      step_speeds_.set(i, std::max(st.penetration_rate, model.contact.min_impact_speed));
    }
  }
}

bool BodyDynamicsSolver::atEnd(const BodyState& s) const
{
  // (not the time: callers round it to their step grid; the contacts depend on q, qd and the memory of the
  // evaluated slots, no other slot touching there) Bitwise.
  if (!end_valid_ || s.contact_speed.size() != end_rate_.size() || !sameBits(s.q, end_q_) || !sameBits(s.qd, end_qd_))
    return false;
  for (size_t k = 0; k < end_slots_.size(); ++k)
    if (s.contact_speed[end_slots_[k]] != end_memory_[k])
      return false;
  return true;
}

const std::vector<ContactPairState>* BodyDynamicsSolver::contactsAt(const BodyState& state) const
{
  if (!atEnd(state))
    return nullptr;
  if (!end_contacts_ready_)
  {
    // the touching end slots with their forces, at the impact speeds their memory keeps (the step's own, which
    // end_memory_ holds for the touching slots; asked for by a consumer: the step's end needs their motion only)
    end_contacts_.clear();
    for (size_t k = 0; k < end_slots_.size(); ++k)
    {
      const int i = end_slots_[k];
      if (!(end_gap_[i] < 0.0))
        continue;
      const ContactPairState st =
          evaluateContact(system_.model(), i, end_q_, end_qd_, end_memory_[k], ContactMode::kDynamic, nullptr);
      if (st.active)
        end_contacts_.push_back(st);
    }
    sortBySlot(end_contacts_);
    end_contacts_ready_ = true;
  }
  return &end_contacts_;
}

void BodyDynamicsSolver::updateContactMemory(BodyState& s, const Eigen::VectorXd& q_start)
{
  const ScopeTimer timer(timings_.contact);
  const Model& model = system_.model();
  const int slots = model.contactSlots();
  // the start's memory at the near slots (whether each was touching), then the memory cleared: when the step
  // began where the last one ended, its nonzero entries are that end's touching slots, all among end_slots_
  // (every other slot was apart there), and only they are cleared (a lattice of 2000 struts has 2 million
  // slots: clearing them all was a 16 MB memset per step); else the whole memory
  near_previous_.clear();
  for (int i : near_)
    near_previous_.push_back(i < s.contact_speed.size() ? s.contact_speed[i] : 0.0);
  if (start_at_end_ && s.contact_speed.size() == slots)
    for (int i : end_slots_)
      s.contact_speed.set(i, 0.0);
  else
    s.contact_speed.reset(slots, 0.0);
  estimate_.onset_depth = 0.0;
  estimate_.onset_gap = 0.0;
  estimate_.onset_pair = -1;
  // the end's evaluation (contactsAt, and the next step's approach rates): the earlier one's slots forgotten
  if (end_rate_.size() != slots)
  {
    end_rate_.reset(slots, std::numeric_limits<double>::quiet_NaN());
    end_gap_.reset(slots, std::numeric_limits<double>::quiet_NaN());
  }
  for (int i : end_slots_)
  {
    end_rate_.set(i, std::numeric_limits<double>::quiet_NaN());
    end_gap_.set(i, std::numeric_limits<double>::quiet_NaN());
  }
  end_slots_.clear();
  end_memory_.clear();
  end_contacts_.clear();
  end_contacts_ready_ = false;
  end_q_ = s.q;
  end_qd_ = s.qd;
  end_valid_ = true;
  if (!model.anyContact())
    return;
  // every slot touching at the step's end is near (attempt() checks the motion): its gap and approach rate there;
  // its forces, with the step's impact speed (the one its memory keeps), only when contactsAt asks, or here when
  // it will ask at every step (evaluateContact gives a slot apart what contactMotion gives, and a touching slot's
  // forces with them, as contactsAt forms them)
  long touching = 0;
  for (size_t k = 0; k < near_.size(); ++k)
  {
    const int i = near_[k];
    const ContactPairState st =
        contacts_every_step_ ? evaluateContact(model, i, s.q, s.qd, step_speeds_[i], ContactMode::kDynamic, nullptr) :
                               contactMotion(model, i, s.q, s.qd);
    if (contacts_every_step_ && st.active)
      end_contacts_.push_back(st);
    end_rate_.set(i, st.penetration_rate);
    end_gap_.set(i, st.gap);
    end_slots_.push_back(i);
    const double gap = st.gap;
    end_memory_.push_back(gap < 0.0 ? step_speeds_[i] : 0.0);
    if (gap >= 0.0)
      continue;
    ++touching;
    s.contact_speed.set(i, step_speeds_[i]);
    const bool was_touching = near_previous_[k] > 0.0;
    if (was_touching || -gap <= estimate_.onset_depth)
      continue;
    const double gap_start = contactGeometry(model, i, q_start).gap;
    if (gap_start > 0.0)  // apart at the start (a scene may start with pairs touching)
    {
      estimate_.onset_depth = -gap;
      estimate_.onset_gap = gap_start;
      estimate_.onset_pair = i;
    }
  }
  most_touching_before_ = timings_.most_touching;
  timings_.most_touching = std::max(timings_.most_touching, touching);
  if (contacts_every_step_)
  {
    sortBySlot(end_contacts_);
    end_contacts_ready_ = true;
  }
}

double BodyDynamicsSolver::errorEstimate(const Eigen::VectorXd& a0, const Eigen::VectorXd& a1, double h) const
{
  // Newmark's local position error is (beta - 1/6) h^3 q''' and its velocity error (gamma - 1/2) h^2 q'''
  // (which becomes a position error of the same order over the next step); h q''' ~ a1 - a0
  const double c = (std::abs(coef_.beta - 1.0 / 6.0) + std::abs(coef_.gamma - 0.5)) * h * h;
  double e = 0.0;
  for (const Body& b : system_.model().bodies)
  {
    double eb = (a1.segment<3>(b.offset) - a0.segment<3>(b.offset)).norm();
    if (b.kind == BodyKind::kStrut)
      eb += b.length * (a1.segment<4>(b.offset + 3) - a0.segment<4>(b.offset + 3)).norm();
    e = std::max(e, eb);
  }
  return c * e;
}

void BodyDynamicsSolver::residual(const BodyState& s, double h, const ActuationValues& u,
                                  const Eigen::VectorXd& qdd_new, const Eigen::VectorXd& lambda_new, Eigen::VectorXd& r,
                                  BlockSparseMatrix* jac)
{
  const double da = (1.0 - coef_.alpha_f) / (1.0 - coef_.alpha_m);  // d acc_{n+1} / d qdd_{n+1}
  const double bh2 = coef_.beta * h * h * da;                       // d q / d qdd
  const double gh = coef_.gamma * h * da;                           // d qd / d qdd
  predict(s, h, qdd_new, q_, qd_, acc_);
  {
    const ScopeTimer timer(timings_.forces);
    if (jac)
      jac->setZero();
    system_.inertialForce(q_, qd_, qdd_new, inertial_, jac, 1.0, bh2, gh);
    system_.appliedForce(q_, qd_, u, applied_, jac, bh2, gh);
  }
  {
    const ScopeTimer timer(timings_.contact);
    system_.contactForce(near_, q_, qd_, step_speeds_, ContactMode::kDynamic, applied_, jac, bh2, gh);
  }
  {
    const ScopeTimer timer(timings_.constraints);
    system_.constraintForce(q_, lambda_new, cforce_);
    system_.constraintValue(q_, u, phi_);
    if (jac)
    {
      system_.addLambdaHessian(q_, lambda_new, *jac, bh2);
      system_.addConstraintJacobian(q_, *jac);
    }
  }
  r.resize(system_.size());
  r.head(system_.nq()) = inertial_ - applied_ + cforce_;
  r.tail(system_.nLambda()) = phi_ / bh2;
}

bool BodyDynamicsSolver::continuesHistory(const BodyState& s) const
{
  return history_count_ > 0 && s.t == last_end_t_ && sameBits(s.qdd, last_end_qdd_);
}

void BodyDynamicsSolver::firstGuess(const BodyState& s, double h, Eigen::VectorXd& qdd, Eigen::VectorXd& lambda) const
{
  // Only from the state the last accepted step ended in (a step cut retries from it too). Through the
  // last three step ends the guess is quadratic: in smooth motion at the tower's dt it is 10-30 times
  // closer to the solution than the linear one, and modified Newton then often accepts its first iterate
  // (docs/physics.md). Through two it is linear, else constant.
  const int n = continuesHistory(s) ? history_count_ : 0;
  if (n == 0)
  {
    qdd = s.qdd;
    lambda = s.lambda;
    return;
  }
  const double t = s.t + h;
  const double t1 = history_[0].t;
  if (n == 1)
  {
    const double r = h / (s.t - t1);
    qdd = s.qdd + r * (s.qdd - history_[0].qdd);
    lambda = s.lambda + r * (s.lambda - history_[0].lambda);
    return;
  }
  // Lagrange weights of the nodes t2 = s.t, t1, t0 at t (3, -3, 1 for equal steps)
  const double t0 = history_[1].t;
  const double t2 = s.t;
  const double w2 = (t - t0) * (t - t1) / ((t2 - t0) * (t2 - t1));
  const double w1 = (t - t0) * (t - t2) / ((t1 - t0) * (t1 - t2));
  const double w0 = (t - t1) * (t - t2) / ((t0 - t1) * (t0 - t2));
  qdd = w2 * s.qdd + w1 * history_[0].qdd + w0 * history_[1].qdd;
  lambda = w2 * s.lambda + w1 * history_[0].lambda + w0 * history_[1].lambda;
}

void BodyDynamicsSolver::rememberStep(const BodyState& start, double t_end, const Eigen::VectorXd& qdd_end)
{
  const bool chained = continuesHistory(start);
  if (chained)
    std::swap(history_[0], history_[1]);  // (swaps the vectors' buffers: no allocation)
  history_[0].t = start.t;
  history_[0].qdd = start.qdd;
  history_[0].lambda = start.lambda;
  history_count_ = chained ? std::min(history_count_ + 1, 2) : 1;
  last_end_t_ = t_end;
  last_end_qdd_ = qdd_end;
}

bool BodyDynamicsSolver::factorizeNewtonMatrix()
{
  reduced_current_ = false;
  if (!use_reduced_)
    return linear_.factorize(jac_.matrix());
  if (linear_.factorizeApproximate(jac_.matrix()))
    return true;
  reduced_current_ = true;
  return reduced_.factorize(jac_, static_cast<int>(system_.model().bodies.size()));
}

Summary BodyDynamicsSolver::attemptOrFullNewton(BodyState& s, double h, const ActuationLaw& law)
{
  Summary sum = attempt(s, h, law, false);
  if (sum.ok() || sum.status == SolveStatus::kPassedThrough || !options_.reuse_jacobian)
    return sum;
  const int spent = sum.iterations;
  {
    const ApproximateSetting restore(linear_);
    linear_.allowApproximate(false);  // Newton's own matrices, factorized exactly
    sum = attempt(s, h, law, true);
  }
  factor_valid_ = false;  // the kept factorization is gone
  sum.iterations += spent;
  ++timings_.full_newton_retries;
  return sum;
}

Summary BodyDynamicsSolver::attempt(BodyState& s, double h, const ActuationLaw& law, bool full_newton)
{
  Summary sum;
  law(s.t + h, u_iter_);  // a member: no allocation in the step loop (with a writing law)
  const ActuationValues& u = u_iter_;
  Eigen::VectorXd& qdd = qdd_iter_;  // members: no allocation in the step loop
  Eigen::VectorXd& lambda = lambda_iter_;
  firstGuess(s, h, qdd, lambda);
  const double bh2 = coef_.beta * h * h * (1.0 - coef_.alpha_f) / (1.0 - coef_.alpha_m);
  const int nq = system_.nq();
  const bool reuse = options_.reuse_jacobian && !full_newton;
  prepareContact(s, h);
  // the pairs touching at the start (remembered impact speed > 0): all of them are near
  touching_.clear();
  for (int i : near_)
    if (i < s.contact_speed.size() && s.contact_speed[i] > 0.0)
      touching_.push_back(i);
  std::sort(touching_.begin(), touching_.end());
  // modified Newton keeps the factorization while it stays a good one (see the option)
  // (h differs in its last bits from step to step: t = k dt; a cut changes it by a factor 2; a variable
  // step keeps it while within 20 %: the matrix is then a little off, which the contraction check sees)
  // After a kept matrix failed (theta > 0.5) in a small dense system, the next steps start with a new one (2, then
  // 4, 8 ... 64 steps while kept matrices go on failing; back to 2 once one serves a whole step): where a kept
  // matrix fails it fails step after step (a robot resting on the ground), and each try wastes two residuals.
  // A change of the touching pairs asks for a new matrix, except where the kept one is the static pivots and the
  // new one would be too (the body blocks paused): there the contraction check decides. In a lattice's rattling
  // contact the touching pairs change at nearly every step, and a static-pivot factorization costs far more than
  // the iterations it saves; while the body blocks serve, a new matrix is theirs and cheap.
  bool rebuild = !reuse || !factor_valid_ || std::abs(h - factor_h_) > kReuseStepChange * h ||
                 factor_age_ >= options_.max_jacobian_age;
  if (!rebuild && touching_ != factor_contacts_)
  {
    if (linear_.staticPivot() && linear_.nextIsLargeExact())
      ++timings_.static_pivots_kept;
    else
      rebuild = true;
  }
  if (!rebuild && fresh_starts_ > 0)
  {
    rebuild = true;
    ++timings_.fresh_starts;
  }
  bool diverged = false;
  double previous = -1.0;  // last scaled increment with this factorization
  double moved = 0.0;      // position increments since it was built, in Newton tolerances
  bool built_this_step = false;
  int static_failures = 0;    // static-pivot matrices built in this attempt that did not contract
  bool newton_each = !reuse;  // a new matrix at every iteration (full Newton, or modified Newton switched to it)
  // (the switch suspends the approximate factorizations for the rest of this attempt only)
  const ApproximateSetting restore(linear_);
  for (int it = 0; it < options_.max_iterations; ++it)
  {
    const bool build = rebuild;
    residual(s, h, u, qdd, lambda, r_, build ? &jac_ : nullptr);
    ++sum.iterations;
    ++timings_.newton_iterations;
    if (!r_.allFinite())
    {
      sum.status = SolveStatus::kNonFinite;
      sum.message = "non-finite residual";
      factor_valid_ = false;
      return sum;
    }
    if (build)
    {
      bool factorized = false;
      {
        const ScopeTimer timer(timings_.factorization);
        factorized = factorizeNewtonMatrix();
      }
      ++timings_.factorizations;
      if (linear_.staticPivot())
        ++timings_.static_pivot_factorizations;
      if (linear_.bodyBlocks())
        ++timings_.body_block_factorizations;
      if (reduced_current_ && reduced_.reduced())
        ++timings_.reduced_factorizations;
      timings_.analyses = linear_.analyses() + reduced_.analyses();
      factor_valid_ = factorized;
      if (!factorized)
      {
        sum.status = SolveStatus::kSingular;
        sum.message = "singular Newton matrix";
        return sum;
      }
      factor_h_ = h;
      factor_age_ = 0;
      built_this_step = true;
      factor_contacts_ = touching_;
      theta_ = 0.0;
      theta_known_ = false;
      previous = -1.0;
      moved = 0.0;
      rebuild = newton_each;
    }
    {
      const ScopeTimer timer(timings_.solve);
      r_ = -r_;
      solveNewtonMatrix(r_, dx_);
    }
    if (!dx_.allFinite())
    {
      sum.status = SolveStatus::kNonFinite;
      sum.message = "non-finite Newton increment";
      factor_valid_ = false;
      return sum;
    }
    qdd += dx_.head(nq);
    lambda += dx_.tail(system_.nLambda());
    sum.residual = bh2 * dx_.head(nq).lpNorm<Eigen::Infinity>();
    // The increment measured against what is asked of it, 1 = at the tolerance: positions (beta h^2 times
    // the acceleration increment) to newton_tolerance, multipliers to it relative to their size. The
    // multipliers cannot be known better than the round-off of phi / (beta h^2) makes them: about
    // eps |q| m / (beta h^2), which at tiny steps is far above the tolerance.
    const double lambda_floor =
        10.0 * std::numeric_limits<double>::epsilon() * (1.0 + s.q.lpNorm<Eigen::Infinity>()) * mass_scale_ / bh2;
    const double q_part = sum.residual / options_.newton_tolerance;
    const double lambda_part = dx_.tail(system_.nLambda()).lpNorm<Eigen::Infinity>() /
                               (options_.newton_tolerance * (1.0 + lambda.lpNorm<Eigen::Infinity>()) + lambda_floor);
    const double scaled = std::max(q_part, lambda_part);
    if (reuse && previous > 0.0 && scaled > 1e-3)  // (not round-off)
    {
      // contraction rate of the iteration with this matrix; slow or diverging: rebuild it
      // (moved_on: the matrix contracted at its rates so far, a rate above 0.5 having rebuilt it, and the iterate
      // moved kRebuildMoved tolerances since it was built)
      const bool moved_on = theta_known_ && moved >= kRebuildMoved;
      theta_ = std::max(theta_, scaled / previous);
      theta_known_ = true;
      if (theta_ > 0.5)
      {
        rebuild = true;
        diverged = diverged || !built_this_step;
        // body blocks too far off in the step that made them: the exact matrix now, and for a while. With fixed
        // steps, body blocks that contracted at first and slowed after the iterate moved far from where they were
        // built (kRebuildMoved; a contact stiffening through the step) are rebuilt there instead, which saves exact
        // factorizations. (With variable steps the step size, not the iterate, makes body blocks fail.)
        if (built_this_step && linear_.bodyBlocks())
        {
          if (!moved_on || variable_steps_)
          {
            linear_.distrustBodyBlocks();
            ++timings_.body_block_distrusts;
          }
          else
            ++timings_.body_block_rebuilds;
        }
        // An exact matrix of one of this step's own iterates that does not contract: the iterates are where a
        // contact or a slack cable switches, and modified Newton can cycle there (rebuilt at x1, it goes to x2,
        // the kept matrix brings it back to x1: the 3x3 quadruplex lattice's steps of 30 iterations and a
        // full-Newton retry). Full Newton from here, exact matrices (not the body blocks) at every iteration.
        // Static pivots only at the second of this attempt's own matrices that fails: switching at the first made
        // about twice as many switches, each an exact factorization per iteration, for iterations within 3 % (the
        // 4 x 5 lattice's rattling contact at three friction coefficients); without a switch such a step rebuilds
        // its matrix at every other iteration until the retry (504 struts, 0.8 s: 85 retries; switching at the
        // second, 19).
        else if (built_this_step && (factorizationExact() || (linear_.staticPivot() && ++static_failures >= 2)))
        {
          newton_each = true;
          linear_.allowApproximate(false);
          ++timings_.newton_switches;
        }
      }
    }
    previous = scaled;
    moved += q_part;
    // Full Newton, or a matrix built in this step (Newton's own step): the increment is the error
    // measure, and the multipliers are as good as the position increment says (at very small h their
    // round-off would fail their test). Modified Newton with an older matrix: the error left in the iterate
    // after this increment is about theta / (1 - theta) times it, the remaining increments summed
    // (Hairer & Wanner, Solving ODEs II, Sec. IV.8), theta the largest rate measured with this matrix
    // (floored at kRateFloor); it is accepted only while the iteration contracts (theta <= 0.5), and its
    // multipliers must settle too: an older matrix can shrink the q increments while they are still off.
    const bool newton_step = !reuse || (built_this_step && factorizationExact());
    const double rate = std::max(theta_, kRateFloor);
    const double left = newton_step ? q_part : (theta_known_ ? rate / (1.0 - rate) : 1.0) * scaled;
    if (left <= 1.0 && !(reuse && theta_ > 0.5))
    {
      predict(s, h, qdd, q_, qd_, acc_);
      int crossed = -1;
      if (system_.model().anyContact())
      {
        const ScopeTimer timer(timings_.contact);
        // the contacts were evaluated for the slots within reach of the step's expected motion; a step
        // that moved further goes on iterating with the slots within reach of its motion
        const double motion = largestMotion(system_.model(), s.q, q_);
        if (motion > near_motion_)
        {
          findNearContacts(s, 2.0 * motion);
          ++timings_.contact_reach_misses;
          continue;
        }
        if (system_.model().contact.enabled)
          crossed = system_.firstPassedThrough(near_, s.q, q_);
      }
      if (crossed >= 0)
      {
        // a step that jumps a strut through another is refused (and cut), never accepted silently
        sum.status = SolveStatus::kPassedThrough;
        sum.message = system_.passedThroughMessage(crossed);
        return sum;
      }
      estimate_.error = errorEstimate(s.acc, acc_, h);
      rememberStep(s, s.t + h, qdd);
      s.q.swap(q_);  // q_ keeps the start positions for the onset check
      s.qd = qd_;
      s.acc = acc_;
      s.qdd = qdd;
      s.lambda = lambda;
      s.t += h;
      s.u = u;
      updateContactMemory(s, q_);
      ++factor_age_;
      if (diverged && linear_.dense() && system_.size() <= kSmallSystem)  // (small: never reduced_)
      {
        fresh_streak_ = std::clamp(2 * fresh_streak_, kFreshStartsLeast, kFreshStartsMost);
        fresh_starts_ = fresh_streak_;
      }
      else if (!built_this_step)
        fresh_streak_ = 0;  // a kept matrix served a whole step
      else if (fresh_starts_ > 0)
        --fresh_starts_;
      return sum;
    }
  }
  sum.status = SolveStatus::kMaxIterations;
  factor_valid_ = false;
  std::ostringstream msg;
  msg << "Newton did not converge in " << options_.max_iterations << " iterations (last increment " << sum.residual
      << ")";
  sum.message = msg.str();
  return sum;
}

Summary BodyDynamicsSolver::advance(BodyState& s, double h, const ActuationLaw& law)
{
  return stepInPieces(
      h, options_, [&](double piece) { return attemptOrFullNewton(s, piece, law); }, [&]() { return s.t; });
}

Summary BodyDynamicsSolver::tryStep(BodyState& s, double h, const ActuationLaw& law)
{
  const ScopeTimer timer(timings_.total);
  return attemptOrFullNewton(s, h, law);
}

Summary BodyDynamicsSolver::step(BodyState& s, double h, const ActuationLaw& law)
{
  const ScopeTimer timer(timings_.total);
  return advance(s, h, law);
}

Summary BodyDynamicsSolver::initialize(BodyState& s, const ActuationLaw& law)
{
  Summary sum;
  history_count_ = 0;
  law(s.t, s.u);
  const int nq = system_.nq();
  const int nl = system_.nLambda();
  Eigen::VectorXd rhs(system_.size()), x, tmp;

  factor_valid_ = false;  // jac_ now holds other matrices
  // these solves must be exact (linear_ may hold the approximate static-pivot factorization of modified
  // Newton): a solver of their own, dense or sparse LU
  SparseLinearSolver exact;
  exact.allowDense(true);
  // [M Phi_q^T; Phi_q 0] at s.q into `exact` (false, with sum's status set, when singular)
  const auto factorizeMassAndConstraints = [&]
  {
    jac_.setZero();
    system_.addMass(s.q, jac_, 1.0);
    system_.addConstraintJacobian(s.q, jac_);
    if (exact.factorize(jac_.matrix()))
      return true;
    sum.status = SolveStatus::kSingular;
    sum.message = "singular mass/constraint matrix at the initial state";
    return false;
  };
  // positions: the nearest (in the mass metric) to the given ones where Phi(q, t) = 0, by Newton on
  // [M Phi_q^T; Phi_q 0] [dq; mu] = [0; -Phi] (a state assembled by hand, or a scene whose joints do not
  // quite meet, would otherwise be pulled together by the first step's constraint forces)
  const double phi_tol = 1e-12 * (1.0 + s.q.lpNorm<Eigen::Infinity>());
  for (int it = 0;; ++it)
  {
    system_.constraintValue(s.q, s.u, phi_);
    if (!phi_.allFinite())
    {
      sum.status = SolveStatus::kNonFinite;
      sum.message = "non-finite constraint values at the initial state";
      return sum;
    }
    if (phi_.lpNorm<Eigen::Infinity>() <= phi_tol)
      break;
    if (it == options_.max_iterations)
    {
      std::ostringstream msg;
      msg << "the initial positions could not be brought onto the constraints (|Phi| = "
          << phi_.lpNorm<Eigen::Infinity>() << " after " << it << " iterations)";
      sum.status = SolveStatus::kMaxIterations;
      sum.message = msg.str();
      return sum;
    }
    if (!factorizeMassAndConstraints())
      return sum;
    rhs.head(nq).setZero();
    rhs.tail(nl) = -phi_;
    exact.solve(rhs, x);
    s.q += x.head(nq);
    ++sum.iterations;
  }

  // velocities: min |qd - qd0|_M subject to Phi_q qd = -Phi_t
  if (!factorizeMassAndConstraints())
    return sum;
  const Eigen::VectorXd no_velocity = Eigen::VectorXd::Zero(nq);
  system_.inertialForce(s.q, no_velocity, s.qd, inertial_, nullptr, 0.0, 0.0, 0.0);  // M qd
  rhs.head(nq) = inertial_;
  system_.velocityRhs(s.u, tmp);
  rhs.tail(nl) = tmp;
  exact.solve(rhs, x);
  s.qd = x.head(nq);
  const Summary acc = consistentAccelerations(s, exact);
  if (!acc.ok())
  {
    sum.status = acc.status;
    sum.message = acc.message;
  }
  return sum;
}

Summary BodyDynamicsSolver::restartAccelerations(BodyState& s)
{
  Summary sum;
  history_count_ = 0;
  factor_valid_ = false;  // jac_ now holds another matrix
  SparseLinearSolver exact;
  exact.allowDense(true);
  jac_.setZero();
  system_.addMass(s.q, jac_, 1.0);
  system_.addConstraintJacobian(s.q, jac_);
  if (!exact.factorize(jac_.matrix()))
  {
    sum.status = SolveStatus::kSingular;
    sum.message = "singular mass/constraint matrix at t = " + shortestNumber(s.t) + " s";
    return sum;
  }
  return consistentAccelerations(s, exact);
}

Summary BodyDynamicsSolver::consistentAccelerations(BodyState& s, SparseLinearSolver& exact)
{
  Summary sum;
  const int nq = system_.nq();
  const int nl = system_.nLambda();
  Eigen::VectorXd rhs(system_.size()), x, tmp;
  // accelerations and multipliers: M qdd + Phi_q^T lambda = F - Qv,  Phi_q qdd = gamma
  Eigen::VectorXd zero = Eigen::VectorXd::Zero(nq);
  system_.inertialForce(s.q, s.qd, zero, inertial_, nullptr, 0.0, 0.0, 0.0);
  system_.appliedForce(s.q, s.qd, s.u, applied_, nullptr, 0.0, 0.0);
  if (s.contact_speed.size() != system_.model().contactSlots())
    s.contact_speed.reset(system_.model().contactSlots(), 0.0);
  system_.contactForce(s.q, s.qd, s.contact_speed, ContactMode::kDynamic, applied_, nullptr, 0.0, 0.0);
  rhs.head(nq) = applied_ - inertial_;
  system_.accelerationRhs(s.q, s.qd, s.u, tmp);
  rhs.tail(nl) = tmp;
  exact.solve(rhs, x);
  s.qdd = x.head(nq);
  s.acc = s.qdd;
  s.lambda = x.tail(nl);
  if (!x.allFinite())
  {
    sum.status = SolveStatus::kNonFinite;
    sum.message = "non-finite accelerations at t = " + shortestNumber(s.t) + " s";
  }
  return sum;
}

}  // namespace active_tensegrity::core
