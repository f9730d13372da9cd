// tensegrity_formfind: finds the self-equilibrated form of a scene (design/form_finding.h) and writes it as a
// loadable scene whose rest lengths give the prestress exactly.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>

#include "active_tensegrity/design/form_finding.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/base/text.h"
#include "cli.h"

namespace at = active_tensegrity::core;
namespace design = active_tensegrity::design;
namespace tools = active_tensegrity::tools;

namespace
{
const char* kUsage =
    "usage: tensegrity_formfind IN.yaml --out OUT.yaml [--mode free|prestress] [--prestress FAMILY=T]...\n"
    "                           [--force-density FAMILY=q]... [--supports fixed|react] [--struts uniform|free]\n"
    "                           [--strut-lengths free|keep] [--tolerance X] [--max-iterations N]\n"
    "  Finds a self-equilibrated form of the scene IN.yaml (its nodes, struts and cable and spring families;\n"
    "  the positions are the start) and writes OUT.yaml ('-': stdout): the scene at the form, each family's\n"
    "  prestress the tension it carries there (rest lengths follow from it). A report goes to stdout (stderr\n"
    "  when OUT is '-').\n"
    "  --mode free        the geometry is found (default): every node that is not fixed moves to where the\n"
    "                     member forces balance; struts share one force density (--struts free: one each),\n"
    "                     families not held carry one free tension each\n"
    "  --mode prestress   the geometry is kept: its states of self-stress, fitted to the --prestress targets\n"
    "  --prestress F=T    family F carries tension T (N): held (free mode) or a target (prestress mode);\n"
    "                     free mode without any holds the first family that has a prestress in the scene\n"
    "  --force-density F=q  free mode: family F has force density q (N/m) held instead of its tension\n"
    "  --supports react   fixed nodes may carry reactions (default fixed: they are in equilibrium too, the\n"
    "                     form is self-equilibrated and the supports carry nothing)\n"
    "  --strut-lengths keep  free mode: every strut keeps its length (the form's scale and height follow)\n"
    "  --tolerance X      force residual relative to the largest member force (default 1e-12)\n"
    "  --max-iterations N Gauss-Newton iterations (default 100)\n"
    "  Exit status: 0 form written, 1 no form (the reason on stderr), 2 bad arguments.\n";

/// "FAMILY=VALUE" with VALUE a positive number.
std::pair<std::string, double> familyValue(const std::string& option, const std::string& text)
{
  const size_t eq = text.find('=');
  if (eq == std::string::npos || eq == 0)
    throw tools::BadArgument(option + ": expected FAMILY=VALUE, got '" + text + "'");
  return { text.substr(0, eq), tools::parsePositive<double>(option + " " + text.substr(0, eq), text.substr(eq + 1)) };
}

std::string choice(const std::string& option, const std::string& value, const char* a, const char* b)
{
  if (value != a && value != b)
    throw tools::BadArgument(option + ": expected " + a + " or " + b + ", got '" + value + "'");
  return value;
}

void report(std::ostream& out, const design::FormFindingResult& r, const design::FormFindingOptions& o)
{
  out << "mode: " << (o.mode == design::FormFindingMode::kFree ? "free" : "prestress") << "\n";
  if (o.mode == design::FormFindingMode::kFree)
    out << "iterations: " << r.iterations << "\n";
  else
    out << "self_stress_states: " << r.self_stress_states << "  # of the given geometry\n";
  out << "residual: " << at::roundedNumber(r.residual, 3) << "  # N, largest force imbalance at a node\n";
  out << "max_move: " << at::roundedNumber(r.max_move, 6) << "  # m, largest node move from the given positions\n";
  if (r.scale != 1.0)
    out << "scale: " << at::roundedNumber(r.scale, 9) << "\n";
  out << "members:  # name: [family, tension N (negative: compression), length m]\n";
  for (const design::FormMember& m : r.members)
    out << "  " << m.name << ": [" << m.family << ", " << at::roundedNumber(m.tension, 9) << ", "
        << at::roundedNumber(m.length, 9) << "]\n";
  if (!r.changes.empty())
  {
    out << "changes:  # of the scene's layout, made by the form\n";
    for (const std::string& c : r.changes)
      out << "  - \"" << c << "\"\n";
  }
  if (!r.notes.empty())
  {
    out << "notes:\n";
    for (const std::string& n : r.notes)
      out << "  - \"" << n << "\"\n";
  }
  const design::FormCheck& c = r.check;
  out << "check:  # the written scene, loaded (tensegrity_run OUT.yaml --check)\n";
  out << "  checked: " << (c.checked ? "true" : "false") << "\n";
  if (c.checked)
  {
    out << "  equilibrium_residual: " << at::roundedNumber(c.equilibrium_residual, 3) << "\n";
    out << "  prestress_stable: " << (c.prestress_stable ? "true" : "false") << "\n";
    out << "  self_stress_states: " << c.self_stress_states << "\n";
    out << "  mechanisms: " << c.mechanisms << "\n";
    out << "  slack_cables: " << c.slack_cables.size() << "\n";
  }
  out << "  overlapping_struts: " << c.overlapping.size() << "\n";
  if (c.newton_converged || c.newton_move > 0.0)
    out << "  static_solve: {converged: " << (c.newton_converged ? "true" : "false")
        << ", largest_move: " << at::roundedNumber(c.newton_move, 3) << "}  # m, from the form at zero actuation\n";
}

}  // namespace

int main(int argc, char** argv)
{
  std::string in_path, out_path;
  design::FormFindingOptions o;
  try
  {
    tools::CommandLine cl;
    cl.value("--out", [&](const std::string& v) { out_path = v; })
        .value("--mode",
               [&](const std::string& v)
               {
                 o.mode = choice("--mode", v, "free", "prestress") == "free" ? design::FormFindingMode::kFree :
                                                                               design::FormFindingMode::kPrestress;
               })
        .value("--supports",
               [&](const std::string& v) { o.supports_react = choice("--supports", v, "fixed", "react") == "react"; })
        .value("--struts",
               [&](const std::string& v) { o.uniform_struts = choice("--struts", v, "uniform", "free") == "uniform"; })
        .value("--strut-lengths", [&](const std::string& v)
               { o.keep_strut_lengths = choice("--strut-lengths", v, "free", "keep") == "keep"; })
        .value("--tolerance",
               [&](const std::string& v)
               {
                 o.tolerance = tools::parsePositive<double>("--tolerance", v);
                 if (o.tolerance >= 1e-3)
                   throw tools::BadArgument("--tolerance: expected a relative tolerance below 1e-3, got '" +
                                            at::shortestNumber(o.tolerance) + "'");
               })
        .value("--max-iterations",
               [&](const std::string& v)
               {
                 o.max_iterations = tools::parsePositive<int>("--max-iterations", v);
                 if (o.max_iterations > 10000)
                   throw tools::BadArgument("--max-iterations: at most 10000, got '" +
                                            std::to_string(o.max_iterations) + "'");
               })
        .positional([&](const std::string& v) { in_path = v; }, 1, true);
    for (const std::string option : { "--prestress", "--force-density" })
      cl.value(option,
               [&o, option](const std::string& v)
               {
                 const auto [family, value] = familyValue(option, v);
                 auto& map = option == "--prestress" ? o.tension : o.force_density;
                 if (!map.emplace(family, value).second)
                   throw tools::BadArgument(option + ": family '" + family + "' given twice");
               });
    if (!cl.parse(argc, argv))
    {
      std::cout << kUsage;
      return 0;
    }
    if (in_path.empty())
      throw tools::BadArgument("no scene given");
    if (out_path.empty())
      throw tools::BadArgument("no --out given (a file, or '-' for stdout)");
  }
  catch (const std::exception& e)
  {
    std::cerr << "tensegrity_formfind: " << e.what() << "\n" << kUsage;
    return 2;
  }

  std::string text;
  try
  {
    text = at::readSceneFile(in_path);  // a regular file of bounded size (not /dev/zero)
  }
  catch (const at::SceneError& e)
  {
    std::cerr << "tensegrity_formfind: cannot read '" << in_path << "': " << e.what() << "\n";
    return 1;
  }
  // the output is opened before the work, so that a bad path costs nothing; a file made for the check is
  // removed again when no form is written
  std::ofstream out_file;
  bool made = false;
  if (out_path != "-")
  {
    made = !std::ifstream(out_path).good();
    out_file.open(out_path, std::ios::app);
    if (!out_file)
    {
      std::cerr << "tensegrity_formfind: cannot write '" << out_path << "'\n";
      return 1;
    }
    out_file.close();
  }
  const auto fail = [&](const std::string& message)
  {
    if (made)
      std::remove(out_path.c_str());
    std::cerr << "tensegrity_formfind: " << message << "\n";
    return 1;
  };
  design::FormFindingResult r;
  try
  {
    r = design::findForm(text, in_path, o);
  }
  catch (const at::SceneError& e)
  {
    return fail(std::string("scene refused: ") + e.what());
  }
  catch (const design::FormFindingError& e)
  {
    return fail(std::string("no form: ") + e.what());
  }
  catch (const std::exception& e)  // nothing else is expected: said, never a crash
  {
    return fail(std::string("form-finding failed: ") + e.what());
  }
  std::ostream& log = out_path == "-" ? std::cerr : std::cout;
  if (out_path == "-")
    std::cout << r.scene;
  else
  {
    out_file.open(out_path, std::ios::trunc);
    if (!(out_file << r.scene) || (out_file.close(), !out_file))
    {
      std::cerr << "tensegrity_formfind: cannot write '" << out_path << "'\n";
      return 1;
    }
  }
  report(log, r, o);
  for (const std::string& c : r.changes)
    std::cerr << "tensegrity_formfind: warning: form-finding changed the " << c << "\n";
  if (!r.check.overlapping.empty())
    std::cerr << "tensegrity_formfind: warning: struts overlap in the form: " << r.check.overlapping.front()
              << (r.check.overlapping.size() > 1 ? " ..." : "") << "\n";
  if (r.check.checked && !r.check.prestress_stable)
    std::cerr << "tensegrity_formfind: warning: the form is not prestress stable (tensegrity_run " << out_path
              << " --check)\n";
  return 0;
}
