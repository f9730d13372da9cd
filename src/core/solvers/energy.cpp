#include "active_tensegrity/core/solvers/energy.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "active_tensegrity/core/elements/cable.h"

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
