// The C++ example of README.md ("Using the C++ library"): the README shows test/example/fold_tower.cpp as it is,
// and that program builds, runs and prints what the README says it prints. Its numbers come from a dynamic fold
// whose path depends on the processor's rounding: checked loosely, never to the digit.
#include <stdio.h>
#include <sys/wait.h>

#include <cmath>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace
{
const std::string kSourceDir = ACTIVE_TENSEGRITY_SOURCE_DIR;

std::string readFile(const std::string& path)
{
  std::ifstream in(path, std::ios::binary);
  EXPECT_TRUE(in.good()) << "cannot read " << path;
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

/// The text of every ```cpp block of a Markdown file, each line with its newline.
std::vector<std::string> cppBlocks(const std::string& markdown)
{
  std::vector<std::string> blocks;
  std::istringstream in(markdown);
  std::string line;
  bool inside = false;
  while (std::getline(in, line))
  {
    if (!inside && line == "```cpp")
    {
      inside = true;
      blocks.emplace_back();
    }
    else if (inside && line.rfind("```", 0) == 0)
      inside = false;
    else if (inside)
      blocks.back() += line + "\n";
  }
  EXPECT_FALSE(inside) << "a ```cpp block is not closed";
  return blocks;
}

/// Runs a command line through the shell: its exit status (-1 when it did not exit) and its output.
int run(const std::string& command_line, std::string* output)
{
  FILE* pipe = popen(command_line.c_str(), "r");
  if (!pipe)
    return -1;
  char buffer[4096];
  while (fgets(buffer, sizeof buffer, pipe))
    *output += buffer;
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}
}  // namespace

TEST(ReadmeExample, ReadmeShowsTheExampleFile)
{
  const std::vector<std::string> blocks = cppBlocks(readFile(kSourceDir + "/README.md"));
  ASSERT_EQ(blocks.size(), 1u) << "README.md should hold one ```cpp block, test/example/fold_tower.cpp";
  EXPECT_EQ(blocks[0], readFile(kSourceDir + "/test/example/fold_tower.cpp"))
      << "README.md's ```cpp block and test/example/fold_tower.cpp differ: copy the file into the README";
}

TEST(ReadmeExample, RunsAndPrintsTheFold)
{
  // from the package's root, as the README runs it (the default scene path is relative to it)
  std::string output;
  const int code = run("cd '" + kSourceDir + "' && '" + std::string(FOLD_TOWER_PATH) + "' 2>&1", &output);
  ASSERT_EQ(code, 0) << output;

  std::smatch m;
  const std::regex status_line(R"(status converged: (\d+) time steps, (\d+) Newton iterations\n)");
  ASSERT_TRUE(std::regex_search(output, m, status_line)) << output;
  EXPECT_GT(std::stol(m[1]), 0) << output;
  EXPECT_GE(std::stol(m[2]), std::stol(m[1])) << "at least one Newton iteration per step\n" << output;

  // the tower starts 2 m high and folds; the struts touch at the end of the fold
  const std::regex height_line(R"(final height (\S+) m, (\d+) contacts\n)");
  ASSERT_TRUE(std::regex_search(output, m, height_line)) << output;
  const double height = std::stod(m[1]);
  EXPECT_GT(height, 0.1) << output;
  EXPECT_LT(height, 1.9) << output;

  // one line per peak, each finite, reached within the run's second
  const std::regex peak_line(R"(peak (\w+) (\S+) at t = (\S+) s\n)");
  std::set<std::string> names;
  for (auto it = std::sregex_iterator(output.begin(), output.end(), peak_line); it != std::sregex_iterator(); ++it)
  {
    const std::string name = (*it)[1];
    const double value = std::stod((*it)[2]), t = std::stod((*it)[3]);
    names.insert(name);
    EXPECT_TRUE(std::isfinite(value)) << name << "\n" << output;
    EXPECT_GE(t, 0.0) << name << "\n" << output;
    EXPECT_LE(t, 1.0 + 1e-9) << name << "\n" << output;
    if (name == "max_normal_force")
    {
      EXPECT_GT(value, 0.0) << "the folding tower's struts touch\n" << output;
    }
  }
  for (const char* name :
       { "actuation_force", "max_normal_force", "max_friction_force", "max_strut_bending_stress", "max_cable_stress" })
    EXPECT_EQ(names.count(name), 1u) << name << "\n" << output;
}
