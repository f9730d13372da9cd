// tensegrity_export: a scene in another program's format. --mjcf: MuJoCo's MJCF, the translation
// tensegrity_bench runs side by side with ours (mujoco_peer.h).
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "active_tensegrity/core/scene/scene.h"
#include "cli.h"
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
#include "mujoco_peer.h"
#endif

namespace at = active_tensegrity::core;
namespace tools = active_tensegrity::tools;

namespace
{
const char* kUsage =
    "usage: tensegrity_export SCENE.yaml [--set key=value]... --mjcf OUT.xml [--timestep S]\n"
    "                         [--integrator euler|implicit|rk4]\n"
    "  --mjcf writes the scene's MuJoCo translation (struts as capsules on free joints with the scene's\n"
    "  masses and inertias, pins and ball joints as equality connects, cables and springs as spatial\n"
    "  tendons with motor actuators, checked strut pairs as contact pairs with the linear law of the\n"
    "  translation), as MuJoCo compiled it: MuJoCo must accept it. The cable tensions and the drives are\n"
    "  set outside MuJoCo at every step (the file's comment says how); --timestep (default 1e-3 s) and\n"
    "  --integrator (default euler) go into its <option>.\n"
    "  Exit status: 0 written, 1 refused (the scene, the translation or the file), 2 bad arguments.\n";
}  // namespace

int main(int argc, char** argv)
{
  std::string scene, mjcf_path;
  std::vector<at::Override> overrides;
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
  tools::MujocoOptions options;
#endif
  try
  {
    const auto into = [](std::string& field) { return [&field](const std::string& v) { field = v; }; };
    tools::CommandLine cl;
    cl.value("--set", [&](const std::string& v) { overrides.push_back(at::parseOverride(v)); })
        .value("--mjcf", into(mjcf_path))
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
        .value("--timestep",
               [&](const std::string& v) { options.timestep = tools::parsePositive<double>("--timestep", v); })
        .value("--integrator",
               [&](const std::string& v)
               {
                 try
                 {
                   options.integrator = tools::parseMujocoIntegrator(v);
                 }
                 catch (const std::invalid_argument&)
                 {
                   throw tools::BadArgument("--integrator: expected euler, implicit or rk4, got '" + v + "'");
                 }
               })
#else
        .value("--timestep", [](const std::string&) {})
        .value("--integrator", [](const std::string&) {})
#endif
        .positional(into(scene));
    if (!cl.parse(argc, argv))
    {
      std::cout << kUsage;
      return 0;
    }
    if (scene.empty())
      throw tools::BadArgument("no scene given");
    if (mjcf_path.empty())
      throw tools::BadArgument("no format given (--mjcf OUT.xml)");
  }
  catch (const std::exception& e)  // BadArgument, a missing value, a malformed --set
  {
    std::cerr << "tensegrity_export: " << e.what() << "\n" << kUsage;
    return 2;
  }
  at::Model model;
  try
  {
    model = at::loadScene(scene, overrides);
  }
  catch (const at::SceneError& e)
  {
    std::cerr << "tensegrity_export: scene refused: " << e.what() << "\n";
    return 1;
  }
#ifdef ACTIVE_TENSEGRITY_HAVE_MUJOCO
  std::string xml;
  try
  {
    const tools::MujocoPeer peer(model, options);
    xml = peer.exportXml();
  }
  catch (const std::exception& e)  // what the translation does not cover, or MuJoCo's refusal
  {
    std::cerr << "tensegrity_export: --mjcf: " << e.what() << "\n";
    return 1;
  }
  std::ofstream out(mjcf_path);
  if (!(out << xml) || (out.close(), !out))
  {
    std::cerr << "tensegrity_export: cannot write '" << mjcf_path << "'\n";
    return 1;
  }
  return 0;
#else
  std::cerr << "tensegrity_export: --mjcf: built without MuJoCo (Debian package libmujoco-dev)\n";
  return 1;
#endif
}
