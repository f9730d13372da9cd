// The short stability stress cases (tensegrity_bench stress --quick), run as a user runs them: every
// case ends converged, or stopped with a named status and a message; never with a non-finite number;
// a strut pushed through another is refused (counted) and reported, never accepted silently.
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

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
}  // namespace

TEST(Stress, QuickCasesEndConvergedOrWithAStatusNeverNonFinite)
{
  const std::string cmd = std::string(TENSEGRITY_BENCH_PATH) + " stress --quick 2>&1";
  FILE* pipe = popen(cmd.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::vector<std::vector<std::string>> rows;
  char line[8192];
  while (fgets(line, sizeof line, pipe))
  {
    std::string l(line);
    if (l.rfind("| ", 0) == 0 && l.find("| case |") == std::string::npos)
      rows.push_back(cells(l));
  }
  const int status = pclose(pipe);
  EXPECT_EQ(WIFEXITED(status) ? WEXITSTATUS(status) : -1, 0);
  ASSERT_GE(rows.size(), 10u);
  int converged = 0, passed_through = 0;
  for (const auto& r : rows)
  {
    ASSERT_EQ(r.size(), 10u) << r[0];
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
