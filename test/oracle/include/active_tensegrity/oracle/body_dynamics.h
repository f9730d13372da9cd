/// Index-3 DAE time integration in the body coordinates (7 per strut), kept as the comparison `tensegrity_bench
/// natural` runs against the package's dynamics in natural coordinates (dynamics.h), with its adaptive steps
/// (BodyAdaptiveStepper, body_adaptive.h).
/// Paper Sec. 5: Newton-Raphson on [qdd_{n+1}; lambda_{n+1}] with the
/// full analytic Jacobian (Eq. 68) and the constraint rows scaled by 1 / (beta h^2) (Bottasso et al.
/// 2007). Integrators: Newmark (gamma, beta) and generalized-alpha (Arnold & Bruls 2007, from
/// rho_infinity). A step whose Newton iteration fails is halved (up to max_step_cuts times).
#pragma once

#include <functional>
#include <type_traits>
#include <utility>

#include "active_tensegrity/core/model/actuation_law.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/oracle/reduced_linear_solver.h"
#include "active_tensegrity/oracle/sparse_linear_solver.h"
#include "active_tensegrity/core/solvers/state.h"
#include "active_tensegrity/oracle/body_state.h"
#include "active_tensegrity/core/base/summary.h"
#include "active_tensegrity/oracle/mechanics.h"

namespace active_tensegrity::core
{
/// What an accepted step tells a step-size controller (AdaptiveStepper).
struct StepEstimate
{
  /// Local error of the strut ends' positions (m): h^2 (|beta - 1/6| + |gamma - 1/2|) |a_{n+1} - a_n|
  /// per body, translation plus length times the quaternion part, largest over bodies (docs/physics.md).
  double error = 0.0;
  /// Pairs that touch at the end of the step but did not at its start: the deepest penetration among
  /// them (m, 0 when none), that pair's gap at the start (m) and its contact slot (contact.h).
  double onset_depth = 0.0;
  double onset_gap = 0.0;
  int onset_pair = -1;
};

class BodyDynamicsSolver
{
public:
  BodyDynamicsSolver(const Model& model, const SolverOptions& options);

  /// Makes `state` consistent with the constraints at state.t: positions and velocities projected
  /// onto them in the mass metric (positions by Newton to |Phi| <= 1e-12 (1 + |q|)), accelerations and
  /// multipliers solved.
  Summary initialize(BodyState& state, const ActuationLaw& law);
  /// Advances by h (halving it on failure); on failure `state` is left at the last good instant.
  Summary step(BodyState& state, double h, const ActuationLaw& law);
  /// One attempt at a step of h, never cut: on success `state` is advanced and estimate() describes
  /// the step; on failure `state` is unchanged.
  Summary tryStep(BodyState& state, double h, const ActuationLaw& law);
  /// Says whether the steps will vary (AdaptiveStepper sets it): the body blocks then solve every body
  /// alone (BodyBlockSolver::allowGroups), as their groups would follow the step size, and body blocks that
  /// stop contracting in the step that built them are distrusted even when they contracted at first and the
  /// iterate moved far since.
  void setVariableSteps(bool variable)
  {
    variable_steps_ = variable;
    linear_.allowBodyGroups(!variable);
  }
  /// Says whether contactsAt will be asked at every step's end (runAnalysis with a per-step consumer of the
  /// contacts): each accepted step then forms its touching slots' forces in the one pass that evaluates its end's
  /// near slots (the same values contactsAt forms on demand, without evaluating those slots' motion twice).
  void setContactsEveryStep(bool every)
  {
    contacts_every_step_ = every;
  }
  /// The error estimate and contact onset of the last accepted step.
  const StepEstimate& estimate() const
  {
    return estimate_;
  }

  const System& system() const
  {
    return system_;
  }
  /// Forces from outside the scene (System::setExternalLoads) from `s` on: constant over each step (a caller
  /// that switches them at a time steps onto it). The forces jump there, so the integration restarts from s as
  /// from an initial state: its accelerations and multipliers are made consistent with them
  /// (restartAccelerations; a trapezoidal step then gives a constant force's impulse exactly).
  Summary setExternalLoads(std::vector<PointLoad> loads, BodyState& s)
  {
    system_.setExternalLoads(std::move(loads));
    return restartAccelerations(s);
  }
  /// The accelerations and multipliers consistent with the forces at s.q, s.qd (as initialize() makes them),
  /// after a jump of the applied forces; positions and velocities are kept.
  Summary restartAccelerations(BodyState& s);

  /// The active contacts of `state` (as activeContacts(model, state) gives them, ordered by contact slot)
  /// when it is the state the last accepted step ended in, evaluated with that step's contact memory; else
  /// null. Every step evaluates its end's near slots (gaps and approach rates: the step after it starts from
  /// them); the first call at that end adds the touching ones' forces, so per-step consumers (peaks, messages)
  /// need no contact pass of their own and a step no one asks about pays for no forces. (Not thread-safe: call
  /// it from the thread that steps.)
  const std::vector<ContactPairState>* contactsAt(const BodyState& state) const;

  const BodyStepTimings& timings() const
  {
    return timings_;
  }
  void resetTimings()
  {
    timings_ = BodyStepTimings();
    most_touching_before_ = 0;
  }
  /// The step control refused the step that tryStep just accepted (on its error estimate or a contact onset):
  /// the figures of that step's end (StepTimings::most_touching) are taken back. Its work stays counted.
  void stepRefused()
  {
    timings_.most_touching = most_touching_before_;
  }

  /// Effective Newmark coefficients and the generalized-alpha weights.
  struct Coefficients
  {
    double gamma, beta, alpha_m, alpha_f;
  };
  Coefficients coefficients() const
  {
    return coef_;
  }

  /// The Newton residual and Jacobian of one step at the unknowns (qdd_new, lambda_new); exposed for
  /// the finite-difference test of the full Jacobian.
  void residualAndJacobian(const BodyState& start, double h, const ActuationValues& u, const Eigen::VectorXd& qdd_new,
                           const Eigen::VectorXd& lambda_new, Eigen::VectorXd& r, BlockSparseMatrix* jac);

private:
  /// M qdd + Phi_q^T lambda = F - Qv, Phi_q qdd = gamma at s.q, s.qd into s.qdd, s.acc, s.lambda, with `exact`
  /// holding the factorization of [M Phi_q^T; Phi_q 0] there.
  Summary consistentAccelerations(BodyState& s, SparseLinearSolver& exact);
  /// Impact speeds v_0 the next step from `start` uses per checked pair (into step_speeds_): the
  /// remembered one of a live contact, else the approach rate at `start` (floored at min_impact_speed)
  /// for pairs close enough to touch within h.
  void prepareContact(const BodyState& start, double h);
  void residual(const BodyState& start, double h, const ActuationValues& u, const Eigen::VectorXd& qdd_new,
                const Eigen::VectorXd& lambda_new, Eigen::VectorXd& r, BlockSparseMatrix* jac);
  /// After a converged step from positions q_start: remember v_0 of pairs in contact at `end`, forget
  /// separated ones; records the contact onsets in estimate_.
  void updateContactMemory(BodyState& end, const Eigen::VectorXd& q_start);
  /// The contact slots of `start` within 2 motion (m) of touching into near_ (the only ones a step in which no
  /// body point moves further than `motion` evaluates), with their impact speeds into step_speeds_.
  void findNearContacts(const BodyState& start, double motion);
  /// The local error estimate of a step of h from algorithmic accelerations a0 to a1 (StepEstimate).
  double errorEstimate(const Eigen::VectorXd& a0, const Eigen::VectorXd& a1, double h) const;
  /// One Newton solve of a step of h (modified Newton as options allow, or full Newton).
  Summary attempt(BodyState& state, double h, const ActuationLaw& law, bool full_newton);
  /// attempt(), and when modified Newton fails (no convergence, or a matrix built at a diverged iterate that is
  /// singular), the same step again in full Newton (an exact factorization per iteration) before the caller cuts
  /// it: a kept matrix can diverge where Newton's own converges (friction as the six-bar robot lands on a face:
  /// 2689 step cuts on its roll without the retry, 6 with it).
  Summary attemptOrFullNewton(BodyState& state, double h, const ActuationLaw& law);
  /// A step of h, halved on failure (a loop over the pieces, at most max_step_cuts levels deep, never
  /// below dt_min).
  Summary advance(BodyState& state, double h, const ActuationLaw& law);
  void predict(const BodyState& start, double h, const Eigen::VectorXd& qdd_new, Eigen::VectorXd& q,
               Eigen::VectorXd& qd, Eigen::VectorXd& acc) const;

  System system_;
  SolverOptions options_;
  Coefficients coef_;
  BlockSparseMatrix jac_;
  /// The Newton matrix's factorizations: linear_ (body blocks when they serve; every method on large systems),
  /// and on systems of at most kReducedMost unknowns the exact ones in reduced_, the one-body rows eliminated
  /// (docs/design.md, "The body coordinates as a test oracle").
  SparseLinearSolver linear_;
  ReducedLinearSolver reduced_;
  bool use_reduced_ = false;      // whether the exact factorizations go to reduced_
  bool reduced_current_ = false;  // whether the last factorization is reduced_'s
  /// Factorizes jac_ (as above); false when it is singular.
  bool factorizeNewtonMatrix();
  void solveNewtonMatrix(const Eigen::VectorXd& b, Eigen::VectorXd& x) const
  {
    if (reduced_current_)
      reduced_.solve(b, x);
    else
      linear_.solve(b, x);
  }
  /// Whether the last factorization solves to round-off (false: body blocks, static pivots).
  bool factorizationExact() const
  {
    return reduced_current_ || linear_.exact();
  }
  Eigen::VectorXd q_, qd_, acc_, inertial_, applied_, cforce_, phi_, r_, dx_, qdd_iter_, lambda_iter_;
  ActuationValues u_iter_;    // the law's values at the attempted step's end
  SlotValues step_speeds_;    // v_0 per contact slot for the step being solved (the near slots set)
  std::vector<int> near_;     // the step's contact slots within reach (findNearContacts)
  double near_motion_ = 0.0;  // the motion near_ allows for (m)
  /// The least motion near_ allows for (m): a body at rest still moves a little in its first step.
  static constexpr double kNearFloor = 1e-4;
  bool start_at_end_ = false;          // the step being solved starts where the last accepted one ended (atEnd)
  std::vector<double> near_previous_;  // contact memory at the start of the step being accepted, per near_ slot
  // the near slots evaluated where the last accepted step ended (end_q_, end_qd_; end_slots_ with their
  // contact memory end_memory_ (the step's impact speed where touching, else 0), every other slot apart there): their
  // approach rates and gaps (per slot, NaN: not evaluated) for the next step's impact speeds and near slots, and
  // the active contacts with their forces, formed when contactsAt first asks (no copy of the whole memory: a
  // lattice of 2000 struts has 2 million slots)
  bool end_valid_ = false;
  Eigen::VectorXd end_q_, end_qd_;
  std::vector<int> end_slots_;
  std::vector<double> end_memory_;
  SlotValues end_rate_;
  SlotValues end_gap_;
  mutable std::vector<ContactPairState> end_contacts_;
  mutable bool end_contacts_ready_ = false;
  /// Whether `s` is the state the last accepted step ended in (end_*).
  bool atEnd(const BodyState& s) const;
  BodyStepTimings timings_;
  long most_touching_before_ = 0;  // timings_.most_touching before the last accepted step's end (stepRefused)
  StepEstimate estimate_;
  // modified Newton (options_.reuse_jacobian): the factorization in linear_ and what it was built for
  bool factor_valid_ = false;
  double factor_h_ = 0.0;
  int factor_age_ = 0;                // steps taken with it
  std::vector<int> factor_contacts_;  // slots touching when it was built (ascending)
  std::vector<int> touching_;         // slots touching at the start of the step being solved (ascending)
  double theta_ = 0.0;                // largest contraction rate seen with it
  bool variable_steps_ = false;       // setVariableSteps
  bool contacts_every_step_ = false;  // setContactsEveryStep
  bool theta_known_ = false;          // whether theta_ was measured (two increments above round-off)
  // after a kept matrix diverged (theta > 0.5): steps still to start with a new matrix, and how many the next
  // divergence orders (doubling while kept matrices keep failing, back to the least once one serves a step)
  int fresh_starts_ = 0;
  int fresh_streak_ = 0;
  double mass_scale_ = 0.0;  // largest body mass (kg): the multipliers' round-off scale
  // the first guess of a step: accelerations and multipliers extrapolated by the polynomial through the
  // ends of the last accepted steps; history_[0] is where the last step started, history_[1] where the one
  // before started; history_count_ of them belong to the chain ending at last_end_ (0: no extrapolation)
  struct Sample
  {
    double t = 0.0;
    Eigen::VectorXd qdd, lambda;
  };
  /// Whether `s` is where the last accepted step ended (the history extends to it).
  bool continuesHistory(const BodyState& s) const;
  void firstGuess(const BodyState& s, double h, Eigen::VectorXd& qdd, Eigen::VectorXd& lambda) const;
  void rememberStep(const BodyState& start, double t_end, const Eigen::VectorXd& qdd_end);
  Sample history_[2];
  int history_count_ = 0;
  double last_end_t_ = 0.0;
  Eigen::VectorXd last_end_qdd_;
};

}  // namespace active_tensegrity::core
