// Helpers of the tests that run the morphmap binary (tests/app/cli_test.cpp, batch_test.cpp,
// tests/io/render_test.cpp): one command's exit status and output, and a scratch folder per test.
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

namespace morphmap::test {

struct CommandRun {
  int status = -1;     ///< exit status, -1 when the command could not run or died of a signal
  std::string output;  ///< stdout and stderr, interleaved
};

/// Runs `morphmap ARGS` (MORPHMAP_BINARY, set by CMake) through the shell and waits for it.
inline CommandRun run_command(const std::string& args) {
  const std::string command = std::string(MORPHMAP_BINARY) + " " + args + " 2>&1";
  CommandRun r;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buffer{};
  while (fgets(buffer.data(), int(buffer.size()), pipe)) r.output += buffer.data();
  const int raw = pclose(pipe);
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  return r;
}

/// An empty folder in the system's temporary folder named after the running test and this process
/// (`<prefix><pid>_<test name>`), so that tests run in parallel by CTest never share one.
inline std::filesystem::path fresh_test_dir(const std::string& prefix) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      (prefix + std::to_string(::getpid()) + "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace morphmap::test
