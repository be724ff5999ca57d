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

/// Called first in main: when GLIBC_TUNABLES does not carry kAllocatorTunables yet, appends them and re-executes the
/// same binary with the same arguments (glibc reads its tunables only at process start, before any constructor).
/// The process keeps its pid, so a parent's wait and PR_SET_PDEATHSIG still apply. Does nothing when
/// MORPHMAP_NO_ALLOCATOR_TUNING is set (to anything but 0), when GLIBC_TUNABLES already sets glibc.malloc.hugetlb
/// (the user's choice wins), or when the re-execution fails (the run goes on with glibc's defaults).
void tune_allocator(char** argv);

/// GLIBC_TUNABLES as this process sees it ("" when unset): report.json records it under "allocator".
std::string allocator_tunables();

}  // namespace morphmap
