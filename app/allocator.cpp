// Start-up settings of the morphmap process: the allocator's tunables and OpenBLAS's spin (see allocator.h for the
// measurements behind them).
#include "app/allocator.h"

#include <unistd.h>

#include <climits>
#include <cstdlib>
#include <cstring>

namespace morphmap {

const char* const kAllocatorTunables =
    "glibc.malloc.hugetlb=1:glibc.malloc.trim_threshold=4294967295:glibc.malloc.top_pad=268435456:"
    "glibc.malloc.mmap_threshold=33554432";

const char* const kBlasThreadTimeout = "20";

namespace {

std::string environment(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr ? value : "";
}

}  // namespace

std::string allocator_tunables() { return environment("GLIBC_TUNABLES"); }

std::string blas_thread_timeout() { return environment("OPENBLAS_THREAD_TIMEOUT"); }

bool set_startup_environment(std::string& previous) {
  previous = allocator_tunables();
  const char* opt_out = std::getenv("MORPHMAP_NO_ALLOCATOR_TUNING");
  if (opt_out != nullptr && std::strcmp(opt_out, "0") != 0) return false;
  bool changed = false;
  // Already set (by us before, or by the user): never append twice.
  if (previous.find("glibc.malloc.hugetlb") == std::string::npos) {
    const std::string tunables = previous.empty() ? kAllocatorTunables : previous + ":" + kAllocatorTunables;
    changed = ::setenv("GLIBC_TUNABLES", tunables.c_str(), 1) == 0;
  }
  if (std::getenv("OPENBLAS_THREAD_TIMEOUT") == nullptr)
    changed = ::setenv("OPENBLAS_THREAD_TIMEOUT", kBlasThreadTimeout, 1) == 0 || changed;
  return changed;
}

std::string executable_path() {
  char self[PATH_MAX];
  const ssize_t length = ::readlink("/proc/self/exe", self, sizeof(self));
  return length > 0 && length < ssize_t(sizeof(self)) ? std::string(self, std::size_t(length))
                                                      : std::string();  // not truncated
}

void tune_startup(char** argv) {
  const std::string self = executable_path();
  if (self.empty()) return;
  std::string previous;
  if (!set_startup_environment(previous)) return;
  ::execv(self.c_str(), argv);
  // Only reached when execv failed: run on with the defaults, and leave the environment as it was.
  if (previous.empty())
    ::unsetenv("GLIBC_TUNABLES");
  else
    ::setenv("GLIBC_TUNABLES", previous.c_str(), 1);
}

}  // namespace morphmap
