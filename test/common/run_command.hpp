#pragma once

// Runs a command line the way a user would and captures what it prints, for tests of the
// command-line tools and of the node's start-up.

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace mild::test {

struct CommandResult {
  int status = -1;     // exit status, -1 when killed by a signal or not started
  std::string output;  // stdout and stderr
};

inline CommandResult runCommand(const std::string& command) {
  CommandResult run;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return run;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) run.output.append(buffer, n);
  const int raw = pclose(pipe);
  run.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  return run;
}

// The last non-empty line of a command's output (where the tools put their --json object).
inline std::string lastLine(const std::string& output) {
  size_t end = output.find_last_not_of('\n');
  if (end == std::string::npos) return "";
  const size_t start = output.rfind('\n', end);
  return output.substr(start == std::string::npos ? 0 : start + 1,
                       end - (start == std::string::npos ? 0 : start + 1) + 1);
}

}  // namespace mild::test
