// Characteristic tracing (paper §7, solver/trace.h) on the Table II morphs as the pipeline maps them: sphere ->
// torus at 13 voxels and cow -> horse at 63 voxels, 10 time steps, the default time scale (twice the box), the
// field solved by the default backend. Each iteration builds the tracer (vertex stars, the tet records with their
// face neighbours from the extraction's lattice record, normals, smoothed field) and traces every vertex of the
// extracted B back to A, as `morphmap map` does for target.obj.
//
// BM_Trace/<morph>: counters traces, reached, descended, stalled, tet_pieces, evaluations (of the weight ODE: the
// tracer's work, which machine load does not change), descent_pieces, seconds_per_trace. The pipeline also traces
// the other vertices of the tets B cuts (for the seam split): 49 k starts on cow -> horse where this traces 18 k.
// Run: morphmap_bench --benchmark_filter=BM_Trace --benchmark_repetitions=3
// The morph and the solve (a few seconds each) are built once per morph, not timed.
#include <benchmark/benchmark.h>

#include <map>
#include <memory>
#include <string>

#include "bench/bench_cases.h"
#include "mesh/adjacency.h"
#include "mesh/extract.h"
#include "mesh/morph.h"
#include "mesh/slice.h"
#include "solver/gradient.h"
#include "solver/laplace.h"
#include "solver/trace.h"

namespace {

struct TraceCase {
  morphmap::TetMesh4 mesh;
  morphmap::LatticeFaces faces;  ///< the extraction's record, from which the pipeline's tracer takes face neighbours
  Eigen::VectorXd s;
  Eigen::MatrixXd field;  ///< #V by 4 vertex field T
  std::vector<morphmap::MeshPoint> starts;
  std::string error;
};

const TraceCase& trace_case(const std::string& morph, int voxels) {
  static std::map<std::string, std::unique_ptr<TraceCase>> cache;
  auto& slot = cache[morph];
  if (slot) return *slot;
  slot = std::make_unique<TraceCase>();
  morphmap::Surface A, B;
  slot->error = bench::case_surfaces(morph, A, B);
  if (!slot->error.empty()) return *slot;
  morphmap::MorphOptions morph_options;
  morph_options.voxels = voxels;
  morphmap::ExtractOptions extract_options;
  extract_options.time_steps = 10;
  extract_options.face_neighbours = true;
  morphmap::ExtractResult extract =
      morphmap::extract_hypersurface(morphmap::build_morph(A, B, morph_options).field, extract_options);
  slot->mesh = std::move(extract.mesh);
  slot->faces = std::move(extract.faces);
  slot->s = morphmap::solve_harmonic(slot->mesh, morphmap::LaplaceOptions{}).s;
  slot->field = morphmap::compute_gradient(slot->mesh, slot->s).vertex_field;
  const morphmap::SliceMesh b = morphmap::target_boundary(slot->mesh, slot->mesh.V.leftCols(3));
  slot->starts = morphmap::edge_points(b.source_edge, b.edge_weight);
  return *slot;
}

void BM_Trace(benchmark::State& state, const std::string& morph, int voxels) {
  const TraceCase& c = trace_case(morph, voxels);
  if (!c.error.empty()) {
    state.SkipWithError(c.error.c_str());
    return;
  }
  morphmap::TraceResult r;
  for (auto _ : state) {
    const morphmap::CharacteristicTracer tracer(c.mesh, c.s, c.field, morphmap::TraceOptions{}, nullptr, &c.faces);
    r = tracer.trace(c.starts);
    benchmark::DoNotOptimize(r.end.data());
  }
  const double traces = double(c.starts.size());
  state.counters["traces"] = traces;
  state.counters["reached"] = double(r.reached);
  state.counters["descended"] = double(r.descended);
  state.counters["stalled"] = double(r.stalled);
  state.counters["tet_pieces"] = double(r.tet_pieces);
  state.counters["evaluations"] = double(r.rate_evaluations);
  state.counters["descent_pieces"] = double(r.descent_pieces);
  state.counters["seconds_per_trace"] =
      benchmark::Counter(traces, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.SetLabel(std::to_string(c.mesh.tet_count()) + " tets");
}

// The tracer's set-up alone, with the stars and the lattice record given as the pipeline gives them: the tet records
// and their face neighbours, vertex normals and the smoothed field (BM_AdjacencyLatticeFaceNeighbours times the
// second).
void BM_TracerSetup(benchmark::State& state, const std::string& morph, int voxels) {
  const TraceCase& c = trace_case(morph, voxels);
  if (!c.error.empty()) {
    state.SkipWithError(c.error.c_str());
    return;
  }
  const morphmap::SharedStars stars =
      std::make_shared<const morphmap::VertexTets>(morphmap::build_vertex_tets(c.mesh.T, c.mesh.vertex_count()));
  for (auto _ : state) {
    const morphmap::CharacteristicTracer tracer(c.mesh, c.s, c.field, morphmap::TraceOptions{}, stars, &c.faces);
    benchmark::DoNotOptimize(&tracer);
  }
  state.SetLabel(std::to_string(c.mesh.tet_count()) + " tets");
}

BENCHMARK_CAPTURE(BM_TracerSetup, cow_horse, std::string("cow-horse"), 63)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_CAPTURE(BM_Trace, sphere_torus, std::string("sphere-torus"), 13)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(BM_Trace, cow_horse, std::string("cow-horse"), 63)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
