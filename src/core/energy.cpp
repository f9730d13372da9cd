#include "active_tensegrity/core/energy.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "active_tensegrity/core/cable.h"
#include "active_tensegrity/core/mechanics.h"

namespace active_tensegrity::core
{
double contactElasticNormalForce(const Model& model, const ContactPairState& st)
{
  const ContactLaw law = st.body_b < 0 ? model.ground.law : model.contact.law;
  if (law == ContactLaw::kLinear)
    return st.stiffness * st.penetration;
  return st.stiffness * st.penetration * std::sqrt(st.penetration) +
         st.core_stiffness * st.core_penetration * std::sqrt(st.core_penetration);
}

double cablePullInForce(const Cable& cable, const CableState& s)
{
  const double stretch = s.length - s.rest_length;
  if (!(stretch > 0.0 || !cable.tension_only) || s.length <= 0.0)
    return 0.0;
  const double elastic = s.stiffness * stretch;
  return elastic + (cable.area > 0.0 ? 0.5 * s.stiffness * stretch * stretch / s.rest_length : 0.0);
}

double EnergyPoint::scale() const
{
  return std::abs(kinetic) + std::abs(elastic) + std::abs(gravity);
}

EnergyMeter::EnergyMeter(const System& system) : system_(system)
{
  const Model& model = system.model();
  for (const Cable& c : model.cables)
  {
    first_.push_back(static_cast<int>(slots_.size()));
    for (const PointRef& p : c.points)
      slots_.push_back(pointSlot(model, p));
  }
}

EnergyPoint EnergyMeter::at(const State& state, const std::vector<ContactPairState>& contacts)
{
  const Model& model = system_.model();
  const Eigen::VectorXd& q = state.q;
  EnergyPoint e;
  e.kinetic = system_.kineticEnergy(q, state.qd);
  if (model.gravity_enabled)
    for (const Body& b : model.bodies)
      e.gravity -= b.mass * model.gravity.dot(q.segment<3>(b.offset) - model.q0.segment<3>(b.offset));
  for (const PointLoad& load : model.loads)
    e.gravity -= system_.loadFactor() *
                 load.force.dot(pointPosition(model, load.point, q) - pointPosition(model, load.point, model.q0));
  for (const PointLoad& load : system_.externalLoads())
    e.gravity -= load.force.dot(pointPosition(model, load.point, q) - pointPosition(model, load.point, model.q0));
  if (!model.cables.empty())
    frames_.update(model, q, state.qd);
  for (size_t k = 0; k < model.cables.size(); ++k)
  {
    const Cable& c = model.cables[k];
    const CableState s = evaluateCable(c, slots_.data() + first_[k], frames_, q, state.qd, state.u, true);
    e.elastic += cablePotentialEnergy(c, s);
    // the damper's power c (l_dot + s_dot)^2 = T_d^2 / c; the actuator pulls against the whole tension
    if (c.damping > 0.0 && !s.slack)
      e.damping_power += s.damping_tension * s.damping_tension / c.damping;
    if (c.actuator >= 0 && c.actuator < static_cast<int>(state.u.size()))
    {
      const double rate = state.u[c.actuator].rate;
      e.actuator_power += (cablePullInForce(c, s) + (s.slack ? 0.0 : s.damping_tension)) * rate;
    }
  }
  for (const ContactPairState& st : contacts)
  {
    if (!st.active)
      continue;
    e.elastic += contactElasticEnergy(model, st);
    e.contact_power += (st.normal_force - contactElasticNormalForce(model, st)) * st.penetration_rate +
                       st.friction_force * st.slip_speed;
  }
  // driven constraint rows: the constraint forces -Phi_q^T lambda do work lambda^T Phi_t = -lambda^T rhs, rhs the
  // right-hand side of Phi_q qd = -Phi_t (zero on every undriven row)
  if (!model.actuators.empty() && state.lambda.size() >= system_.nLambda())
  {
    system_.velocityRhs(state.u, rhs_);
    e.actuator_power -= state.lambda.head(system_.nLambda()).dot(rhs_);
  }
  return e;
}

EnergyPoint energyPoint(const System& system, const State& state, const std::vector<ContactPairState>& contacts)
{
  EnergyMeter meter(system);
  return meter.at(state, contacts);
}

double stepNumericalDissipation(const EnergyPoint& a, const EnergyPoint& b, double h)
{
  const double supplied = 0.5 * h * (a.actuator_power + b.actuator_power);
  const double taken = 0.5 * h * (a.damping_power + b.damping_power + a.contact_power + b.contact_power);
  return a.total() + supplied - taken - b.total();
}

double stepEnergyRoundoff(const Model& model, const Eigen::VectorXd& q, double h)
{
  double mass = 0.0;
  for (const Body& b : model.bodies)
    mass += b.mass;
  const double v = 2.0 * std::numeric_limits<double>::epsilon() * (1.0 + q.lpNorm<Eigen::Infinity>()) / h;
  return 0.5 * mass * v * v;
}

StepEnergyCheck checkStepEnergy(const EnergyPoint& a, const EnergyPoint& b, double h, double tolerance,
                                double roundoff_energy, bool in_contact)
{
  const double numerical = stepNumericalDissipation(a, b, h);
  const double roundoff =
      64.0 * std::numeric_limits<double>::epsilon() * std::max(a.scale(), b.scale()) + roundoff_energy;
  const double mechanical =
      std::max(std::abs(a.kinetic) + std::abs(a.elastic), std::abs(b.kinetic) + std::abs(b.elastic));
  const double allowed = tolerance * mechanical + roundoff;
  StepEnergyCheck c;
  c.gained = -numerical > allowed;
  c.lost_in_contact = in_contact && numerical > allowed;
  c.in_contact = in_contact;
  return c;
}

void EnergyAccount::begin(const EnergyPoint& p)
{
  *this = EnergyAccount();
  start = p;
  now = p;
  peak_mechanical = std::abs(p.kinetic) + std::abs(p.elastic);
}

void EnergyAccount::add(const EnergyPoint& end, double h, double t_end, const StepEnergyCheck& check)
{
  if (!check.ok() && gaining_steps + contact_loss_steps == 0)
    first_unresolved_t = t_end;
  gaining_steps += check.gained ? 1 : 0;
  contact_loss_steps += check.lost_in_contact ? 1 : 0;
  if (!check.ok() && check.in_contact)
    contact_unresolved_energy += std::abs(stepNumericalDissipation(now, end, h));
  peak_mechanical = std::max(peak_mechanical, std::abs(end.kinetic) + std::abs(end.elastic));
  actuator_work += 0.5 * h * (now.actuator_power + end.actuator_power);
  damping_dissipation += 0.5 * h * (now.damping_power + end.damping_power);
  contact_dissipation += 0.5 * h * (now.contact_power + end.contact_power);
  const double gain = -stepNumericalDissipation(now, end, h);
  if (gain > largest_step_gain)
  {
    largest_step_gain = gain;
    largest_gain_t = t_end;
  }
  now = end;
  numerical_dissipation = start.total() + actuator_work - damping_dissipation - contact_dissipation - now.total();
  ++steps;
}

}  // namespace active_tensegrity::core
