/// Runs a command line through the shell, as a user would, for the tests of the package's executables.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <string>

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

}  // namespace active_tensegrity::test
