// docs/tutorial.md as a new user runs it: scripts/run_tutorial executes every command block marked bash,
// in order, in a fresh directory (the generator, form-finding, --check, the static and dynamic folds, the
// exports, the node driven through its topics and its planning service on a ROS master of its own). A
// command the docs show that no longer works fails this test.
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "../tools/command.h"

TEST(Tutorial, EveryBashBlockRuns)
{
  // the script in the repository (the workspace's package folder is a set of links to it)
  const std::string script =
      std::filesystem::canonical(std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/scripts/run_tutorial").string();
  const active_tensegrity::test::CommandResult r = active_tensegrity::test::runCommand(script + " 2>&1");
  EXPECT_EQ(r.code, 0) << r.output;
  // the last block ran to its end: the node took the command and was stopped
  EXPECT_NE(r.output.find("grep -q 'commands_rejected: 0' status.txt"), std::string::npos) << r.output;
}
