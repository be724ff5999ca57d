// Closest-point location on a surface (mesh/transfer.h SurfaceLocator), as the distance-field morph's exact
// distances (mesh/morph.cpp) and the map's labels, seams and transfer use it: happy_buddha_100k.obj (100 k
// triangles) and a 27^3 lattice (19,683 points) over its bounding box grown by 30% about its centre, so most
// points are off the surface, some far, as lattice points near a morph's box corners are.
//
// BM_Locator/build: the constructor alone (index over every triangle). BM_Locator/query: closest_all over the
// lattice with one locator built outside the timing; counter seconds_per_query. Models folder: $MORPHMAP_MODELS,
// default ../shared/data/models.
//   Run: morphmap_bench --benchmark_filter=BM_Locator --benchmark_repetitions=3
#include <benchmark/benchmark.h>

#include <filesystem>
#include <string>

#include "bench/bench_cases.h"
#include "io/mesh_io.h"
#include "mesh/transfer.h"

namespace {

struct LocatorCase {
  morphmap::Surface surface;
  Eigen::MatrixXd queries;  ///< #Q by 3 lattice points
  std::string error;
};

const LocatorCase& locator_case() {
  static const LocatorCase c = [] {
    LocatorCase out;
    const std::string path = bench::models_dir() + "/happy_buddha_100k.obj";
    if (!std::filesystem::exists(path)) {
      out.error = path + " not found: set MORPHMAP_MODELS to the models folder";
      return out;
    }
    out.surface = morphmap::read_surface(path);
    const Eigen::AlignedBox3d box = morphmap::bounding_box(out.surface.V);
    const Eigen::Vector3d lo = box.center() - 0.65 * box.sizes();
    const Eigen::Vector3d step = 1.3 * box.sizes() / 26.0;
    constexpr int n = 27;
    out.queries.resize(n * n * n, 3);
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
          out.queries.row((k * n + j) * n + i) = (lo + step.cwiseProduct(Eigen::Vector3d(i, j, k))).transpose();
    return out;
  }();
  return c;
}

void BM_Locator(benchmark::State& state, bool query) {
  const LocatorCase& c = locator_case();
  if (!c.error.empty()) {
    state.SkipWithError(c.error.c_str());
    return;
  }
  if (!query) {
    for (auto _ : state) {
      const morphmap::SurfaceLocator locator(c.surface);
      benchmark::ClobberMemory();
    }
  } else {
    const morphmap::SurfaceLocator locator(c.surface);
    for (auto _ : state) {
      const std::vector<morphmap::SurfaceHit> hits = locator.closest_all(c.queries);
      benchmark::DoNotOptimize(hits.data());
    }
    const double queries = double(c.queries.rows());
    state.counters["queries"] = queries;
    state.counters["seconds_per_query"] =
        benchmark::Counter(queries, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  }
  state.SetLabel(std::to_string(c.surface.F.rows()) + " triangles");
}

BENCHMARK_CAPTURE(BM_Locator, build, false)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Locator, query, true)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
