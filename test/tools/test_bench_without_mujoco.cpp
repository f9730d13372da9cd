// tensegrity_bench built without MuJoCo (CMake found no libmujoco-dev, or -DACTIVE_TENSEGRITY_WITH_MUJOCO=OFF):
// its MuJoCo options are refused up front with a clear message and exit status 2, and the rest of the
// work-precision command is untouched. Built only in that configuration (CMakeLists.txt).
#include <sys/wait.h>

#include <cstdio>
#include <string>

#include <gtest/gtest.h>

namespace
{
struct Result
{
  int code = -1;
  std::string output;  // stdout and stderr together
};

Result bench(const std::string& args)
{
  const std::string cmd = std::string(TENSEGRITY_BENCH_PATH) + " " + args + " 2>&1";
  Result r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe)
    return r;
  char buffer[4096];
  while (fgets(buffer, sizeof buffer, pipe))
    r.output += buffer;
  const int status = pclose(pipe);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
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
