// Allocator settings of the morphmap process (see allocator.h for the measurement behind them).
#include "app/allocator.h"

#include <unistd.h>

#include <climits>
#include <cstdlib>
#include <cstring>

namespace morphmap {

const char* const kAllocatorTunables =
    "glibc.malloc.hugetlb=1:glibc.malloc.trim_threshold=4294967295:glibc.malloc.top_pad=268435456:"
    "glibc.malloc.mmap_threshold=33554432";

std::string allocator_tunables() {
  const char* value = std::getenv("GLIBC_TUNABLES");
  return value != nullptr ? value : "";
}

bool set_allocator_tunables(std::string& previous) {
  previous = allocator_tunables();
  const char* opt_out = std::getenv("MORPHMAP_NO_ALLOCATOR_TUNING");
  if (opt_out != nullptr && std::strcmp(opt_out, "0") != 0) return false;
  // Already set (by us before, or by the user): never append twice.
  if (previous.find("glibc.malloc.hugetlb") != std::string::npos) return false;
  const std::string tunables = previous.empty() ? kAllocatorTunables : previous + ":" + kAllocatorTunables;
  return ::setenv("GLIBC_TUNABLES", tunables.c_str(), 1) == 0;
}

std::string executable_path() {
  char self[PATH_MAX];
  const ssize_t length = ::readlink("/proc/self/exe", self, sizeof(self));
  return length > 0 && length < ssize_t(sizeof(self)) ? std::string(self, std::size_t(length))
                                                      : std::string();  // not truncated
}

void tune_allocator(char** argv) {
  const std::string self = executable_path();
  if (self.empty()) return;
  std::string previous;
  if (!set_allocator_tunables(previous)) return;
  ::execv(self.c_str(), argv);
  // Only reached when execv failed: run on with the defaults, and leave the environment as it was.
  if (previous.empty())
    ::unsetenv("GLIBC_TUNABLES");
  else
    ::setenv("GLIBC_TUNABLES", previous.c_str(), 1);
}

}  // namespace morphmap
