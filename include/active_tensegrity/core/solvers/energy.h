/// The energy account of a dynamic run: the mechanical energy of a state and the powers that change it
/// (actuators, dampers, contact), summed over the steps; what is left is the integrator's own (numerical)
/// dissipation, or a gain where a step did not resolve a stiff event (docs/physics.md, "Energy account").
#pragma once

#include <vector>

#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
/// The elastic part of a contact's normal force (N): what its elastic energy is the integral of.
double contactElasticNormalForce(const Model& model, const ContactPairState& st);
/// A cable's elastic energy's derivative with respect to the pull-in s at fixed positions (N): the tension's elastic
/// part, plus, for a material cable (k = EA / l0, l0 shortening with s), (1/2) k stretch^2 / l0.
double cablePullInForce(const Cable& cable, const CableState& s);

/// The energy of one state (J) and the powers acting on it there (W).
struct EnergyPoint
{
  double kinetic = 0.0;  // translation and rotation of every body
  double elastic = 0.0;  // cables and springs (after pull-in), contacts (Hertz or linear, sleeves and cores)
  double gravity = 0.0;  // gravity, the constant point loads and the external ones, 0 at the scene's positions
  /// Put in by the actuators: cables pulled in (T s_dot plus the change of k = EA / l0 with l0) and driven
  /// constraint rows (lambda^T Phi_t).
  double actuator_power = 0.0;
  double damping_power = 0.0;  // taken out by the cables' dampers, c (l_dot + s_dot)^2 >= 0
  double contact_power = 0.0;  // taken out by contact: normal damping (hysteresis) and friction, >= 0
  double total() const
  {
    return kinetic + elastic + gravity;
  }
  /// The size of the energy's round-off: its terms' magnitudes (J).
  double scale() const;
};

/// The energy one step of h took from a to b that no force accounts for (J, the trapezoidal rule over the
/// powers): positive when the integrator dissipated it, negative when it gained energy.
double stepNumericalDissipation(const EnergyPoint& a, const EnergyPoint& b, double h);

/// The kinetic energy a step of h can create by round-off alone (J): the index-3 multipliers are known to
/// eps |q| m / (beta h^2), which gives the bodies velocities of about 2 eps (1 + |q|) / h.
double stepEnergyRoundoff(const Model& model, const Eigen::VectorXd& q, double h);

/// What a step of h from a to b did to the energy, against solver.energy_tolerance (relative to the kinetic and
/// elastic energy at either end; round-off, the energies' own and `roundoff` (stepEnergyRoundoff), allowed on top).
struct StepEnergyCheck
{
  bool gained = false;  // gained more than the tolerance allows: a stiff event (contact, cable going taut) unresolved
  /// with contacts active at either end, lost more than the tolerance allows: an impact resolved too coarsely for
  /// its restitution (the integrator's numerical damping acting on the contact)
  bool lost_in_contact = false;
  bool in_contact = false;  // contacts were active at either end
  bool ok() const
  {
    return !gained && !lost_in_contact;
  }
};
StepEnergyCheck checkStepEnergy(const EnergyPoint& a, const EnergyPoint& b, double h, double tolerance, double roundoff,
                                bool in_contact);

/// The account summed over a run's accepted steps (J).
struct EnergyAccount
{
  EnergyPoint start;  // at the run's first instant
  EnergyPoint now;    // at its last accepted step's end
  double actuator_work = 0.0;
  double damping_dissipation = 0.0;
  double contact_dissipation = 0.0;
  /// start.total() + actuator_work - damping_dissipation - contact_dissipation - now.total(): what the
  /// integrator took (negative: gained)
  double numerical_dissipation = 0.0;
  double largest_step_gain = 0.0;  // the largest energy one step gained (J, >= 0) and the time it ended at
  double largest_gain_t = 0.0;
  long steps = 0;
  /// steps that checkStepEnergy refused: that gained energy, or lost it in contact, beyond solver.energy_tolerance
  long gaining_steps = 0;
  long contact_loss_steps = 0;
  double first_unresolved_t = 0.0;  // the end of the first of either (s)
  /// what those of them in contact gained or lost (J, >= 0): the energy impacts resolved too coarsely moved
  double contact_unresolved_energy = 0.0;
  double peak_mechanical = 0.0;  // the largest kinetic plus elastic energy at a step's end (J)
  /// Whether the run's net numerical dissipation is a gain above 100 tolerance (1 % at the default 1e-4) of its
  /// peak mechanical energy, and whether the unresolved steps in contact moved more than that: what those decide
  /// (a rebound, the motion's amplitude) is off by about as much.
  bool gainedMaterially(double tolerance) const
  {
    return -numerical_dissipation > 100.0 * tolerance * peak_mechanical;
  }
  bool contactsUnresolved(double tolerance) const
  {
    return contact_unresolved_energy > 100.0 * tolerance * peak_mechanical;
  }

  void begin(const EnergyPoint& p);
  /// Adds the step of h from `now` to `end`, ending at t_end, with its checkStepEnergy.
  void add(const EnergyPoint& end, double h, double t_end, const StepEnergyCheck& check);
};

}  // namespace active_tensegrity::core
