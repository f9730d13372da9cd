// tensegrity_run: runs a scene's analysis without a ROS master and writes CSV rows and a summary.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <memory>
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
#include "active_tensegrity/core/outputs/vtk_writer.h"
#include "active_tensegrity/ros/bag_writer.h"

namespace at = active_tensegrity::core;

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
}  // namespace

int main(int argc, char** argv)
{
  std::string scene, out_path, summary_path, contacts_path, nodes_path, members_path, vtk_dir, bag_path, modes_path,
      bag_ns = kDefaultBagNs;
  bool check = false;
  std::vector<at::Override> overrides;
  try
  {
    for (int i = 1; i < argc; ++i)
    {
      const std::string arg = argv[i];
      auto value = [&](const char* name) -> std::string
      {
        if (i + 1 >= argc)
          throw std::invalid_argument(std::string(name) + " needs a value");
        // (an empty name opened nothing and wrote nothing, and the run said nothing of it)
        if (argv[i + 1][0] == '\0')
          throw std::invalid_argument(std::string(name) + " needs a value, got an empty one ('')");
        return argv[++i];
      };
      if (arg == "-h" || arg == "--help")
      {
        std::cout << kUsage;
        return 0;
      }
      if (arg == "--set")
        overrides.push_back(at::parseOverride(value("--set")));
      else if (arg == "--out")
        out_path = value("--out");
      else if (arg == "--summary")
        summary_path = value("--summary");
      else if (arg == "--contacts")
        contacts_path = value("--contacts");
      else if (arg == "--nodes")
        nodes_path = value("--nodes");
      else if (arg == "--members")
        members_path = value("--members");
      else if (arg == "--vtk")
        vtk_dir = value("--vtk");
      else if (arg == "--bag")
        bag_path = value("--bag");
      else if (arg == "--bag-ns")
        bag_ns = value("--bag-ns");
      else if (arg == "--modes")
        modes_path = value("--modes");
      else if (arg == "--check")
        check = true;
      else if (!arg.empty() && arg[0] == '-')
        throw std::invalid_argument("unknown option '" + arg + "'");
      else if (scene.empty())
        scene = arg;
      else
        throw std::invalid_argument("more than one scene given ('" + scene + "' and '" + arg + "')");
    }
    if (scene.empty())
      throw std::invalid_argument("no scene given");
    if (!bag_path.empty())
      active_tensegrity::ros_layer::BagWriter::checkNamespace(bag_ns);
    else if (bag_ns != kDefaultBagNs)
      throw std::invalid_argument("--bag-ns needs --bag");
    if (check && !(out_path.empty() && summary_path.empty() && contacts_path.empty() && nodes_path.empty() &&
                   members_path.empty() && vtk_dir.empty() && bag_path.empty() && modes_path.empty()))
      throw std::invalid_argument("--check prints its report on stdout and runs no analysis: it takes no --out, "
                                  "--summary, --contacts, --nodes, --members, --vtk, --bag or --modes");
  }
  catch (const std::exception& e)
  {
    std::cerr << "tensegrity_run: " << e.what() << "\n" << kUsage;
    return 2;
  }

  at::Model model;
  try
  {
    model = at::loadScene(scene, overrides);
  }
  catch (const at::SceneError& e)
  {
    std::cerr << "tensegrity_run: scene refused: " << e.what() << "\n";
    return 1;
  }

  if (check)
    return runCheck(scene, model);
  const bool modal = model.analysis.type == at::AnalysisType::kModal;
  const char* misfit = nullptr;
  if (modal &&
      !(contacts_path.empty() && nodes_path.empty() && members_path.empty() && vtk_dir.empty() && bag_path.empty()))
    misfit = "a modal analysis writes no --contacts, --nodes, --members, --vtk or --bag (its mode shapes: --modes)";
  else if (!modal && !modes_path.empty())
    misfit = "--modes writes the mode shapes of a modal analysis (analysis.type: modal)";
  if (misfit)
  {
    std::cerr << "tensegrity_run: " << misfit << "\n" << kUsage;
    return 2;
  }

  // output files are opened before the run, so that a bad path costs no simulation
  const auto open = [](const std::string& path, std::ofstream& f)
  {
    if (path.empty())
      return true;
    f.open(path);
    if (!f)
      std::cerr << "tensegrity_run: cannot write '" << path << "'\n";
    return static_cast<bool>(f);
  };
  std::ofstream file, contacts, nodes, members, summary_file, shapes;
  if (!open(out_path, file) || !open(contacts_path, contacts) || !open(nodes_path, nodes) ||
      !open(members_path, members) || !open(summary_path, summary_file) || !open(modes_path, shapes))
    return 1;
  if (modal)
    return runModalScene(scene, model, out_path.empty() ? std::cout : file, shapes, summary_file, summary_path);
  std::unique_ptr<at::VtkWriter> vtk;
  bool vtk_failed = false;
  if (!vtk_dir.empty())
  {
    try
    {
      vtk = std::make_unique<at::VtkWriter>(model, vtk_dir);
    }
    catch (const std::exception& e)
    {
      std::cerr << "tensegrity_run: --vtk: " << e.what() << "\n";
      return 1;
    }
  }
  std::unique_ptr<active_tensegrity::ros_layer::BagWriter> bag;
  if (!bag_path.empty())
  {
    try
    {
      bag = std::make_unique<active_tensegrity::ros_layer::BagWriter>(bag_path, model, bag_ns);
    }
    catch (const std::exception& e)
    {
      std::cerr << "tensegrity_run: cannot write the bag '" << bag_path << "': " << e.what() << "\n";
      return 1;
    }
  }
  std::ostream& csv = out_path.empty() ? std::cout : file;
  if (contacts.is_open())
    contacts << kContactColumns;
  if (nodes.is_open())
  {
    nodes << "t";
    for (const at::Node& n : model.nodes)
      nodes << "," << n.name << "_x," << n.name << "_y," << n.name << "_z";
    nodes << "\n";
  }
  if (members.is_open())
  {
    const std::vector<std::string> member_cols = at::memberColumns(model);
    for (size_t i = 0; i < member_cols.size(); ++i)
      members << (i ? "," : "") << member_cols[i];
    members << "\n";
  }
  const std::vector<std::string> cols = at::csvColumns(model);
  for (size_t i = 0; i < cols.size(); ++i)
    csv << (i ? "," : "") << cols[i];
  csv << "\n";

  // peaks over every time step (or load step), not only the output steps
  at::PeakTracker peaks(model);
  const auto track_peaks = [&](const at::State& s, const std::vector<at::ContactPairState>* contacts)
  { peaks.add(s, contacts); };

  bool started = false;  // the first output row is the start: its values count for the peaks too
  const auto wall_start = std::chrono::steady_clock::now();
  auto last_report = wall_start;
  bool reported = false;
  const at::RunResult result = at::runAnalysis(
      model,
      [&](const at::State& s)
      {
        if (!started)
        {
          peaks.add(s);
          started = true;
        }
        const std::vector<double> row = at::csvRow(model, s);
        for (size_t i = 0; i < row.size(); ++i)
          csv << (i ? "," : "") << csvNumber(row[i]);
        csv << "\n";
        if (bag)
          bag->write(s);
        if (vtk)
        {
          try
          {
            vtk->write(s);
          }
          catch (const std::exception& e)  // a full disk: said once, the run goes on without VTK files
          {
            std::cerr << "tensegrity_run: --vtk: " << e.what() << " (no more VTK files are written)\n";
            vtk.reset();
            vtk_failed = true;
          }
        }
        if (nodes.is_open())
        {
          nodes << csvNumber(s.t);
          for (const at::Node& n : model.nodes)
          {
            const at::Vec3 p = at::pointPosition(model, n.point, s.q);
            nodes << "," << csvNumber(p.x()) << "," << csvNumber(p.y()) << "," << csvNumber(p.z());
          }
          nodes << "\n";
        }
        if (members.is_open())
        {
          const std::vector<double> member_row = at::memberRow(model, s);
          for (size_t i = 0; i < member_row.size(); ++i)
            members << (i ? "," : "") << csvNumber(member_row[i]);
          members << "\n";
        }
        if (!contacts.is_open())
          return;
        for (const at::ContactPairState& c : at::activeContacts(model, s))
        {
          contacts << csvNumber(s.t) << "," << at::contactBodyName(model, c.body_a) << ","
                   << at::contactBodyName(model, c.body_b);
          for (const at::Vec3* v : { &c.point_a, &c.point_b, &c.normal })
            contacts << "," << csvNumber(v->x()) << "," << csvNumber(v->y()) << "," << csvNumber(v->z());
          contacts << "," << csvNumber(c.penetration) << "," << csvNumber(c.penetration_rate) << ","
                   << csvNumber(c.normal_force);
          for (int k = 0; k < 3; ++k)
            contacts << "," << csvNumber(c.friction_on_a(k));
          contacts << "\n";
        }
      },
      [&](double fraction)
      {
        const auto now = std::chrono::steady_clock::now();
        if (std::chrono::duration<double>(now - last_report).count() < 2.0)
          return;
        last_report = now;
        reported = true;
        std::fprintf(stderr, "\rtensegrity_run: %5.1f %%  (%.0f s wall)", 100.0 * fraction,
                     std::chrono::duration<double>(now - wall_start).count());
      },
      track_peaks);
  if (reported)
    std::fprintf(stderr, "\n");
  csv.flush();
  if (bag)
  {
    bag->close();
    std::cerr << "tensegrity_run: wrote " << bag->written() << " states to " << bag_path << "\n";
  }

  const at::State& fin = result.final_state;
  const std::vector<double> final_row = at::csvRow(model, fin);
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
  if (model.analysis.type == at::AnalysisType::kDynamic)
  {
    summary << "duration: " << csvNumber(model.analysis.duration) << "\n";
    if (!model.analysis.duration_note.empty())
      summary << "duration_note: " << yamlString(model.analysis.duration_note) << "\n";
  }
  if (model.analysis.type == at::AnalysisType::kDynamic && result.wall_time > 0.0)
    summary << "real_time_factor: " << fin.t / result.wall_time << "\n";
  if (model.analysis.type == at::AnalysisType::kDynamic && model.solver.adaptive)
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
  if (model.analysis.type == at::AnalysisType::kDynamic)
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
  for (const at::Peak& p : peaks.peaks())
    summary << "  " << p.name << ": {value: " << csvNumber(p.value) << ", t: " << csvNumber(p.t) << "}\n";
  const int code = finish(summary.str(), summary_file, summary_path, result.summary);
  return code == 0 && vtk_failed ? 1 : code;
}
