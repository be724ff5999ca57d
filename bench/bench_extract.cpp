// Extraction throughput on analytic morph fields (sphere -> torus), built without OpenVDB so the
// benchmark times the 4D marching alone. Reports output tets per second.
#include <benchmark/benchmark.h>

#include <cmath>

#include "mesh/extract.h"

namespace {

morphmap::MorphField sphere_to_torus(int n) {
  morphmap::MorphField field;
  const double extent = 1.1;
  field.voxel_size = 2.0 * extent / (n - 1);
  field.dims = Eigen::Vector3i(n, n, n);
  field.origin = Eigen::Vector3d::Constant(-extent);
  field.dA.resize(std::size_t(n) * n * n);
  field.dB.resize(field.dA.size());
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d p = field.point(i, j, k);
        const std::size_t idx = std::size_t(field.index(i, j, k));
        field.dA[idx] = float(p.norm() - 0.9);
        field.dB[idx] = float(Eigen::Vector2d(p.head<2>().norm() - 0.6, p.z()).norm() - 0.25);
      }
  return field;
}

void BM_ExtractSphereTorus(benchmark::State& state) {
  const morphmap::MorphField field = sphere_to_torus(int(state.range(0)));
  morphmap::ExtractOptions options;
  options.time_steps = int(state.range(1));
  std::int64_t tets = 0;
  for (auto _ : state) {
    const morphmap::ExtractResult result = morphmap::extract_hypersurface(field, options);
    tets = result.mesh.tet_count();
    benchmark::DoNotOptimize(result.mesh.V.data());
  }
  state.counters["tets"] = double(tets);
  state.counters["tets_per_second"] = benchmark::Counter(double(tets), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ExtractSphereTorus)->Args({32, 8})->Args({64, 16})->Args({96, 24})->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
