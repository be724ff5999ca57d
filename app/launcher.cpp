// The `morphmap` command as it is started: it sets the allocator's glibc tunables and OpenBLAS's thread timeout
// (app/allocator.h) and executes the program itself, morphmap-run, from its own folder. The program links OpenVDB,
// OpenBLAS and the rest, and loading them costs a process about 60 ms (57 k symbol bindings in libopenvdb alone,
// LD_DEBUG=bindings); re-executing the program to apply the tunables paid that twice. This launcher needs nothing but
// libc and libstdc++.
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "app/allocator.h"

int main(int /*argc*/, char** argv) {
  const std::string path = morphmap::executable_path();
  if (path.empty()) {
    std::fprintf(stderr, "morphmap: cannot find its own path (/proc/self/exe: %s)\n", std::strerror(errno));
    return 127;
  }
  const std::string program = path.substr(0, path.rfind('/') + 1) + "morphmap-run";
  std::string previous;
  morphmap::set_startup_environment(previous);
  ::execv(program.c_str(), argv);
  std::fprintf(stderr, "morphmap: cannot run %s (%s)\n", program.c_str(), std::strerror(errno));
  return 127;
}
