#include "active_tensegrity/core/solvers/dynamics.h"

#include <cmath>
#include <limits>

#include "active_tensegrity/core/solvers/natural.h"

namespace active_tensegrity::core
{
struct DynamicsSolver::Impl
{
  explicit Impl(const Model& m, const SolverOptions& options)
    : model(m), nm(buildNaturalModel(model)), solver(nm, options)
  {
  }
  Model model;  // the natural model points at it
  NaturalModel nm;
  NaturalSolver solver;
  StepTimings timings;
  NaturalStats stats_at_reset;
  // the state the last accepted step (or initialize) ended in: its time and positions, and its contacts when asked
  double end_t = std::numeric_limits<double>::quiet_NaN();
  Eigen::VectorXd end_x, end_v;
  Eigen::VectorXd end_q, end_qd;  // the body poses the end's state carried
  std::vector<NaturalTouch> end_touching;
  ActuationValues u;   // scratch: the law's values
  bool defer = false;  // deferPoses

  void countTimings()
  {
    const NaturalStats& s = solver.stats();
    timings.newton_iterations = s.iterations - stats_at_reset.iterations;
    timings.factorizations = s.factorizations - stats_at_reset.factorizations;
    timings.analyses = s.analyses - stats_at_reset.analyses;
    timings.forces = s.forces_time - stats_at_reset.forces_time;
    timings.contact = s.contact_time - stats_at_reset.contact_time;
    timings.constraints = s.constraints_time - stats_at_reset.constraints_time;
    timings.factorization = s.factorization_time - stats_at_reset.factorization_time;
    timings.solve = s.solve_time - stats_at_reset.solve_time;
  }
  /// `s` ended an accepted step (or initialize): remembered for contactsAt, the most touching counted; its actuators'
  /// forces are formed when asked (formActuatorForces).
  void ended(State& s)
  {
    s.natural.actuator_force.clear();
    end_t = s.natural.t;
    end_x = s.natural.x;
    end_v = s.natural.v;
    if (s.natural.poses_pending)
    {
      end_q.resize(0);
      end_qd.resize(0);
    }
    else
    {
      end_q = s.q;
      end_qd = s.qd;
    }
    end_touching = s.natural.touching;
    timings.most_touching = std::max(timings.most_touching, static_cast<long>(s.natural.touching.size()));
  }
  /// Whether s is the state the last accepted step ended in, untouched since (its time up to callers' rounding).
  bool atEnd(const State& s) const
  {
    if (!(s.natural.t == end_t) || s.natural.x.size() != end_x.size() || s.natural.x != end_x || s.natural.v != end_v ||
        s.natural.touching.size() != end_touching.size() || !carriesOwn(s))
      return false;
    for (size_t i = 0; i < end_touching.size(); ++i)
      if (s.natural.touching[i].slot != end_touching[i].slot || s.natural.touching[i].speed != end_touching[i].speed)
        return false;
    return true;
  }
  /// Whether s carries natural coordinates of this model whose body poses are q, qd (a state a step made, untouched
  /// since), at its time up to callers' rounding (sameTime).
  bool carriesOwn(const State& s) const;
  bool carriesFrames(const State& s) const
  {
    return s.natural.frame_spin.size() == static_cast<Eigen::Index>(nm.struts.size());
  }
  static bool sameTime(double a, double b)
  {
    return std::abs(a - b) <= 1e-8 * std::max(1.0, std::abs(a));
  }
  void fromBody(State& s) const
  {
    naturalFromBody(nm, s);
  }
  void writeBody(State& s) const
  {
    writeBodyPoses(nm, s);
    s.natural.poses_pending = false;
  }
  /// A step's end: the body poses written, or their frames carried and the rest left to writePoses
  void stepped(State& s) const
  {
    if (!defer)
    {
      writeBody(s);
      return;
    }
    carryBodyFrames(nm, s);
    s.t = s.natural.t;
    s.natural.poses_pending = true;
  }
};

bool DynamicsSolver::Impl::carriesOwn(const State& s) const
{
  if (s.natural.equilibrium || !carriesFrames(s) || !sameTime(s.natural.t, s.t))
    return false;
  const auto same = [](const Eigen::VectorXd& a, const Eigen::VectorXd& b) { return a.size() == b.size() && a == b; };
  // (the state the last step left with its poses deferred: its natural coordinates alone say what it is)
  if (s.natural.poses_pending)
    return s.natural.t == end_t && same(s.natural.x, end_x) && same(s.natural.v, end_v);
  // (the state the last step left, untouched: its body poses are the ones written from its natural coordinates)
  if (s.natural.t == end_t && same(s.natural.x, end_x) && same(s.natural.v, end_v) && same(s.q, end_q) &&
      same(s.qd, end_qd))
    return true;
  return carriesNaturalOf(nm, s);
}

DynamicsSolver::DynamicsSolver(const Model& model, const SolverOptions& options)
  : impl_(std::make_unique<Impl>(model, options))
{
}
DynamicsSolver::~DynamicsSolver() = default;
DynamicsSolver::DynamicsSolver(DynamicsSolver&&) noexcept = default;
DynamicsSolver& DynamicsSolver::operator=(DynamicsSolver&&) noexcept = default;

Summary DynamicsSolver::prepare(State& s, const ActuationLaw& law)
{
  if (impl_->carriesOwn(s))
    return Summary();
  return initialize(s, law);
}

Summary DynamicsSolver::initialize(State& s, const ActuationLaw& law)
{
  Impl& m = *impl_;
  law(s.t, s.u);
  // (a static equilibrium's own coordinates too)
  if (!m.carriesOwn(s) && !(m.carriesFrames(s) && carriesNaturalOf(m.nm, s)))
    m.fromBody(s);
  s.natural.t = s.t;
  s.natural.equilibrium = false;
  Summary out = m.solver.project(s.natural, s.u);
  if (out.ok())
  {
    const Summary init = m.solver.initialize(s.natural, law);
    out.status = init.status;
    out.message = init.message;
  }
  if (!out.ok())
  {
    out.message = "initial state: " + out.message;
    return out;
  }
  m.writeBody(s);
  m.ended(s);
  return out;
}

Summary DynamicsSolver::step(State& s, double h, const ActuationLaw& law)
{
  Impl& m = *impl_;
  if (const Summary init = prepare(s, law); !init.ok())
    return init;
  const double t1 = s.t + h, t0 = s.natural.t;
  Summary out;
  ScopeTimer timer(m.timings.total);  // (the body poses' writing included)
  out = m.solver.step(s.natural, t1 - s.natural.t, law);
  m.countTimings();
  if (s.natural.t == t0)
    return out;  // (nothing taken: the state is as it was)
  if (out.ok())
    s.u = m.solver.actuation();  // (the step's end: the law is not asked again)
  else
    law(s.natural.t, s.u);
  m.stepped(s);
  m.ended(s);
  return out;
}

Summary DynamicsSolver::setExternalLoads(const std::vector<PointLoad>& loads, State& s)
{
  Impl& m = *impl_;
  const ActuationValues u = s.u;
  const ActuationLaw held = ActuationLaw::writing([&u](double, ActuationValues& out) { out = u; });
  if (const Summary init = prepare(s, held); !init.ok())
    return init;
  const Summary out = m.solver.setExternalLoads(loads, s.natural, held);
  if (out.ok())
    m.ended(s);
  return out;
}

const std::vector<ContactPairState>* DynamicsSolver::contactsAt(const State& s) const
{
  const Impl& m = *impl_;
  if (!m.atEnd(s))
    return nullptr;
  return &s.natural.contacts;
}

bool DynamicsSolver::formActuatorForces(State& s)
{
  Impl& m = *impl_;
  if (!m.carriesOwn(s))
  {
    const ActuationValues u = s.u;  // (initialized at its own actuation values)
    if (!initialize(s, ActuationLaw::writing([&u](double, ActuationValues& out) { out = u; })).ok())
      return false;
  }
  if (s.natural.actuator_force.size() != m.model.actuators.size())
    m.solver.actuationForces(s.natural, s.u, s.natural.actuator_force);
  return true;
}

void DynamicsSolver::deferPoses(bool defer)
{
  impl_->defer = defer;
}

void DynamicsSolver::writePoses(State& s)
{
  Impl& m = *impl_;
  if (!s.natural.poses_pending)
    return;
  const bool at_end = m.carriesOwn(s);
  writeBodyMotion(m.nm, s);  // (the frames carried at every step)
  s.natural.poses_pending = false;
  if (at_end)
  {
    m.end_q = s.q;
    m.end_qd = s.qd;
  }
}

EnergyPoint DynamicsSolver::energyAt(const State& s)
{
  return impl_->solver.energyAt(s.natural, s.u);
}

const StepTimings& DynamicsSolver::timings() const
{
  return impl_->timings;
}

void DynamicsSolver::resetTimings()
{
  impl_->timings = StepTimings();
  impl_->stats_at_reset = impl_->solver.stats();
}

// ---- adaptive steps ----------------------------------------------------------------------------------------

AdaptiveStepper::AdaptiveStepper(DynamicsSolver& solver, const SolverOptions& options) : solver_(solver)
{
  solver_.impl_->solver.setAdaptiveOptions(options);
  each_ = [this](const NaturalState& n)
  {
    DynamicsSolver::Impl& m = *solver_.impl_;
    State& s = *state_;
    const double h = n.t - last_t_;
    last_t_ = n.t;
    stats_.h_min = stats_.h_max == 0.0 ? h : std::min(stats_.h_min, h);
    stats_.h_max = std::max(stats_.h_max, h);
    s.u = m.solver.actuation();  // (the step's end: the law is not asked again)
    m.stepped(s);
    m.ended(s);
    if (*on_step_)
    {
      const ScopeTimer timer(callback_time_);
      (*on_step_)(s);
    }
  };
}

Summary AdaptiveStepper::advanceTo(State& s, double t_end, const ActuationLaw& law,
                                   const std::function<void(const State&)>& on_step)
{
  DynamicsSolver::Impl& m = *solver_.impl_;
  if (const Summary init = solver_.prepare(s, law); !init.ok())
    return init;
  const NaturalStats before = m.solver.stats();
  Summary out;
  state_ = &s;
  on_step_ = &on_step;
  last_t_ = s.t;
  callback_time_ = 0.0;
  {
    ScopeTimer timer(m.timings.total);
    out = m.solver.advanceAdaptive(s.natural, t_end, law, each_);
  }
  m.timings.total -= callback_time_;  // (the caller's on_step is not the solver's time)
  m.countTimings();
  const NaturalStats& after = m.solver.stats();
  stats_.accepted += after.accepted - before.accepted;
  stats_.rejected_error += after.rejected_error - before.rejected_error;
  stats_.rejected_onset += after.rejected_onset - before.rejected_onset;
  stats_.rejected_energy += after.rejected_energy - before.rejected_energy;
  stats_.rejected_solver += after.rejected_solver - before.rejected_solver;
  stats_.at_min_step += after.at_min_step - before.at_min_step;
  if (!out.ok())
    law(s.natural.t, s.u);
  m.stepped(s);
  m.ended(s);
  return out;
}

const EnergyPoint& AdaptiveStepper::lastEnergy() const
{
  return solver_.impl_->solver.lastEnergy();
}

const StepEnergyCheck& AdaptiveStepper::lastEnergyCheck() const
{
  return solver_.impl_->solver.lastEnergyCheck();
}

}  // namespace active_tensegrity::core
