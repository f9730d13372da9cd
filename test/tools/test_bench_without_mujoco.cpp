// tensegrity_bench built without MuJoCo (CMake found no libmujoco-dev, or -DACTIVE_TENSEGRITY_WITH_MUJOCO=OFF):
// its MuJoCo options are refused up front with a clear message and exit status 2, and the rest of the
// work-precision command is untouched. Built only in that configuration (CMakeLists.txt).
#include <sys/wait.h>

#include <cstdio>
#include <string>

#include <gtest/gtest.h>

#include "command.h"

namespace
{
using Result = active_tensegrity::test::CommandResult;

Result bench(const std::string& args)
{
  return active_tensegrity::test::runCommand(std::string(TENSEGRITY_BENCH_PATH) + " " + args + " 2>&1");
}

const std::string kPrism = std::string(ACTIVE_TENSEGRITY_SOURCE_DIR) + "/config/scenes/prism.yaml";
}  // namespace

TEST(BenchWithoutMujoco, MujocoOptionsSayBuiltWithoutMujoco)
{
  for (const std::string option : { "--mujoco-dts 1e-3", "--mujoco-integrators euler", "--mujoco-contact-force 10" })
  {
    const Result r = bench("work-precision " + kPrism + " --set analysis.type=dynamic " + option);
    EXPECT_EQ(r.code, 2) << option << ":\n" << r.output;
    EXPECT_NE(r.output.find("built without MuJoCo"), std::string::npos) << option << ":\n" << r.output;
  }
}

TEST(BenchWithoutMujoco, OtherOptionsStillChecked)
{
  const Result r = bench("work-precision " + kPrism + " --set analysis.type=dynamic --dts 0");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_EQ(r.output.find("MuJoCo"), std::string::npos) << r.output;
}
