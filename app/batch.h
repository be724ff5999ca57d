// `morphmap batch`: many `map` runs from a JSON manifest, one after another, each in its own folder, with a
// summary in the columns of the paper's Table II (execution statistics, paper §9). Resumable and crash-safe:
// a job is complete exactly when its folder holds report.json written for the job's current arguments.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace morphmap {

struct BatchJob {
  std::string name;               ///< folder name under the batch's output directory (unique, plain file name)
  std::vector<std::string> args;  ///< `map` arguments: SOURCE TARGET [options], without -o (see job_command)
};

/// Reads a manifest: {"defaults": {KEY: VALUE, ...}, "jobs": [{"name": ..., "source": ..., "target": ..., KEY:
/// VALUE, ...}, ...]} (or just the array of jobs). KEY is any long option of `map` without its dashes
/// ("voxels", "time-steps", "solver", "compare-solvers", "max-memory", ...); a flag takes true/false, a list
/// option an array. Relative mesh paths are relative to the manifest's folder. Every job's options are parsed
/// by `map`'s own parser, so the whole manifest is checked before anything runs. Throws InvalidInput naming
/// the manifest, the job and the problem (unknown key, missing source or target, bad value, duplicate name).
std::vector<BatchJob> read_manifest(const std::string& path);

/// The same from the manifest's text; `path` names it in messages and anchors relative mesh paths.
std::vector<BatchJob> parse_manifest(const std::string& text, const std::string& path);

/// The stages `map --progress` reports for these `map` arguments (a job's args), in the order it reports them
/// (app/pipeline.cpp's run_pipeline): the batch's status line names the stage after the last one reported as the one
/// running. tests/app/batch_test.cpp checks the list against real runs.
std::vector<std::string> planned_stages(const std::vector<std::string>& map_args);

/// One row of summary.csv / summary.md: Table II's columns plus total time and peak memory. Numbers that do
/// not apply (no diffusion solve, failed job) are absent.
struct SummaryRow {
  std::string job;
  std::string status;                ///< "ok", "failed", "interrupted" or "pending" (not run yet)
  std::optional<std::int64_t> tets;  ///< tetrahedra of the 4D mesh
  std::optional<int> time_steps;
  std::optional<int> diffusion_iterations;  ///< Gauss-Seidel sweeps (the map's solver or a comparison solve)
  std::optional<double> diffusion_seconds;  ///< set-up + solve
  std::optional<double> diffusion_change;   ///< mean |change| per unknown in the last sweep (paper's "conv.")
  std::string solve_backend;                ///< the direct or implicit solve: cg, cholmod, cg-ic, ldlt
  std::optional<int> solve_iterations;
  std::optional<double> solve_seconds;       ///< set-up (factorisation, preconditioner) + solve
  std::optional<double> solve_residual;      ///< relative residual |b - Ax| / |b|
  std::optional<std::int64_t> label_passes;  ///< transport's dependency wavefronts (sequential passes)
  std::optional<double> label_seconds;
  std::optional<double> map_seconds;         ///< the map end to end: total_seconds less the comparison solves
  std::optional<double> total_seconds;       ///< the whole job, comparison solves included
  std::optional<double> cpu_seconds;         ///< the job's CPU time (user + system, all threads)
  std::optional<double> system_cpu_seconds;  ///< the system (kernel) part of cpu_seconds
  std::optional<std::int64_t> peak_memory_bytes;
  std::string warnings;  ///< report.json's topology warnings, joined by "; " (the lattice changed A's or B's topology)
  std::string error;     ///< failed: the job's one-line error
};

/// The row of a job from the text of its report.json (status "ok"). Throws InvalidInput if it is not JSON.
SummaryRow summary_row(const std::string& job, const std::string& report_json);

/// summary.csv (RFC 4180 quoting) and summary.md (a Markdown table) of the rows, in order.
std::string summary_csv(const std::vector<SummaryRow>& rows);
std::string summary_markdown(const std::vector<SummaryRow>& rows);

struct BatchOptions {
  std::string manifest;                       ///< path of the JSON manifest
  std::string output_dir;                     ///< one folder per job in here, plus summary.csv and summary.md
  std::string executable = "/proc/self/exe";  ///< the morphmap binary whose `map` runs each job
  bool progress = false;                      ///< redraw one status line (job i of n, stage, elapsed) on stderr
};

struct BatchResult {
  std::vector<SummaryRow> rows;  ///< one per job, manifest order
  int succeeded = 0;             ///< ok, including skipped
  int skipped = 0;               ///< complete from an earlier run, not rerun
  int failed = 0;
  bool interrupted = false;  ///< SIGINT/SIGTERM arrived: the running job was stopped, the rest not started
};

/// Runs every job not already complete, writing summary.csv and summary.md (atomically) after each job.
/// Throws InvalidInput for a bad manifest (before running anything) and IoError if the output directory is
/// unusable or held by another running batch.
BatchResult run_batch(const BatchOptions& options);

}  // namespace morphmap
