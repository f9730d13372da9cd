/// Form-finding (docs/form_finding.md): a self-equilibrated geometry and prestress for the topology of a scene.
///
/// Members are the scene's struts (one force density each, compression expected) and its cables and springs
/// (a sliding cable is one member along its whole path). A cable or spring family is held at a tension (every
/// member of it carries T), held at a force density q (a member of length l carries q l), or free (one unknown
/// tension for the whole family). At a node that must be in equilibrium the member forces sum to zero:
///   sum over members e at node i of T_e u_e,i = 0,
/// u_e,i the unit vector from node i along the member's segment at i (both segments at an inner node of a
/// sliding cable). Fixed nodes keep their positions; by default they must be in equilibrium too (the form is
/// self-equilibrated and the supports carry nothing), with `supports_react` only the free nodes are.
///
/// Free mode: the unknowns are the free nodes' positions, the free families' tensions and the struts' force
/// densities; the equations above are solved by Gauss-Newton with minimum-norm steps (complete orthogonal
/// decomposition) from the scene's positions, so the form found is one near the given layout. A structure
/// whose equations are homogeneous in scale (no fixed node; held families all tensions or all force
/// densities) is then scaled about its centroid so that its mean strut length is the given one.
/// Prestress mode: the positions are kept; the states of self-stress of the geometry (the null space of its
/// equilibrium matrix) are fitted in least squares to the held tensions of the families.
/// Both modes write the scene back with the positions found and each cable family's `prestress` (a family
/// whose members carry different tensions is split into families of equal tension), and check the written
/// scene with the package's own model: its equilibrium residual, structural diagnostics and a static Newton
/// solve from it.
#pragma once

#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "active_tensegrity/core/base/rotation.h"

namespace active_tensegrity::design
{
using core::Vec3;

/// A form that cannot be found (no convergence, a collapsed member, a cable in compression, no state of
/// self-stress ...) or options that do not fit the scene: the message says which and why.
class FormFindingError : public std::runtime_error
{
public:
  using std::runtime_error::runtime_error;
};

enum class FormFindingMode
{
  kFree,       // the geometry is found
  kPrestress,  // the geometry is kept, its self-stress scaled to the held tensions
};

struct FormFindingOptions
{
  FormFindingMode mode = FormFindingMode::kFree;
  std::map<std::string, double> tension;        // family -> N: held (free mode), target (prestress mode)
  std::map<std::string, double> force_density;  // family -> N/m: held (free mode only)
  bool supports_react = false;                  // fixed nodes may carry reactions
  bool uniform_struts = true;                   // one force density for every strut (false: one each)
  bool keep_strut_lengths = false;              // free mode: every strut keeps its length in the scene
  double tolerance = 1e-12;                     // force residual relative to the largest member force
  int max_iterations = 100;                     // Gauss-Newton iterations (free mode)
};

/// A member of the form: its force and length.
struct FormMember
{
  std::string name;
  std::string family;  // the scene's family; "struts" for struts
  bool strut = false;
  double tension = 0.0;  // N; negative is compression
  double length = 0.0;   // m (a sliding cable: its whole path)
};

/// The written scene's own check (docs/form_finding.md, "What is checked").
struct FormCheck
{
  bool checked = false;               // false when the diagnostics were skipped (too many coordinates)
  double equilibrium_residual = 0.0;  // N, of the loaded scene at its start
  bool prestress_stable = false;
  int self_stress_states = 0;
  int mechanisms = 0;
  std::vector<std::string> slack_cables;
  /// checked strut pairs that overlap in the form (form-finding knows no strut thickness): "S1-S3 (gap
  /// -0.004 m)"; the written scene starts with these struts in contact
  std::vector<std::string> overlapping;
  bool newton_converged = false;  // the static solve from the start at zero actuation
  double newton_move = 0.0;       // m: the largest node displacement that solve made
};

struct FormFindingResult
{
  std::string scene;  // the written scene, YAML
  std::vector<std::string> node_names;
  std::vector<Vec3> positions;      // the form, in the scene's node order
  std::vector<FormMember> members;  // struts first, then cables and springs, in the scene's order
  int iterations = 0;               // Gauss-Newton iterations (0 in prestress mode)
  double residual = 0.0;            // N: largest force imbalance at a node that must be in equilibrium
  double max_move = 0.0;            // m: largest node displacement from the scene's positions
  double scale = 1.0;               // the factor the free-standing form was scaled by (1: not scaled)
  int self_stress_states = 0;       // prestress mode: of the given geometry
  std::vector<std::string> notes;   // families split, scaling, loads left out ...
  /// The geometric parameters of the scene's layout that the form changed (formChanges), one text each naming
  /// the parameter and both values: warnings, since the scene gave them.
  std::vector<std::string> changes;
  FormCheck check;
};

/// The form of the scene `yaml` (refused as the loader refuses it: SceneError, with `name` for the file).
FormFindingResult findForm(const std::string& yaml, const std::string& name, const FormFindingOptions& options);

/// The topology a scene gives form-finding: its nodes, and its members with the families they belong to.
struct FormTopology
{
  struct Member
  {
    std::string name;
    int family = -1;         // index into families; -1 for a strut
    std::vector<int> nodes;  // two, or the path of a sliding cable
  };
  struct Family
  {
    std::string name;
    std::string section;  // "cables" or "springs"
    std::vector<int> members;
    double prestress = -1.0;  // N as the scene gives it, -1 when it gives none
  };
  std::vector<std::string> node_names;
  std::vector<Vec3> positions;
  std::vector<char> fixed;
  std::vector<Member> members;  // struts first, then the families' members in the scene's order
  std::vector<Family> families;
};

/// The topology of a scene the loader accepts (SceneError otherwise).
FormTopology readFormTopology(const std::string& yaml, const std::string& name);

/// The geometric parameters a scene's layout gives, as a person designing it would name them, that differ in
/// `form` (the topology's nodes, moved) by more than 1e-6 of the mean member length; one text each, naming the
/// parameter and its value in the scene and in the form, e.g.
///   "overlap of stages 'S1', 'S2', 'S3' (z 0 to 1 m) and 'R1', 'R2', 'R3' (z 0.7 to 1.7 m): 0.3 m in the
///    scene, 0 m in the form".
/// Levels are the sets of at least three nodes at one height in the scene; a stage is the struts that join the
/// same two levels. The parameters: the structure's height (z extent of its nodes), each stage's height (its
/// levels' distance) and twist (the mean turn about z of its struts from the lower level to the upper one, in
/// degrees), the overlap of two stages where one starts below the other's top (the upper one's lower
/// level below the lower one's upper level), each level's radius (mean distance of its nodes from their
/// centroid) and flatness, each strut's length.
std::vector<std::string> formChanges(const FormTopology& topology, const std::vector<Vec3>& form);

/// The equilibrium equations of a topology (see the header comment) as functions of
///   z = [positions of the nodes that are not fixed (3 each, the scene's order); the free parameters],
/// a parameter being the struts' force density (or one strut's), a free family's tension.
class FormEquations
{
public:
  enum class Kind
  {
    kTension,  // the member carries the parameter
    kDensity,  // the member carries the parameter times its length
  };
  /// held: family index -> (kind, value); every other family is a free tension; the struts share one free
  /// force density (uniform_struts) or have one each. With length_weight > 0 every strut keeps its length in
  /// the topology: one more row each, length_weight (N/m) times its length error.
  FormEquations(const FormTopology& topology, const std::map<int, std::pair<Kind, double>>& held, bool supports_react,
                bool uniform_struts, double length_weight = 0.0);

  int unknowns() const;
  /// The rows: the force rows (forceRows(), 3 per node in equilibrium), then one per kept strut length.
  int equations() const;
  int forceRows() const
  {
    return rows_;
  }
  /// z at the topology's positions, the free parameters given by `parameters` (one per free parameter).
  Eigen::VectorXd pack(const std::vector<Vec3>& positions, const Eigen::VectorXd& parameters) const;
  std::vector<Vec3> positions(const Eigen::VectorXd& z) const;
  /// Every member's tension (N) at z.
  Eigen::VectorXd tensions(const Eigen::VectorXd& z) const;
  /// The force imbalance of every node that must be in equilibrium (3 rows each, N), then the weighted
  /// length errors of the kept struts (N).
  Eigen::VectorXd residual(const Eigen::VectorXd& z) const;
  /// d residual / dz.
  Eigen::MatrixXd jacobian(const Eigen::VectorXd& z) const;
  /// The free parameters: one name each ("struts" or "strut S1", "tension verticals").
  const std::vector<std::string>& parameterNames() const
  {
    return parameter_names_;
  }

private:
  FormTopology topology_;
  std::vector<int> column_;         // per node: first column of its position in z, -1 when fixed
  std::vector<int> row_;            // per node: first residual row, -1 when it need not be in equilibrium
  std::vector<Kind> kind_;          // per member
  std::vector<int> parameter_;      // per member: column of its free parameter in z, -1 when held
  std::vector<double> held_value_;  // per member: the held value
  std::vector<std::string> parameter_names_;
  int position_columns_ = 0;
  int rows_ = 0;
  double length_weight_ = 0.0;
  std::vector<int> kept_struts_;      // members whose length is kept, in row order
  std::vector<double> kept_lengths_;  // their lengths in the topology
};

}  // namespace active_tensegrity::design
