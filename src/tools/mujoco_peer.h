/// The same scene built in MuJoCo (Debian's libmujoco-dev 2.2.2), for side-by-side runs against our
/// solver (tensegrity_bench work-precision --mujoco-dts; docs/benchmarks.md, "MuJoCo side by side").
///
/// Translation of a loaded core::Model into an MJCF string generated here:
/// - a strut: a body with a free joint, a capsule of the strut's outer radius and length along body z,
///   mass and principal inertia set explicitly to ours (body frame = our body frame, origin at the centre);
/// - a point mass that no actuator drives: a body with three slide joints (no rotation);
/// - a point mass driven by a guided node actuator (the tower's B1-B4): not a MuJoCo body at all; it moves
///   kinematically in our model too, so its position p0 + s(t) d is evaluated at each force evaluation
///   and the cable segments that touch it are computed here (length, rate, and the force on the other end);
/// - a ground pin and a strut-to-strut ball joint: an equality `connect` (to the world for a pin);
/// - a driven strut end (the quadruplex's top nodes, the prism's T1): a light carrier body connected to the
///   strut end, on slide joints across d and on one along d with a huge armature, pushed by
///   (mass + armature) s_dd(t) at every force evaluation and put on s(t), s_dot(t) before every step (a
///   mocap body would do without the velocity, and the connect's Baumgarte damping would then resist the
///   motion with a force growing as 1 / timestep);
/// - a cable (two points or sliding through several): a spatial tendon through sites, one per run of
///   points between driven point masses, carrying a motor actuator whose control is set to -T at every
///   force evaluation (mjcb_control) with T = k (l - l0) + c l_dot when positive, else 0 (tension only;
///   MuJoCo's tendon springs are two-sided); pulled-in cables use l0 - s(t) and k = EA / (l0 - s);
/// - contact: explicit capsule-capsule pairs for the model's checked pairs only (contype/conaffinity 0),
///   a linear spring-dashpot set through solref in MuJoCo's direct format with a tiny impedance
///   (see MujocoOptions::contact_force and docs/benchmarks.md); friction mu with an elliptic cone
///   (condim 3), frictionless with condim 1;
/// - the ground (model.ground): a plane at its height and a pair with each body that touches it (a strut's
///   capsule, whose two end spheres are MuJoCo's capsule-plane contacts as they are ours; a point mass with a
///   radius gets a sphere), the same linear law through MujocoOptions::ground_force.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "active_tensegrity/core/model/model.h"

struct mjModel_;
struct mjData_;

namespace active_tensegrity::tools
{
enum class MujocoIntegrator
{
  kEuler,     // semi-implicit Euler (MuJoCo's default)
  kImplicit,  // implicit in velocity
  kRk4        // explicit Runge-Kutta of order 4
};

const char* toString(MujocoIntegrator integrator);
/// "euler", "implicit" or "rk4" (throws std::invalid_argument otherwise)
MujocoIntegrator parseMujocoIntegrator(const std::string& name);

struct MujocoOptions
{
  MujocoIntegrator integrator = MujocoIntegrator::kEuler;
  double timestep = 1e-3;  // s
  /// Contact: MuJoCo's contact is a linear spring-dashpot here, ours Hertzian. The linear stiffness is the
  /// secant of ours through the force scale F*: K_lin = F* / zeta* with K90 zeta*^1.5 = F*, i.e.
  /// K_lin = K90^(2/3) F*^(1/3) (K90 the pair's stiffness at a right crossing), so that the two laws
  /// give the same overlap at F*. The damping gives a linear oscillator's restitution equal to our c_e.
  double contact_force = 1000.0;  // F*, N
  /// The same for the ground's contacts (each end sphere on the plane: K = (4/3) E* sqrt(r)); 0: the
  /// structure's weight shared by three contacts (a robot standing on a triangle), else contact_force.
  double ground_force = 0.0;  // N
  /// Impedance d of the contacts (constant): small, so that the force is K_lin r + C_lin r_dot to O(d)
  /// whatever the effective mass at the contact point (docs/benchmarks.md).
  double contact_impedance = 1e-4;
  /// Equality constraints (pins, joints, carriers): solref (timeconst, dampratio 1) with timeconst =
  /// equality_timeconst * timestep, constant impedance equality_impedance (near-hard).
  double equality_timeconst = 2.0;
  double equality_impedance = 0.9999;
  /// Mass of the light body that carries a driven strut end across the drive direction, as a fraction of
  /// the strut's mass.
  double carrier_mass_fraction = 1e-8;
  int solver_iterations = 100;
  double solver_tolerance = 1e-10;
  /// Load the model from this MJCF file (one MujocoPeer::exportXml wrote for the same scene and options)
  /// instead of the text generated here; empty: the generated text.
  std::string xml_file;
};

/// A scene translated and loaded into MuJoCo: the model, its data and the state of the drives.
class MujocoPeer
{
public:
  /// Throws std::invalid_argument for what the translation does not support (named) and
  /// std::runtime_error when MuJoCo refuses the generated model (with its message).
  MujocoPeer(const core::Model& model, const MujocoOptions& options);
  ~MujocoPeer();
  MujocoPeer(const MujocoPeer&) = delete;
  MujocoPeer& operator=(const MujocoPeer&) = delete;

  const std::string& xml() const
  {
    return xml_;
  }
  /// The translation as a file (tensegrity_export --mjcf): xml() with the contact parameters MuJoCo's
  /// compiled model got here (each pair's solref, the impratio) and a comment on what runs outside MuJoCo.
  std::string exportXml() const;
  const mjModel_* mujocoModel() const
  {
    return m_;
  }
  mjData_* mujocoData()
  {
    return d_;
  }

  /// Back to the initial state (t = 0, at rest) and forward().
  void reset();
  /// One MuJoCo step (mj_step) with the drives set for its start; false (and message()) when MuJoCo raised
  /// a warning or a number became non-finite.
  bool step();
  /// Whether the last step that failed diverged: a non-finite position or velocity, or one of MuJoCo's warnings of
  /// an unstable simulation (bad qpos, qvel, qacc or ctrl: a NaN, an infinity or a value above 1e10); false
  /// for its other warnings (a full contact or constraint list, a near-singular inertia).
  bool diverged() const
  {
    return diverged_;
  }
  /// Recomputes everything derived (positions, tendon lengths, tensions, constraint and contact forces) at
  /// the current state (mj_forward): call before reading results.
  void forward();
  double time() const;
  const std::string& message() const
  {
    return message_;
  }

  /// Our body's centre (a strut's centre of mass, a point mass's position), world frame.
  core::Vec3 bodyPosition(int body) const;
  /// A material point of ours (body -1: the ground), world frame.
  core::Vec3 pointPosition(const core::PointRef& point) const;
  /// Cable length (all segments, the driven ones included) and tension of our cable i, as of the last
  /// force evaluation.
  double cableLength(int cable) const;
  double cableTension(int cable) const;
  /// Our actuationForce(): the force the actuator applies along its direction summed over its targets
  /// (driven point masses: from their cables, mass and gravity; driven strut ends: the connect's force),
  /// or the sum of the tensions of the cables it pulls in.
  double actuationForce(int actuator) const;
  /// Largest normal force among the current contacts (N), 0 without contact.
  double maxContactForce() const;
  /// Sum of the normal forces of the current contacts (N).
  double contactForceSum() const;
  /// Sum of the masses of MuJoCo's moving bodies (kg), carriers included.
  double totalMass() const;
  /// Mass of the carriers alone (kg).
  double carrierMass() const;
  /// Linear contact stiffness (N/m) and damping (N s/m) used for checked pair i.
  double contactStiffness(int pair) const;  // (pair: index into Model::checkedPairList())
  double contactDamping(int pair) const;
  /// MuJoCo ids (for tests): the body of our body i (-1 for a driven point mass), the tendons of cable i.
  int bodyId(int body) const;
  const std::vector<int>& tendonIds(int cable) const;
  int pairCount() const;

  /// Called by MuJoCo at every force evaluation (mjcb_control): tensions, tendon controls, driven segments.
  void evaluateForces();

private:
  void setDrives();
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string xml_;
  std::string message_;
  bool diverged_ = false;
  mjModel_* m_ = nullptr;
  mjData_* d_ = nullptr;
};

/// A MuJoCo run of the scene's dynamic analysis, comparable to tensegrity_bench's Trace: the outputs on
/// the model's output grid (analysis.output_interval), the time of the stepping alone.
struct MujocoTrace
{
  std::vector<double> t, force;                    // actuation force of actuator 0 (as csvRow's column)
  std::vector<std::vector<double>> heights;        // per output: the layer heights (or the height)
  std::vector<std::vector<core::Vec3>> positions;  // per output: every body's centre, our body order
  double peak = 0.0, peak_t = 0.0;                 // largest contact normal force over every step, and when
  double impulse = 0.0;    // N s: each step's summed normal contact forces times the step (what Euler applies)
  double wall_time = 0.0;  // s, mj_step calls and the drives only
  long steps = 0;
  long solver_iterations = 0;  // MuJoCo's constraint solver iterations, summed over steps
  double size = 0.0;           // m: the structure's size at the start (core::structureSize)
  double joint_drift = 0.0;    // m: the largest distance between the two points of a pin or ball joint at an output
  /// "converged"; "diverged" (MujocoPeer::diverged(), or a pin or ball joint drifted apart by more than
  /// kMaxJointDrift of the structure's size: the run is no longer the structure); "mujoco_failed" (MuJoCo's
  /// other warnings). `message` says what and when.
  std::string status = "converged";
  std::string message;
  bool ok() const
  {
    return status == "converged";
  }
};

/// The largest drift of a pin or ball joint, as a fraction of the structure's size, that a MuJoCo run may show
/// before it counts as diverged: its soft connects give way by micrometres to millimetres in a sound run.
constexpr double kMaxJointDrift = 0.1;

/// Runs model.analysis (dynamic: duration, output_interval, the actuation schedule) in MuJoCo.
MujocoTrace runMujoco(const core::Model& model, const MujocoOptions& options);

}  // namespace active_tensegrity::tools
