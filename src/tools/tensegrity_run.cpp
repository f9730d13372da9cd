// tensegrity_run: runs a scene's analysis without a ROS master and writes CSV rows and a summary.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <functional>
#include <memory>
#include <sstream>
#include <type_traits>
#include <utility>
#include <string>
#include <vector>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/outputs/csv.h"
#include "active_tensegrity/core/outputs/peaks.h"
#include "active_tensegrity/core/outputs/run.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/solvers/modal.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/structure_check.h"
#include "active_tensegrity/ros/bag_writer.h"
#include "cli.h"
#include "vtk_writer.h"

namespace at = active_tensegrity::core;
namespace tools = active_tensegrity::tools;

namespace
{
const char* kUsage =
    "usage: tensegrity_run SCENE.yaml [--set key=value]... [--out FILE.csv] [--summary FILE.yaml]\n"
    "                     [--contacts FILE.csv] [--nodes FILE.csv] [--members FILE.csv] [--bag FILE.bag]\n"
    "                     [--bag-ns /NAME] [--vtk DIR] [--modes FILE.csv]\n"
    "       tensegrity_run SCENE.yaml [--set key=value]... --check\n"
    "  Runs the scene's analysis (static path or dynamic run) and writes one CSV row per output step\n"
    "  (stdout when --out is not given) and a YAML summary. Any scene key can be overridden with\n"
    "  --set, e.g. --set struts.radius=0.06 --set analysis.max_actuation=1.0\n"
    "  --contacts writes one row per strut pair in contact (and per body on the ground, second strut \"ground\")\n"
    "  per output step (points, normal, forces).\n"
    "  --nodes writes one row per output step: t and the x, y, z (m) of every node, in the scene's order\n"
    "  (columns NAME_x, NAME_y, NAME_z).\n"
    "  --members writes one row per output step: t, every cable's and spring's tension (N), length and rest\n"
    "  length (m) (NAME_tension, NAME_length, NAME_rest_length) and every strut's axial force (NAME_force, N,\n"
    "  negative in compression) from the forces at its ends.\n"
    "  --vtk writes DIR/run_000000.vtp ... (one VTK PolyData file per output step: struts and cables as lines\n"
    "  with kind, force and radius, contact points with their forces) and DIR/run.pvd, the collection\n"
    "  ParaView opens to play the run.\n"
    "  --bag writes, per output step, what the tensegrity_sim node publishes (/tf, NS/contacts, NS/cables,\n"
    "  NS/struts, NS/actuators, NS/markers with NS = --bag-ns, default /tensegrity_sim), stamped in\n"
    "  simulated time from the wall time of the start; no master needed. Watch it with\n"
    "  roslaunch active_tensegrity playback.launch bag:=$PWD/FILE.bag\n"
    "  A modal scene (analysis.type: modal) writes one CSV row per mode (mode, frequency_hz, omega,\n"
    "  eigenvalue) instead, and with --modes the mode shapes: one row per mode and node (mode, node,\n"
    "  dx, dy, dz), the largest node displacement of each mode 1.\n"
    "  --check runs no analysis: it prints the structural diagnostics of the scene's initial state as\n"
    "  YAML on stdout (self-stress states, mechanisms, rigid-body modes, prestress stability, ...).\n";

const char* kDefaultBagNs = "/tensegrity_sim";

const char* kContactColumns = "t,strut_a,strut_b,point_a_x,point_a_y,point_a_z,point_b_x,point_b_y,point_b_z,"
                              "normal_x,normal_y,normal_z,penetration,penetration_rate,normal_force,friction_x,"
                              "friction_y,friction_z\n";

// +inf is "no value" (min_gap of a scene that checks no strut pair): an empty field
std::string csvNumber(double v)
{
  if (std::isinf(v))
    return v > 0 ? "" : "-inf";
  // what an ostream with setprecision(10) writes (%.10g in the C locale), without forming one per number
  char buf[32];
  const int n = std::snprintf(buf, sizeof buf, "%.10g", v);
  return std::string(buf, static_cast<size_t>(std::max(n, 0)));
}

// A YAML double-quoted scalar: backslashes, quotes and control characters escaped
std::string yamlString(const std::string& text)
{
  std::string out = "\"";
  for (const char c : text)
  {
    if (c == '"' || c == '\\')
      out += std::string("\\") + c;
    else if (c == '\n')
      out += "\\n";
    else if (static_cast<unsigned char>(c) < 0x20)
    {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", static_cast<unsigned char>(c));
      out += buf;
    }
    else
      out += c;
  }
  return out + "\"";
}

// Writes the summary (to its file, or stderr), then the warnings and why the analysis stopped on stderr;
// the exit status: 0, 1 (the summary file could not be written) or 3 (the analysis stopped early)
int finish(const std::string& text, std::ofstream& summary_file, const std::string& summary_path,
           const at::Summary& outcome)
{
  if (summary_file.is_open())
  {
    summary_file << text;
    summary_file.close();
    if (!summary_file)
    {
      std::cerr << "tensegrity_run: cannot write '" << summary_path << "'\n";
      return 1;
    }
  }
  else
    std::cerr << text;
  for (const std::string& w : outcome.warnings)
    std::cerr << "tensegrity_run: warning: " << w << "\n";
  if (!outcome.ok())
  {
    std::cerr << "tensegrity_run: the analysis stopped: " << outcome.message << "\n";
    return 3;
  }
  return 0;
}

// a YAML flow list of numbers
std::string yamlNumbers(const std::vector<double>& values)
{
  std::string out = "[";
  for (size_t i = 0; i < values.size(); ++i)
    out += (i ? ", " : "") + csvNumber(values[i]);
  return out + "]";
}

// a number for YAML: NaN as null
std::string yamlNumber(double v)
{
  return std::isnan(v) ? "null" : csvNumber(v);
}

// The structural diagnostics (core/solvers/structure_check.h) as YAML lines, each indented by `indent`.
std::string structureYaml(const at::StructureReport& r, const std::string& indent)
{
  std::ostringstream y;
  y << indent << "checked: " << (r.checked ? "true" : "false") << "\n";
  if (!r.note.empty())
    y << indent << "note: " << yamlString(r.note) << "\n";
  y << indent << "coordinates: " << r.coordinates << "\n"
    << indent << "members: " << r.members << "\n"
    << indent << "struts: " << r.struts << "\n"
    << indent << "tension_members: " << r.tension_members << "\n";
  if (!r.checked)
    return y.str();
  y << indent << "free_coordinates: " << r.free_coordinates << "\n"
    << indent << "equilibrium_matrix_rank: " << r.rank << "\n"
    << indent << "self_stress_states: " << r.self_stress_states << "\n"
    << indent << "mechanisms: " << r.mechanisms << "\n"
    << indent << "rigid_body_modes: " << r.rigid_body_modes << "\n"
    << indent << "prestress_stable: " << (r.prestress_stable ? "true" : "false") << "\n"
    << indent << "smallest_stiffness_eigenvalue: " << yamlNumber(r.smallest_stiffness_eigenvalue) << "  # N/m\n"
    << indent << "largest_stiffness_eigenvalue: " << yamlNumber(r.largest_stiffness_eigenvalue) << "  # N/m\n"
    << indent << "smallest_rigid_mode_eigenvalue: " << yamlNumber(r.smallest_rigid_mode_eigenvalue) << "  # N/m\n"
    << indent << "equilibrium_residual: " << csvNumber(r.equilibrium_residual) << "  # N\n"
    << indent << "slack_cables: [";
  for (size_t i = 0; i < r.slack_cables.size(); ++i)
    y << (i ? ", " : "") << yamlString(r.slack_cables[i]);
  y << "]\n";
  return y.str();
}

// --check: the diagnostics of the initial state on stdout
int runCheck(const std::string& scene, const at::Model& model)
{
  at::StructureReport r;
  try
  {
    r = at::checkStructure(model, at::initialState(model));
  }
  catch (const std::invalid_argument& e)
  {
    std::cerr << "tensegrity_run: --check: " << e.what() << "\n";
    return 3;
  }
  std::cout << std::setprecision(10) << "scene: " << scene << "\n"
            << "name: " << model.name << "\n"
            << structureYaml(r, "");
  return 0;
}

// A modal scene: the frequencies (csv), the mode shapes (--modes) and the summary.
int runModalScene(const std::string& scene, const at::Model& model, std::ostream& csv, std::ofstream& shapes,
                  std::ofstream& summary_file, const std::string& summary_path)
{
  const at::ModalRun run = at::runModal(model);
  csv << "mode,frequency_hz,omega,eigenvalue\n";
  for (size_t k = 0; k < run.modal.modes.size(); ++k)
  {
    const at::NaturalMode& m = run.modal.modes[k];
    csv << k + 1 << "," << csvNumber(m.frequency_hz) << "," << csvNumber(m.omega) << "," << csvNumber(m.eigenvalue)
        << "\n";
  }
  csv.flush();
  if (shapes.is_open())
  {
    shapes << "mode,node,dx,dy,dz\n";
    for (size_t k = 0; k < run.modal.modes.size(); ++k)
      for (size_t i = 0; i < model.nodes.size(); ++i)
      {
        const at::Vec3& d = run.modal.modes[k].node_displacements[i];
        shapes << k + 1 << "," << model.nodes[i].name << "," << csvNumber(d.x()) << "," << csvNumber(d.y()) << ","
               << csvNumber(d.z()) << "\n";
      }
    shapes.close();
    if (!shapes)
    {
      std::cerr << "tensegrity_run: cannot write the mode shapes\n";
      return 1;
    }
  }
  std::vector<double> lowest;
  for (size_t k = 0; k < std::min<size_t>(10, run.modal.modes.size()); ++k)
    lowest.push_back(run.modal.modes[k].frequency_hz);
  const std::vector<std::string> cols = at::csvColumns(model);
  const std::vector<double> row = at::csvRow(model, run.equilibrium);
  std::ostringstream summary;
  summary << std::setprecision(10) << "scene: " << scene << "\n"
          << "name: " << model.name << "\n"
          << "analysis: modal\n"
          << "status: " << at::toString(run.summary.status) << "\n"
          << "message: " << yamlString(run.summary.message) << "\n"
          << "newton_iterations: " << run.summary.iterations << "\n"
          << "step_cuts: " << run.summary.step_cuts << "\n"
          << "wall_time: " << run.wall_time << "\n"
          << "free_coordinates: " << run.modal.free_coordinates << "\n"
          << "modes: " << run.modal.modes.size() << "\n"
          << "frequencies_hz: " << yamlNumbers(lowest) << "  # the lowest ten\n";
  summary << "warnings:" << (run.summary.warnings.empty() ? " []" : "") << "\n";
  for (const std::string& w : run.summary.warnings)
    summary << "  - " << yamlString(w) << "\n";
  if (run.summary.ok())
    summary << "structure:  # the equilibrium's diagnostics (tensegrity_run --check)\n"
            << structureYaml(run.structure, "  ");
  summary << "equilibrium:\n";
  for (size_t i = 0; i < cols.size(); ++i)
    summary << "  " << cols[i] << ": " << csvNumber(row[i]) << "\n";
  return finish(summary.str(), summary_file, summary_path, run.summary);
}
/// What the command line asks for.
struct Options
{
  std::string scene, out_path, summary_path, contacts_path, nodes_path, members_path, vtk_dir, bag_path, modes_path,
      bag_ns = kDefaultBagNs;
  bool check = false;
  std::vector<at::Override> overrides;
};

/// The command line into o; false when help was asked. Throws (BadArgument, std::invalid_argument, a malformed
/// --set) when it is wrong.
bool parseCommandLine(int argc, char** argv, Options& o)
{
  const auto into = [](std::string& field) { return [&field](const std::string& v) { field = v; }; };
  tools::CommandLine cl;
  cl.value("--set", [&](const std::string& v) { o.overrides.push_back(at::parseOverride(v)); })
      .value("--out", into(o.out_path))
      .value("--summary", into(o.summary_path))
      .value("--contacts", into(o.contacts_path))
      .value("--nodes", into(o.nodes_path))
      .value("--members", into(o.members_path))
      .value("--vtk", into(o.vtk_dir))
      .value("--bag", into(o.bag_path))
      .value("--bag-ns", into(o.bag_ns))
      .value("--modes", into(o.modes_path))
      .flag("--check", [&] { o.check = true; })
      .positional(into(o.scene));
  if (!cl.parse(argc, argv))
    return false;
  if (o.scene.empty())
    throw tools::BadArgument("no scene given");
  if (!o.bag_path.empty())
    active_tensegrity::ros_layer::BagWriter::checkNamespace(o.bag_ns);
  else if (o.bag_ns != kDefaultBagNs)
    throw tools::BadArgument("--bag-ns needs --bag");
  if (o.check && !(o.out_path.empty() && o.summary_path.empty() && o.contacts_path.empty() && o.nodes_path.empty() &&
                   o.members_path.empty() && o.vtk_dir.empty() && o.bag_path.empty() && o.modes_path.empty()))
    throw tools::BadArgument("--check prints its report on stdout and runs no analysis: it takes no --out, "
                             "--summary, --contacts, --nodes, --members, --vtk, --bag or --modes");
  return true;
}

/// The files of a run that is not modal: opened (with their headers) before the run, so that a bad path costs no
/// simulation, and a row for each output state.
class RunFiles
{
public:
  /// Opens every file asked for; false (said on stderr) when one cannot be written.
  bool open(const Options& o, const at::Model& model)
  {
    if (!openFile(o.out_path, file_) || !openFile(o.contacts_path, contacts_) || !openFile(o.nodes_path, nodes_) ||
        !openFile(o.members_path, members_) || !openFile(o.summary_path, summary_))
      return false;
    try
    {
      if (!o.vtk_dir.empty())
        vtk_ = std::make_unique<tools::VtkWriter>(model, o.vtk_dir);
    }
    catch (const std::exception& e)
    {
      std::cerr << "tensegrity_run: --vtk: " << e.what() << "\n";
      return false;
    }
    try
    {
      if (!o.bag_path.empty())
        bag_ = std::make_unique<active_tensegrity::ros_layer::BagWriter>(o.bag_path, model, o.bag_ns);
    }
    catch (const std::exception& e)
    {
      std::cerr << "tensegrity_run: cannot write the bag '" << o.bag_path << "': " << e.what() << "\n";
      return false;
    }
    csv_ = o.out_path.empty() ? &std::cout : &file_;
    if (contacts_.is_open())
      contacts_ << kContactColumns;
    if (nodes_.is_open())
    {
      nodes_ << "t";
      for (const at::Node& n : model.nodes)
        nodes_ << "," << n.name << "_x," << n.name << "_y," << n.name << "_z";
      nodes_ << "\n";
    }
    if (members_.is_open())
      writeRow(members_, at::memberColumns(model));
    writeRow(*csv_, at::csvColumns(model));
    return true;
  }

  /// The rows of an output state in every file.
  void write(const at::Model& model, const at::State& s)
  {
    writeRow(*csv_, at::csvRow(model, s));
    if (bag_)
      bag_->write(s);
    if (vtk_)
    {
      try
      {
        vtk_->write(s);
      }
      catch (const std::exception& e)  // a full disk: said once, the run goes on without VTK files
      {
        std::cerr << "tensegrity_run: --vtk: " << e.what() << " (no more VTK files are written)\n";
        vtk_.reset();
        vtk_failed_ = true;
      }
    }
    if (nodes_.is_open())
    {
      nodes_ << csvNumber(s.t);
      for (const at::Node& n : model.nodes)
      {
        const at::Vec3 p = at::pointPosition(model, n.point, s.q);
        nodes_ << "," << csvNumber(p.x()) << "," << csvNumber(p.y()) << "," << csvNumber(p.z());
      }
      nodes_ << "\n";
    }
    if (members_.is_open())
      writeRow(members_, at::memberRow(model, s));
    if (!contacts_.is_open())
      return;
    for (const at::ContactPairState& c : at::activeContacts(model, s))
    {
      contacts_ << csvNumber(s.t) << "," << at::contactBodyName(model, c.body_a) << ","
                << at::contactBodyName(model, c.body_b);
      for (const at::Vec3* v : { &c.point_a, &c.point_b, &c.normal })
        contacts_ << "," << csvNumber(v->x()) << "," << csvNumber(v->y()) << "," << csvNumber(v->z());
      contacts_ << "," << csvNumber(c.penetration) << "," << csvNumber(c.penetration_rate) << ","
                << csvNumber(c.normal_force);
      for (int k = 0; k < 3; ++k)
        contacts_ << "," << csvNumber(c.friction_on_a(k));
      contacts_ << "\n";
    }
  }

  /// After the run: the CSV flushed, the bag closed and said.
  void close(const std::string& bag_path)
  {
    csv_->flush();
    if (!bag_)
      return;
    bag_->close();
    std::cerr << "tensegrity_run: wrote " << bag_->written() << " states to " << bag_path << "\n";
  }
  std::ofstream& summary()
  {
    return summary_;
  }
  bool vtkFailed() const
  {
    return vtk_failed_;
  }

private:
  static bool openFile(const std::string& path, std::ofstream& f)
  {
    if (path.empty())
      return true;
    f.open(path);
    if (!f)
      std::cerr << "tensegrity_run: cannot write '" << path << "'\n";
    return static_cast<bool>(f);
  }
  template <class Row>
  static void writeRow(std::ostream& out, const Row& row)
  {
    for (size_t i = 0; i < row.size(); ++i)
    {
      out << (i ? "," : "");
      if constexpr (std::is_same_v<typename Row::value_type, double>)
        out << csvNumber(row[i]);
      else
        out << row[i];
    }
    out << "\n";
  }

  std::ofstream file_, contacts_, nodes_, members_, summary_;
  std::ostream* csv_ = &std::cout;
  std::unique_ptr<tools::VtkWriter> vtk_;
  bool vtk_failed_ = false;
  std::unique_ptr<active_tensegrity::ros_layer::BagWriter> bag_;
};

/// The YAML summary of a run that is not modal.
std::string runSummary(const std::string& scene, const at::Model& model, const at::RunResult& result,
                       const std::vector<at::Peak>& peaks)
{
  const at::State& fin = result.final_state;
  const std::vector<std::string> cols = at::csvColumns(model);
  const std::vector<double> final_row = at::csvRow(model, fin);
  const bool dynamic = model.analysis.type == at::AnalysisType::kDynamic;
  std::ostringstream summary;
  summary << std::setprecision(10);
  summary << "scene: " << scene << "\n"
          << "name: " << model.name << "\n"
          << "analysis: " << (model.analysis.type == at::AnalysisType::kStatic ? "static" : "dynamic") << "\n"
          << "status: " << at::toString(result.summary.status) << "\n"
          << "message: " << yamlString(result.summary.message) << "\n"
          << "output_steps: " << result.steps << "\n"
          << "solver_steps: " << result.solver_steps << "\n"
          << "newton_iterations: " << result.summary.iterations << "\n"
          << "step_cuts: " << result.summary.step_cuts << "\n"
          << "wall_time: " << result.wall_time << "\n";
  if (dynamic)
  {
    summary << "duration: " << csvNumber(model.analysis.duration) << "\n";
    if (!model.analysis.duration_note.empty())
      summary << "duration_note: " << yamlString(model.analysis.duration_note) << "\n";
  }
  if (dynamic && result.wall_time > 0.0)
    summary << "real_time_factor: " << fin.t / result.wall_time << "\n";
  if (dynamic && model.solver.adaptive)
  {
    const at::AdaptiveStats& a = result.adaptive;
    summary << "adaptive_steps:  # solver.adaptive: accepted steps, refused ones by cause, step sizes (s)\n"
            << "  accepted: " << a.accepted << "\n"
            << "  rejected_error: " << a.rejected_error << "\n"
            << "  rejected_onset: " << a.rejected_onset << "\n"
            << "  rejected_solver: " << a.rejected_solver << "\n"
            << "  rejected_energy: " << a.rejected_energy << "\n"
            << "  at_min_step: " << a.at_min_step << "\n"
            << "  smallest: " << csvNumber(a.h_min) << "\n"
            << "  largest: " << csvNumber(a.h_max) << "\n";
  }
  if (dynamic)
  {
    // E = kinetic + elastic + gravity; start + actuator_work - damping - contact - numerical = end, each term summed
    // over every accepted step
    const at::EnergyAccount& e = result.energy;
    summary << "energy:  # J over every step: start + actuator_work - damping - contact - numerical = end\n"
            << "  start: {kinetic: " << csvNumber(e.start.kinetic) << ", elastic: " << csvNumber(e.start.elastic)
            << ", gravity: " << csvNumber(e.start.gravity) << ", total: " << csvNumber(e.start.total()) << "}\n"
            << "  end: {kinetic: " << csvNumber(e.now.kinetic) << ", elastic: " << csvNumber(e.now.elastic)
            << ", gravity: " << csvNumber(e.now.gravity) << ", total: " << csvNumber(e.now.total()) << "}\n"
            << "  actuator_work: " << csvNumber(e.actuator_work) << "\n"
            << "  damping_dissipation: " << csvNumber(e.damping_dissipation) << "\n"
            << "  contact_dissipation: " << csvNumber(e.contact_dissipation) << "\n"
            << "  numerical_dissipation: " << csvNumber(e.numerical_dissipation) << "\n"
            << "  largest_step_gain: {value: " << csvNumber(e.largest_step_gain)
            << ", t: " << csvNumber(e.largest_gain_t) << "}\n"
            << "  gaining_steps: " << e.gaining_steps << "\n"
            << "  contact_loss_steps: " << e.contact_loss_steps << "\n"
            << "  contact_unresolved: " << csvNumber(e.contact_unresolved_energy) << "\n";
  }
  summary << "warnings:" << (result.summary.warnings.empty() ? " []" : "") << "\n";
  for (const std::string& w : result.summary.warnings)
    summary << "  - " << yamlString(w) << "\n";
  summary << "time_breakdown:  # wall seconds (share); callbacks = output rows, per-step peaks, writing\n";
  for (const auto& [part, seconds] : at::timeBreakdown(result))
    summary << "  " << part << ": {seconds: " << csvNumber(seconds)
            << ", share: " << csvNumber(result.wall_time > 0.0 ? seconds / result.wall_time : 0.0) << "}\n";
  summary << "final:\n";
  for (size_t i = 0; i < cols.size(); ++i)
    summary << "  " << cols[i] << ": " << csvNumber(final_row[i]) << "\n";
  summary << "peaks:  # largest magnitude over every step, and when (t: time, or path parameter in statics)\n";
  for (const at::Peak& p : peaks)
    summary << "  " << p.name << ": {value: " << csvNumber(p.value) << ", t: " << csvNumber(p.t) << "}\n";
  return summary.str();
}

/// Progress on stderr, at most every two seconds of wall time; end() ends its line once any was written.
class Progress
{
public:
  void operator()(double fraction)
  {
    const auto now = std::chrono::steady_clock::now();
    if (std::chrono::duration<double>(now - last_).count() < 2.0)
      return;
    last_ = now;
    reported_ = true;
    std::fprintf(stderr, "\rtensegrity_run: %5.1f %%  (%.0f s wall)", 100.0 * fraction,
                 std::chrono::duration<double>(now - start_).count());
  }
  void end() const
  {
    if (reported_)
      std::fprintf(stderr, "\n");
  }

private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now(), last_ = start_;
  bool reported_ = false;
};
}  // namespace

int main(int argc, char** argv)
{
  Options o;
  try
  {
    if (!parseCommandLine(argc, argv, o))
    {
      std::cout << kUsage;
      return 0;
    }
  }
  catch (const std::exception& e)  // BadArgument, a missing value, a malformed --set
  {
    std::cerr << "tensegrity_run: " << e.what() << "\n" << kUsage;
    return 2;
  }
  at::Model model;
  try
  {
    model = at::loadScene(o.scene, o.overrides);
  }
  catch (const at::SceneError& e)
  {
    std::cerr << "tensegrity_run: scene refused: " << e.what() << "\n";
    return 1;
  }
  if (o.check)
    return runCheck(o.scene, model);
  if (model.analysis.type == at::AnalysisType::kModal)
  {
    if (!(o.contacts_path.empty() && o.nodes_path.empty() && o.members_path.empty() && o.vtk_dir.empty() &&
          o.bag_path.empty()))
    {
      std::cerr << "tensegrity_run: a modal analysis writes no --contacts, --nodes, --members, --vtk or --bag (its "
                   "mode shapes: --modes)\n"
                << kUsage;
      return 2;
    }
    std::ofstream file, summary_file, shapes;
    for (const auto& [path, f] : { std::pair{ &o.out_path, &file }, std::pair{ &o.summary_path, &summary_file },
                                   std::pair{ &o.modes_path, &shapes } })
      if (!path->empty() && !(f->open(*path), *f))
      {
        std::cerr << "tensegrity_run: cannot write '" << *path << "'\n";
        return 1;
      }
    return runModalScene(o.scene, model, o.out_path.empty() ? std::cout : file, shapes, summary_file, o.summary_path);
  }
  if (!o.modes_path.empty())
  {
    std::cerr << "tensegrity_run: --modes writes the mode shapes of a modal analysis (analysis.type: modal)\n"
              << kUsage;
    return 2;
  }
  RunFiles files;
  if (!files.open(o, model))
    return 1;
  // peaks over every time step (or load step), not only the output steps; the first output row is the start, whose
  // values count for the peaks too
  at::PeakTracker peaks(model);
  bool started = false;
  Progress progress;
  const at::RunResult result = at::runAnalysis(
      model,
      [&](const at::State& s)
      {
        if (!started)
          peaks.add(s);
        started = true;
        files.write(model, s);
      },
      std::ref(progress),
      [&](const at::State& s, const std::vector<at::ContactPairState>* contacts) { peaks.add(s, contacts); });
  progress.end();
  files.close(o.bag_path);
  const int code =
      finish(runSummary(o.scene, model, result, peaks.peaks()), files.summary(), o.summary_path, result.summary);
  return code == 0 && files.vtkFailed() ? 1 : code;
}
