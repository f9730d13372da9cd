/// The changing part of a simulation. Includes the solvers' Summary (summary.h) as well, which code written against
/// this header finds through it.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/contact/contact.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/base/summary.h"

namespace active_tensegrity::core
{
/// A contact touching at a state's instant: its slot and the impact speed it remembers (m/s).
struct NaturalTouch
{
  int slot = -1;
  double speed = 0.0;
};

struct NaturalState
{
  double t = 0.0;
  Eigen::VectorXd x, v, a;  // free coordinates (then each spin rate's angle), velocities, algorithmic accelerations
  Eigen::VectorXd qdd;      // accelerations (equal to a with Newmark)
  Eigen::VectorXd lambda;   // one multiplier per strut, then per NaturalModel::rows entry
  std::vector<NaturalTouch> touching;      // the contacts touching, ascending by slot (the others remember nothing)
  std::vector<ContactPairState> contacts;  // and their states and forces (the same slots in the same order)
  Eigen::VectorXd frame_spin;              // per strut: the spin angle its body frame (State::q) carries (rad)
  std::vector<double>
      actuator_force;  // per actuator: the force it exerts (N; DynamicsSolver::formActuatorForces, StaticSolver)
  /// A static equilibrium (StaticSolver): velocities and accelerations zero, no contact memory; the dynamics
  /// starts from it by initializing (DynamicsSolver::initialize).
  bool equilibrium = false;
  /// State::q and qd are not yet written from x and v (DynamicsSolver::deferPoses; DynamicsSolver::writePoses writes
  /// them).
  bool poses_pending = false;
  /// The impact speed slot remembers (0: not touching).
  double contactSpeed(int slot) const;
};

struct State
{
  double t = 0.0;      // s (dynamics) or load parameter (statics)
  Eigen::VectorXd q;   // body coordinates, 7 per strut (centre, Euler parameters), 3 per point mass
  Eigen::VectorXd qd;  // their time derivatives
  ActuationValues u;   // actuation values at t
  /// The coordinates the dynamics solver integrates (natural.h): the free nodes' positions, velocities and
  /// accelerations, the strut-length and row multipliers, the touching contacts. q and qd above are their body
  /// poses and rates when a solver (dynamics or statics) made the state; a state made otherwise (a caller's q) has
  /// none (x empty), and the solvers form them from q and qd.
  NaturalState natural;
  /// The impact speed slot remembers (0: not touching, or a state without natural coordinates).
  double contactSpeed(int slot) const
  {
    return natural.contactSpeed(slot);
  }
};

/// A state at rest in the model's initial configuration.
State initialState(const Model& model);

}  // namespace active_tensegrity::core
