/// Running a scene's analysis (static path or dynamic run) and measuring what the batch command
/// writes: the common CSV columns and the run summary.
#pragma once

#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "active_tensegrity/core/adaptive.h"
#include "active_tensegrity/core/energy.h"
#include "active_tensegrity/core/broad_phase.h"
#include "active_tensegrity/core/dynamics.h"
#include "active_tensegrity/core/state.h"
#include "active_tensegrity/core/summary.h"

namespace active_tensegrity::core
{
/// Force the actuator applies along its directions, summed over its targets (N); positive when it
/// pushes the nodes the way they are driven. A static state: from the multipliers (the constraint force on a
/// body is -Phi_q^T lambda, so each target contributes -lambda) and the pulled cables' tensions. A dynamics state:
/// what DynamicsSolver::formActuatorForces formed (runAnalysis forms them before its callbacks see a state);
/// throws std::logic_error when they were not.
double actuationForce(const Model& model, const State& state, int actuator);

/// The scene's actuation law of a dynamic run at time t, one value per actuator: every actuator on
/// analysis.schedule's ramp to max_actuation, or each on its own ramps of actuation.sequence.
ActuationValues scheduledActuation(const Model& model, double t);
/// The same into `out` (resized to the actuators; no allocation once it has that size).
void scheduledActuation(const Model& model, double t, ActuationValues& out);
/// When the last ramp of that law ends (s).
double actuationEndTime(const Model& model);
/// Where that law is not smooth (s, ascending, distinct): an adaptive run steps onto them.
std::vector<double> actuationBreakpoints(const Model& model);

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
/// running over an end, the reactions of the constraints at an end (ball joints, pins, drives: -Phi_q^T
/// lambda, from state.lambda) and the point loads there. Forces along the strut (contact, gravity,
/// inertia) are not end forces: with none and at rest both ends give the same force. `end_imbalance`
/// (when given) receives F_top . u + F_bottom . u per strut: the net axial force of the ends, which the
/// forces along the strut balance (0 in a static state without them). A state the dynamics solver made
/// (State::natural) gives each strut's length-row force, 2 L lambda, which its two ends share (net 0).
std::vector<double> strutAxialForces(const Model& model, const State& state,
                                     std::vector<double>* end_imbalance = nullptr);

/// Column names of tensegrity_run --members: t, then NAME_tension, NAME_length, NAME_rest_length per cable
/// and spring (Model::cables order), then NAME_force per strut.
std::vector<std::string> memberColumns(const Model& model);
/// The row of memberColumns (state.t first).
std::vector<double> memberRow(const Model& model, const State& state);

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

/// Whether a static path scales its point loads (analysis.load_factor with start != end).
bool hasLoadPath(const Model& model);
/// The point loads' factor in a state (static paths: from the path parameter state.t; 1 otherwise).
double loadFactor(const Model& model, const State& state);

/// Column names of the CSV: t, actuation, actuation_force, height, active_contacts, min_gap,
/// max_normal_force, max_friction_force (these three of strut pairs), slack_cables, max_strut_bending_stress,
/// max_cable_stress, min_cable_strut_gap (minimumCableStrutGap; empty when no pair is near), with the ground on
/// ground_contacts, min_ground_gap, ground_normal_force (their sum) and max_ground_friction_force, then
/// load_factor (static paths that scale their loads), height_<layer> per output layer, then actuation_<name> and
/// actuation_force_<name> per actuator when there are several.
std::vector<std::string> csvColumns(const Model& model);
std::vector<double> csvRow(const Model& model, const State& state);

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

/// A CSV column's largest magnitude over every step of a run (time step or load step, not only the output
/// steps), with its sign, and the time (or path parameter) at which it was reached.
struct Peak
{
  std::string name;
  double value = 0.0;
  double t = 0.0;
};

/// Tracks the peaks of actuation_force, max_normal_force, max_friction_force, max_strut_bending_stress and
/// max_cable_stress (what a run's summary lists under `peaks`): give it every step's state (runAnalysis's
/// on_step) and the initial one.
class PeakTracker
{
public:
  explicit PeakTracker(const Model& model);
  /// `contacts`: the state's active contacts when the caller has them (runAnalysis's StepCallback), else null
  /// and they are found here.
  void add(const State& state, const std::vector<ContactPairState>* contacts = nullptr);
  const std::vector<Peak>& peaks() const
  {
    return peaks_;
  }

private:
  const Model& model_;
  std::vector<Peak> peaks_;
  ContactScan contacts_;
  CableStressScan cable_stress_;
};

struct RunResult
{
  Summary summary;
  int steps = 0;           // output steps written
  int solver_steps = 0;    // time steps or load increments taken
  double wall_time = 0.0;  // s
  /// Dynamic runs: where the solver's time went. Both: wall time spent in on_step and on_output (s).
  StepTimings timings;
  double callback_time = 0.0;
  /// Dynamic runs with solver.adaptive: accepted and rejected steps, smallest and largest step.
  AdaptiveStats adaptive;
  /// Dynamic runs: the energy account over every accepted step (energy.h).
  EnergyAccount energy;
  State final_state;
};

/// Where a run's wall time went, in order: forces, contact, constraints, factorization, solve,
/// solver_other (the rest of step(): vector work, step bookkeeping), callbacks (on_step and on_output:
/// output rows, peak tracking, writing), rest (setup, initialization, the loop itself); seconds that
/// sum to wall_time. Static runs have only callbacks and rest (the step split is dynamic only).
std::vector<std::pair<std::string, double>> timeBreakdown(const RunResult& result);

/// runAnalysis's per-step callback: the state after a time step or load step, and its active contacts (as
/// activeContacts gives them) when the solver evaluated them there (dynamics: DynamicsSolver::contactsAt), else
/// null (statics).
using StepCallback = std::function<void(const State&, const std::vector<ContactPairState>* contacts)>;

/// Runs model.analysis; calls on_output for every output step (the initial state included) and
/// on_step, when given, after every time step or load step (for peaks between output steps).
RunResult runAnalysis(const Model& model, const std::function<void(const State&)>& on_output,
                      const std::function<void(double fraction)>& on_progress = {}, const StepCallback& on_step = {});
/// As above, with a per-step callback that takes the state alone.
RunResult runAnalysis(const Model& model, const std::function<void(const State&)>& on_output,
                      const std::function<void(double fraction)>& on_progress,
                      const std::function<void(const State&)>& on_step);

}  // namespace active_tensegrity::core
