// tensegrity_generate: writes the scene of a standard structure (design/generators.h, lattice.h), ready to run.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/design/generators.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/base/text.h"
#include "cli.h"
#include "lattice.h"

namespace at = active_tensegrity::core;
namespace design = active_tensegrity::design;
namespace tools = active_tensegrity::tools;

namespace
{
const char* kUsage =
    "usage: tensegrity_generate STRUCTURE [options] [--out FILE.yaml]\n"
    "  Writes the scene of a standard structure (stdout without --out); every scene loads as it is.\n"
    "  Lengths (R, H, r, L, P, W) lie in [0.001, 1000] m, prestresses (T) in [0.001, 1e6] N.\n"
    "  prism --struts N [--radius R] [--height H] [--twist DEG] [--prestress T] [--strut-radius r]\n"
    "        [--pinned [--driven]]\n"
    "      class-1 prism of N (3..64) struts, rings of radius R (0.5 m) H (0.8 m) apart; at the form's twist\n"
    "      -(90 + 180/N) deg unless --twist is given (-360..360; then a start for tensegrity_formfind); ring\n"
    "      cables at T N (100), verticals and struts at the form's prestress; struts of radius r (0.012 m);\n"
    "      --pinned fixes the bottom nodes; --driven adds the actuator press, which pushes the top nodes down\n"
    "      (a static fold to 0.3 H with contact between the struts)\n"
    "  octahedron [--strut-length L] [--prestress T] [--pinned]\n"
    "      expanded octahedron of six struts of L (1 m), its 24 cables at T N (100); --pinned fixes three\n"
    "      nodes of its lowest cable triangle\n"
    "  quadruplex-lattice --cells AxB [--pitch P] [--height H] [--top-radius R] [--strut-radius r]\n"
    "      A x B quadruplex cells (4 struts each; at most 8000 cells) on the ground, P (1 m) apart, top nodes\n"
    "      on circles of R (0.3 m, below P/2) at H (0.5 m); bracing cables pulled in by 0.4 m, or by 0.8 of\n"
    "      their rest length when that is less (a dynamic fold with contact)\n"
    "  tower --stages K [--width W]\n"
    "      clustered quadruplex tower of K (1..30) stages of W/2 (W = 1 m), four sliding cables folding it\n"
    "  -h, --help (anywhere) prints this.\n"
    "  Exit status: 0 written, 1 cannot write, 2 bad arguments.\n";

/// `--help` or `-h` among a structure's options.
struct HelpRequested
{
};

/// A number in [lo, hi] (unit) for `option`, else BadArgument naming the option, the range and the value.
double bounded(const std::string& option, const std::string& text, double lo, double hi, const std::string& unit)
{
  const double v = tools::parsePositive<double>(option, text);
  if (v < lo || v > hi)
    throw tools::BadArgument(option + ": must lie in [" + at::shortestNumber(lo) + ", " + at::shortestNumber(hi) +
                             "] " + unit + ", got '" + text + "'");
  return v;
}

/// Takes a length (m) or a prestress (N) within the generators' bounds into `field`.
tools::CommandLine::Take length(const std::string& option, double& field)
{
  return [&field, option](const std::string& v)
  { field = bounded(option, v, design::kMinGeneratedLength, design::kMaxGeneratedLength, "m"); };
}
tools::CommandLine::Take prestress(const std::string& option, double& field)
{
  return [&field, option](const std::string& v)
  { field = bounded(option, v, design::kMinGeneratedPrestress, design::kMaxGeneratedPrestress, "N"); };
}

// at most this many lattice cells (4 struts each): the most struts whose pairs the loader numbers (auto pairs,
// Model::kMostAutoPairStruts)
constexpr int kMaxLatticeCells = at::Model::kMostAutoPairStruts / 4;

/// The options of one structure: its own, then --out; no positional argument. Help among them: HelpRequested.
void parseStructure(tools::CommandLine& cl, tools::Args& args, std::string& out_path)
{
  cl.value("--out", [&](const std::string& v) { out_path = v; });
  if (!cl.parse(args))
    throw HelpRequested{};
}

std::string generate(const std::string& structure, tools::Args& args, std::string& out_path)
{
  tools::CommandLine cl("argument", structure + ": ", " (tensegrity_generate --help)");
  if (structure == "prism")
  {
    design::PrismSpec s;
    bool struts = false;
    cl.value("--struts",
             [&](const std::string& v)
             {
               s.struts = tools::parsePositive<int>("--struts", v);
               struts = true;
             })
        .value("--radius", length("--radius", s.radius))
        .value("--height", length("--height", s.height))
        .value("--twist",
               [&](const std::string& v)
               {
                 size_t used = 0;
                 try
                 {
                   s.twist = std::stod(v, &used) * M_PI / 180.0;
                 }
                 catch (const std::exception&)
                 {
                   used = 0;
                 }
                 if (used != v.size() || v.empty() || !std::isfinite(s.twist))
                   throw tools::BadArgument("--twist: expected an angle in degrees, got '" + v + "'");
                 if (std::abs(std::stod(v)) > design::kMaxGeneratedTwist)
                   throw tools::BadArgument("--twist: must lie in [" + at::shortestNumber(-design::kMaxGeneratedTwist) +
                                            ", " + at::shortestNumber(design::kMaxGeneratedTwist) + "] degrees, got '" +
                                            v + "'");
               })
        .value("--prestress", prestress("--prestress", s.ring_prestress))
        .flag("--pinned", [&] { s.pinned = true; })
        .flag("--driven", [&] { s.driven = true; })
        .value("--strut-radius", length("--strut-radius", s.strut_radius));
    parseStructure(cl, args, out_path);
    if (s.driven && !s.pinned)
      throw tools::BadArgument("prism: --driven needs --pinned (the top nodes are pressed against the base)");
    if (!struts)
      throw tools::BadArgument("prism: --struts N is required");
    if (s.struts < 3 || s.struts > 64)
      throw tools::BadArgument("--struts: a prism has 3 to 64 struts, got '" + std::to_string(s.struts) + "'");
    return design::prismScene(s);
  }
  if (structure == "octahedron")
  {
    design::OctahedronSpec s;
    cl.value("--strut-length", length("--strut-length", s.strut_length))
        .value("--prestress", prestress("--prestress", s.prestress))
        .flag("--pinned", [&] { s.pinned = true; });
    parseStructure(cl, args, out_path);
    return design::octahedronScene(s);
  }
  if (structure == "quadruplex-lattice")
  {
    tools::LatticeOptions o;
    bool cells = false, top_radius_given = false;
    cl.value("--cells",
             [&](const std::string& v)
             {
               const size_t x = v.find('x');
               if (x == std::string::npos)
                 throw tools::BadArgument("--cells: expected AxB (e.g. 2x3), got '" + v + "'");
               o.nx = tools::parsePositive<int>("--cells", v.substr(0, x));
               o.ny = tools::parsePositive<int>("--cells", v.substr(x + 1));
               if (static_cast<long>(o.nx) * o.ny > kMaxLatticeCells)
                 throw tools::BadArgument("--cells: at most " + std::to_string(kMaxLatticeCells) +
                                          " cells (e.g. 80x100), got '" + v + "'");
               cells = true;
             })
        .value("--pitch", length("--pitch", o.pitch))
        .value("--height", length("--height", o.height))
        .value("--top-radius",
               [&, take = length("--top-radius", o.top_radius)](const std::string& v)
               {
                 take(v);
                 top_radius_given = true;
               })
        .value("--strut-radius", length("--strut-radius", o.strut_radius));
    parseStructure(cl, args, out_path);
    if (!cells)
      throw tools::BadArgument("quadruplex-lattice: --cells AxB is required");
    if (!(o.top_radius < o.pitch / 2.0))
      throw tools::BadArgument("--top-radius: must be below half the pitch (" + at::shortestNumber(o.pitch / 2.0) +
                               " m), got '" + at::shortestNumber(o.top_radius) + "'" +
                               (top_radius_given ? "" : " (its default; give --top-radius)"));
    // the bracings' pull-in leaves them a fifth of their rest length at least (lattice.cpp: prestress 400 N/m
    // times the length, EA 2463 N)
    const double h = o.pitch / 2.0;
    const double bracing = std::sqrt((h - o.top_radius) * (h - o.top_radius) + h * h + o.height * o.height);
    o.max_actuation = std::min(o.max_actuation, 0.8 * bracing / (1.0 + 400.0 * bracing / 2463.0));
    return tools::quadruplexLatticeYaml(o);
  }
  if (structure == "tower")
  {
    design::TowerSpec s;
    bool stages = false;
    cl.value("--stages",
             [&](const std::string& v)
             {
               s.stages = tools::parsePositive<int>("--stages", v);
               stages = true;
             })
        .value("--width", length("--width", s.width));
    parseStructure(cl, args, out_path);
    if (!stages)
      throw tools::BadArgument("tower: --stages K is required");
    if (s.stages > design::kMaxTowerStages)
      throw tools::BadArgument("--stages: a tower has 1 to " + std::to_string(design::kMaxTowerStages) +
                               " stages (its sliding cables run through every level and end at a driven body: " +
                               "at most 32 nodes), got '" + std::to_string(s.stages) + "'");
    return design::towerScene(s);
  }
  throw tools::BadArgument("unknown structure '" + structure + "' (prism, octahedron, quadruplex-lattice, tower)");
}

}  // namespace

int main(int argc, char** argv)
{
  std::string out_path, yaml;
  try
  {
    tools::Args args(std::vector<std::string>(argv + 1, argv + argc));
    if (!args.more())
      throw tools::BadArgument("no structure given");
    const std::string structure = args.option();
    if (structure == "-h" || structure == "--help")
    {
      std::cout << kUsage;
      return 0;
    }
    yaml = generate(structure, args, out_path);
  }
  catch (const HelpRequested&)
  {
    std::cout << kUsage;
    return 0;
  }
  catch (const std::exception& e)  // BadArgument, a missing value, a generator's refusal
  {
    std::cerr << "tensegrity_generate: " << e.what() << "\n" << kUsage;
    return 2;
  }
  // every generated scene must load: a refusal here is a defect of the generator, said as such
  try
  {
    at::loadSceneFromString(yaml, "generated scene");
  }
  catch (const at::SceneError& e)
  {
    std::cerr << "tensegrity_generate: the generated scene does not load (a defect): " << e.what() << "\n";
    return 1;
  }
  if (out_path.empty() || out_path == "-")
  {
    std::cout << yaml;
    return 0;
  }
  std::ofstream out(out_path);
  if (!(out << yaml) || (out.close(), !out))
  {
    std::cerr << "tensegrity_generate: cannot write '" << out_path << "'\n";
    return 1;
  }
  return 0;
}
