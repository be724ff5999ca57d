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

/// OPENBLAS_THREAD_TIMEOUT for the program: its pool's threads spin 2^20 cycles (about 0.4 ms) after a BLAS call
/// before they sleep. OpenBLAS, linked for CHOLMOD's supernodal factorisation, starts the pool when the program loads,
/// and by default each thread spins on sched_yield for 2^28 cycles (about 0.1 s): on 2 cores it held one for the first
/// 0.1 s of every run, while the load and the morph's parallel loops ran on the other (cow -> horse, Table II, ten
/// interleaved pairs, 2026-12-08: the morph stage's median 0.195 -> 0.168 s). Shorter than 2^20 slows CHOLMOD, whose
/// BLAS calls then find the pool asleep (2^4, OpenBLAS's shortest: cow -> horse at 40 voxels, factorisation 2.43-2.73 s
/// against 2.22-2.45 s; at 2^20 2.03-2.48 s against 2.18-2.64 s, three interleaved runs each).
extern const char* const kBlasThreadTimeout;

/// Sets the environment the program is to start with (glibc reads its tunables only at process start, before any
/// constructor, and OpenBLAS its variables when it loads): appends kAllocatorTunables to GLIBC_TUNABLES unless it
/// already sets glibc.malloc.hugetlb (ours, set before, or the user's choice, which wins), and sets
/// OPENBLAS_THREAD_TIMEOUT to kBlasThreadTimeout unless it is set. Returns whether it changed anything; does nothing
/// when MORPHMAP_NO_ALLOCATOR_TUNING is set (to anything but 0). `previous` receives GLIBC_TUNABLES as it was.
bool set_startup_environment(std::string& previous);

/// Called first in main: when set_startup_environment() changes the environment, re-executes the same binary with
/// the same arguments. The process keeps its pid, so a parent's wait and PR_SET_PDEATHSIG still apply. The `morphmap`
/// launcher (app/launcher.cpp) sets the environment before it starts the program, so this re-executes only a program
/// started directly (morphmap-run). When the re-execution fails the run goes on with glibc's defaults.
void tune_startup(char** argv);

/// The path of the running binary (/proc/self/exe), or "" when it cannot be read.
std::string executable_path();

/// GLIBC_TUNABLES as this process sees it ("" when unset): report.json records it under "allocator".
std::string allocator_tunables();

/// OPENBLAS_THREAD_TIMEOUT as this process sees it ("" when unset): report.json records it under "allocator" too.
std::string blas_thread_timeout();

}  // namespace morphmap
