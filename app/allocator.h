// The allocator settings of the `morphmap` process. Every stage of the pipeline allocates arrays of tens to hundreds
// of megabytes (the 4D mesh, the Laplace rows, the multigrid levels, the tracer's caches) and writes them once; on
// the 2-core virtual machines we run on, faulting those pages in 4 KiB at a time, and faulting them in again after
// glibc hands freed arrays back to the kernel, took a third of a whole run (sphere -> Buddha, Table II: 3.6 s against
// 2.1 s with the settings below, measured interleaved in one session).
#pragma once

#include <string>

namespace morphmap {

/// The glibc tunables morphmap runs with: transparent huge pages for malloc's memory (2 MiB faults), freed memory
/// kept for reuse instead of trimmed (trim_threshold, top_pad), and blocks below 32 MiB (glibc's largest allowed
/// threshold) served from the heap, not from fresh mappings.
extern const char* const kAllocatorTunables;

/// Appends kAllocatorTunables to GLIBC_TUNABLES in this process's environment, for a program about to be executed
/// (glibc reads its tunables only at process start, before any constructor). Does nothing, and returns false, when
/// MORPHMAP_NO_ALLOCATOR_TUNING is set (to anything but 0) or when GLIBC_TUNABLES already sets glibc.malloc.hugetlb
/// (ours, set before, or the user's choice, which wins). `previous` receives GLIBC_TUNABLES as it was.
bool set_allocator_tunables(std::string& previous);

/// Called first in main: when set_allocator_tunables() changes the environment, re-executes the same binary with the
/// same arguments. The process keeps its pid, so a parent's wait and PR_SET_PDEATHSIG still apply. The `morphmap`
/// launcher (app/launcher.cpp) sets the tunables before it starts the program, so this re-executes only a program
/// started directly (morphmap-run). When the re-execution fails the run goes on with glibc's defaults.
void tune_allocator(char** argv);

/// The path of the running binary (/proc/self/exe), or "" when it cannot be read.
std::string executable_path();

/// GLIBC_TUNABLES as this process sees it ("" when unset): report.json records it under "allocator".
std::string allocator_tunables();

}  // namespace morphmap
