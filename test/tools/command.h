/// Runs a command line through the shell, as a user would, for the tests of the package's executables.
#pragma once

#include <stdlib.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include <gtest/gtest.h>

namespace active_tensegrity::test
{
struct CommandResult
{
  int code = -1;       // exit status (-1 when it could not start or did not exit)
  std::string output;  // stdout, and stderr when the command line redirects it (2>&1)
};

inline CommandResult runCommand(const std::string& command_line)
{
  CommandResult r;
  FILE* pipe = popen(command_line.c_str(), "r");
  if (!pipe)
    return r;
  char buffer[4096];
  while (fgets(buffer, sizeof buffer, pipe))
    r.output += buffer;
  const int status = pclose(pipe);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

/// A path for a test's file `name` in a directory of this process's own: made under gtest's TempDir() at the
/// first call, removed with its files when the process exits. Two runs of a test binary at once (two
/// workspaces on one machine) so never share a file.
inline std::string scratchPath(const std::string& name)
{
  struct Dir
  {
    std::string path;
    Dir()
    {
      std::string pattern = ::testing::TempDir() + "active_tensegrity_XXXXXX";
      std::vector<char> buffer(pattern.begin(), pattern.end());
      buffer.push_back('\0');
      if (!mkdtemp(buffer.data()))
        throw std::runtime_error("cannot make a scratch directory from " + pattern);
      path = std::string(buffer.data()) + "/";
    }
    ~Dir()
    {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  };
  static const Dir dir;
  return dir.path + name;
}

}  // namespace active_tensegrity::test
