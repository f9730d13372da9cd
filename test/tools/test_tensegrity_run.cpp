// The batch command as a user runs it: exit codes, CSV shape, messages on bad input.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "command.h"

namespace
{
using Result = active_tensegrity::test::CommandResult;

Result run(const std::string& args)
{
  return active_tensegrity::test::runCommand(std::string(TENSEGRITY_RUN_PATH) + " " + args + " 2>&1");
}

std::string scene(const std::string& name)
{
  return std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/" + name;
}

std::vector<std::string> lines(const std::string& path)
{
  std::ifstream in(path);
  std::vector<std::string> out;
  for (std::string l; std::getline(in, l);)
    out.push_back(l);
  return out;
}

/// The file's lines, each ended by a newline.
std::string text(const std::string& path)
{
  std::string all;
  for (const std::string& l : lines(path))
    all += l + "\n";
  return all;
}

/// The cells of a CSV row of numbers.
std::vector<double> numbers(const std::string& row)
{
  std::vector<double> v;
  std::stringstream in(row);
  for (std::string cell; std::getline(in, cell, ',');)
    v.push_back(std::stod(cell));
  return v;
}

std::string tmp(const std::string& name)
{
  return active_tensegrity::test::scratchPath(name);
}
}  // namespace

TEST(TensegrityRun, QuadruplexWritesCsvAndSummary)
{
  const std::string csv = tmp("q.csv"), summary = tmp("q.yaml");
  const Result r = run(scene("quadruplex.yaml") + " --set analysis.steps=20 --set analysis.max_actuation=0.4 --out " +
                       csv + " --summary " + summary);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> rows = lines(csv);
  ASSERT_EQ(rows.size(), 1u + 21u);  // header, v = 0 and 20 load steps
  EXPECT_EQ(rows[0].rfind("t,actuation,actuation_force,height,active_contacts,min_gap,max_normal_force,"
                          "max_friction_force",
                          0),
            0u)
      << rows[0];
  EXPECT_EQ(rows.back().rfind("1,0.4,", 0), 0u) << rows.back();
  const std::string all = text(summary);
  EXPECT_NE(all.find("status: converged"), std::string::npos) << all;
  EXPECT_NE(all.find("output_steps: 21"), std::string::npos) << all;
}

TEST(TensegrityRun, RefusesABadOverrideNamingTheKey)
{
  const Result r = run(scene("quadruplex.yaml") + " --set struts.radius=-1 --out " + tmp("bad.csv"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("struts.radius"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("-1"), std::string::npos) << r.output;
}

TEST(TensegrityRun, RefusesAMisspeltKey)
{
  const Result r = run(scene("quadruplex.yaml") + " --set analysis.stepz=3");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("analysis.stepz"), std::string::npos) << r.output;
}

TEST(TensegrityRun, BadArgumentsGiveUsage)
{
  EXPECT_EQ(run("").code, 2);
  EXPECT_EQ(run(scene("quadruplex.yaml") + " --frobnicate").code, 2);
  EXPECT_EQ(run(scene("quadruplex.yaml") + " --set").code, 2);
  // an empty file name is refused by its option, not run without output
  for (const char* option : { "--out", "--summary", "--contacts", "--nodes", "--members", "--vtk", "--bag", "--modes" })
  {
    const Result empty = run(scene("quadruplex.yaml") + " " + option + " ''");
    EXPECT_EQ(empty.code, 2) << option << ": " << empty.output;
    EXPECT_NE(empty.output.find(std::string(option) + " needs a value, got an empty one"), std::string::npos)
        << empty.output;
  }
  const Result missing = run("/nonexistent/scene.yaml");
  EXPECT_EQ(missing.code, 1);
  EXPECT_NE(missing.output.find("/nonexistent/scene.yaml"), std::string::npos) << missing.output;
}

TEST(TensegrityRun, SolverFailureStopsWithStatusAndNoNaN)
{
  // one Newton iteration cannot meet a 1e-14 tolerance: the run stops with status 3
  const std::string csv = tmp("fail.csv");
  const Result r = run(scene("quadruplex.yaml") +
                       " --set solver.max_iterations=1 --set solver.max_step_cuts=1 --set solver.newton_tolerance=1e-14"
                       " --out " +
                       csv);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("max_iterations"), std::string::npos) << r.output;
  for (const std::string& row : lines(csv))
    EXPECT_EQ(row.find("nan"), std::string::npos) << row;
}

TEST(TensegrityRun, DynamicPrismRuns)
{
  const std::string csv = tmp("prism.csv");
  const Result r = run(scene("prism.yaml") + " --set analysis.duration=0.05 --out " + csv);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> rows = lines(csv);
  EXPECT_EQ(rows.size(), 1u + 1u + 10u);  // header, t = 0, every 5 ms
}

TEST(TensegrityRun, ContactsFileListsEveryTouchingPairPerOutputStep)
{
  // Rs = 0.05 m: the four neighbouring pairs touch from v = 0.138 m (docs/validation.md)
  const std::string csv = tmp("qc.csv"), contacts = tmp("qc_contacts.csv");
  const Result r = run(scene("quadruplex.yaml") +
                       " --set contact.enabled=true --set analysis.steps=20 --set analysis.max_actuation=0.2 --out " +
                       csv + " --summary " + tmp("qc.yaml") + " --contacts " + contacts);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> rows = lines(contacts);
  ASSERT_FALSE(rows.empty());
  EXPECT_EQ(rows[0].rfind("t,strut_a,strut_b,point_a_x", 0), 0u) << rows[0];
  // load steps at v = 0.14 ... 0.2 (7 of them) with four pairs each
  EXPECT_EQ(rows.size(), 1u + 7u * 4u);
  for (size_t i = 1; i < rows.size(); ++i)
  {
    EXPECT_NE(rows[i].find(",S"), std::string::npos) << rows[i];
    EXPECT_EQ(std::count(rows[i].begin(), rows[i].end(), ','), 17) << rows[i];
  }
  // the main CSV counts the same contacts
  const std::vector<std::string> main_rows = lines(csv);
  EXPECT_NE(main_rows.back().find(",4,"), std::string::npos) << main_rows.back();
}

TEST(TensegrityRun, EveryOutputPathIsCheckedBeforeTheRun)
{
  // the summary's folder is missing: refused at once, nothing written to the CSV path
  const std::string csv = tmp("never.csv");
  std::remove(csv.c_str());
  const Result r = run(scene("tower.yaml") + " --out " + csv + " --summary /nonexistent/folder/x.yaml");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot write '/nonexistent/folder/x.yaml'"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("status:"), std::string::npos) << "the run went ahead: " << r.output;
  EXPECT_TRUE(lines(csv).empty());
}

TEST(TensegrityRun, ABagNamespaceMustBeAGraphName)
{
  for (const std::string ns : { "'bad name!'", "relative", "/trailing/", "'/a b'" })
  {
    const Result r = run(scene("prism.yaml") + " --bag " + tmp("ns.bag") + " --bag-ns " + ns);
    EXPECT_EQ(r.code, 2) << ns << ": " << r.output;
    EXPECT_NE(r.output.find("namespace"), std::string::npos) << r.output;
  }
  EXPECT_EQ(run(scene("prism.yaml") + " --bag-ns /x").code, 2);  // without --bag it would do nothing
  const Result ok = run(scene("prism.yaml") + " --set analysis.duration=0.01 --bag " + tmp("ns.bag") +
                        " --bag-ns /robot/sim --out " + tmp("ns.csv"));
  EXPECT_EQ(ok.code, 0) << ok.output;
}

TEST(TensegrityRun, AnOverrideKeyEndingInADotIsRefused)
{
  const Result r = run(scene("prism.yaml") + " --set analysis.duration.=0.001");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("malformed"), std::string::npos) << r.output;
}

TEST(TensegrityRun, NoInfiniteOrNanFieldWhenNoPairIsChecked)
{
  // a single pinned strut swinging under gravity: no strut pair, so min_gap has no value (an empty field)
  const std::string yaml = tmp("pendulum.yaml"), csv = tmp("pendulum.csv");
  std::ofstream(yaml) << "name: pendulum\n"
                         "materials: {steel: {youngs_modulus: 2.0e11, density: 7850.0}}\n"
                         "nodes:\n  A: {position: [0.0, 0.0, 0.0], fixed: true}\n  B: {position: [1.0, 0.0, 0.0]}\n"
                         "struts: {material: steel, radius: 0.01, members: {S: [A, B]}}\n"
                         "gravity: {enabled: true}\n"
                         "analysis: {type: dynamic, duration: 0.02}\n";
  const Result r = run(yaml + " --out " + csv);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> rows = lines(csv);
  ASSERT_GT(rows.size(), 2u);
  for (const std::string& row : rows)
  {
    EXPECT_EQ(row.find("inf"), std::string::npos) << row;
    EXPECT_EQ(row.find("nan"), std::string::npos) << row;
  }
  EXPECT_NE(rows[1].find(",0,,"), std::string::npos) << rows[1];  // active_contacts 0, min_gap empty
}

TEST(TensegrityRun, CheckPrintsTheDiagnosticsAndRunsNothing)
{
  // the pinned prism: one self-stress state of the prism and one per ring cable between two pins, one
  // mechanism stiffened by the prestress (test_structure_check derives the counts)
  const Result r = run(scene("prism_pinned.yaml") + " --check");
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* line : { "checked: true", "members: 12", "struts: 3", "tension_members: 9", "free_coordinates: 6",
                            "self_stress_states: 4", "mechanisms: 1", "rigid_body_modes: 0", "prestress_stable: true",
                            "slack_cables: []" })
    EXPECT_NE(r.output.find(std::string("\n") + line + "\n"), std::string::npos) << line << "\n" << r.output;
  EXPECT_EQ(r.output.find("status:"), std::string::npos) << "an analysis ran: " << r.output;
  // overrides apply; the unstressed tower lists its slack elements
  const Result free = run(scene("prism.yaml") + " --set actuators={} --check");
  EXPECT_NE(free.output.find("\nrigid_body_modes: 6\n"), std::string::npos) << free.output;
  const Result tower = run(scene("tower.yaml") + " --check");
  EXPECT_NE(tower.output.find("\nprestress_stable: false\n"), std::string::npos) << tower.output;
  EXPECT_NE(tower.output.find("\"L1\""), std::string::npos) << tower.output;
}

TEST(TensegrityRun, CheckRefusesABadSceneAndOutputOptions)
{
  const Result bad = run(scene("prism_pinned.yaml") + " --check --set struts.radius=-1");
  EXPECT_EQ(bad.code, 1) << bad.output;
  EXPECT_NE(bad.output.find("struts.radius"), std::string::npos) << bad.output;
  const Result out = run(scene("prism_pinned.yaml") + " --check --out " + tmp("check.csv"));
  EXPECT_EQ(out.code, 2) << out.output;
  EXPECT_NE(out.output.find("--check"), std::string::npos) << out.output;
}

TEST(TensegrityRun, ModalSceneWritesFrequenciesShapesAndSummary)
{
  const std::string csv = tmp("modes.csv"), shapes = tmp("shapes.csv"), summary = tmp("modes.yaml");
  const Result r = run(scene("prism_pinned.yaml") + " --set analysis.type=modal --out " + csv + " --modes " + shapes +
                       " --summary " + summary);
  ASSERT_EQ(r.code, 0) << r.output;
  // six free coordinates: six modes (fewer than the ten asked for: a warning), ascending
  const std::vector<std::string> rows = lines(csv);
  ASSERT_EQ(rows.size(), 1u + 6u);
  EXPECT_EQ(rows[0], "mode,frequency_hz,omega,eigenvalue");
  double previous = 0.0;
  for (size_t k = 1; k < rows.size(); ++k)
  {
    double f = 0.0, omega = 0.0, eigenvalue = 0.0;
    int mode = 0;
    ASSERT_EQ(std::sscanf(rows[k].c_str(), "%d,%lf,%lf,%lf", &mode, &f, &omega, &eigenvalue), 4) << rows[k];
    EXPECT_EQ(mode, static_cast<int>(k));
    EXPECT_GE(f, previous);
    EXPECT_NEAR(omega, 2.0 * M_PI * f, 1e-8 * omega);
    EXPECT_NEAR(eigenvalue, omega * omega, 1e-8 * eigenvalue);
    previous = f;
  }
  // one row per mode and node, the largest node displacement of each mode 1, the pinned nodes still
  const std::vector<std::string> s = lines(shapes);
  ASSERT_EQ(s.size(), 1u + 6u * 6u);
  EXPECT_EQ(s[0], "mode,node,dx,dy,dz");
  std::vector<double> largest(7, 0.0);
  for (size_t i = 1; i < s.size(); ++i)
  {
    int mode = 0;
    char node[8] = {};
    double dx = 0, dy = 0, dz = 0;
    ASSERT_EQ(std::sscanf(s[i].c_str(), "%d,%7[^,],%lf,%lf,%lf", &mode, node, &dx, &dy, &dz), 5) << s[i];
    largest[mode] = std::max(largest[mode], std::sqrt(dx * dx + dy * dy + dz * dz));
    if (node[0] == 'B')
    {
      EXPECT_EQ(s[i].substr(s[i].find(node) + 2), ",0,0,0") << s[i];
    }
  }
  for (int k = 1; k <= 6; ++k)
    EXPECT_NEAR(largest[k], 1.0, 1e-8) << "mode " << k;
  const std::string all = text(summary);
  EXPECT_NE(all.find("analysis: modal\nstatus: converged\n"), std::string::npos) << all;
  EXPECT_NE(all.find("frequencies_hz: [" + rows[1].substr(2, rows[1].find(',', 2) - 2) + ", "), std::string::npos)
      << all;
  EXPECT_NE(all.find("asks for 10 modes"), std::string::npos) << all;
  EXPECT_NE(all.find("  mechanisms: 1\n"), std::string::npos) << all;
}

TEST(TensegrityRun, ModalOptionsOnlyWhereTheyApply)
{
  const Result modes = run(scene("prism_pinned.yaml") + " --modes " + tmp("m.csv"));
  EXPECT_EQ(modes.code, 2) << modes.output;
  EXPECT_NE(modes.output.find("--modes"), std::string::npos) << modes.output;
  const Result contacts = run(scene("prism_pinned.yaml") + " --set analysis.type=modal --contacts " + tmp("mc.csv"));
  EXPECT_EQ(contacts.code, 2) << contacts.output;
  EXPECT_NE(contacts.output.find("modal"), std::string::npos) << contacts.output;
  const Result huge = run(scene("prism_pinned.yaml") + " --set analysis.type=modal --set analysis.modes=1e9");
  EXPECT_EQ(huge.code, 1) << huge.output;
  EXPECT_NE(huge.output.find("analysis.modes: must be at most 1000, got '1e9'"), std::string::npos) << huge.output;
}

TEST(TensegrityRun, ADurationThatEndsBeforeTheRampWarns)
{
  // the prism's ramp: 0.02 m at 0.4 m/s with 0.05 s blends ends at 0.1 s
  const std::string summary = tmp("short.yaml");
  const Result r = run(scene("prism.yaml") + " --set analysis.duration=0.05 --out /dev/null --summary " + summary);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("analysis.duration 0.05 s ends before the actuators reach analysis.max_actuation 0.02 m "
                          "(the ramp ends at 0.1 s)"),
            std::string::npos)
      << r.output;
  const std::string all = text(summary);
  EXPECT_NE(all.find("ends before the actuators reach"), std::string::npos) << all;
  EXPECT_NE(all.find("duration: 0.05\n"), std::string::npos) << all;
  EXPECT_EQ(all.find("duration_note"), std::string::npos) << all;
  // long enough: no such warning
  const Result full = run(scene("prism.yaml") + " --set analysis.duration=0.1 --out /dev/null");
  ASSERT_EQ(full.code, 0) << full.output;
  EXPECT_EQ(full.output.find("ends before the actuators reach"), std::string::npos) << full.output;
}

TEST(TensegrityRun, AMissingDurationIsTheRampPlusTheSettleTimeAndSaysSo)
{
  std::ifstream in(scene("prism.yaml"));
  const std::string file = tmp("no_duration.yaml");
  {
    std::ofstream out(file);
    for (std::string l; std::getline(in, l);)
      if (l.find("duration:") == std::string::npos)
        out << l << "\n";
  }
  const std::string csv = tmp("no_duration.csv"), summary = tmp("no_duration_summary.yaml");
  const Result r = run(file + " --set analysis.settle_time=0.02 --out " + csv + " --summary " + summary);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string all = text(summary);
  EXPECT_NE(all.find("duration: 0.12\n"), std::string::npos) << all;
  EXPECT_NE(all.find("duration_note: \"analysis.duration not given: the actuation ramp ends at 0.1 s, plus "
                     "analysis.settle_time 0.02 s\""),
            std::string::npos)
      << all;
  const std::vector<std::string> rows = lines(csv);
  ASSERT_GE(rows.size(), 2u);
  EXPECT_EQ(rows.back().rfind("0.12,", 0), 0u) << rows.back();
  // settle_time where it has no meaning is refused
  const Result both = run(scene("prism.yaml") + " --set analysis.settle_time=0.5 --out /dev/null");
  EXPECT_EQ(both.code, 1) << both.output;
  EXPECT_NE(both.output.find("analysis.settle_time"), std::string::npos) << both.output;
  const Result statics = run(scene("quadruplex.yaml") + " --set analysis.settle_time=0.5 --out /dev/null");
  EXPECT_EQ(statics.code, 1) << statics.output;
  EXPECT_NE(statics.output.find("is not dynamic"), std::string::npos) << statics.output;
}

TEST(TensegrityRun, CablesAboveTheirYieldStrengthAreNamedOnce)
{
  // verticals 291 N on 7.07 mm^2: 41.2 MPa; rings 173 N: 24.5 MPa; a yield strength of 40 MPa between them
  const std::string summary = tmp("yield.yaml");
  const Result r = run(scene("prism.yaml") +
                       " --set materials.fibreglass.yield_strength=4e7 --out /dev/null "
                       "--summary " +
                       summary);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string all = text(summary);
  for (const char* name : { "V1", "V2", "V3" })
  {
    const std::string needle = std::string("cable '") + name + "' is above its material's yield_strength 4e+07 Pa";
    const size_t at = all.find(needle);
    EXPECT_NE(at, std::string::npos) << name << "\n" << all;
    EXPECT_EQ(all.find(needle, at + 1), std::string::npos) << name << " named twice\n" << all;
  }
  for (const char* name : { "R1", "R4" })
    EXPECT_EQ(all.find(std::string("cable '") + name + "' is above"), std::string::npos) << all;
  EXPECT_NE(all.find("first at t = 0 s"), std::string::npos) << all;
  // a bad value is refused with the key
  const Result bad = run(scene("prism.yaml") + " --set materials.fibreglass.yield_strength=-1 --out /dev/null");
  EXPECT_EQ(bad.code, 1) << bad.output;
  EXPECT_NE(bad.output.find("yield_strength"), std::string::npos) << bad.output;
}

TEST(TensegrityRun, NodesFileHasEveryNodesPositionPerOutputStep)
{
  const std::string csv = tmp("nodes_main.csv"), nodes = tmp("nodes.csv");
  const Result r = run(scene("prism.yaml") + " --set analysis.duration=0.1 --out " + csv + " --nodes " + nodes);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> main_rows = lines(csv), node_rows = lines(nodes);
  ASSERT_EQ(node_rows.size(), main_rows.size());
  EXPECT_EQ(node_rows[0],
            "t,B1_x,B1_y,B1_z,B2_x,B2_y,B2_z,B3_x,B3_y,B3_z,T1_x,T1_y,T1_z,T2_x,T2_y,T2_z,T3_x,T3_y,T3_z");
  // the scene's positions at t = 0; the height column (highest of T1-T3 above the ground at z = 0) on every row
  const std::vector<double> first = numbers(node_rows[1]);
  ASSERT_EQ(first.size(), 19u);
  EXPECT_NEAR(first[1], 0.0, 1e-9);
  EXPECT_NEAR(first[2], 0.5, 1e-9);
  EXPECT_NEAR(first[12], 0.8, 1e-9);  // T1_z
  for (size_t i = 1; i < node_rows.size(); ++i)
  {
    const std::vector<double> n = numbers(node_rows[i]), m = numbers(main_rows[i]);
    ASSERT_EQ(n[0], m[0]) << "row " << i;
    EXPECT_NEAR(std::max({ n[12], n[15], n[18] }), m[3], 1e-9) << "row " << i;  // height
  }
  // T1 is lifted by the actuation (0.02 m at the end of the ramp)
  EXPECT_NEAR(numbers(node_rows.back())[12], 0.82, 1e-6);
  // nowhere to write: refused before the run; a modal scene has no node rows
  const Result bad = run(scene("prism.yaml") + " --nodes /nonexistent/dir/n.csv --out /dev/null");
  EXPECT_EQ(bad.code, 1) << bad.output;
  EXPECT_NE(bad.output.find("cannot write '/nonexistent/dir/n.csv'"), std::string::npos) << bad.output;
  const Result check = run(scene("prism.yaml") + " --check --nodes " + nodes);
  EXPECT_EQ(check.code, 2) << check.output;
}

TEST(TensegrityRun, MembersFileHasEveryMembersForcePerOutputStep)
{
  const std::string csv = tmp("members_main.csv"), members = tmp("members.csv");
  const Result r = run(scene("quadruplex.yaml") + " --set analysis.max_actuation=0.5 --set analysis.steps=10 --out " +
                       csv + " --members " + members);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> main_rows = lines(csv), member_rows = lines(members);
  ASSERT_EQ(member_rows.size(), main_rows.size());
  // t, 12 cables x (tension, length, rest length), 4 struts
  std::vector<std::string> header;
  std::stringstream in(member_rows[0]);
  for (std::string cell; std::getline(in, cell, ',');)
    header.push_back(cell);
  ASSERT_EQ(header.size(), 1u + 12u * 3u + 4u);
  EXPECT_EQ(header[1], "C1_tension");
  EXPECT_EQ(header[2], "C1_length");
  EXPECT_EQ(header[3], "C1_rest_length");
  EXPECT_EQ(header.back(), "S4_force");
  const std::vector<double> first = numbers(member_rows[1]);
  EXPECT_NEAR(first[1], 200.0, 1e-6);                        // C1, a lower cable (Table 1)
  EXPECT_NEAR(first.back(), -200.0 * std::sqrt(6.0), 0.01);  // S4
  EXPECT_GT(first[2], first[3]);                             // stretched: longer than its rest length
  const Result modal = run(scene("quadruplex.yaml") + " --set analysis.type=modal --members " + members);
  EXPECT_EQ(modal.code, 2) << modal.output;
  const Result check = run(scene("prism.yaml") + " --check --members " + members);
  EXPECT_EQ(check.code, 2) << check.output;
}

// --vtk as ParaView reads it: the files read back with Python's XML parser (test/tools/read_vtk.py checks
// counts, offsets and array lengths) agree with --nodes, --members and --contacts step by step
TEST(TensegrityRun, VtkFilesAgreeWithTheCsvFiles)
{
  const std::string dir = tmp("vtk"), members = tmp("vtk_members.csv"), nodes = tmp("vtk_nodes.csv"),
                    contacts = tmp("vtk_contacts.csv");
  const Result r = run(scene("tower.yaml") +
                       " --set analysis.type=dynamic --set actuation.speed=2 --set analysis.duration=0.8 "
                       "--set analysis.output_interval=0.1 --out /dev/null --vtk " +
                       dir + " --members " + members + " --nodes " + nodes + " --contacts " + contacts);
  ASSERT_EQ(r.code, 0) << r.output;
  const Result read =
      active_tensegrity::test::runCommand("/usr/bin/python3 " + std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) +
                                          "/test/tools/read_vtk.py --csv " + dir + "/run.pvd 2>&1");
  ASSERT_EQ(read.code, 0) << read.output;
  std::vector<std::string> steps;
  std::stringstream in(read.output);
  for (std::string l; std::getline(in, l);)
    steps.push_back(l);
  const std::vector<std::string> member_rows = lines(members), node_rows = lines(nodes), contact_rows = lines(contacts);
  ASSERT_EQ(steps.size() + 1, member_rows.size());
  ASSERT_EQ(steps.size(), 9u);
  size_t touching_total = 0;
  for (size_t k = 0; k < steps.size(); ++k)
  {
    // t, contact-point cells, the first point (the first node, G1), the 16 strut cells' forces
    const std::vector<double> v = numbers(steps[k]), m = numbers(member_rows[k + 1]), n = numbers(node_rows[k + 1]);
    ASSERT_EQ(v.size(), 5u + 16u) << steps[k];
    EXPECT_NEAR(v[0], m[0], 1e-9) << k;
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(v[2 + c], n[1 + c], 1e-9) << k;
    for (size_t i = 0; i < 16; ++i)
      EXPECT_NEAR(v[5 + i], m[m.size() - 16 + i], 1e-6 * (1.0 + std::abs(v[5 + i]))) << k;
    // two contact points per touching pair (the contact rows' first field is t)
    size_t touching = 0;
    for (size_t i = 1; i < contact_rows.size(); ++i)
      touching += std::abs(std::stod(contact_rows[i].substr(0, contact_rows[i].find(','))) - m[0]) < 1e-9;
    EXPECT_EQ(v[1], 2.0 * touching) << k;
    touching_total += touching;
  }
  EXPECT_GT(touching_total, 0u) << "the fold should bring struts into contact";
  // a directory that cannot be made: refused before the run
  const Result bad = run(scene("prism.yaml") + " --vtk /proc/no/such/dir --out /dev/null");
  EXPECT_EQ(bad.code, 1) << bad.output;
  EXPECT_NE(bad.output.find("--vtk: cannot make the directory '/proc/no/such/dir'"), std::string::npos) << bad.output;
}
