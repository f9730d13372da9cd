/// What a state shows: actuator and member forces, heights, gaps, contacts, stresses, slack cables, and their scans
/// over a run's every step.
#pragma once

#include <limits>
#include <vector>

#include "active_tensegrity/core/contact/broad_phase.h"
#include "active_tensegrity/core/elements/cable.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
/// Force the actuator applies along its directions, summed over its targets (N); positive when it
/// pushes the nodes the way they are driven. A state a solver made (State::natural): the forces it formed, a driven
/// node's reaction or a driven row's multiplier plus the pulled cables' tensions (StaticSolver forms them at every
/// equilibrium, DynamicsSolver::formActuatorForces at a step; runAnalysis forms them before its callbacks see a
/// state); throws std::logic_error when they were not. A state without natural coordinates (initialState, a
/// caller's q) has no reactions: the pulled cables' tensions alone.
double actuationForce(const Model& model, const State& state, int actuator);

/// Highest z of the model's height nodes above the ground level (m).
double structureHeight(const Model& model, const Eigen::VectorXd& q);

/// Smallest surface gap between the checked strut pairs (m, negative when they overlap); +inf when
/// the scene checks no pair, NaN when q is not finite. Every pair of a small scene; a large one's through
/// minimumGapNear.
double minimumGap(const Model& model, const Eigen::VectorXd& q);
/// The same through the broad phase at a growing margin m (a pair whose boxes grown by m do not overlap is more
/// than 2 m apart): O(n log n) for n struts, not O(n^2).
double minimumGapNear(const Model& model, const BroadPhase& broad, const Eigen::VectorXd& q);
/// Smallest gap (m) between the ground and the spheres that can touch it (negative when one presses into it;
/// +inf without a ground).
double minimumGroundGap(const Model& model, const Eigen::VectorXd& q);

/// The smallest gap between a cable segment and a strut: the distance of the segment from the strut's axis
/// segment less the strut's radius (negative: the cable runs through the strut). Every cable and spring segment
/// against every strut except those that end at the segment's two nodes (the cable meets them there); pairs
/// whose boxes, grown by the mean strut length, do not overlap are skipped (sorted sweep along x). gap = +inf
/// when no pair is that close; cable, segment (from point `segment` to the next) and strut name the pair.
struct CableStrutGap
{
  double gap = std::numeric_limits<double>::infinity();
  int cable = -1;
  int segment = -1;
  int strut = -1;
};
CableStrutGap minimumCableStrutGap(const Model& model, const Eigen::VectorXd& q);
/// Every cable that runs through a strut (gap < 0), once per cable and strut, at its deepest segment. (Such a
/// segment meets the strut's box grown by its radius alone: only pairs whose boxes overlap so are measured.)
std::vector<CableStrutGap> cableStrutCrossings(const Model& model, const Eigen::VectorXd& q);

/// The contacts in a state: touching strut pairs, then spheres touching the ground (body_b = -1), evaluated as the
/// analysis does (Hertz in statics; Lankarani-Nikravesh and friction with the state's impact speeds in dynamics).
/// Empty when neither strut contact nor the ground is on. A state the dynamics solver made carries them
/// (State::natural.contacts, from its natural coordinates) and they are returned as they are.
std::vector<ContactPairState> activeContacts(const Model& model, const State& state);

/// Highest z of the given nodes above the ground level (m).
double nodesHeight(const Model& model, const std::vector<int>& nodes, const Eigen::VectorXd& q);

/// Largest bending stress in a strut from its contact forces (Pa; strut pairs and the ground): each strut is a beam
/// pinned at its ends (docs/physics.md, "Derived outputs"), loaded by the components of its contact forces across its
/// axis at the contact points' axial positions; the bending is carried by the innermost layer (the steel core of a
/// sleeved strut, the whole section of a solid one): sigma = M r / I = 4 M / (pi r^3). 0 without contact.
double maxStrutBendingStress(const Model& model, const Eigen::VectorXd& q,
                             const std::vector<ContactPairState>& contacts);

/// Length, rate, rest length, stiffness, tension and slackness of every cable (Model::cables order).
std::vector<CableState> cableStates(const Model& model, const State& state);

/// The axial force of every strut (Model::bodies order, 0 for point masses), N, positive in tension: half
/// the difference of the axial components of the forces applied at its two ends (F_top . u - F_bottom . u,
/// u from the bottom end, local -z, to the top end): the tensions of the cables and springs attached or
/// running over an end and the point loads there. A state a solver made (State::natural, dynamics or statics) gives
/// each strut's length-row force, 2 L lambda, which holds the joints' reactions too and which its two ends share
/// (`end_imbalance`, when given: 0). A state without natural coordinates (initialState, a caller's q) has no
/// reactions: its forces are the cables', springs' and loads' at the ends, and `end_imbalance` receives
/// F_top . u + F_bottom . u per strut, the net axial force of those ends.
std::vector<double> strutAxialForces(const Model& model, const State& state,
                                     std::vector<double>* end_imbalance = nullptr);

/// Largest stress T / A in a material cable (springs have no section and are left out), Pa.
double maxCableStress(const Model& model, const State& state);

/// maxCableStress for a sequence of states (every step of a run): the material cables and their points' slots
/// are found once, the points' motion comes from frames formed at each state (no allocation after the first).
class CableStressScan
{
public:
  explicit CableStressScan(const Model& model);
  /// maxCableStress(model, state), the same number.
  double largest(const State& state);

private:
  const Model& model_;
  BodyFrames frames_;
  std::vector<int> cables_, first_;  // the material cables; cables_[k]'s points are slots_[first_[k]] on
  std::vector<PointSlot> slots_;
};

/// Number of slack cables (tension-only elements carrying no tension) in a state.
int slackCables(const Model& model, const State& state);

/// The point loads' factor in a state (static paths: from the path parameter state.t; 1 otherwise).
double loadFactor(const Model& model, const State& state);

/// activeContacts() for a sequence of nearby states (every step of a run): it keeps the contact slots within
/// reach of a reference state, and judges only those while no body point has moved by more than `reach` since;
/// a state further away makes the reference anew (broad phase and geometry of every candidate). reach is a tenth
/// of the smallest contact radius (strut or ground sphere).
class ContactScan
{
public:
  explicit ContactScan(const Model& model);
  /// The contacts in `state`, as activeContacts(model, state) gives them.
  const std::vector<ContactPairState>& active(const State& state);

private:
  const Model& model_;
  BroadPhase broad_;
  double reach_ = 0.0;
  bool have_reference_ = false;
  Eigen::VectorXd reference_q_;
  std::vector<int> candidates_, near_;
  std::vector<ContactPairState> contacts_;
};

}  // namespace active_tensegrity::core
