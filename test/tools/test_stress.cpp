// The short stability stress cases (tensegrity_bench stress --quick), run as a user runs them: every
// case ends converged, or stopped with a named status and a message; never with a non-finite number;
// a strut pushed through another is refused (counted) and reported, never accepted silently.
#include <cstdio>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "command.h"

namespace
{
std::vector<std::string> cells(const std::string& row)
{
  std::vector<std::string> out;
  std::stringstream ss(row);
  std::string c;
  std::getline(ss, c, '|');  // before the first bar
  while (std::getline(ss, c, '|'))
  {
    const size_t a = c.find_first_not_of(" \n"), b = c.find_last_not_of(" \n");
    out.push_back(a == std::string::npos ? "" : c.substr(a, b - a + 1));
  }
  if (!out.empty() && out.back().empty())
    out.pop_back();
  return out;
}

// The rows of `tensegrity_bench stress ARGS` (its table's cells), its exit status and its whole output.
struct StressRun
{
  std::vector<std::vector<std::string>> rows;
  int status = -1;
  std::string output;
};

StressRun runStress(const std::string& args)
{
  const active_tensegrity::test::CommandResult r =
      active_tensegrity::test::runCommand(std::string(TENSEGRITY_BENCH_PATH) + " stress " + args + " 2>&1");
  StressRun run;
  run.status = r.code;
  run.output = r.output;
  std::stringstream lines(r.output);
  std::string l;
  while (std::getline(lines, l))
    if (l.rfind("| ", 0) == 0 && l.find("| case |") == std::string::npos)
      run.rows.push_back(cells(l));
  return run;
}

const char* const kTowerLargeSteps = "tower V = 0.5 m/s, dt = 1e-2 s";
}  // namespace

// every short case but the tower at 10 ms steps (a case of its own below: about half of the time)
TEST(Stress, QuickCasesEndConvergedOrWithAStatusNeverNonFinite)
{
  const StressRun run = runStress(std::string("--quick --skip '") + kTowerLargeSteps + "'");
  EXPECT_EQ(run.status, 0);
  const auto& rows = run.rows;
  ASSERT_GE(rows.size(), 10u);
  int converged = 0, passed_through = 0;
  for (const auto& r : rows)
  {
    ASSERT_EQ(r.size(), 10u) << r[0];
    EXPECT_NE(r[0], kTowerLargeSteps);
    const std::string& ended = r[1];
    EXPECT_EQ(r[8], "yes") << r[0] << ": non-finite numbers";
    if (ended == "converged")
      ++converged;
    else
    {
      // a named status, then the solver's message
      EXPECT_NE(ended.find(": "), std::string::npos) << r[0] << ": " << ended;
      EXPECT_TRUE(ended.rfind("passed_through", 0) == 0 || ended.rfind("max_iterations", 0) == 0 ||
                  ended.rfind("singular", 0) == 0)
          << r[0] << ": " << ended;
      if (ended.rfind("passed_through", 0) == 0)
      {
        ++passed_through;
        EXPECT_GT(std::stoi(r[5]), 0) << r[0] << ": crossings must have been refused, and counted";
      }
    }
    std::printf("[ measured ] %s: %s\n", r[0].c_str(), ended.substr(0, 60).c_str());
  }
  // cases that hold; any the model cannot hold are reported with their status (above), not hidden. (Since the
  // cores of layered struts meet, the tower's fast folds hold too; a run that ends passed_through is tested in
  // test_contact_dynamics, ContactTunnelling.)
  EXPECT_GT(converged, 0);
  std::printf("[ measured ] %d converged, %d passed_through\n", converged, passed_through);
}

// The tower folding at 10 ms steps, 50 times the paper's: the step cuts carry it into contact. Whether they carry it to
// the end is chaotic at this step (measured: dt 9.8, 9.9 and 10.1 ms fold to the end, 10 and 10.2 ms stop at 2.54 and
// 1.50 s with Newton failing at dt_min, and which do changes with round-off): the run ends converged at its end time or
// with that status at an earlier one, never with a non-finite number, and it has cut steps.
TEST(Stress, TheTowerAtStepsOf10msFoldsToTheEndThroughStepCuts)
{
  const StressRun run = runStress(std::string("--case '") + kTowerLargeSteps + "'");
  EXPECT_EQ(run.status, 0);
  ASSERT_EQ(run.rows.size(), 1u);
  const auto& r = run.rows[0];
  ASSERT_EQ(r.size(), 10u);
  EXPECT_EQ(r[0], kTowerLargeSteps);
  EXPECT_EQ(r[8], "yes") << "non-finite numbers";
  if (r[1] == "converged")
    EXPECT_NEAR(std::stod(r[2]), 4.0, 1e-9) << "simulated time";
  else
  {
    EXPECT_EQ(r[1].rfind("max_iterations", 0), 0u) << r[1];
    EXPECT_NE(r[1].find("step cut to"), std::string::npos) << r[1];
    EXPECT_GT(std::stod(r[2]), 1.0) << "simulated time: into the fold's contact";
    EXPECT_LT(std::stod(r[2]), 4.0);
  }
  EXPECT_GT(std::stoi(r[4]), 0) << "the step cuts that carry it";
  std::printf("[ measured ] %s: %s steps, %s step cuts, %s s wall\n", r[0].c_str(), r[3].c_str(), r[4].c_str(),
              r[9].c_str());
}

// a misspelt case is refused, not run as an empty selection; a good one runs the cases it names
TEST(Stress, ASelectionThatNamesNoCaseIsRefused)
{
  const std::vector<std::pair<std::string, std::string>> bad = {
    { "--case 'no such case'", "no case's name contains 'no such case' (--case)" },
    { "--skip 'no such case'", "no case's name contains 'no such case' (--skip)" },
    { "--case", "missing or empty text after '--case'" },
    { "--skip ''", "missing or empty text after '--skip'" },
    { "--quick --quick", "repeated argument '--quick'" },
    { "--quick --case 'tower V = 5 m/s'", "the selection leaves no case to run" },
  };
  for (const auto& [args, message] : bad)
  {
    const StressRun run = runStress(args);
    EXPECT_EQ(run.status, 2) << args;
    EXPECT_NE(run.output.find(message), std::string::npos) << args << ": " << run.output;
    EXPECT_TRUE(run.rows.empty()) << args;
  }
  const StressRun good = runStress("--case 'two struts' --skip '10 m/s'");
  EXPECT_EQ(good.status, 0);
  ASSERT_EQ(good.rows.size(), 1u);
  EXPECT_EQ(good.rows[0][0], "two struts 1 degree apart pressed side by side, 1 m/s");
}
