// Command-line options of a pipeline run, shared by `map`, `demo` and the jobs of `batch` (a batch job's
// manifest keys are these options' long names, parsed by the same code so both accept the same values).
#pragma once

#include <CLI/CLI.hpp>
#include <limits>

#include "app/pipeline.h"

namespace morphmap {

/// Adds every PipelineOptions option (--voxels, --solver, --compare-solvers, ...) to `cmd`, writing into `o`.
void add_pipeline_options(CLI::App& cmd, PipelineOptions& o);

/// Validator of an integer option: a whole number in [lo, hi] (hi = INT_MAX: no upper bound), whose message names the
/// range and the value given ("must be a whole number from 4 to 4096, not 'abc'").
CLI::Validator whole_number(int lo, int hi = std::numeric_limits<int>::max());

}  // namespace morphmap
