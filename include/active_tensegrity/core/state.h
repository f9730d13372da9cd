/// The changing part of a simulation. Includes the solvers' Summary (summary.h) and linear solver
/// (sparse_linear_solver.h) as well, which code written against this header finds through it.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/mechanics.h"
#include "active_tensegrity/core/sparse_linear_solver.h"
#include "active_tensegrity/core/summary.h"

namespace active_tensegrity::core
{
struct State
{
  double t = 0.0;          // s (dynamics) or load parameter (statics)
  Eigen::VectorXd q;       // coordinates, 7 per strut, 3 per point mass
  Eigen::VectorXd qd;      // their time derivatives
  Eigen::VectorXd qdd;     // accelerations
  Eigen::VectorXd acc;     // generalized-alpha pseudo-accelerations (equal to qdd for Newmark)
  Eigen::VectorXd lambda;  // multipliers of the model's constraints (then any solver-added ones)
  ActuationValues u;       // actuation values at t
  /// Contact memory per contact slot (strut pairs, then ground contacts): the impact speed v_0 (m/s) of a
  /// live contact, 0 when apart. Set at contact onset, forgotten at separation (dynamics).
  SlotValues contact_speed;
};

/// A state at rest in the model's initial configuration.
State initialState(const Model& model);

}  // namespace active_tensegrity::core
