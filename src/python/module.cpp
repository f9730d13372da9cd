// active_tensegrity._core: the core's scene loader and analyses for Python (pybind11). The package's Python
// code (python/active_tensegrity) wraps it; docs/python.md describes the API.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "active_tensegrity/core/solvers/actuation_control.h"
#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/csv.h"
#include "active_tensegrity/core/outputs/peaks.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/solvers/dynamics.h"
#include "active_tensegrity/core/solvers/energy.h"
#include "active_tensegrity/design/form_finding.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/solvers/modal.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/core/base/text.h"
#include "active_tensegrity/planning/folding_planner.h"

namespace py = pybind11;
namespace at = active_tensegrity::core;
namespace design = active_tensegrity::design;

namespace
{
std::vector<at::Override> overrides(const std::vector<std::string>& texts)
{
  std::vector<at::Override> out;
  out.reserve(texts.size());
  for (const std::string& t : texts)
    out.push_back(at::parseOverride(t));
  return out;
}

/// rows x columns of doubles as a numpy array (copied)
py::array_t<double> table(const std::vector<double>& values, size_t rows, size_t columns)
{
  py::array_t<double> a({ rows, columns });
  std::copy(values.begin(), values.end(), a.mutable_data());
  return a;
}

/// The names of a model's nodes, bodies, cables or actuators, in order.
template <typename T>
std::vector<std::string> namesOf(const std::vector<T>& items)
{
  std::vector<std::string> names;
  names.reserve(items.size());
  for (const T& item : items)
    names.push_back(item.name);
  return names;
}

/// Appends x, y, z of every node at q (m), in the model's node order.
void appendNodePositions(const at::Model& model, const Eigen::VectorXd& q, std::vector<double>& out)
{
  for (const at::Node& n : model.nodes)
  {
    const at::Vec3 p = at::pointPosition(model, n.point, q);
    out.insert(out.end(), { p.x(), p.y(), p.z() });
  }
}

const char* analysisName(at::AnalysisType t)
{
  switch (t)
  {
    case at::AnalysisType::kStatic:
      return "static";
    case at::AnalysisType::kDynamic:
      return "dynamic";
    case at::AnalysisType::kModal:
      return "modal";
  }
  return "unknown";
}

/// What one run collects at every output step (filled with the GIL released, converted afterwards).
struct Collected
{
  std::vector<double> rows, nodes, members, contacts;
  size_t steps = 0;
};

/// The largest and smallest value of chosen columns of the CSV (csvColumns) and of the members' table
/// (memberColumns) over every state of a run: its start and the state after every time step or load step,
/// not only the output steps. Each extreme comes with the time (or path parameter) of the first state that
/// reached it; a NaN at any state makes both extremes NaN (from the first such state on).
class ExtremeTracker
{
public:
  ExtremeTracker(const at::Model& model, const std::vector<std::string>& names)
    : model_(model), contacts_(model), cable_stress_(model), alone_(columnFunctions())
  {
    const std::vector<std::string> csv = at::csvColumns(model), members = at::memberColumns(model);
    const auto index = [](const std::vector<std::string>& in, const std::string& name)
    { return static_cast<size_t>(std::find(in.begin(), in.end(), name) - in.begin()); };
    for (const std::string& name : names)
    {
      if (std::any_of(columns_.begin(), columns_.end(), [&](const Column& c) { return c.name == name; }))
        continue;
      Column c;
      c.name = name;
      c.index = index(csv, name);
      if (c.index == csv.size())
      {
        c.member = true;
        c.index = index(members, name);
        if (c.index == members.size())
          throw py::value_error("run: extremes: no column '" + name.substr(0, 200) + "' (columns: " + joined(csv) +
                                "; members: " + joined(members) + ")");
      }
      c.alone = !c.member && alone_[c.index].value;
      any_row_ |= !c.member && !c.alone;
      any_member_ |= c.member;
      any_contacts_ |= c.alone && alone_[c.index].contacts;
      columns_.push_back(c);
    }
  }

  bool empty() const
  {
    return columns_.empty();
  }

  /// `contacts`: the state's active contacts when the run has them (runAnalysis's StepCallback), else null
  void add(const at::State& s, const std::vector<at::ContactPairState>* contacts)
  {
    if (any_contacts_ && !contacts)
      contacts = &contacts_.active(s);
    if (any_row_)
      row_ = at::csvRow(model_, s);
    if (any_member_)
      member_row_ = at::memberRow(model_, s);
    for (Column& c : columns_)
    {
      const double v = c.alone ? alone_[c.index].value(s, contacts) : c.member ? member_row_[c.index] : row_[c.index];
      if (c.states++ == 0 || (std::isnan(v) && !std::isnan(c.max)))
      {
        c.max = c.min = v;
        c.t_max = c.t_min = s.t;
        continue;
      }
      if (v > c.max)
      {
        c.max = v;
        c.t_max = s.t;
      }
      if (v < c.min)
      {
        c.min = v;
        c.t_min = s.t;
      }
    }
  }

  /// {column: {"max": {"value", "t"}, "min": {"value", "t"}, "states": n}}
  py::dict result() const
  {
    py::dict out;
    for (const Column& c : columns_)
    {
      const auto peak = [](double value, double t)
      {
        py::dict d;
        d["value"] = value;
        d["t"] = t;
        return d;
      };
      py::dict d;
      d["max"] = peak(c.max, c.t_max);
      d["min"] = peak(c.min, c.t_min);
      d["states"] = c.states;
      out[py::str(c.name)] = d;
    }
    return out;
  }

private:
  using Contacts = std::vector<at::ContactPairState>;
  /// A CSV column's value in a state, computed alone as csvRow computes it (`contacts`: the state's, when it
  /// reads them)
  struct Function
  {
    std::function<double(const at::State&, const Contacts*)> value;
    bool contacts = false;
  };

  static std::string joined(const std::vector<std::string>& names)
  {
    std::string out;
    for (const std::string& n : names)
      out += (out.empty() ? "" : ", ") + n;
    return out;
  }

  /// What the contacts give a column: (strut pairs or the ground's) count, largest normal force, largest
  /// friction force, sum of the normal forces, as csvRow sums them.
  enum class Over
  {
    kPairs,
    kGround
  };
  enum class Figure
  {
    kCount,
    kLargestNormal,
    kLargestFriction,
    kNormalSum
  };
  static double fromContacts(const Contacts& contacts, Over over, Figure figure)
  {
    double out = 0.0;
    for (const at::ContactPairState& c : contacts)
    {
      if ((c.body_b < 0) != (over == Over::kGround))
        continue;
      switch (figure)
      {
        case Figure::kCount:
          out += 1.0;
          break;
        case Figure::kLargestNormal:
          out = std::max(out, c.normal_force);
          break;
        case Figure::kLargestFriction:
          out = std::max(out, c.friction_force);
          break;
        case Figure::kNormalSum:
          out += c.normal_force;
          break;
      }
    }
    return out;
  }

  /// Per CSV column, the function that computes its value alone (the whole row is not formed at every step,
  /// nor the contacts when the run gives them). The columns are laid out here as csvColumns lays them out; when
  /// the names differ from csvColumns', every column is left to csvRow.
  std::vector<Function> columnFunctions()
  {
    const at::Model& m = model_;
    const bool any = !m.actuators.empty();
    std::vector<std::string> names;
    std::vector<Function> f;
    const auto state = [&](const std::string& name, std::function<double(const at::State&)> value)
    {
      names.push_back(name);
      f.push_back({ [value](const at::State& s, const Contacts*) { return value(s); }, false });
    };
    const auto contact = [&](const std::string& name, Over over, Figure figure)
    {
      names.push_back(name);
      f.push_back(
          { [over, figure](const at::State&, const Contacts* c) { return fromContacts(*c, over, figure); }, true });
    };
    state("t", [](const at::State& s) { return s.t; });
    state("actuation", [any](const at::State& s) { return any ? s.u[0].value : 0.0; });
    state("actuation_force", [&m, any](const at::State& s) { return any ? at::actuationForce(m, s, 0) : 0.0; });
    state("height", [&m](const at::State& s) { return at::structureHeight(m, s.q); });
    contact("active_contacts", Over::kPairs, Figure::kCount);
    state("min_gap", [&m](const at::State& s) { return at::minimumGap(m, s.q); });
    contact("max_normal_force", Over::kPairs, Figure::kLargestNormal);
    contact("max_friction_force", Over::kPairs, Figure::kLargestFriction);
    state("slack_cables", [&m](const at::State& s) { return static_cast<double>(at::slackCables(m, s)); });
    names.push_back("max_strut_bending_stress");
    f.push_back({ [&m](const at::State& s, const Contacts* c) { return at::maxStrutBendingStress(m, s.q, *c); }, true });
    state("max_cable_stress", [this](const at::State& s) { return cable_stress_.largest(s); });
    state("min_cable_strut_gap", [&m](const at::State& s) { return at::minimumCableStrutGap(m, s.q).gap; });
    if (m.ground.enabled)
    {
      contact("ground_contacts", Over::kGround, Figure::kCount);
      state("min_ground_gap", [&m](const at::State& s) { return at::minimumGroundGap(m, s.q); });
      contact("ground_normal_force", Over::kGround, Figure::kNormalSum);
      contact("max_ground_friction_force", Over::kGround, Figure::kLargestFriction);
    }
    if (at::hasLoadPath(m))
      state("load_factor", [&m](const at::State& s) { return at::loadFactor(m, s); });
    for (const at::OutputLayer& layer : m.layers)
      state("height_" + layer.name, [&m, &layer](const at::State& s) { return at::nodesHeight(m, layer.nodes, s.q); });
    if (m.actuators.size() > 1)
      for (size_t i = 0; i < m.actuators.size(); ++i)
      {
        state("actuation_" + m.actuators[i].name, [i](const at::State& s) { return s.u[i].value; });
        state("actuation_force_" + m.actuators[i].name,
              [&m, i](const at::State& s) { return at::actuationForce(m, s, static_cast<int>(i)); });
      }
    if (names != at::csvColumns(m))
      return std::vector<Function>(at::csvColumns(m).size());
    return f;
  }

  struct Column
  {
    std::string name;
    bool member = false, alone = false;
    size_t index = 0;
    long states = 0;
    double max = std::numeric_limits<double>::quiet_NaN(), min = max, t_max = max, t_min = max;
  };
  const at::Model& model_;
  at::ContactScan contacts_;
  at::CableStressScan cable_stress_;
  std::vector<Function> alone_;
  std::vector<Column> columns_;
  bool any_row_ = false, any_member_ = false, any_contacts_ = false;
  std::vector<double> row_, member_row_;
};

/// kinetic, elastic, gravity and total energy of a state (J), as tensegrity_run's summary writes them
py::dict energyPoint(const at::EnergyPoint& p)
{
  py::dict d;
  d["kinetic"] = p.kinetic;
  d["elastic"] = p.elastic;
  d["gravity"] = p.gravity;
  d["total"] = p.total();
  return d;
}

/// A dynamic run's energy account with the keys and nesting of tensegrity_run's summary (`energy:`)
py::dict energy(const at::EnergyAccount& e)
{
  py::dict d;
  d["start"] = energyPoint(e.start);
  d["end"] = energyPoint(e.now);
  d["actuator_work"] = e.actuator_work;
  d["damping_dissipation"] = e.damping_dissipation;
  d["contact_dissipation"] = e.contact_dissipation;
  d["numerical_dissipation"] = e.numerical_dissipation;
  py::dict gain;
  gain["value"] = e.largest_step_gain;
  gain["t"] = e.largest_gain_t;
  d["largest_step_gain"] = gain;
  d["gaining_steps"] = e.gaining_steps;
  d["contact_loss_steps"] = e.contact_loss_steps;
  d["contact_unresolved"] = e.contact_unresolved_energy;
  return d;
}

py::dict run(const at::Model& model, const std::vector<std::string>& extremes)
{
  if (model.analysis.type == at::AnalysisType::kModal)
    throw py::value_error("run: the scene's analysis.type is modal (natural modes have no output steps; run it with "
                          "tensegrity_run)");
  Collected c;
  at::RunResult result;
  at::PeakTracker peaks(model);
  ExtremeTracker tracked(model, extremes);
  {
    const py::gil_scoped_release release;
    // the extremes see the start (the first output step) and every step's state once: an output step that is
    // not the state of the step just taken (none so far) is given to them too
    bool stepped = false;
    double last_step_t = 0.0;
    result = at::runAnalysis(
        model,
        [&](const at::State& s)
        {
          if (c.steps == 0)  // the start (the first output row) counts for the peaks, as tensegrity_run counts it
            peaks.add(s);
          const std::vector<double> row = at::csvRow(model, s);
          c.rows.insert(c.rows.end(), row.begin(), row.end());
          appendNodePositions(model, s.q, c.nodes);
          const std::vector<double> m = at::memberRow(model, s);
          c.members.insert(c.members.end(), m.begin(), m.end());
          for (const at::ContactPairState& k : at::activeContacts(model, s))
          {
            c.contacts.insert(c.contacts.end(),
                              { static_cast<double>(c.steps), static_cast<double>(k.body_a),
                                static_cast<double>(k.body_b), k.point_a.x(), k.point_a.y(), k.point_a.z(),
                                k.point_b.x(), k.point_b.y(), k.point_b.z(), k.normal.x(), k.normal.y(), k.normal.z(),
                                k.penetration, k.penetration_rate, k.normal_force, k.friction_on_a.x(),
                                k.friction_on_a.y(), k.friction_on_a.z() });
          }
          if (!tracked.empty() && (!stepped || s.t != last_step_t))
            tracked.add(s, nullptr);
          ++c.steps;
        },
        {},
        [&](const at::State& s, const std::vector<at::ContactPairState>* contacts)
        {
          peaks.add(s, contacts);
          if (!tracked.empty())
          {
            tracked.add(s, contacts);
            stepped = true;
            last_step_t = s.t;
          }
        });
  }
  const std::vector<std::string> columns = at::csvColumns(model);
  const std::vector<std::string> member_columns = at::memberColumns(model);
  py::dict out;
  out["columns"] = columns;
  out["table"] = table(c.rows, c.steps, columns.size());
  py::array_t<double> nodes({ c.steps, model.nodes.size(), size_t{ 3 } });
  std::copy(c.nodes.begin(), c.nodes.end(), nodes.mutable_data());
  out["nodes"] = nodes;
  out["member_columns"] = member_columns;
  out["members"] = table(c.members, c.steps, member_columns.size());
  out["contacts"] = table(c.contacts, c.contacts.size() / 18, 18);
  out["extremes"] = tracked.result();
  // the fields of tensegrity_run's summary but its scene (the file it ran), with the same names
  const bool dynamic = model.analysis.type == at::AnalysisType::kDynamic;
  py::dict summary;
  summary["name"] = model.name;
  summary["analysis"] = analysisName(model.analysis.type);
  summary["status"] = at::toString(result.summary.status);
  summary["message"] = result.summary.message;
  summary["output_steps"] = result.steps;
  summary["solver_steps"] = result.solver_steps;
  summary["newton_iterations"] = result.summary.iterations;
  summary["step_cuts"] = result.summary.step_cuts;
  summary["wall_time"] = result.wall_time;
  if (dynamic)
  {
    summary["duration"] = model.analysis.duration;
    if (!model.analysis.duration_note.empty())
      summary["duration_note"] = model.analysis.duration_note;
    if (result.wall_time > 0.0)
      summary["real_time_factor"] = result.final_state.t / result.wall_time;
    if (model.solver.adaptive)
    {
      const at::AdaptiveStats& a = result.adaptive;
      py::dict adaptive;
      adaptive["accepted"] = a.accepted;
      adaptive["rejected_error"] = a.rejected_error;
      adaptive["rejected_onset"] = a.rejected_onset;
      adaptive["rejected_solver"] = a.rejected_solver;
      adaptive["rejected_energy"] = a.rejected_energy;
      adaptive["at_min_step"] = a.at_min_step;
      adaptive["smallest"] = a.h_min;
      adaptive["largest"] = a.h_max;
      summary["adaptive_steps"] = adaptive;
    }
    summary["energy"] = energy(result.energy);
  }
  summary["warnings"] = result.summary.warnings;
  py::dict breakdown;
  for (const auto& [part, seconds] : at::timeBreakdown(result))
  {
    py::dict one;
    one["seconds"] = seconds;
    one["share"] = result.wall_time > 0.0 ? seconds / result.wall_time : 0.0;
    breakdown[py::str(part)] = one;
  }
  summary["time_breakdown"] = breakdown;
  py::dict final_row;
  const std::vector<double> last = at::csvRow(model, result.final_state);
  for (size_t i = 0; i < columns.size(); ++i)
    final_row[py::str(columns[i])] = last[i];
  summary["final"] = final_row;
  py::dict peak;
  for (const at::Peak& p : peaks.peaks())
  {
    py::dict one;
    one["value"] = p.value;
    one["t"] = p.t;
    peak[py::str(p.name)] = one;
  }
  summary["peaks"] = peak;
  out["summary"] = summary;
  return out;
}
py::dict report(const at::StructureReport& r)
{
  py::dict d;
  d["checked"] = r.checked;
  d["note"] = r.note;
  d["coordinates"] = r.coordinates;
  d["free_coordinates"] = r.free_coordinates;
  d["members"] = r.members;
  d["struts"] = r.struts;
  d["tension_members"] = r.tension_members;
  d["equilibrium_matrix_rank"] = r.rank;
  d["self_stress_states"] = r.self_stress_states;
  d["mechanisms"] = r.mechanisms;
  d["rigid_body_modes"] = r.rigid_body_modes;
  d["prestress_stable"] = r.prestress_stable;
  d["smallest_rigid_mode_eigenvalue"] = r.smallest_rigid_mode_eigenvalue;
  d["smallest_stiffness_eigenvalue"] = r.smallest_stiffness_eigenvalue;
  d["largest_stiffness_eigenvalue"] = r.largest_stiffness_eigenvalue;
  d["slack_cables"] = r.slack_cables;
  d["equilibrium_residual"] = r.equilibrium_residual;
  return d;
}

py::dict modal(const at::Model& model)
{
  if (model.analysis.type != at::AnalysisType::kModal)
    throw py::value_error("modal: the scene's analysis.type is " + std::string(analysisName(model.analysis.type)) +
                          ", not modal (set analysis.type=modal)");
  at::ModalRun r;
  {
    const py::gil_scoped_release release;
    r = at::runModal(model);
  }
  const size_t n = r.modal.modes.size();
  py::array_t<double> frequency(n), omega(n), eigenvalue(n);
  py::array_t<double> shapes({ n, model.nodes.size(), size_t{ 3 } });
  double* out = shapes.mutable_data();
  for (size_t k = 0; k < n; ++k)
  {
    const at::NaturalMode& mode = r.modal.modes[k];
    frequency.mutable_at(k) = mode.frequency_hz;
    omega.mutable_at(k) = mode.omega;
    eigenvalue.mutable_at(k) = mode.eigenvalue;
    for (const at::Vec3& d : mode.node_displacements)
    {
      *out++ = d.x();
      *out++ = d.y();
      *out++ = d.z();
    }
  }
  py::dict d;
  d["status"] = at::toString(r.summary.status);
  d["message"] = r.summary.message;
  d["warnings"] = r.summary.warnings;
  d["free_coordinates"] = r.modal.free_coordinates;
  d["frequency_hz"] = frequency;
  d["omega"] = omega;
  d["eigenvalue"] = eigenvalue;
  d["shapes"] = shapes;
  d["structure"] = report(r.structure);
  d["wall_time"] = r.wall_time;
  return d;
}

py::dict findForm(const std::string& yaml, const std::string& name, const std::string& mode,
                  const std::map<std::string, double>& tension, const std::map<std::string, double>& force_density,
                  bool supports_react, bool uniform_struts, bool keep_strut_lengths, double tolerance,
                  int max_iterations)
{
  // the options tensegrity_formfind refuses, refused alike
  design::FormFindingOptions o;
  if (mode != "free" && mode != "prestress")
    throw py::value_error("find_form: mode must be 'free' or 'prestress', got '" + mode.substr(0, 200) + "'");
  o.mode = mode == "free" ? design::FormFindingMode::kFree : design::FormFindingMode::kPrestress;
  if (!(tolerance > 0.0 && tolerance < 1e-3))
    throw py::value_error("find_form: tolerance must be a relative tolerance in (0, 1e-3), got " +
                          at::shortestNumber(tolerance));
  if (max_iterations < 1 || max_iterations > 10000)
    throw py::value_error("find_form: max_iterations must be 1 ... 10000, got " + std::to_string(max_iterations));
  for (const auto* values : { &tension, &force_density })
    for (const auto& [family, value] : *values)
      if (!std::isfinite(value))
        throw py::value_error("find_form: family '" + family.substr(0, 200) + "' has a non-finite value");
  o.tension = tension;
  o.force_density = force_density;
  o.supports_react = supports_react;
  o.uniform_struts = uniform_struts;
  o.keep_strut_lengths = keep_strut_lengths;
  o.tolerance = tolerance;
  o.max_iterations = max_iterations;
  design::FormFindingResult r;
  {
    const py::gil_scoped_release release;
    r = design::findForm(yaml, name, o);
  }
  py::array_t<double> positions({ r.positions.size(), size_t{ 3 } });
  double* out = positions.mutable_data();
  for (const at::Vec3& p : r.positions)
  {
    *out++ = p.x();
    *out++ = p.y();
    *out++ = p.z();
  }
  py::list members;
  for (const design::FormMember& m : r.members)
  {
    py::dict d;
    d["name"] = m.name;
    d["family"] = m.family;
    d["strut"] = m.strut;
    d["tension"] = m.tension;
    d["length"] = m.length;
    members.append(d);
  }
  py::dict check;
  check["checked"] = r.check.checked;
  check["equilibrium_residual"] = r.check.equilibrium_residual;
  check["prestress_stable"] = r.check.prestress_stable;
  check["self_stress_states"] = r.check.self_stress_states;
  check["mechanisms"] = r.check.mechanisms;
  check["slack_cables"] = r.check.slack_cables;
  check["overlapping"] = r.check.overlapping;
  check["newton_converged"] = r.check.newton_converged;
  check["newton_move"] = r.check.newton_move;
  py::dict d;
  d["scene"] = r.scene;
  d["node_names"] = r.node_names;
  d["positions"] = positions;
  d["members"] = members;
  d["iterations"] = r.iterations;
  d["residual"] = r.residual;
  d["max_move"] = r.max_move;
  d["scale"] = r.scale;
  d["self_stress_states"] = r.self_stress_states;
  d["notes"] = r.notes;
  d["changes"] = r.changes;
  d["check"] = check;
  return d;
}

/// `model` as a dynamic simulation reads it: analysis.type dynamic, so that the contact forces of its rows are
/// those the solver integrates (with the contacts' damping and memory), not the quasi-static ones of a scene
/// whose analysis is static
at::Model dynamicModel(at::Model model)
{
  model.analysis.type = at::AnalysisType::kDynamic;
  return model;
}

bool finite(const at::State& s)
{
  return s.q.allFinite() && s.qd.allFinite() && s.natural.lambda.allFinite();
}

/// A dynamic simulation stepped from Python: the ROS node's loop without ROS (fixed steps of solver.dt, the
/// actuation from an ActuationController that commands change without jumps in value or rate).
class Simulation
{
public:
  explicit Simulation(at::Model model)
    : model_(dynamicModel(std::move(model)))
    , solver_(model_, model_.solver)
    , controller_(model_, at::initialState(model_).u)
    , state_(at::initialState(model_))
  {
    const at::Summary init = solver_.initialize(state_, law());
    if (!init.ok())
      throw std::runtime_error(std::string("Simulation: the initial state could not be made consistent (") +
                               at::toString(init.status) + ": " + init.message + ")");
    solver_.formActuatorForces(state_);
  }

  Simulation(const Simulation&) = delete;  // the solver and the controller refer to model_
  Simulation& operator=(const Simulation&) = delete;

  /// Advances by `steps` steps of solver.dt, calling `callback(self)` after every `every` steps (when given);
  /// stops early when the callback returns False. The last good state is kept when a step fails; the
  /// failure raises RuntimeError with the solver's status and message.
  int advance(long steps, const py::object& self, const py::object& callback, long every)
  {
    if (steps < 0)
      throw py::value_error("advance: steps must be >= 0, got " + std::to_string(steps));
    if (every < 1)
      throw py::value_error("advance: every must be >= 1, got " + std::to_string(every));
    long done = 0;
    while (done < steps)
    {
      const long chunk = callback.is_none() ? steps - done : std::min(every, steps - done);
      std::string failure;
      {
        const py::gil_scoped_release release;
        failure = stepMany(chunk);
      }
      if (!failure.empty())
        throw std::runtime_error(failure);
      done += chunk;
      if (!callback.is_none())
      {
        const py::object go_on = callback(self);
        if (!go_on.is_none() && !go_on.cast<bool>())
          break;
      }
    }
    return static_cast<int>(done);
  }

  void setTargets(const std::vector<std::string>& names, const std::vector<double>& targets,
                  const std::vector<double>& speeds, const std::vector<double>& accels, double speed, double accel)
  {
    // 0: the node's defaults, the scene's actuation.speed (else 0.1 m/s), reached in its blend_time (else 0.1 s)
    const at::RampSchedule& ramp = model_.analysis.schedule;
    if (speed == 0.0)
      speed = ramp.speed > 0.0 ? ramp.speed : 0.1;
    if (accel == 0.0)
      accel = speed / (ramp.blend_time > 0.0 ? ramp.blend_time : 0.1);
    const std::string err = controller_.setTargets(state_.t, names, targets, speeds, accels, speed, accel);
    if (!err.empty())
      throw py::value_error("set_targets: " + err);
  }

  /// Follows timed points from now (ActuationController::setTrajectory: the node's ~follow_trajectory): the
  /// named actuators go through positions[k] (and velocities[k]) at t + times[k]; the others keep their law.
  void follow(const std::vector<std::string>& names, const std::vector<double>& times,
              const std::vector<std::vector<double>>& positions, const std::vector<std::vector<double>>& velocities)
  {
    const std::string err = controller_.setTrajectory(state_.t, names, times, positions, velocities);
    if (!err.empty())
      throw py::value_error("follow: " + err);
  }

  const at::Model& model() const
  {
    return model_;
  }
  const at::ActuationController& controller() const
  {
    return controller_;
  }
  const at::State& state() const
  {
    return state_;
  }
  long steps() const
  {
    return steps_.load(std::memory_order_relaxed);
  }
  at::ActuationValues actuation() const
  {
    return controller_.values(state_.t);
  }

private:
  at::ActuationLaw law()
  {
    return at::ActuationLaw::writing([this](double t, at::ActuationValues& u) { controller_.values(t, u); });
  }
  std::string stepMany(long n)
  {
    const at::ActuationLaw l = law();
    const double dt = model_.solver.dt;
    for (long i = 0; i < n; ++i)
    {
      const at::State before = state_;
      const double t_next = static_cast<double>(steps() + 1) * dt;  // t = k dt exactly
      const at::Summary s = solver_.step(state_, t_next - state_.t, l);
      if (!s.ok() || !finite(state_))
      {
        state_ = before;
        return "the solver failed at t = " + std::to_string(before.t) + " s (" +
               (s.ok() ? std::string("non_finite: non-finite state") :
                         std::string(at::toString(s.status)) + ": " + s.message) +
               "); the simulation keeps the last good state";
      }
      state_.t = t_next;
      solver_.formActuatorForces(state_);  // (the rows read them)
      steps_.fetch_add(1, std::memory_order_relaxed);
    }
    return {};
  }

  at::Model model_;
  at::DynamicsSolver solver_;
  at::ActuationController controller_;
  at::State state_;
  // readable from another thread while an advance runs there (the interpreter's lock is released during
  // the steps); the rest of the state is read between advances or from a callback
  std::atomic<long> steps_{ 0 };
};
namespace ap = active_tensegrity::planning;

py::array_t<double> rows(const std::vector<std::vector<double>>& v, size_t columns)
{
  py::array_t<double> a({ v.size(), columns });
  double* out = a.mutable_data();
  for (const std::vector<double>& r : v)
    for (size_t j = 0; j < columns; ++j)
      *out++ = j < r.size() ? r[j] : std::numeric_limits<double>::quiet_NaN();
  return a;
}

/// Sets the PlanRequest field named `key` from a Python value (py::cast_error on the wrong type).
void setRequestField(ap::PlanRequest& req, const std::string& key, const py::handle& v)
{
  if (key == "actuators")
    req.actuators = v.cast<std::vector<std::string>>();
  else if (key == "target_height")
    req.target_height = v.cast<double>();
  else if (key == "target_values")
    req.target_values = v.cast<std::vector<double>>();
  else if (key == "min_clearance")
    req.limits.min_clearance = v.cast<double>();
  else if (key == "allow_contact")
    req.limits.allow_contact = v.cast<bool>();
  else if (key == "max_contact_force")
    req.limits.max_contact_force = v.cast<double>();
  else if (key == "max_cable_stress")
    req.limits.max_cable_stress = v.cast<double>();
  else if (key == "max_speeds")
    req.max_speeds = v.cast<std::vector<double>>();
  else if (key == "max_accelerations")
    req.max_accelerations = v.cast<std::vector<double>>();
  else if (key == "planner")
    req.planner = v.cast<std::string>();
  else if (key == "time_limit")
    req.time_limit = v.cast<double>();
  else if (key == "seed")
    req.seed = v.cast<unsigned>();
  else if (key == "continuation_step")
    req.continuation_step = v.cast<double>();
  else if (key == "range")
    req.range = v.cast<double>();
  else if (key == "sample_dt")
    req.sample_dt = v.cast<double>();
  else if (key == "reachability_check")
    req.reachability_check = v.cast<bool>();
  else if (key == "verify_dynamics")
    req.verify_dynamics = v.cast<bool>();
  else if (key == "find_speed_limit")
    req.find_speed_limit = v.cast<bool>();
  else if (key == "max_bending_stress")
    req.max_bending_stress = v.cast<double>();
  else if (key == "settle_time")
    req.settle_time = v.cast<double>();
  else if (key == "blend_tolerance")
    req.blend_tolerance = v.cast<double>();
  else
    throw py::value_error("plan_folding: unknown argument '" + key.substr(0, 200) + "'");
}

/// The folding planner, the request from keyword arguments named as PlanRequest's fields. Without `live`, from
/// the scene's initial state (its equilibrium). With it, as the node plans: from a Simulation's live state
/// (a copy, with a copy of its controller, `law`), the path from the equilibrium nearest to where the actuators
/// come to rest, verified from the live state itself (positions, velocities, contact memory) under that law.
py::dict plan(const at::Model& model, const at::State* live, const at::ActuationController* law, const py::dict& args)
{
  ap::PlanRequest req;
  for (const auto& [k, v] : args)
  {
    const std::string key = py::str(k);
    try
    {
      setRequestField(req, key, v);
    }
    catch (const py::cast_error&)
    {
      throw py::type_error("plan_folding: " + key + ": a value of the wrong type (" +
                           std::string(py::str(py::repr(v))).substr(0, 200) + ")");
    }
  }
  ap::PlanResult r;
  std::string start_error;
  if (live)
  {
    req.relax_start = true;
    const py::gil_scoped_release release;
    r = ap::planFolding(model, *live, req, {}, law);
  }
  else
  {
    const py::gil_scoped_release release;
    at::State start;
    start_error = ap::startEquilibrium(model, at::initialState(model), start);
    if (start_error.empty())
      r = ap::planFolding(model, start, req);
  }
  if (!start_error.empty())
  {
    r.status = ap::PlanStatus::kInvalidStart;
    r.message = "no equilibrium to start from: " + start_error;
  }
  const size_t n = r.names.size();
  py::dict d;
  d["status"] = ap::toString(r.status);
  d["message"] = r.message;
  d["names"] = r.names;
  d["waypoints"] = rows(r.waypoints, n);
  py::array_t<double> times(r.times.size());
  std::copy(r.times.begin(), r.times.end(), times.mutable_data());
  d["times"] = times;
  d["positions"] = rows(r.positions, n);
  d["velocities"] = rows(r.velocities, n);
  d["accelerations"] = rows(r.accelerations, n);
  d["duration"] = r.duration;
  d["rest_to_rest_duration"] = r.rest_to_rest_duration;
  d["stop_duration"] = r.stop_duration;
  d["min_gap"] = r.min_gap;
  d["peak_contact_force"] = r.peak_contact_force;
  d["final_height"] = r.final_height;
  d["equilibrium_solves"] = r.equilibrium_solves;
  d["planning_time"] = r.planning_time;
  d["stopped_by_time_limit"] = r.stopped_by_time_limit;
  d["cancelled"] = r.cancelled;
  d["dynamics_verified"] = r.dynamics_verified;
  d["dynamics_within_limits"] = r.dynamics_within_limits;
  d["dynamic_peak_contact_force"] = r.dynamic_peak_contact_force;
  d["dynamic_peak_bending_stress"] = r.dynamic_peak_bending_stress;
  d["dynamic_min_gap"] = r.dynamic_min_gap;
  d["settle_duration"] = r.settle_duration;
  d["time_scale"] = r.time_scale;
  d["dynamic_runs"] = r.dynamic_runs;
  return d;
}
}  // namespace

PYBIND11_MODULE(_core, m)
{
  m.doc() = "active_tensegrity's core: scenes and their analyses (use the package active_tensegrity)";
  // a refused scene: ValueError with the loader's message; the key it names is the exception's `key`
  static py::handle scene_error = py::exception<at::SceneError>(m, "SceneError", PyExc_ValueError).release();
  py::register_exception_translator(
      [](std::exception_ptr p)
      {
        try
        {
          if (p)
            std::rethrow_exception(p);
        }
        catch (const at::SceneError& e)
        {
          py::object error = py::reinterpret_borrow<py::object>(scene_error)(e.what());
          error.attr("key") = e.key();
          PyErr_SetObject(scene_error.ptr(), error.ptr());
        }
      });

  // a form that cannot be found: RuntimeError with form-finding's message
  py::register_exception<design::FormFindingError>(m, "FormFindingError", PyExc_RuntimeError);

  py::class_<at::Model>(m, "Model", "A loaded, validated scene")
      .def_property_readonly("name", [](const at::Model& s) { return s.name; })
      .def_property_readonly("source", [](const at::Model& s) { return s.source; })
      .def_property_readonly("analysis", [](const at::Model& s) { return analysisName(s.analysis.type); })
      .def_property_readonly("nodes", [](const at::Model& s) { return namesOf(s.nodes); })
      .def_property_readonly("bodies", [](const at::Model& s) { return namesOf(s.bodies); })
      .def_property_readonly("cables", [](const at::Model& s) { return namesOf(s.cables); })
      .def_property_readonly("actuators", [](const at::Model& s) { return namesOf(s.actuators); })
      .def_property_readonly("columns", [](const at::Model& s) { return at::csvColumns(s); })
      .def_property_readonly("member_columns", [](const at::Model& s) { return at::memberColumns(s); });

  m.def(
      "load_scene",
      [](const std::string& path, const std::vector<std::string>& sets)
      {
        const std::vector<at::Override> o = overrides(sets);
        const py::gil_scoped_release release;
        return at::loadScene(path, o);
      },
      py::arg("path"), py::arg("overrides") = std::vector<std::string>{},
      "Loads and validates a scene file; overrides are 'key=value' texts as tensegrity_run --set takes them");
  m.def(
      "load_scene_text",
      [](const std::string& text, const std::string& name, const std::vector<std::string>& sets)
      {
        const std::vector<at::Override> o = overrides(sets);
        const py::gil_scoped_release release;
        return at::loadSceneFromString(text, name, o);
      },
      py::arg("text"), py::arg("name") = "<string>", py::arg("overrides") = std::vector<std::string>{},
      "The same from YAML text (`name` stands for the file in messages)");
  py::class_<Simulation>(m, "Simulation")
      .def(py::init<at::Model>(), py::arg("model"))
      .def(
          "advance",
          [](py::object self, long steps, const py::object& callback, long every)
          { return self.cast<Simulation&>().advance(steps, self, callback, every); },
          py::arg("steps"), py::arg("callback") = py::none(), py::arg("every") = 1)
      .def("follow", &Simulation::follow, py::arg("names"), py::arg("times"), py::arg("positions"),
           py::arg("velocities") = std::vector<std::vector<double>>{})
      .def("set_targets", &Simulation::setTargets, py::arg("names"), py::arg("targets"),
           py::arg("speeds") = std::vector<double>{}, py::arg("accels") = std::vector<double>{}, py::arg("speed") = 0.0,
           py::arg("accel") = 0.0)
      .def_property_readonly("t", [](const Simulation& s) { return s.state().t; })
      .def_property_readonly("steps", &Simulation::steps)
      .def_property_readonly("dt", [](const Simulation& s) { return s.model().solver.dt; })
      .def_property_readonly("model", &Simulation::model)
      .def_property_readonly("height", [](const Simulation& s) { return at::structureHeight(s.model(), s.state().q); })
      .def_property_readonly("actuation",
                             [](const Simulation& s)
                             {
                               py::dict d;
                               const at::ActuationValues u = s.state().u;
                               for (size_t i = 0; i < s.model().actuators.size(); ++i)
                                 d[py::str(s.model().actuators[i].name)] = u[i].value;
                               return d;
                             })
      .def_property_readonly("row",
                             [](const Simulation& s)
                             {
                               py::dict d;
                               const std::vector<std::string> cols = at::csvColumns(s.model());
                               const std::vector<double> row = at::csvRow(s.model(), s.state());
                               for (size_t i = 0; i < cols.size(); ++i)
                                 d[py::str(cols[i])] = row[i];
                               return d;
                             })
      .def_property_readonly("nodes",
                             [](const Simulation& s)
                             {
                               std::vector<double> xyz;
                               appendNodePositions(s.model(), s.state().q, xyz);
                               return table(xyz, s.model().nodes.size(), 3);
                             });
  m.def(
      "check",
      [](const at::Model& model)
      {
        at::StructureReport r;
        {
          const py::gil_scoped_release release;
          r = at::checkStructure(model, at::initialState(model));
        }
        return report(r);
      },
      py::arg("model"), "The structural diagnostics of the scene's initial state (tensegrity_run --check)");
  m.def("modal", &modal, py::arg("model"),
        "The natural modes about the equilibrium at analysis.max_actuation (a scene of analysis.type modal)");
  m.def("find_form", &findForm, py::arg("yaml"), py::arg("name"), py::arg("mode") = "free",
        py::arg("tension") = std::map<std::string, double>{},
        py::arg("force_density") = std::map<std::string, double>{}, py::arg("supports_react") = false,
        py::arg("uniform_struts") = true, py::arg("keep_strut_lengths") = false, py::arg("tolerance") = 1e-12,
        py::arg("max_iterations") = 100,
        "Form-finding (tensegrity_formfind): the self-equilibrated form of a scene's topology");
  m.def(
      "plan_folding",
      [](const py::object& scene, const py::kwargs& args)
      {
        if (py::isinstance<Simulation>(scene))
        {
          // copies: the plan does not read the simulation while it plans with the interpreter's lock released
          const Simulation& sim = scene.cast<const Simulation&>();
          const at::State live = sim.state();
          const at::ActuationController law = sim.controller();
          return plan(sim.model(), &live, &law, args);
        }
        return plan(scene.cast<const at::Model&>(), nullptr, nullptr, args);
      },
      py::arg("scene"),
      "The folding planner (docs/planning.md) from a Model's initial state, or from a Simulation's live state under "
      "its actuation, as the node plans");
  m.def("planners", &ap::plannerNames, "The OMPL planners plan_folding accepts");
  m.def("run", &run, py::arg("model"), py::arg("extremes") = std::vector<std::string>{},
        "Runs the scene's analysis (static or dynamic); a dict of numpy arrays per output step, the summary, and "
        "the largest and smallest value over every step of the columns named in `extremes`");
}
