// The pipeline's load stage (DESIGN.md, stage "load"): reading a model file (io/mesh_io.h) and the closed-manifold
// check of the surface read (mesh/surface.h, validate_surface), on the Table II models.
//
// BM_ReadSurface/<model>: read_surface alone; counters vertices, faces.
// BM_ValidateSurface/<model>: validate_surface(surface, true) of the surface read once, not timed.
// Run: morphmap_bench --benchmark_filter='BM_(Read|Validate)Surface' --benchmark_repetitions=5
#include <benchmark/benchmark.h>

#include <filesystem>
#include <string>

#include "bench/bench_cases.h"

namespace {

// The model's path in `path`; false, with the benchmark skipped, when the file is missing.
bool find_model(benchmark::State& state, const std::string& file, std::string& path) {
  path = bench::models_dir() + "/" + file;
  if (std::filesystem::exists(path)) return true;
  state.SkipWithError((path + " not found: set MORPHMAP_MODELS to the models folder").c_str());
  return false;
}

void BM_ReadSurface(benchmark::State& state, const std::string& file) {
  std::string path;
  if (!find_model(state, file, path)) return;
  morphmap::Surface surface;
  for (auto _ : state) {
    surface = morphmap::read_surface(path);
    benchmark::DoNotOptimize(surface.V.data());
  }
  state.counters["vertices"] = double(surface.V.rows());
  state.counters["faces"] = double(surface.F.rows());
}

void BM_ValidateSurface(benchmark::State& state, const std::string& file) {
  std::string path;
  if (!find_model(state, file, path)) return;
  const morphmap::Surface surface = morphmap::read_surface(path);
  morphmap::SurfaceCheck check;
  for (auto _ : state) {
    check = morphmap::validate_surface(surface, true);
    benchmark::DoNotOptimize(check.edges);
  }
  state.counters["edges"] = double(check.edges);
  state.counters["components"] = double(check.components);
}

BENCHMARK_CAPTURE(BM_ReadSurface, horse, std::string("horse.obj"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadSurface, happy_buddha, std::string("happy_buddha_100k.obj"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ReadSurface, cow, std::string("cow.off"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ValidateSurface, horse, std::string("horse.obj"))->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_ValidateSurface, happy_buddha, std::string("happy_buddha_100k.obj"))
    ->Unit(benchmark::kMillisecond);

}  // namespace
