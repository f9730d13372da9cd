// tensegrity_generate and tensegrity_formfind as a user runs them: generated scenes load and run, a generated
// start is taken to its form, the form written is a fixed point, and bad arguments are refused with the
// option and the value.
#include <algorithm>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "active_tensegrity/design/generators.h"
#include "active_tensegrity/core/model/kinematics.h"
#include "active_tensegrity/core/scene/scene.h"
#include "active_tensegrity/core/solvers/state.h"
#include "command.h"

namespace at = active_tensegrity::core;
namespace design = active_tensegrity::design;
using Result = active_tensegrity::test::CommandResult;

namespace
{
Result generate(const std::string& args)
{
  return active_tensegrity::test::runCommand(std::string(TENSEGRITY_GENERATE_PATH) + " " + args + " 2>&1");
}

Result formfind(const std::string& args)
{
  return active_tensegrity::test::runCommand(std::string(TENSEGRITY_FORMFIND_PATH) + " " + args + " 2>&1");
}

std::string tmp(const std::string& name)
{
  return active_tensegrity::test::scratchPath(name);
}

std::string text(const std::string& path)
{
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// The number after "key: " in a report (NaN when absent).
double reported(const std::string& report, const std::string& key)
{
  const size_t at = report.find("\n" + key + ": ");
  if (at == std::string::npos)
    return NAN;
  return std::stod(report.substr(at + key.size() + 3));
}

/// Every strut's end points, rounded to 0.1 mm and ordered, as a set (names aside).
std::set<std::vector<long>> strutEnds(const at::Model& model)
{
  const at::State s = at::initialState(model);
  std::set<std::vector<long>> out;
  for (int b = 0; b < static_cast<int>(model.bodies.size()); ++b)
  {
    if (model.bodies[b].kind != at::BodyKind::kStrut)
      continue;
    std::vector<long> a, c;
    const at::Vec3 p = at::pointPosition(model, { b, at::Vec3(0.0, 0.0, -0.5 * model.bodies[b].length) }, s.q);
    const at::Vec3 q = at::pointPosition(model, { b, at::Vec3(0.0, 0.0, 0.5 * model.bodies[b].length) }, s.q);
    for (int k = 0; k < 3; ++k)
    {
      a.push_back(std::lround(p[k] * 1e4));
      c.push_back(std::lround(q[k] * 1e4));
    }
    std::vector<long> both = std::min(a, c);
    const std::vector<long>& other = std::max(a, c);
    both.insert(both.end(), other.begin(), other.end());
    out.insert(both);
  }
  return out;
}
}  // namespace

TEST(TensegrityGenerate, EveryStructureLoads)
{
  for (const char* args :
       { "prism --struts 3", "prism --struts 12 --radius 0.3 --height 1.2 --prestress 50 --pinned",
         "prism --struts 6 --pinned --driven --strut-radius 0.03", "octahedron --strut-length 2 --pinned",
         "quadruplex-lattice --cells 2x3", "tower --stages 3" })
  {
    const std::string out = tmp("generated.yaml");
    const Result r = generate(std::string(args) + " --out " + out);
    ASSERT_EQ(r.code, 0) << args << ": " << r.output;
    EXPECT_NO_THROW(at::loadScene(out)) << args;
  }
  // stdout without --out
  const Result r = generate("octahedron");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.output.find("name: octahedron"), std::string::npos) << r.output;
}

// The generated four-stage tower is the package's tower scene: the same struts (the node names differ)
TEST(TensegrityGenerate, FourStageTowerIsTheShippedTower)
{
  const at::Model generated = at::loadSceneFromString(design::towerScene({}), "tower4");
  const at::Model shipped = at::loadScene(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/tower.yaml");
  EXPECT_EQ(strutEnds(generated), strutEnds(shipped));
  EXPECT_EQ(generated.cables.size(), shipped.cables.size());
  EXPECT_EQ(generated.checkedPairList().size(), shipped.checkedPairList().size());
  EXPECT_EQ(generated.actuators.size(), shipped.actuators.size());
  // six stages: 24 struts, 4 sliding cables through 7 levels and a driven body
  const at::Model six = at::loadSceneFromString(design::towerScene({ 6, 1.0 }), "tower6");
  EXPECT_EQ(strutEnds(six).size(), 24u);
}

TEST(TensegrityGenerate, BadArgumentsNameTheOptionAndValue)
{
  const std::vector<std::pair<std::string, std::string>> cases = {
    { "", "no structure given" },
    { "dodecahedron", "unknown structure 'dodecahedron'" },
    { "prism", "--struts N is required" },
    { "prism --struts 2", "3 to 64 struts, got '2'" },
    { "prism --struts 5 --radius -1", "--radius: expected a positive number, got '-1'" },
    { "prism --struts 5 --twist abc", "--twist: expected an angle in degrees, got 'abc'" },
    { "prism --struts 5 --height", "--height needs a value" },
    { "octahedron --struts 5", "unknown option '--struts'" },
    { "quadruplex-lattice --cells 3", "--cells: expected AxB" },
    { "quadruplex-lattice --cells 2x2 --top-radius 0.6", "--top-radius: must be below half the pitch" },
    { "tower --stages 31", "1 to 30 stages (its sliding cables run through every level" },
    { "tower --stages 2 --width 1e-4", "--width: must lie in [0.001, 1000] m, got '1e-4'" },
    { "prism --struts 65", "3 to 64 struts, got '65'" },
    { "prism --struts 5 --radius 1001", "--radius: must lie in [0.001, 1000] m, got '1001'" },
    { "prism --struts 5 --height 0.0009", "--height: must lie in [0.001, 1000] m, got '0.0009'" },
    { "prism --struts 5 --strut-radius 1e300", "--strut-radius: must lie in [0.001, 1000] m, got '1e300'" },
    { "prism --struts 5 --prestress 2e6", "--prestress: must lie in [0.001, 1e+06] N, got '2e6'" },
    { "prism --struts 5 --twist 1e30", "--twist: must lie in [-360, 360] degrees, got '1e30'" },
    { "octahedron --strut-length 1e-300", "--strut-length: must lie in [0.001, 1000] m, got '1e-300'" },
    { "octahedron --prestress 1e-4", "--prestress: must lie in [0.001, 1e+06] N, got '1e-4'" },
    { "quadruplex-lattice --cells 80x101", "--cells: at most 8000 cells (e.g. 80x100), got '80x101'" },
    { "quadruplex-lattice --cells 2x2 --pitch 1e4", "--pitch: must lie in [0.001, 1000] m, got '1e4'" },
    { "quadruplex-lattice --cells 2x2 --pitch 0.5",
      "--top-radius: must be below half the pitch (0.25 m), got '0.3' (its default; give --top-radius)" },
    { "prism --struts 4 --driven", "--driven needs --pinned" },
  };
  for (const auto& [args, message] : cases)
  {
    const Result r = generate(args);
    EXPECT_EQ(r.code, 2) << args << ": " << r.output;
    EXPECT_NE(r.output.find(message), std::string::npos) << args << ": " << r.output;
  }
  const Result r = generate("prism --struts 4 --out /nonexistent/dir/p.yaml");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot write '/nonexistent/dir/p.yaml'"), std::string::npos) << r.output;
}

// Every boundary of every documented range gives a scene that loads (tower --stages 31, in the documented 1..40,
// wrote a scene the loader refused: its sliding cables had 33 nodes), alone and with the other options at theirs
TEST(TensegrityGenerate, EveryBoundaryOfEveryRangeLoads)
{
  std::vector<std::string> cases;
  for (const char* n : { "3", "64" })
    for (const char* base : { "", " --pinned", " --pinned --driven" })
    {
      const std::string prism = std::string("prism --struts ") + n + base;
      cases.push_back(prism);
      for (const char* option : { "--radius", "--height", "--strut-radius" })
        for (const char* v : { "0.001", "1000" })
          cases.push_back(prism + " " + option + " " + v);
      for (const char* v : { "0.001", "1e6" })
        cases.push_back(prism + " --prestress " + v);
      for (const char* v : { "-360", "360" })
        cases.push_back(prism + " --twist " + v);
      cases.push_back(prism + " --radius 0.001 --height 0.001 --strut-radius 1000 --prestress 1e6 --twist -360");
      cases.push_back(prism + " --radius 1000 --height 1000 --strut-radius 0.001 --prestress 0.001 --twist 360");
    }
  for (const char* pinned : { "", " --pinned" })
    for (const char* l : { "0.001", "1000" })
      for (const char* t : { "0.001", "1e6" })
        cases.push_back(std::string("octahedron --strut-length ") + l + " --prestress " + t + pinned);
  for (const char* k : { "1", "30" })
    for (const char* w : { "0.001", "1000" })
      cases.push_back(std::string("tower --stages ") + k + " --width " + w);
  for (const char* c : { "1x1", "1x8000", "80x100" })
    cases.push_back(std::string("quadruplex-lattice --cells ") + c);
  for (const char* p : { "0.0021", "1000" })
    for (const char* h : { "0.001", "1000" })
      for (const char* r : { "0.001", "1000" })
      {
        const std::string lattice = std::string("quadruplex-lattice --cells 2x2 --pitch ") + p + " --height " + h +
                                    " --strut-radius " + r + " --top-radius ";
        cases.push_back(lattice + "0.001");
        cases.push_back(lattice + (std::string(p) == "1000" ? "499.99" : "0.00104"));
      }
  const std::string out = tmp("boundary.yaml");
  for (const std::string& args : cases)
  {
    const Result r = generate(args + " --out " + out);
    ASSERT_EQ(r.code, 0) << args << ": " << r.output;
    EXPECT_NO_THROW(at::loadScene(out)) << args;
  }
}

// Every tool and every subcommand answers --help and -h with its usage, status 0 ("tensegrity_generate octahedron
// --help" said "unknown option")
TEST(ToolHelp, EveryToolAndSubcommandAnswersHelp)
{
  const std::vector<std::pair<std::string, std::string>> tools = {
    { TENSEGRITY_GENERATE_PATH, "usage: tensegrity_generate" },
    { TENSEGRITY_FORMFIND_PATH, "usage: tensegrity_formfind" },
    { TENSEGRITY_EXPORT_PATH, "usage: tensegrity_export" },
    { TENSEGRITY_BENCH_PATH, "usage: tensegrity_bench" },
  };
  for (const auto& [tool, usage] : tools)
    for (const char* help : { "--help", "-h" })
    {
      const Result r = active_tensegrity::test::runCommand(tool + " " + help + " 2>&1");
      EXPECT_EQ(r.code, 0) << tool << " " << help << ": " << r.output;
      EXPECT_EQ(r.output.rfind(usage, 0), 0u) << tool << " " << help << ": " << r.output;
    }
  const std::vector<std::pair<std::string, std::string>> subcommands = {
    { std::string(TENSEGRITY_GENERATE_PATH) + " octahedron", "usage: tensegrity_generate" },
    { std::string(TENSEGRITY_GENERATE_PATH) + " prism --struts 5", "usage: tensegrity_generate" },
    { std::string(TENSEGRITY_GENERATE_PATH) + " quadruplex-lattice --cells 2x2", "usage: tensegrity_generate" },
    { std::string(TENSEGRITY_GENERATE_PATH) + " tower", "usage: tensegrity_generate" },
    { std::string(TENSEGRITY_FORMFIND_PATH) + " in.yaml --out out.yaml", "usage: tensegrity_formfind" },
    { std::string(TENSEGRITY_EXPORT_PATH) + " scene.yaml --mjcf out.xml", "usage: tensegrity_export" },
    { std::string(TENSEGRITY_BENCH_PATH) + " steps scene.yaml", "usage: tensegrity_bench steps" },
    { std::string(TENSEGRITY_BENCH_PATH) + " steps", "usage: tensegrity_bench steps" },
    { std::string(TENSEGRITY_BENCH_PATH) + " contact-pair", "usage: tensegrity_bench contact-pair" },
    { std::string(TENSEGRITY_BENCH_PATH) + " broad-phase", "usage: tensegrity_bench broad-phase" },
    { std::string(TENSEGRITY_BENCH_PATH) + " plan scene.yaml", "usage: tensegrity_bench plan" },
    { std::string(TENSEGRITY_BENCH_PATH) + " work-precision scene.yaml", "usage: tensegrity_bench work-precision" },
    { std::string(TENSEGRITY_BENCH_PATH) + " stress", "usage: tensegrity_bench stress" },
    { std::string(TENSEGRITY_BENCH_PATH) + " lattice", "usage: tensegrity_bench lattice" },
  };
  for (const auto& [command, usage] : subcommands)
    for (const char* help : { "--help", "-h" })
    {
      const Result r = active_tensegrity::test::runCommand(command + " " + help + " 2>&1");
      EXPECT_EQ(r.code, 0) << command << " " << help << ": " << r.output;
      EXPECT_EQ(r.output.rfind(usage, 0), 0u) << command << " " << help << ": " << r.output;
    }
  // an unknown subcommand is still refused, with the whole usage
  const Result bogus = active_tensegrity::test::runCommand(std::string(TENSEGRITY_BENCH_PATH) + " bogus 2>&1");
  EXPECT_EQ(bogus.code, 2) << bogus.output;
  EXPECT_NE(bogus.output.find("unknown command 'bogus'"), std::string::npos) << bogus.output;
}

// A seven-strut prism generated 15 degrees off its twist: tensegrity_formfind takes it to the form, and the
// form written, found again, moves nothing
TEST(TensegrityFormfind, GeneratedStartToFormAndFixedPoint)
{
  const std::string start = tmp("start.yaml"), form = tmp("form.yaml"), again = tmp("again.yaml");
  ASSERT_EQ(generate("prism --struts 7 --twist -130 --out " + start).code, 0);
  const Result r = formfind(start + " --out " + form + " --prestress rings=80");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_GT(reported(r.output, "max_move"), 0.05) << r.output;
  EXPECT_LT(reported(r.output, "residual"), 1e-9) << r.output;
  EXPECT_NE(r.output.find("prestress_stable: true"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("slack_cables: 0"), std::string::npos) << r.output;
  const at::Model model = at::loadScene(form);
  EXPECT_NE(text(form).find("prestress: 80\n"), std::string::npos) << text(form);
  // the twist it was given and the one of the form, named (nothing was said)
  EXPECT_NE(r.output.find("warning: form-finding changed the twist of stage 'S1', 'S2', 'S3' ... (z 0 to 0.8 m): "
                          "-130 degrees in the scene, -115.714 degrees in the form"),
            std::string::npos)
      << r.output;
  const Result a = formfind(form + " --out " + again);
  ASSERT_EQ(a.code, 0) << a.output;
  EXPECT_LT(reported(a.output, "max_move"), 1e-9) << a.output;
  EXPECT_EQ(a.output.find("form-finding changed"), std::string::npos) << a.output;  // nothing changes
  EXPECT_EQ(a.output.find("\nchanges:"), std::string::npos) << a.output;
  // to stdout, the report on stderr
  const Result s = formfind(form + " --out -");
  ASSERT_EQ(s.code, 0) << s.output;
  EXPECT_NE(s.output.find("name: prism7"), std::string::npos);
  EXPECT_NE(s.output.find("iterations:"), std::string::npos);
}

// The quadruplex's prestress designed at its geometry: Table 1's ratios
TEST(TensegrityFormfind, PrestressModeOnTheQuadruplex)
{
  const std::string out = tmp("quadruplex.yaml");
  const Result r = formfind(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) +
                            "/config/scenes/quadruplex.yaml --mode prestress "
                            "--prestress lower=200 --out " +
                            out);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(text(out).find("prestress: 282.84271247461"), std::string::npos) << text(out);
  EXPECT_LT(reported(r.output, "max_move"), 1e-15) << r.output;
}

TEST(TensegrityFormfind, RefusalsNameTheOptionAndValue)
{
  const std::string prism = tmp("refusal_start.yaml"), out = tmp("refusal_out.yaml");
  ASSERT_EQ(generate("prism --struts 4 --out " + prism).code, 0);
  const std::vector<std::tuple<std::string, int, std::string>> cases = {
    { "", 2, "no scene given" },
    { prism, 2, "no --out given" },
    { prism + " --out " + out + " --prestress rings", 2, "--prestress: expected FAMILY=VALUE, got 'rings'" },
    { prism + " --out " + out + " --prestress rings=-5", 2, "--prestress rings: expected a positive number, got '-5'" },
    { prism + " --out " + out + " --prestress rings=nan", 2, "got 'nan'" },
    { prism + " --out " + out + " --mode fast", 2, "--mode: expected free or prestress, got 'fast'" },
    { prism + " --out " + out + " --supports maybe", 2, "--supports: expected fixed or react, got 'maybe'" },
    { prism + " --out " + out + " --tolerance 0.1", 2, "--tolerance: expected a relative tolerance below 1e-3" },
    { prism + " --out " + out + " --prestress rings=1 --prestress rings=2", 2, "family 'rings' given twice" },
    { prism + " --out " + out + " --prestress bracing=5", 1, "no cable or spring family 'bracing'" },
    { prism + " --out " + out + " --mode prestress", 1, "needs a target tension" },
    { prism + " --out " + out + " --mode prestress --prestress rings=5 --strut-lengths keep", 1,
      "--strut-lengths keep: prestress mode keeps the whole geometry" },
    { prism + " --out " + out + " --prestress rings=5 --force-density rings=5", 1, "held already" },
    { "/nonexistent/in.yaml --out " + out, 1, "cannot read '/nonexistent/in.yaml'" },
    { prism + " --out /nonexistent/dir/out.yaml", 1, "cannot write '/nonexistent/dir/out.yaml'" },
  };
  for (const auto& [args, code, message] : cases)
  {
    std::remove(out.c_str());
    const Result r = formfind(args);
    EXPECT_EQ(r.code, code) << args << ": " << r.output;
    EXPECT_NE(r.output.find(message), std::string::npos) << args << ": " << r.output;
    if (code != 0)
    {
      EXPECT_FALSE(std::ifstream(out).good()) << args << ": a refused run wrote its output";
    }
  }
  // a malformed scene is refused by the loader, naming the key
  const std::string bad = tmp("bad.yaml");
  std::ofstream(bad) << text(prism) << "struts: {radius: 0.01}\n";
  const Result r = formfind(bad + " --out " + out);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("scene refused"), std::string::npos) << r.output;
}

// Form-finding that changes what the scene's layout gave says so, naming the parameter and both values: a
// two-stage tower whose stages overlap by 0.3 m (its nodes in rings at z = 0, 0.7, 1 and 1.7 m) comes out with
// 0.42 m (it said nothing)
TEST(TensegrityFormfind, ChangedLayoutParametersAreWarnedAbout)
{
  const std::string scene = tmp("tower2.yaml"), form = tmp("tower2_form.yaml");
  std::ofstream(scene) << R"(name: tower2
materials:
  alu: {youngs_modulus: 70.0e9, density: 2700.0}
  fib: {youngs_modulus: 73.0e9, density: 2450.0}
nodes:
  B1: {position: [0.5, 0.0, 0.0], fixed: true}
  B2: {position: [-0.25, 0.4330127, 0.0], fixed: true}
  B3: {position: [-0.25, -0.4330127, 0.0], fixed: true}
  T1: {position: [-0.4330127, 0.25, 1.0]}
  T2: {position: [0.0, -0.5, 1.0]}
  T3: {position: [0.4330127, 0.25, 1.0]}
  M1: {position: [0.25, 0.4330127, 0.7]}
  M2: {position: [-0.5, 0.0, 0.7]}
  M3: {position: [0.25, -0.4330127, 0.7]}
  U1: {position: [-0.4330127, -0.25, 1.7]}
  U2: {position: [0.4330127, -0.25, 1.7]}
  U3: {position: [0.0, 0.5, 1.7]}
struts:
  radius: 0.01
  material: alu
  members: {S1: [B1, T1], S2: [B2, T2], S3: [B3, T3], R1: [M1, U1], R2: [M2, U2], R3: [M3, U3]}
cables:
  bottom:
    material: fib
    radius: 0.001
    prestress: 100
    members: {b1: [B1, B2], b2: [B2, B3], b3: [B3, B1]}
  top: {material: fib, radius: 0.001, members: {t1: [U1, U2], t2: [U2, U3], t3: [U3, U1]}}
  verticals:
    material: fib
    radius: 0.001
    members: {v1: [B1, T2], v2: [B2, T3], v3: [B3, T1], v4: [M1, U2], v5: [M2, U3], v6: [M3, U1]}
  saddle:
    material: fib
    radius: 0.001
    members: {s1: [T1, M1], s2: [T2, M2], s3: [T3, M3], s4: [T1, M2], s5: [T2, M3], s6: [T3, M1]}
  inter:
    material: fib
    radius: 0.001
    members: {i1: [B1, M1], i2: [B2, M2], i3: [B3, M3], i4: [T1, U1], i5: [T2, U2], i6: [T3, U3]}
analysis: {type: static, steps: 10}
)";
  const Result r = formfind(scene + " --out " + form + " --supports react");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string overlap = "warning: form-finding changed the overlap of stage 'S1', 'S2', 'S3' (z 0 to 1 m) and "
                              "stage 'R1', 'R2', 'R3' (z 0.7 to 1.7 m): 0.3 m in the scene, 0.42";
  EXPECT_NE(r.output.find(overlap), std::string::npos) << r.output;
  for (const char* changed :
       { "warning: form-finding changed the height (the nodes' z extent): 1.7 m in the scene, 1.72",
         "warning: form-finding changed the height of stage 'S1', 'S2', 'S3' (z 0 to 1 m): 1 m in the scene, 1.06",
         "warning: form-finding changed the radius of the level of nodes 'T1', 'T2', 'T3' (z = 1 m): 0.5 m in the "
         "scene, 0.56",
         "warning: form-finding changed the twist of stage 'R1', 'R2', 'R3' (z 0.7 to 1.7 m): 150 degrees in the "
         "scene, 175",
         "warning: form-finding changed the length of strut 'S1': 1.39" })
    EXPECT_NE(r.output.find(changed), std::string::npos) << changed << "\n" << r.output;
  // and in the report
  EXPECT_NE(r.output.find("\nchanges:  # of the scene's layout, made by the form\n  - \"height (the nodes' z extent)"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("\n  - \"overlap of stage 'S1', 'S2', 'S3'"), std::string::npos) << r.output;
}

TEST(TensegrityFormfind, OnlyRegularSceneFilesAreRead)
{
  // /dev/zero was read without end
  const Result r = formfind("/dev/zero --out " + tmp("zero.yaml"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot read '/dev/zero': /dev/zero: is not a regular file (a device)"), std::string::npos)
      << r.output;
}
