// The benchmarks' main: the process runs with the start-up settings of the `morphmap` program (app/allocator.h),
// so that a benchmark that allocates its arrays in every repetition measures what the pipeline's stage costs.
// With glibc's defaults each repetition faulted its arrays in afresh: BM_Assemble/cow-horse took 0.38 s of assembly
// against 0.13 s with the program's settings (2026-12-04).
#include <benchmark/benchmark.h>

#include "app/allocator.h"

int main(int argc, char** argv) {
  morphmap::tune_startup(argv);  // re-executes this binary once with the tunables set
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
