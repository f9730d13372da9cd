// tensegrity_bench: the usage and the dispatch to the subcommands, one file each in this folder (bench.h).
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/core/scene/scene.h"
#include "../cli.h"
#include "bench.h"

namespace at = active_tensegrity::core;
namespace bench = active_tensegrity::tools::bench;
namespace tools = active_tensegrity::tools;

namespace
{
/// The usage, one section per subcommand (`tensegrity_bench SUBCOMMAND --help` prints its own).
struct Section
{
  const char* command;
  const char* text;
};
const Section kSections[] = {
  { "steps", "       tensegrity_bench steps SCENE.yaml [--set key=value]... [--repeat N] [--peaks]\n"
             "  Runs the scene's analysis N times (default 5) and prints wall time and Newton iterations per step\n"
             "  and where the time goes; --peaks also tracks the summary's peaks after every step (as\n"
             "  tensegrity_run does).\n" },
  { "contact-pair", "       tensegrity_bench contact-pair [--repeat N]\n"
                    "  Times one strut pair's contact evaluation (dynamic with friction, with and without tangents;\n"
                    "  static): ns per call, median over N (default 5) loops of 100000 calls.\n" },
  { "broad-phase",
    "       tensegrity_bench broad-phase [--repeat N]\n"
    "  Random scenes of 10 to 1000 struts with all pairs checked: candidates and the time of the broad\n"
    "  phase (sweep and direct) and of the narrow phase over the candidates, median over N (default 5).\n" },
  { "plan",
    "       tensegrity_bench plan SCENE.yaml --actuators a,b,.. (--height H | --values v,..) [--set key=value]...\n"
    "                        [--clearance M] [--contact-limit N] [--bending-limit PA] [--speed V] [--accel A]\n"
    "                        [--planner NAME|all] [--time-limit S] [--seeds K] [--start v,..] [--verify]\n"
    "                        [--blend M] [--settle-time S] [--step M] [--speed-limit]\n"
    "  Plans from the scene's start equilibrium (--start: from the equilibrium reached by continuation with\n"
    "  the actuators at these values) with seeds 1..K (default 5; --step: the continuation increment, default\n"
    "  0.02 m): status, planning time, equilibrium\n"
    "  solves, figures per seed, the median time and the peak memory; --planner all: every planner once with\n"
    "  its overrun of the time limit; --contact-limit allows contact up to N newtons (else --clearance,\n"
    "  default 0.005 m); --speed-limit (seed 1) finds the time scale that keeps the dynamic contact force,\n"
    "  bending stress and gap within the limits and prints the resulting largest speed; the time limit\n"
    "  covers the verification too (raise it for dynamic runs).\n" },
  { "work-precision",
    "       tensegrity_bench work-precision SCENE.yaml [--set key=value]... [--dts a,b,..] [--tols a,b,..]\n"
    "                        [--schemes a,b,..] [--ref-dt R] [--csv FILE]\n"
    "  Integrators (newmark_paper, trapezoidal, generalized_alpha, newmark_paper_modified_newton over the\n"
    "  steps, default 1e-3,5e-4,2e-4,1e-4 s; adaptive_newmark_paper, adaptive_generalized_alpha over the\n"
    "  error tolerances, default 1e-3,1e-4,1e-5,1e-6 m) against a reference at R (default 2.5e-5 s):\n"
    "  errors and wall time per run (CSV to FILE or stdout). natural_generalized_alpha and\n"
    "  adaptive_natural_generalized_alpha (natural coordinates) run only when named in --schemes.\n"
    "                        [--mujoco-dts a,b,..] [--mujoco-integrators euler,implicit,rk4]\n"
    "                        [--mujoco-contact-force F]\n"
    "  --mujoco-dts adds the scene in MuJoCo over that ladder (rows mujoco_<integrator>; contact\n"
    "  stiffness from F, default the reference's peak force; only when built with MuJoCo).\n"
    "                        [--paths FILE]\n"
    "  --paths writes each run's path: the bodies' mass centre per output step (scheme,dt,t,x,y,z).\n" },
  { "natural",
    "       tensegrity_bench natural SCENE.yaml [--set key=value]... [--dts a,b,..] [--tols a,b,..] [--ref-dt R]\n"
    "                        [--repeat N] [--csv FILE] [--no-spin] [--fixed-only]\n"
    "  The dynamic analysis in body coordinates and in natural (nodal) coordinates, fixed steps (default\n"
    "  4e-4,2e-4,1e-4 s) and adaptive (tolerances 1e-4,1e-5,1e-6 m), against a fine reference of each at R\n"
    "  (default 2.5e-5 s): steps, Newton iterations, least wall time of N (default 3), errors, and the time\n"
    "  ratio at equal error; --no-spin: the natural coordinates without the struts' spin rates;\n"
    "  --fixed-only: no adaptive runs. A static scene: its path of equilibria in both, the least wall time\n"
    "  of N and the largest strut-centre difference over the path.\n" },
  { "stress", "       tensegrity_bench stress [--quick] [--case TEXT]... [--skip TEXT]...\n"
              "  The stability stress cases (docs/benchmarks.md): one row per case; --quick runs the short ones;\n"
              "  --case runs only the cases whose name contains one of the TEXTs, --skip leaves out those that do.\n" },
  { "lattice",
    "       tensegrity_bench lattice [--struts a,b,..] [--width W] [--max-struts N] [--duration S] [--repeat N]\n"
    "                        [--pairs all|auto|near] [--csv FILE] [--set key=value]... [--print-scene]\n"
    "  Quadruplex-cell lattices (default about 10, 20, 50, 100, 200, 500 struts) run dynamically into contact:\n"
    "  us per step (median over N runs, default 3), its breakdown, sizes, and the fitted exponent vs struts;\n"
    "  pairs: auto (default: every pair sharing no node), all (the same pairs listed), near (same or adjacent cells);\n"
    "  --width W: strips W cells across instead of nearly square lattices; --print-scene prints the scenes (YAML).\n" },
};

std::string usage()
{
  std::string text;
  for (const Section& s : kSections)
    text += s.text;
  return "usage: " + text.substr(7) +
         "  -h, --help: this text; tensegrity_bench SUBCOMMAND --help: the subcommand's part of it.\n";
}

/// The section of `command` ("" when there is none), as a usage line of its own.
std::string usage(const std::string& command)
{
  for (const Section& s : kSections)
    if (command == s.command)
      return "usage: " + std::string(s.text).substr(7);
  return "";
}

bool isHelp(const std::string& arg)
{
  return arg == "-h" || arg == "--help";
}

}  // namespace

int main(int argc, char** argv)
{
  const std::string command = argc >= 2 ? argv[1] : "";
  if (isHelp(command))
  {
    std::cout << usage();
    return 0;
  }
  // SUBCOMMAND ... --help: its part of the usage (before any argument is parsed or a scene read)
  for (int i = 2; i < argc; ++i)
    if (isHelp(argv[i]) && !usage(command).empty())
    {
      std::cout << usage(command);
      return 0;
    }
  if (command == "lattice")
    return bench::lattice(std::vector<std::string>(argv + 2, argv + argc));
  const bool needs_scene =
      command == "steps" || command == "plan" || command == "work-precision" || command == "natural";
  if (usage(command).empty())
  {
    std::cerr << (command.empty() ? "" : "tensegrity_bench: unknown command '" + command + "'\n") << usage();
    return 2;
  }
  if (needs_scene && argc < 3)
  {
    std::cerr << "tensegrity_bench: " << command << ": no scene given\n" << usage(command);
    return 2;
  }
  std::vector<at::Override> overrides;
  int repeat = 5;
  bool peaks = false;
  const std::string scene = needs_scene ? argv[2] : "";
  try
  {
    if (command == "plan")
      return bench::plan(scene, std::vector<std::string>(argv + 3, argv + argc));
    if (command == "work-precision")
      return bench::workPrecision(scene, std::vector<std::string>(argv + 3, argv + argc));
    if (command == "natural")
      return bench::natural(scene, std::vector<std::string>(argv + 3, argv + argc));
    if (command == "stress")
    {
      bench::StressSelection select;
      for (int i = 2; i < argc; ++i)
      {
        const std::string a = argv[i];
        if (a == "--quick" && !select.quick_only)
          select.quick_only = true;
        else if ((a == "--case" || a == "--skip") && i + 1 < argc && argv[i + 1][0] != '\0')
          (a == "--case" ? select.cases : select.skipped).emplace_back(argv[++i]);
        else
        {
          const char* what = a == "--case" || a == "--skip" ? "missing or empty text after" :
                             a == "--quick"                 ? "repeated argument" :
                                                              "unknown argument";
          std::cerr << "tensegrity_bench: " << what << " '" << a << "'\n" << usage(command);
          return 2;
        }
      }
      return bench::stress(select);
    }
    for (int i = needs_scene ? 3 : 2; i < argc; ++i)
    {
      const std::string arg = argv[i];
      if (needs_scene && arg == "--set" && i + 1 < argc)
        overrides.push_back(at::parseOverride(argv[++i]));
      else if (needs_scene && arg == "--peaks")
        peaks = true;
      else if (arg == "--repeat" && i + 1 < argc)
        repeat = tools::parsePositive<int>("--repeat", argv[++i]);
      else
      {
        std::cerr << "tensegrity_bench: unknown argument '" << arg << "'\n" << usage(command);
        return 2;
      }
    }
    if (command == "contact-pair")
      return bench::contactPair(repeat);
    if (command == "broad-phase")
      return bench::broadPhase(repeat);
    return bench::steps(scene, overrides, repeat, peaks);
  }
  catch (const tools::BadArgument& e)
  {
    std::cerr << "tensegrity_bench: " << e.what() << "\n";
    return 2;
  }
  catch (const std::exception& e)
  {
    std::cerr << "tensegrity_bench: " << e.what() << "\n";
    return 1;
  }
}
