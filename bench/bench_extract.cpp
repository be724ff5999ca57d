// Extraction throughput and memory (issue: 4D extraction at scale). Sphere -> torus on an analytic
// field (no OpenVDB in the loop) and sphere -> bunny on the real OpenVDB morph field, three resolutions
// each. Counters: output tets per wall-clock second, bytes the stage holds per output tet (its output
// arrays plus its per-cell tables, exact), and the process's peak RSS per output tet (includes the
// morph field and everything before). Models folder: $MORPHMAP_MODELS, default ../shared/data/models.
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>

#include "io/mesh_io.h"
#include "io/output_dir.h"
#include "mesh/extract.h"
#include "mesh/morph.h"
#include "mesh/shapes.h"

namespace {

morphmap::MorphField sphere_to_torus(int n) {
  return morphmap::sample_morph(
      [](const Eigen::Vector3d& p) { return p.norm() - 0.9; },
      [](const Eigen::Vector3d& p) { return Eigen::Vector2d(p.head<2>().norm() - 0.6, p.z()).norm() - 0.25; }, 1.1, n);
}

std::string models_dir() {
  const char* env = std::getenv("MORPHMAP_MODELS");
  return env ? env : "../shared/data/models";
}

// Morph fields are built once per resolution and reused across repetitions.
const morphmap::MorphField* sphere_to_bunny(int voxels) {
  static std::map<int, std::unique_ptr<morphmap::MorphField>> cache;
  auto& slot = cache[voxels];
  if (!slot) {
    const std::string path = models_dir() + "/bunny_closed.obj";
    if (!std::filesystem::exists(path)) return nullptr;
    const morphmap::Surface bunny = morphmap::read_surface(path);
    const morphmap::Surface sphere =
        morphmap::make_shape(morphmap::parse_shape_spec("sphere"), morphmap::bounding_box(bunny.V));
    morphmap::MorphOptions options;
    options.voxels = voxels;
    slot = std::make_unique<morphmap::MorphField>(morphmap::build_morph(sphere, bunny, options).field);
  }
  return slot.get();
}

void run(benchmark::State& state, const morphmap::MorphField& field, int time_steps, bool face_neighbours = false) {
  morphmap::ExtractOptions options;
  options.time_steps = time_steps;
  options.face_neighbours = face_neighbours;
  std::int64_t tets = 0, vertices = 0, scratch = 0;
  std::size_t source_cells = 0;
  for (auto _ : state) {
    const morphmap::ExtractResult result = morphmap::extract_hypersurface(field, options);
    tets = result.mesh.tet_count();
    source_cells = result.mesh.source_cell.size();
    vertices = result.mesh.vertex_count();
    scratch = result.scratch_bytes;
    benchmark::DoNotOptimize(result.mesh.V.data());
  }
  // Output arrays: T (4 ints) per tet, the faces' codes (4 bytes; the per-cell tables are scratch_bytes) and
  // source_cell (8 bytes) when asked for; V (4 doubles) and side (1 byte) per vertex.
  const double stage_bytes = double(tets) * (face_neighbours ? 20 : 16) + double(source_cells) * 8 +
                             double(vertices) * (32 + 1) + double(scratch);
  state.counters["tets"] = double(tets);
  state.counters["tets_per_second"] = benchmark::Counter(double(tets), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["stage_bytes_per_tet"] = stage_bytes / double(tets);
  state.counters["peak_rss_bytes_per_tet"] = double(morphmap::peak_memory_bytes()) / double(tets);
}

void BM_ExtractSphereTorus(benchmark::State& state) {
  run(state, sphere_to_torus(int(state.range(0))), int(state.range(1)));
}
BENCHMARK(BM_ExtractSphereTorus)
    ->Args({32, 8})
    ->Args({64, 16})
    ->Args({96, 24})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_ExtractSphereBunny(benchmark::State& state) {
  const morphmap::MorphField* field = sphere_to_bunny(int(state.range(0)));
  if (!field) {
    state.SkipWithError("bunny_closed.obj not found: set MORPHMAP_MODELS to the models folder");
    return;
  }
  run(state, *field, int(state.range(1)));
}
BENCHMARK(BM_ExtractSphereBunny)
    ->Args({40, 8})
    ->Args({80, 16})
    ->Args({120, 24})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The extraction recording the lattice faces (ExtractOptions::face_neighbours) against without.
void BM_ExtractFaceNeighbours(benchmark::State& state) {
  const morphmap::MorphField* field = sphere_to_bunny(80);
  if (!field) {
    state.SkipWithError("bunny_closed.obj not found: set MORPHMAP_MODELS to the models folder");
    return;
  }
  run(state, *field, 16, state.range(0) != 0);
}
BENCHMARK(BM_ExtractFaceNeighbours)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
