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

void tune_allocator(char** argv) {
  const char* opt_out = std::getenv("MORPHMAP_NO_ALLOCATOR_TUNING");
  if (opt_out != nullptr && std::strcmp(opt_out, "0") != 0) return;
  const std::string current = allocator_tunables();
  // Already set (by us before the re-execution, or by the user): never re-execute twice.
  if (current.find("glibc.malloc.hugetlb") != std::string::npos) return;
  const std::string tunables = current.empty() ? kAllocatorTunables : current + ":" + kAllocatorTunables;
  char self[PATH_MAX];
  const ssize_t length = ::readlink("/proc/self/exe", self, sizeof(self) - 1);
  if (length <= 0) return;
  self[length] = '\0';
  if (::setenv("GLIBC_TUNABLES", tunables.c_str(), 1) != 0) return;
  ::execv(self, argv);
  // Only reached when execv failed: run on with the defaults, and leave the environment as it was.
  if (current.empty())
    ::unsetenv("GLIBC_TUNABLES");
  else
    ::setenv("GLIBC_TUNABLES", current.c_str(), 1);
}

}  // namespace morphmap
