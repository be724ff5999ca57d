// Command-line options of a pipeline run, shared by `map`, `demo` and the jobs of `batch` (a batch job's
// manifest keys are these options' long names, parsed by the same code so both accept the same values).
#pragma once

#include <CLI/CLI.hpp>

#include "app/pipeline.h"

namespace morphmap {

/// Adds every PipelineOptions option (--voxels, --solver, --compare-solvers, ...) to `cmd`, writing into `o`.
void add_pipeline_options(CLI::App& cmd, PipelineOptions& o);

}  // namespace morphmap
