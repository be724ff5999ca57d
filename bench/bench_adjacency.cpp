// The passes over the 4D mesh's vertex stars that every stage after the extraction shares (mesh/adjacency.h): the
// stars themselves (build_vertex_tets) and the tracer's face neighbours (face_neighbours, and
// lattice_face_neighbours from the extraction's record), on cow -> horse at 63
// voxels and 10 time steps (1.66 M tets), the Table II row they matter most for.
// Run: morphmap_bench --benchmark_filter=BM_Adjacency --benchmark_repetitions=5
// The morph and the extraction are built once, not timed.
#include <benchmark/benchmark.h>

#include <memory>
#include <string>

#include "bench/bench_cases.h"
#include "mesh/adjacency.h"
#include "mesh/extract.h"
#include "mesh/morph.h"

namespace {

struct MeshCase {
  morphmap::TetMesh4 mesh;
  morphmap::LatticeFaces faces;
  std::string error;
};

const MeshCase& cow_horse() {
  static std::unique_ptr<MeshCase> c;
  if (c) return *c;
  c = std::make_unique<MeshCase>();
  morphmap::Surface A, B;
  c->error = bench::case_surfaces("cow-horse", A, B);
  if (!c->error.empty()) return *c;
  morphmap::MorphOptions morph_options;
  morph_options.voxels = 63;
  morphmap::ExtractOptions extract_options;
  extract_options.time_steps = 10;
  extract_options.face_neighbours = true;
  morphmap::ExtractResult extract =
      morphmap::extract_hypersurface(morphmap::build_morph(A, B, morph_options).field, extract_options);
  c->mesh = std::move(extract.mesh);
  c->faces = std::move(extract.faces);
  return *c;
}

// cow_horse(), or nullptr with the benchmark skipped when its models are missing.
const MeshCase* case_or_skip(benchmark::State& state) {
  const MeshCase& c = cow_horse();
  if (c.error.empty()) return &c;
  state.SkipWithError(c.error.c_str());
  return nullptr;
}

void BM_AdjacencyStars(benchmark::State& state) {
  const MeshCase* found = case_or_skip(state);
  if (found == nullptr) return;
  const MeshCase& c = *found;
  for (auto _ : state) {
    const morphmap::VertexTets stars = morphmap::build_vertex_tets(c.mesh.T, c.mesh.vertex_count());
    benchmark::DoNotOptimize(stars.tets.data());
  }
  state.SetLabel(std::to_string(c.mesh.tet_count()) + " tets");
}

void BM_AdjacencyFaceNeighbours(benchmark::State& state) {
  const MeshCase* found = case_or_skip(state);
  if (found == nullptr) return;
  const MeshCase& c = *found;
  const morphmap::VertexTets stars = morphmap::build_vertex_tets(c.mesh.T, c.mesh.vertex_count());
  for (auto _ : state) {
    const morphmap::FaceNeighbours across = morphmap::face_neighbours(c.mesh.T, stars);
    benchmark::DoNotOptimize(across.across.get());
  }
  state.SetLabel(std::to_string(c.mesh.tet_count()) + " tets");
}

// The same neighbours from the extraction's lattice record (what the pipeline's tracer uses).
void BM_AdjacencyLatticeFaceNeighbours(benchmark::State& state) {
  const MeshCase* found = case_or_skip(state);
  if (found == nullptr) return;
  const MeshCase& c = *found;
  for (auto _ : state) {
    const morphmap::FaceNeighbours across = morphmap::lattice_face_neighbours(c.faces, c.mesh.T);
    benchmark::DoNotOptimize(across.across.get());
  }
  state.SetLabel(std::to_string(c.mesh.tet_count()) + " tets");
}

}  // namespace

BENCHMARK(BM_AdjacencyStars)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_AdjacencyFaceNeighbours)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_AdjacencyLatticeFaceNeighbours)->Unit(benchmark::kMillisecond)->UseRealTime();
