/// The immutable description of a tensegrity scene: bodies, named nodes, force elements,
/// constraints, actuators, contact pairs and the analysis. Built by loadScene() (scene.h) and
/// validated there; algorithms take it by const reference.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/base/rotation.h"
#include "active_tensegrity/core/base/schedule.h"

namespace active_tensegrity::core
{
/// A strut is a rigid body with q = [R; Theta] (7 numbers, R the centre of mass, body z the axis);
/// a point mass has q = R (3 numbers) and no orientation.
enum class BodyKind
{
  kStrut,
  kPointMass
};

/// One layer of a strut's cross-section (a solid core has inner_radius 0).
struct StrutLayer
{
  std::string material;
  double inner_radius = 0.0;    // m
  double outer_radius = 0.0;    // m
  double density = 0.0;         // kg/m^3
  double youngs_modulus = 0.0;  // Pa
  double poisson_ratio = 0.0;
};

struct Body
{
  std::string name;
  BodyKind kind = BodyKind::kStrut;
  int nq = 7;                      // coordinates of this body
  int offset = 0;                  // first coordinate in the global q
  double mass = 0.0;               // kg
  Vec3 inertia = Vec3::Zero();     // principal moments about the centre of mass in the body frame, kg m^2
  double length = 0.0;             // m (struts)
  std::vector<StrutLayer> layers;  // innermost first (struts)

  double radius() const
  {
    return layers.empty() ? 0.0 : layers.back().outer_radius;
  }
};

/// A material point: body -1 is the ground, and then `local` is the world position.
struct PointRef
{
  int body = -1;
  Vec3 local = Vec3::Zero();  // body frame (m) or world frame for the ground
};

/// A named node of the scene (strut end, point mass, ground point).
struct Node
{
  std::string name;
  PointRef point;
};

/// Tension element through an ordered list of points (at least two): its length is the sum of the
/// segment lengths and it carries one tension T = k (l - l0) + c l_dot while l > l0 (never below zero
/// when tension_only), else 0, along every segment. Two points make a classical cable or spring; more
/// make a clustered (sliding) cable running frictionlessly through the inner points (docs/physics.md,
/// "Force elements").
/// A material cable has k = EA / l0 (area > 0; pulling it in keeps EA); a spring has a given k (area 0).
/// When actuator >= 0 its rest length is l0 - s(t) (pulled in at one end by the actuation value s).
struct Cable
{
  static constexpr int kMaxPoints = 32;

  std::string name;
  std::vector<PointRef> points;
  double stiffness = 0.0;    // k at rest_length, N/m
  double rest_length = 0.0;  // l0 without actuation, m
  double damping = 0.0;      // c, N s/m
  bool tension_only = true;
  double area = 0.0;            // m^2, for stresses (0 when not a material cable)
  double yield_strength = 0.0;  // Pa, the material's (0: none given); runs warn about stresses above it
  int actuator = -1;            // index into Model::actuators that pulls this cable in, or -1
  // per point: the struts that end at its node (the cable meets them there; its segments from that point are
  // not checked against them for crossings, observables.h). Filled by the scene loader; empty: the point's body.
  std::vector<std::vector<int>> point_struts;

  bool sliding() const
  {
    return points.size() > 2;
  }
};

/// A constant force at a material point, fixed in the world frame (N). Its generalized force is
/// B_P^T f, which depends on the orientation of a strut, hence a (geometric) tangent stiffness.
struct PointLoad
{
  std::string name;
  PointRef point;
  Vec3 force = Vec3::Zero();  // N, world frame
};

/// A constraint block. kPoints: rows d_k . (p_a - p_b) - offset_k - (actuator >= 0 ? s(t) : 0) = 0,
/// p_b the ground when b.body < 0 (covers ball joints, ground pins, and rheonomic actuation);
/// kQuatNorm: Theta.Theta - 1 = 0; kSpinLock: a . Theta = 0 (statics only, spin about a strut axis).
struct Constraint
{
  enum class Kind
  {
    kPoints,
    kQuatNorm,
    kSpinLock
  };
  Kind kind = Kind::kPoints;
  std::string name;
  PointRef a, b;
  std::vector<Vec3> directions;      // one per row (kPoints)
  std::vector<double> offsets;       // one per row (kPoints)
  int actuator = -1;                 // index into Model::actuators, or -1
  int body = -1;                     // kQuatNorm, kSpinLock
  Vec4 coefficients = Vec4::Zero();  // kSpinLock

  int rows() const
  {
    return kind == Kind::kPoints ? static_cast<int>(directions.size()) : 1;
  }
};

/// One actuation value s (m) drives either a group of node motions (each target point moves by s
/// along its direction: constraints) or the pull-in of cables (each cable's rest length becomes
/// l0 - s: cables). The actuation force is, for node targets, the sum over targets of the force
/// the actuator applies along its direction (positive when it pushes the way the node is driven),
/// and for cables the sum of their tensions (the force the winch pulls with).
struct Actuator
{
  std::string name;
  double min_value = 0.0;        // m
  double max_value = 0.0;        // m
  std::vector<int> constraints;  // indices into Model::constraints (node targets)
  std::vector<int> cables;       // indices into Model::cables (pulled in)
};

/// A pair of struts whose surface gap is measured and, when contact is on, whose contact is computed.
/// Built by makeStrutPair(), which fills the constants.
struct StrutPair
{
  int body_a = -1;
  int body_b = -1;
  double stiffness90 = 0.0;  // K at a right crossing, (4/3) E* (r_a r_b)^(1/4), N/m^1.5
  // layered struts (a `core`): the cores' contact, which adds to the sleeves' once their overlap exceeds the
  // sleeves' thicknesses; core_stiffness90 = 0 when neither strut has a core
  double core_stiffness90 = 0.0;  // (4/3) E*_c (rc_a rc_b)^(1/4), N/m^1.5 (a strut without a core: its own layer)
  double core_gap = 0.0;          // the penetration at which the cores meet, (r_a - rc_a) + (r_b - rc_b), m
};

/// The normal force law of a contact (docs/physics.md, "Contact laws"): Hertz's with Lankarani-Nikravesh damping,
/// F_N = K zeta^(3/2) (1 + D zeta_dot) with K from the materials and D from the restitution, or a linear
/// spring-dashpot, F_N = k zeta + c zeta_dot with k and c given (MuJoCo's soft contact with a direct solref); both
/// never pull (F_N >= 0).
enum class ContactLaw
{
  kHertz,
  kLinear
};

/// Contact law parameters (docs/physics.md, "Strut contact"; scene keys under `contact`, docs/scenes.md).
struct ContactSettings
{
  bool enabled = false;
  ContactLaw law = ContactLaw::kHertz;
  double linear_stiffness = 0.0;          // k of the linear law, N/m (the same for every pair)
  double linear_damping = 0.0;            // c of the linear law, N s/m
  double restitution = 1.0;               // c_e in [0, 1]; 1 = elastic (no hysteresis damping)
  double friction = 0.0;                  // mu; 0 skips all friction work
  double stick_velocity = 1e-3;           // v0 of the modified Coulomb law, m/s
  double slip_velocity = 5e-2;            // v1, m/s
  double min_crossing_angle = 0.1745329;  // rad (10 deg): |sin theta| is floored there (near-parallel cap)
  double min_impact_speed = 1e-3;         // m/s: floor of the impact speed v_0 in D = 3(1 - c_e^2)/(4 v_0)
};

/// The ground: an optional half-space z <= height under the structure (scene key `ground`, docs/scenes.md).
/// Strut ends (the spheres that cap each strut's capsule) and point masses with a radius touch it with
/// Hertz's sphere-on-plane law, Lankarani-Nikravesh damping and the modified Coulomb friction
/// (docs/physics.md, "Ground contact").
struct GroundSettings
{
  bool enabled = false;
  ContactLaw law = ContactLaw::kHertz;
  double linear_stiffness = 0.0;  // k of the linear law, N/m (the same for every sphere)
  double linear_damping = 0.0;    // c of the linear law, N s/m
  double height = 0.0;            // m, the plane z = height
  std::string material;           // its elastic constants (from `materials`)
  double youngs_modulus = 0.0;    // Pa
  double poisson_ratio = 0.0;
  double restitution = 1.0;  // c_e in [0, 1]
  double friction = 0.0;     // mu; 0 skips all friction work
  /// the modified Coulomb law's v0 and v1 (m/s): with v0 = 0 (the default) friction grows linearly with the slip
  /// below v1, so a body at rest on the ground is held (it creeps at a speed proportional to its tangential
  /// load) and the law has no kink at v0 for Newton to chatter over
  double stick_velocity = 0.0;
  double slip_velocity = 0.05;
};

/// A sphere that can touch the ground: one end of a strut (centre on the axis at +-L/2, the strut's outer
/// radius) or a point mass with a radius. K = (4/3) E* sqrt(r), E* from the body's and the ground's
/// materials.
struct GroundContact
{
  int body = -1;
  Vec3 local = Vec3::Zero();  // the sphere's centre in the body frame, m
  double radius = 0.0;        // m
  double stiffness = 0.0;     // K, N/m^1.5 (under the linear law its k, N/m)
  std::string node;           // the node at the sphere's centre
};

enum class Integrator
{
  kNewmark,
  kGeneralizedAlpha
};

struct SolverOptions
{
  double dt = 2e-4;  // s
  Integrator integrator = Integrator::kNewmark;
  double newmark_gamma = 0.6;
  double newmark_beta = 0.3025;
  double rho_infinity = 0.8;       // generalized-alpha spectral radius at infinite frequency
  double newton_tolerance = 1e-6;  // on the position increment (m, or quaternion units)
  int max_iterations = 25;
  int max_step_cuts = 10;  // halvings of a step (or load increment) before failure
  /// dynamics: keep the factorized Newton matrix across iterations and steps (modified Newton) while
  /// the iteration contracts fast (rate < 0.5), the step size and the set of touching pairs are unchanged,
  /// for at most max_jacobian_age steps; otherwise it is rebuilt (docs/physics.md)
  bool reuse_jacobian = true;
  int max_jacobian_age = 50;
  /// dynamics: variable step size from a local error estimate, contact onsets located in time
  /// (AdaptiveStepper, docs/physics.md); dt is then the first step
  bool adaptive = false;
  double error_tolerance = 1e-5;  // m: local error per step of the strut ends' positions
  double dt_min = 1e-7;           // s: below this a step is taken (or fails) without error control
  double dt_max = 1e-2;           // s
  double onset_depth = 1e-5;      // m: deepest penetration a step may end with in a pair it brought into contact
  /// largest energy one step may gain that no force accounts for, relative to the kinetic and elastic energy at
  /// its ends (adaptive steps refuse and halve such a step; fixed steps cut it: energy.h)
  double energy_tolerance = 1e-4;
};

enum class AnalysisType
{
  kStatic,
  kDynamic,
  kModal  // natural modes about the equilibrium at max_actuation (core/solvers/modal.h)
};

/// One step of actuation.sequence: from `time`, the listed actuators ramp from where they are to their
/// targets (the schedule's speed and blend); the loader sees that an actuator's ramps do not overlap.
struct ActuationStep
{
  double time = 0.0;            // s
  std::vector<int> actuators;   // indices into Model::actuators
  std::vector<double> targets;  // m, one per actuator
};

struct AnalysisSettings
{
  AnalysisType type = AnalysisType::kStatic;
  double max_actuation = 0.0;  // m (static path end)
  int steps = 100;             // static load steps
  double duration = 0.0;       // s (dynamic)
  /// dynamic, when analysis.duration is not given: how it was derived (the actuation ramp's end plus
  /// settle_time); empty when given
  std::string duration_note;
  double settle_time = 1.0;      // s after the ramp's end, for the derived duration
  double output_interval = 0.0;  // s (dynamic, 0 = every step)
  int modes = 10;                // modal: how many of the lowest modes
  RampSchedule schedule;         // dynamic actuation law for every actuator (without a sequence)
  /// dynamic: per-actuator ramps (actuation.sequence) instead of every actuator ramping to max_actuation; the
  /// schedule then gives the speed and blend only
  std::vector<ActuationStep> sequence;
  /// static: the point loads' factor runs from start to end along the path (with the actuation)
  double load_factor_start = 1.0;
  double load_factor_end = 1.0;
  bool arc_length = false;  // static: arc-length continuation (passes limit points of the path parameter)
};

/// A named group of nodes whose highest z above the ground is written as the CSV column height_<name>
/// (e.g. the top level of each stage of a tower).
struct OutputLayer
{
  std::string name;
  std::vector<int> nodes;  // node indices
};

struct Model
{
  std::string name;
  std::string source;  // file it came from
  std::vector<Body> bodies;
  std::vector<Node> nodes;
  std::vector<Cable> cables;
  std::vector<PointLoad> loads;
  std::vector<Constraint> constraints;
  std::vector<Actuator> actuators;
  /// The strut pairs whose contact is checked, each a contact slot, in one of two forms:
  /// - listed (`contact.pairs` given, or a model built in code): listed_pairs, slot i the i-th;
  /// - every two struts that share no node (`pairs: auto`, all_strut_pairs): numbered, not stored. With n
  ///   struts (pair_struts, ascending), the k-th and l-th (k < l) are slot k (2n - k - 1)/2 + l - k - 1; the pairs
  ///   of struts that share a node (joined_struts) are slots no one checks (isCheckedPair false). The broad phase
  ///   finds the slots near contact; nothing of size n^2 is built.
  /// Read them through strutPair(slot), isCheckedPair(slot) and pairSlots(), which serve both forms.
  std::vector<StrutPair> listed_pairs;
  bool all_strut_pairs = false;
  std::vector<int> pair_struts;              // all_strut_pairs: the struts' body indices, ascending
  std::vector<int> strut_rank;               // all_strut_pairs: body -> index in pair_struts (-1: not a strut)
  std::vector<std::uint64_t> joined_struts;  // all_strut_pairs: pairKey of two struts sharing a node, ascending
  GroundSettings ground;
  /// the spheres that can touch the ground (empty when it is off); contact slot pairSlots() + i
  std::vector<GroundContact> ground_contacts;
  std::vector<int> height_nodes;  // node indices whose highest z gives the height
  std::vector<OutputLayer> layers;
  double ground_level = 0.0;  // z of the ground points, m
  bool gravity_enabled = false;
  Vec3 gravity = Vec3(0.0, 0.0, -9.81);
  bool damping_enabled = true;
  ContactSettings contact;
  SolverOptions solver;
  AnalysisSettings analysis;
  Eigen::VectorXd q0;  // initial configuration
  int nq = 0;          // total coordinates
  int n_lambda = 0;    // total constraint rows (model constraints only)

  /// Contact slots: the strut pairs' (pairSlots()), then the ground contacts.
  int contactSlots() const
  {
    return pairSlots() + static_cast<int>(ground_contacts.size());
  }
  /// The strut pairs' slots: listed_pairs.size(), or n (n - 1)/2 for n struts with all_strut_pairs.
  int pairSlots() const
  {
    return all_strut_pairs ? all_pair_slots_ : static_cast<int>(listed_pairs.size());
  }
  bool isGroundSlot(int slot) const
  {
    return slot >= pairSlots();
  }
  /// The ground contact of a ground slot (isGroundSlot).
  const GroundContact& groundContactOf(int slot) const
  {
    return ground_contacts[slot - pairSlots()];
  }
  /// The pair of a strut pair's slot (0 <= slot < pairSlots()), with its constants.
  StrutPair strutPair(int slot) const;
  /// The bodies of a strut pair's slot (body_a < body_b for all_strut_pairs; as listed otherwise).
  std::pair<int, int> pairBodies(int slot) const;
  /// Whether a strut pair's slot is checked (false only for two struts sharing a node with all_strut_pairs).
  bool isCheckedPair(int slot) const;
  /// all_strut_pairs: the slot of two struts (bodies, either order), -1 when they share a node or are one.
  int allPairsSlot(int body_a, int body_b) const;
  /// How many strut pairs are checked (pairSlots() less the unchecked slots).
  long checkedPairCount() const;
  /// Every checked pair, in slot order, with its slot into `slots` when given: O(pairs), for small scenes and
  /// tests (a large scene's solvers reach pairs through the broad phase, broad_phase.h).
  std::vector<StrutPair> checkedPairList(std::vector<int>* slots = nullptr) const;
  /// Makes the pairs every two of the given struts that do not share a node (all_strut_pairs; `joined`: pairs
  /// of body indices sharing one, either order). Throws std::invalid_argument past kMostAutoPairStruts struts.
  void checkAllStrutPairs(const std::vector<int>& struts, const std::vector<std::pair<int, int>>& joined);
  /// The most struts all_strut_pairs numbers (four times their pairs and ground slots fit an int: rviz
  /// marker ids).
  static constexpr int kMostAutoPairStruts = 32000;
  /// Whether any contact (strut pairs or the ground) is computed.
  bool anyContact() const
  {
    return contact.enabled || !ground_contacts.empty();
  }

  int findNode(const std::string& name) const;
  int findBody(const std::string& name) const;
  int findActuator(const std::string& name) const;

private:
  int all_pair_slots_ = 0;
};

/// The key of two body indices, either order (smaller << 32 | larger).
inline std::uint64_t pairKey(int a, int b)
{
  if (a > b)
    std::swap(a, b);
  return (static_cast<std::uint64_t>(a) << 32) | static_cast<std::uint32_t>(b);
}

/// E* = [(1 - nu1^2)/E1 + (1 - nu2^2)/E2]^-1 (Pa) of the outer layers of two struts.
double effectiveModulus(const Body& a, const Body& b);
/// The same for two layers.
double effectiveModulus(const StrutLayer& a, const StrutLayer& b);
/// A checked pair with its constants: K at a right crossing, (4/3) E* (r1 r2)^(1/4) (N/m^1.5).
StrutPair makeStrutPair(const Model& model, int body_a, int body_b);

/// Sizes, offsets and the initial configuration; call after bodies are filled.
void finalizeModel(Model& model);

/// Whether a static path scales its point loads (analysis.load_factor with start != end).
bool hasLoadPath(const Model& model);

}  // namespace active_tensegrity::core
