// The fold repair's relief of compression (mesh/untangle.h, UntangleOptions::compression_seed) on an analytic case:
// the identity labels of a sphere (res 96: 4514 vertices) whose target is the same sphere with a disk of about eight
// rings squashed to a tenth along one tangent direction (sigma2 about 0.1 there, nothing folded), as where the traced
// map fans out at the bunny's ears. The map is copied before each run (outside the timing).
//
// BM_Untangle/relief: untangle_labels at the defaults (the relief runs: Newton sweeps, then the worst-triangle
// moves); BM_Untangle/off: --compression-seed 0 (nothing to do but classify). Counter min_sigma2: the map's smallest
// sigma2 after the run.
//   Run: morphmap_bench --benchmark_filter=BM_Untangle --benchmark_repetitions=3
#include <benchmark/benchmark.h>

#include <optional>
#include <string>

#include "mesh/metrics.h"
#include "mesh/shapes.h"
#include "mesh/transfer.h"
#include "mesh/untangle.h"

namespace {

struct UntangleCase {
  morphmap::Surface A;
  Eigen::MatrixXd B;  ///< #V by 3: A's vertices with the disk squashed
};

const UntangleCase& untangle_case() {
  static const UntangleCase c = [] {
    UntangleCase out;
    out.A = morphmap::make_shape(morphmap::parse_shape_spec("sphere:size=1,center=0/0/0,res=96"), std::nullopt);
    double edges = 0.0;
    for (Eigen::Index f = 0; f < out.A.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) edges += (out.A.V.row(out.A.F(f, k)) - out.A.V.row(out.A.F(f, (k + 1) % 3))).norm();
    const double rim = 8.0 * edges / double(3 * out.A.F.rows());
    const Eigen::Vector3d c = Eigen::Vector3d(-0.2, 0.4, 1.0).normalized();
    const Eigen::Vector3d u = c.cross(Eigen::Vector3d::UnitX()).normalized();
    out.B = out.A.V;
    for (Eigen::Index i = 0; i < out.A.V.rows(); ++i) {
      const Eigen::Vector3d p = out.A.V.row(i).transpose();
      const double r = (p - c).norm();
      if (r >= rim) continue;
      const double squash = 0.1 + 0.9 * (r / rim) * (r / rim);  // increasing in r: still a surface
      out.B.row(i) = (p - (1.0 - squash) * (p - c).dot(u) * u).transpose();
    }
    return out;
  }();
  return c;
}

void BM_Untangle(benchmark::State& state, bool relief) {
  const UntangleCase& c = untangle_case();
  const morphmap::SurfaceLocator locator(c.A);
  morphmap::UntangleOptions options;
  if (!relief) options.compression_seed = 0.0;
  Eigen::MatrixXd labels;
  morphmap::UntangleResult result;
  for (auto _ : state) {
    state.PauseTiming();
    labels = c.A.V;
    state.ResumeTiming();
    result = morphmap::untangle_labels(c.A, locator, c.B, c.A.F, labels, options);
    benchmark::DoNotOptimize(labels.data());
  }
  state.counters["min_sigma2"] = morphmap::measure_stretch(c.A, c.B, c.A.F, labels).min_sigma2;
  state.counters["parts_relieved"] = double(result.compression_parts_relieved);
  state.SetLabel(std::to_string(c.A.V.rows()) + " vertices");
}

BENCHMARK_CAPTURE(BM_Untangle, relief, true)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_CAPTURE(BM_Untangle, off, false)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
