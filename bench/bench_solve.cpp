// Laplace solve, every backend side by side (paper §6.1 and Table II: Gauss-Seidel diffusion against implicit
// integration with conjugate gradients, 0.2 to 1.7 million tets). The systems are built exactly as
// solve_harmonic builds them (dirichlet_system) from real morphs: sphere -> torus (built-in shapes), sphere ->
// bunny ($MORPHMAP_MODELS/bunny_closed.obj) and cow -> horse (cow.off, horse.obj, each normalised to its own
// bounding box like the pipeline's --align bbox), at about 0.2M, 0.8M and 1.7M tets. Models folder:
// $MORPHMAP_MODELS, default ../shared/data/models.
//
// BM_Solve/<morph>/<size>/<backend>: one compute + solve per iteration from s = t (solve_harmonic's warm start),
// to relative residual 1e-8 for cg, cg-ic, cg-amg and auto (cholmod and ldlt are direct), and to the paper's change
// threshold 1e-5 for gauss-seidel: measured as the paper does, the total change of s in a sweep (which leaves a
// residual of a few 1e-9), and as gauss-seidel-mean, the mean change per unknown (far fewer sweeps, residual
// ~1e-4). Counters: iterations, residual, change (gauss-seidel), setup_seconds, solve_seconds, memory_bytes,
// unknowns, nnz, tets. ldlt and gauss-seidel are skipped (with a message) where they would take more than about
// a minute. The label of auto names its choice
// and its estimates; cg-amg's names its levels (unknowns and stored entries, finest first).
//
// BM_SpMV/<morph>/<size>: the TBB SpMV every iterative backend runs, with the bytes it must move
// (symmetric_multiply_bytes) per second as GB/s. The largest matrix (~47 MB) fits in this machine's 105 MB L3, so
// BM_SpMV/cow-horse/1.7Mx4 also multiplies four copies of it as one block-diagonal matrix (~190 MB) to measure
// the memory-bound rate.
//
// BM_MapSolve: see below (the map's own systems, deflated). BM_Assemble: the Laplace stage's assembly of those
// systems (dirichlet_system), alone and with the quality figures it reads off the local stiffness.
//
// Run: morphmap_bench --benchmark_filter='BM_Solve|BM_SpMV' --benchmark_repetitions=3 --benchmark_format=json
// Systems are built once per size (a few seconds each, not timed) and cached for all backends and repetitions.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bench/bench_cases.h"
#include "mesh/adjacency.h"
#include "mesh/extract.h"
#include "mesh/morph.h"
#include "mesh/quality.h"
#include "mesh/shapes.h"
#include "solver/laplace.h"
#include "solver/linear_solver.h"

namespace {

using morphmap::SparseMatrixD;

struct Case {
  std::string morph;  ///< sphere-torus, sphere-bunny, cow-horse
  std::string size;   ///< label: 0.2M, 0.8M, 1.7M tets (approximately)
  int voxels;         ///< MorphOptions::voxels
  int time_steps;     ///< ExtractOptions::time_steps (the paper's Table II: 10, 6 for the bunny)
};

// Sizes chosen to bracket Table II (220k tets sphere -> torus, 417k sphere -> bunny, 1.69M cow -> horse).
const std::vector<Case>& cases() {
  static const std::vector<Case> all = {
      {"sphere-torus", "0.2M", 12, 10}, {"sphere-torus", "0.8M", 23, 10}, {"sphere-torus", "1.6M", 32, 10},
      {"sphere-bunny", "0.2M", 14, 6},  {"sphere-bunny", "0.7M", 26, 6},  {"sphere-bunny", "1.6M", 36, 6},
      {"cow-horse", "0.2M", 24, 10},    {"cow-horse", "0.8M", 45, 10},    {"cow-horse", "1.7M", 64, 10},
  };
  return all;
}

struct System {
  morphmap::DirichletSystem laplace;
  morphmap::TetMesh4 mesh;  ///< kept for the deflation spaces (map systems only)
  std::int64_t tets = 0;
  std::string error;  ///< non-empty when the inputs are missing
};

/// Builds A, B as the pipeline does (a built-in shape is fitted to the other's bounding box), then the morph,
/// the 4D mesh and the Dirichlet system. Cached per case: benchmarks and repetitions share it. `map_time_scale`:
/// the map's default c (twice the bounding box, cells about 13 times longer in time than wide) instead of cubic
/// cells.
const System& system_for(const Case& c, bool map_time_scale = false) {
  static std::map<std::string, std::unique_ptr<System>> cache;
  auto& slot = cache[c.morph + "/" + c.size + (map_time_scale ? "/map" : "")];
  if (slot) return *slot;
  slot = std::make_unique<System>();
  morphmap::Surface A, B;
  slot->error = bench::case_surfaces(c.morph, A, B);
  if (!slot->error.empty()) return *slot;
  morphmap::MorphOptions morph_options;
  morph_options.voxels = c.voxels;
  const morphmap::MorphResult morph = morphmap::build_morph(A, B, morph_options);
  morphmap::ExtractOptions extract_options;
  extract_options.time_steps = c.time_steps;
  // Cubic lattice cells (c = K h), as the paper's meshes and the measurements quoted in solver/laplace.h: the
  // map's default c (twice the bounding box) makes s = t nearly harmonic, where Gauss-Seidel meets the paper's
  // change threshold after a few dozen sweeps at a residual far from converged.
  extract_options.time_scale = map_time_scale ? 0.0 : c.time_steps * morph.field.voxel_size;
  morphmap::ExtractResult extract = morphmap::extract_hypersurface(morph.field, extract_options);
  slot->tets = extract.mesh.tet_count();
  slot->laplace = morphmap::dirichlet_system(extract.mesh);
  if (map_time_scale) slot->mesh = std::move(extract.mesh);
  return *slot;
}

// Beyond these sizes the reference backends would take more than about a minute per solve on this machine
// (2 cores): ldlt took 39 s at 31k unknowns and grows faster than n^1.5 (DESIGN.md: 108 s at 125k); gauss-seidel
// takes ~0.5 us per unknown per sweep and needs more sweeps as the mesh refines.
constexpr Eigen::Index kLdltMaxUnknowns = 40000;
constexpr Eigen::Index kGaussSeidelMaxUnknowns = 1000000;

void BM_Solve(benchmark::State& state, const Case& c, const std::string& name) {
  const bool mean_change = name == "gauss-seidel-mean";
  const std::string backend = mean_change ? "gauss-seidel" : name;
  const System& system = system_for(c);
  if (!system.error.empty()) {
    state.SkipWithError(system.error.c_str());
    return;
  }
  const morphmap::DirichletSystem& s = system.laplace;
  const Eigen::Index n = s.A.rows();
  if ((backend == "ldlt" && n > kLdltMaxUnknowns) || (backend == "gauss-seidel" && n > kGaussSeidelMaxUnknowns)) {
    const std::string message = "skipped: " + backend + " would take over ~60 s on " + std::to_string(n) +
                                " unknowns (limit " +
                                std::to_string(backend == "ldlt" ? kLdltMaxUnknowns : kGaussSeidelMaxUnknowns) + ")";
    state.SkipWithError(message.c_str());
    return;
  }
  morphmap::SolveOptions options;
  options.tolerance = 1e-8;
  options.max_iterations = 100000;
  options.change_threshold = 1e-5;  // Table II
  options.change_measure = mean_change ? morphmap::ChangeMeasure::Mean : morphmap::ChangeMeasure::Total;
  morphmap::SolveReport report;
  for (auto _ : state) {
    auto solver = morphmap::make_solver(backend, options);
    Eigen::VectorXd x = s.x0;  // s = t, as solve_harmonic's warm start
    solver->compute(s.A);
    report = solver->solve(s.b, x);
    benchmark::DoNotOptimize(x.data());
  }
  state.counters["iterations"] = report.iterations;
  state.counters["residual"] = report.residual;
  // Only where it means something: a counter that is 0 in every repetition makes the cv aggregate NaN, which is
  // not valid JSON.
  if (backend == "gauss-seidel") state.counters["change"] = report.change;
  state.counters["setup_seconds"] = report.setup_seconds;
  state.counters["solve_seconds"] = report.solve_seconds;
  state.counters["memory_bytes"] = static_cast<double>(report.memory_bytes);
  state.counters["unknowns"] = static_cast<double>(n);
  state.counters["nnz"] = static_cast<double>(s.A.nonZeros());
  state.counters["tets"] = static_cast<double>(system.tets);
  state.SetLabel(report.detail.empty() ? report.backend : report.detail);
}

// BM_MapSolve/<morph>/<size>/cg-amg/<cells>: cg-amg on the map's own systems (default c), set-up + solve from s = t to
// 1e-8, deflated by the space-time cells of <cells> voxels (solve_harmonic's default 6; 0 = no deflation). The
// space is built inside the timing, as solve_harmonic builds it. Counters as BM_Solve's, plus the columns.
void BM_MapSolve(benchmark::State& state, const Case& c, double cell_voxels) {
  const System& system = system_for(c, true);
  if (!system.error.empty()) {
    state.SkipWithError(system.error.c_str());
    return;
  }
  const morphmap::DirichletSystem& s = system.laplace;
  morphmap::SolveOptions options;
  options.tolerance = 1e-8;
  morphmap::SolveReport report;
  for (auto _ : state) {
    auto solver = morphmap::make_solver("cg-amg", options);
    Eigen::VectorXd x = s.x0;
    solver->set_deflation(morphmap::space_time_cells(system.mesh, s.unknown, int(s.A.rows()), cell_voxels,
                                                     morphmap::kMaxDeflationColumns, &s.A));
    solver->compute(s.A);
    report = solver->solve(s.b, x);
    benchmark::DoNotOptimize(x.data());
  }
  state.counters["iterations"] = report.iterations;
  state.counters["residual"] = report.residual;
  state.counters["columns"] = report.deflation_columns;
  state.counters["setup_seconds"] = report.setup_seconds;
  state.counters["solve_seconds"] = report.solve_seconds;
  state.counters["memory_bytes"] = static_cast<double>(report.memory_bytes);
  state.counters["unknowns"] = static_cast<double>(s.A.rows());
  state.counters["tets"] = static_cast<double>(system.tets);
}

// BM_Assemble/<morph>/<size>/<quality>: dirichlet_system on the map's own mesh (default c) with its vertex stars built
// once outside the timing, as the pipeline shares them; quality = 1 also measures the mesh quality (the Laplace stage
// with LaplaceOptions::measure_quality, the pipeline's default). Repetitions reuse memory the previous one freed, so
// this is the assembly's compute, without the first-touch cost a fresh process pays (docs/performance_log.md).
void BM_Assemble(benchmark::State& state, const Case& c, bool quality) {
  const System& system = system_for(c, true);
  if (!system.error.empty()) {
    state.SkipWithError(system.error.c_str());
    return;
  }
  const morphmap::SharedStars stars = morphmap::stars_or_build(nullptr, system.mesh.T, system.mesh.vertex_count());
  morphmap::DirichletSystem s;
  morphmap::QualityResult figures;
  for (auto _ : state) {
    s = morphmap::dirichlet_system(system.mesh, stars, quality ? &figures : nullptr);
    benchmark::DoNotOptimize(s.A.valuePtr());
  }
  state.counters["assemble_seconds"] = s.assemble_seconds;
  if (quality) state.counters["quality_seconds"] = figures.seconds;
  state.counters["nnz"] = static_cast<double>(s.A.nonZeros());
  state.counters["tets"] = static_cast<double>(system.tets);
}

/// `copies` copies of A on the diagonal: the same rows, more bytes than the last-level cache holds.
SparseMatrixD block_diagonal(const SparseMatrixD& A, int copies) {
  const Eigen::Index n = A.rows();
  SparseMatrixD M(copies * n, copies * n);
  M.reserve(copies * A.nonZeros());
  for (int c = 0; c < copies; ++c) {
    for (Eigen::Index j = 0; j < n; ++j) {
      M.startVec(c * n + j);
      for (SparseMatrixD::InnerIterator it(A, j); it; ++it) M.insertBack(c * n + it.row(), c * n + j) = it.value();
    }
  }
  M.finalize();
  return M;
}

void BM_SpMV(benchmark::State& state, const Case& c, int copies) {
  const System& system = system_for(c);
  if (!system.error.empty()) {
    state.SkipWithError(system.error.c_str());
    return;
  }
  static std::map<std::string, SparseMatrixD> big;  // block-diagonal copies, built once
  const SparseMatrixD* A = &system.laplace.A;
  if (copies > 1) {
    SparseMatrixD& slot = big[c.morph + "/" + c.size + "x" + std::to_string(copies)];
    if (slot.rows() == 0) slot = block_diagonal(*A, copies);
    A = &slot;
  }
  Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(A->cols(), 0.0, 1.0), y;
  morphmap::symmetric_multiply(*A, x, y);  // first touch of y outside the timing
  for (auto _ : state) {
    morphmap::symmetric_multiply(*A, x, y);
    benchmark::DoNotOptimize(y.data());
    benchmark::ClobberMemory();
  }
  const double bytes = static_cast<double>(morphmap::symmetric_multiply_bytes(*A));
  state.SetBytesProcessed(static_cast<std::int64_t>(bytes) * state.iterations());
  state.counters["GBps"] = benchmark::Counter(bytes * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["bytes_per_spmv"] = bytes;
  state.counters["unknowns"] = static_cast<double>(A->rows());
  state.counters["nnz"] = static_cast<double>(A->nonZeros());
}

/// Registered at start-up so that every (morph, size, backend) gets its own name.
const bool registered = [] {
  for (const Case& c : cases()) {
    std::vector<std::string> backends = morphmap::solver_names();
    backends.insert(std::find(backends.begin(), backends.end(), "gauss-seidel") + 1, "gauss-seidel-mean");
    for (const std::string& backend : backends) {
      benchmark::RegisterBenchmark(("BM_Solve/" + c.morph + "/" + c.size + "/" + backend).c_str(),
                                   [c, backend](benchmark::State& state) { BM_Solve(state, c, backend); })
          ->Iterations(1)
          ->UseRealTime()
          ->Unit(benchmark::kMillisecond);
    }
  }
  for (const Case& c : cases()) {
    benchmark::RegisterBenchmark(("BM_SpMV/" + c.morph + "/" + c.size).c_str(),
                                 [c](benchmark::State& state) { BM_SpMV(state, c, 1); })
        ->UseRealTime()
        ->Unit(benchmark::kMicrosecond);
  }
  for (const Case& c : cases()) {
    if (c.size.rfind("1.", 0) != 0) continue;  // the largest of each morph
    for (const double cells : {0.0, 4.0, 6.0, 8.0}) {
      const std::string name = "BM_MapSolve/" + c.morph + "/" + c.size + "/cg-amg/" + std::to_string(int(cells));
      benchmark::RegisterBenchmark(name.c_str(), [c, cells](benchmark::State& state) { BM_MapSolve(state, c, cells); })
          ->Iterations(1)
          ->UseRealTime()
          ->Unit(benchmark::kMillisecond);
    }
  }
  for (const Case& c : cases()) {
    if (c.size.rfind("1.", 0) != 0) continue;
    for (const bool quality : {false, true}) {
      const std::string name = "BM_Assemble/" + c.morph + "/" + c.size + "/" + (quality ? "quality" : "plain");
      benchmark::RegisterBenchmark(name.c_str(),
                                   [c, quality](benchmark::State& state) { BM_Assemble(state, c, quality); })
          ->UseRealTime()
          ->Unit(benchmark::kMillisecond);
    }
  }
  const Case& largest = cases().back();
  benchmark::RegisterBenchmark(("BM_SpMV/" + largest.morph + "/" + largest.size + "x4").c_str(),
                               [largest](benchmark::State& state) { BM_SpMV(state, largest, 4); })
      ->UseRealTime()
      ->Unit(benchmark::kMicrosecond);
  return true;
}();

}  // namespace
