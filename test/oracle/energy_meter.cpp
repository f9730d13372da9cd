#include "active_tensegrity/oracle/energy_meter.h"

#include "active_tensegrity/core/elements/cable.h"

namespace active_tensegrity::core
{
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

EnergyPoint EnergyMeter::at(const BodyState& state, const std::vector<ContactPairState>& contacts)
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

EnergyPoint energyPoint(const System& system, const BodyState& state, const std::vector<ContactPairState>& contacts)
{
  EnergyMeter meter(system);
  return meter.at(state, contacts);
}

}  // namespace active_tensegrity::core
