// The morph stage alone (paper §5.1), both of the paper's morphs on sphere -> bunny_closed.obj (the sphere fitted to
// the bunny's box, as the pipeline builds it) at 40 voxels: the distance-field morph (exact distances within the band
// and beyond) and the variational implicit morph at 600 and 1000 samples per surface, sampled at 9 time levels
// (8 steps, the map's default). Counters: lattice points, RBF centres and the seconds of the constraint fit (the
// rest is the lattice evaluation). Models folder: $MORPHMAP_MODELS, default ../shared/data/models.
//   Run: morphmap_bench --benchmark_filter=BM_Morph --benchmark_repetitions=3
#include <benchmark/benchmark.h>

#include <string>

#include "bench/bench_cases.h"
#include "mesh/morph.h"
#include "mesh/thin_features.h"
#include "mesh/vim.h"

namespace {

void BM_Morph(benchmark::State& state, const std::string& method) {
  morphmap::Surface A, B;
  const std::string error = bench::case_surfaces("sphere-bunny", A, B);
  if (!error.empty()) {
    state.SkipWithError(error.c_str());
    return;
  }
  morphmap::MorphOptions lattice;
  lattice.voxels = 40;
  morphmap::VimOptions vim;
  vim.samples = int(state.range(0));
  morphmap::MorphResult result;
  for (auto _ : state) {
    result = method == "vim" ? morphmap::build_vim_morph(A, B, lattice, vim, 8) : morphmap::build_morph(A, B, lattice);
    benchmark::DoNotOptimize(result.field.dA.data());
  }
  state.counters["lattice_points"] = double(result.lattice_points);
  state.counters["rbf_centres"] = double(result.rbf_centres);
  state.counters["fit_seconds"] = result.fit_seconds;
}

// cow -> horse's surfaces and Table II's 63 voxels; false (the benchmark skipped) when a model is missing.
bool cow_horse(benchmark::State& state, morphmap::Surface& A, morphmap::Surface& B, morphmap::MorphOptions& lattice) {
  const std::string error = bench::case_surfaces("cow-horse", A, B);
  if (!error.empty()) state.SkipWithError(error.c_str());
  lattice.voxels = 63;
  return error.empty();
}

// The distance-field morph of cow -> horse at Table II's 63 voxels with the meshes' topology kept on the lattice
// (Arg 1, the default) or not (Arg 0): the cost of mesh/thin_features.h, counted in the morph stage.
void BM_MorphThinFeatures(benchmark::State& state) {
  morphmap::Surface A, B;
  morphmap::MorphOptions lattice;
  if (!cow_horse(state, A, B, lattice)) return;
  lattice.thin.enabled = state.range(0) != 0;
  morphmap::MorphResult result;
  for (auto _ : state) {
    result = morphmap::build_morph(A, B, lattice);
    benchmark::DoNotOptimize(result.field.dA.data());
  }
  state.counters["groups"] = double(result.thin_a.groups + result.thin_b.groups);
  state.counters["sign_flips"] = double(result.thin_a.sign_flips + result.thin_b.sign_flips);
}

BENCHMARK(BM_MorphThinFeatures)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// The distance-field morph of cow -> horse at 63 voxels with each way of finding the meshes' distances near their
// surfaces: closest-point queries (Arg 0, "exact", the default) or OpenVDB's meshToVolume (Arg 1, "openvdb").
void BM_MorphDistances(benchmark::State& state) {
  morphmap::Surface A, B;
  morphmap::MorphOptions lattice;
  if (!cow_horse(state, A, B, lattice)) return;
  lattice.distances = state.range(0) == 0 ? "exact" : "openvdb";
  morphmap::MorphResult result;
  for (auto _ : state) {
    result = morphmap::build_morph(A, B, lattice);
    benchmark::DoNotOptimize(result.field.dA.data());
  }
  state.counters["band_queries"] = double(result.band_queries);
  state.counters["exact_queries"] = double(result.exact_queries);
}

BENCHMARK(BM_MorphDistances)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

// keep_thin_features alone on cow -> horse's samples at 63 voxels (both surfaces, one after the other): the part of
// BM_MorphThinFeatures/1 that /0 does not have, without the noise of the rest of the morph.
void BM_KeepThinFeatures(benchmark::State& state) {
  morphmap::Surface A, B;
  morphmap::MorphOptions lattice;
  if (!cow_horse(state, A, B, lattice)) return;
  lattice.thin.enabled = false;
  const morphmap::MorphResult sampled = morphmap::build_morph(A, B, lattice);
  const morphmap::SurfaceLocator locator_a(A), locator_b(B);
  const morphmap::SurfaceCheck check_a = morphmap::check_surface(A.F, A.V.rows());
  const morphmap::SurfaceCheck check_b = morphmap::check_surface(B.F, B.V.rows());
  for (auto _ : state) {
    std::vector<float> a = sampled.field.dA, b = sampled.field.dB;
    morphmap::keep_thin_features(locator_a, sampled.field, a, {check_a.euler(), check_a.components});
    morphmap::keep_thin_features(locator_b, sampled.field, b, {check_b.euler(), check_b.components});
    benchmark::DoNotOptimize(a.data());
    benchmark::DoNotOptimize(b.data());
  }
}

BENCHMARK(BM_KeepThinFeatures)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Morph, distance, std::string("distance"))->Arg(0)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Morph, vim, std::string("vim"))->Arg(600)->Arg(1000)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
