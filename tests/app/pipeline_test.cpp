// End-to-end properties of the whole pipeline on analytic inputs (identity morph, concentric spheres).
#include "app/pipeline.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <utility>
#include <vector>

#include "io/image.h"
#include "io/mesh_io.h"
#include "mesh/errors.h"
#include "mesh/shapes.h"
#include "mesh/surface.h"

namespace morphmap {
namespace {

PipelineOptions small_options(const std::string& source, const std::string& target, const std::string& solver) {
  PipelineOptions o;
  o.source = source;
  o.target = target;
  o.morph.voxels = 24;
  o.extract.time_steps = 6;
  o.laplace.solver = solver;
  return o;
}

/// Largest angle between a target vertex and its preimage (labels.txt's point), seen from the origin: 0 for the
/// exact (radial) map of concentric spheres.
double worst_radial_angle(const PipelineResult& r) {
  double worst = 0.0;
  for (Eigen::Index v = 0; v < r.target.V.rows(); ++v) {
    const Eigen::Vector3d q = r.target.V.row(v).transpose();
    const Eigen::Vector3d label = r.target_labels.row(v).transpose();
    worst = std::max(worst, std::acos(std::clamp(q.normalized().dot(label.normalized()), -1.0, 1.0)));
  }
  return worst;
}

class PipelineSolvers : public ::testing::TestWithParam<std::string> {};

TEST_P(PipelineSolvers, IdentityMorphMapsEveryPointToItself) {
  // With the closest-point projection the labels are the traces' own ends, which come straight back.
  PipelineOptions o = small_options("sphere:res=48", "sphere:res=48", GetParam());
  o.source_projection = "closest";
  const PipelineResult r = run_pipeline(o);
  ASSERT_GT(r.target.V.rows(), 100);
  const double diagonal = bounding_box(r.target.V).diagonal().norm();
  double worst = 0.0;
  for (Eigen::Index v = 0; v < r.target.V.rows(); ++v)
    worst = std::max(worst, (r.target.labels.row(v) - r.target.V.row(v)).norm());
  EXPECT_LT(worst, 1e-9 * diagonal);
  // The preimage written to labels.txt is a point of A's mesh: within a voxel of the vertex.
  for (Eigen::Index v = 0; v < r.target.V.rows(); ++v)
    ASSERT_LT((r.target_labels.row(v) - r.target.V.row(v)).norm(), 0.1 * diagonal);
}

TEST_P(PipelineSolvers, ConcentricSpheresMapRadially) {
  const double r0 = 0.5, r1 = 0.8;
  PipelineOptions o =
      small_options("sphere:size=0.5,center=0/0/0,res=64", "sphere:size=0.8,center=0/0/0,res=64", GetParam());
  o.morph.voxels = 32;
  const PipelineResult r = run_pipeline(o);
  const nlohmann::json report = nlohmann::json::parse(r.report_json);
  const double h = report["options"]["voxel_size"].get<double>();
  for (Eigen::Index v = 0; v < r.target.V.rows(); ++v) ASSERT_NEAR(r.target_labels.row(v).norm(), r0, 0.01 * r0);
  EXPECT_LT(worst_radial_angle(r), h / r1) << "voxel " << h;
  // Every characteristic reaches the inner sphere along the flow, none by the descent fallback.
  EXPECT_EQ(report["trace"]["stalled"].get<int>(), 0);
  EXPECT_EQ(report["trace"]["descended"].get<int>(), 0);
  EXPECT_FALSE(report.contains("transport"));  // the traced map runs no upwind sweep
}

TEST(Pipeline, VariationalMorphOfConcentricSpheresMapsRadially) {
  PipelineOptions o = small_options("sphere:size=0.5,center=0/0/0,res=64", "sphere:size=0.8,center=0/0/0,res=64", "cg");
  o.morph_method = "vim";
  o.vim.samples = 200;
  const PipelineResult r = run_pipeline(o);
  const nlohmann::json report = nlohmann::json::parse(r.report_json);
  EXPECT_EQ(report["morph"]["method"], "vim");
  EXPECT_EQ(report["morph"]["rbf_centres"].get<int>(), 2 * 2 * 200 + 16);
  const double h = report["options"]["voxel_size"].get<double>();
  EXPECT_LT(worst_radial_angle(r), 2.0 * h / 0.8) << "voxel " << h;
  EXPECT_EQ(report["trace"]["stalled"].get<int>(), 0);
}

TEST(Pipeline, MorphTopologyIsKeptOnlyBetweenEndsOfOneTopology) {
  PipelineOptions o = small_options("sphere:size=0.5,center=0/0/0,res=64", "sphere:size=0.8,center=0/0/0,res=64", "cg");
  o.morph_topology.mode = "auto";
  const PipelineResult same = run_pipeline(o);
  const nlohmann::json report = nlohmann::json::parse(same.report_json);
  EXPECT_EQ(report["morph"]["topology"]["applied"], true);
  EXPECT_EQ(report["morph"]["topology"]["levels_changed_kept"].get<int>(), 0);
  EXPECT_GT(report["morph"]["topology"]["changing_points"].get<int>(), 0);
  const double h = report["options"]["voxel_size"].get<double>();
  EXPECT_LT(worst_radial_angle(same), 2.0 * h / 0.8) << "voxel " << h;

  o.target = "two-spheres";
  const nlohmann::json split = nlohmann::json::parse(run_pipeline(o).report_json);
  EXPECT_EQ(split["morph"]["topology"]["applied"], false);
  EXPECT_EQ(split["morph"]["topology"]["target"]["components"].get<int>(), 2);
}

TEST(Pipeline, CriticalPointsOfTheHarmonicFieldAreCounted) {
  // Concentric spheres: s is radial, no critical point. Sphere -> torus: the hole opens at one saddle, in the middle.
  PipelineOptions o = small_options("sphere:size=0.5,center=0/0/0,res=64", "sphere:size=0.8,center=0/0/0,res=64", "cg");
  o.critical_points = true;
  nlohmann::json report = nlohmann::json::parse(run_pipeline(o).report_json);
  EXPECT_GT(report["critical_points"]["interior_vertices"].get<int>(), 0);
  EXPECT_EQ(report["critical_points"]["saddles"].get<int>(), 0);
  EXPECT_EQ(report["critical_points"]["minima"].get<int>(), 0);
  EXPECT_EQ(report["critical_points"]["maxima"].get<int>(), 0);
  o.source = "sphere";
  o.target = "torus";
  report = nlohmann::json::parse(run_pipeline(o).report_json);
  EXPECT_EQ(report["critical_points"]["saddles"].get<int>(), 1);
  EXPECT_EQ(report["critical_points"]["minima"].get<int>() + report["critical_points"]["maxima"].get<int>(), 0);
  const double h = report["options"]["voxel_size"].get<double>();
  const auto& at = report["critical_points"]["listed"][0]["position"];
  EXPECT_LT(std::hypot(at[0].get<double>(), at[1].get<double>(), at[2].get<double>()), 2.0 * h);
  o.critical_points = false;
  EXPECT_FALSE(nlohmann::json::parse(run_pipeline(o).report_json).contains("critical_points"));
}

TEST(Pipeline, OptionsThatWouldDoNothingAreRefusedBeforeAnyWork) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "morphmap_pipeline_noop_options";
  std::filesystem::remove_all(dir);
  PipelineOptions o = small_options("sphere", "torus", "cg");
  o.output_dir = dir.string();
  const auto refused = [&](const PipelineOptions& options, const std::string& words) {
    try {
      run_pipeline(options);
      ADD_FAILURE() << "accepted, expected: " << words;
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
    EXPECT_FALSE(std::filesystem::exists(dir));
  };
  PipelineOptions vim = o;
  vim.morph_method = "vim";
  vim.morph_topology.mode = "auto";
  refused(vim, "--morph-topology auto");
  PipelineOptions closest = o;
  closest.method = "closest-point";
  closest.critical_points = true;
  refused(closest, "--critical-points");
  PipelineOptions unknown = o;
  unknown.morph_topology.mode = "always";
  refused(unknown, "--morph-topology: unknown value 'always'");
}

INSTANTIATE_TEST_SUITE_P(Solvers, PipelineSolvers, ::testing::Values("cholmod", "cg"));

/// An octahedron of radius 0.8 with every face cut into 36 triangles (146 vertices), as an OFF file: its corners
/// and edges are sharper than the lattice, so its extraction is rounded there.
std::string write_subdivided_octahedron(const std::filesystem::path& path) {
  const Eigen::Vector3d corner[6] = {{0.8, 0, 0}, {-0.8, 0, 0}, {0, 0.8, 0}, {0, -0.8, 0}, {0, 0, 0.8}, {0, 0, -0.8}};
  const int face[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  constexpr int n = 6;
  std::vector<Eigen::Vector3d> V;
  std::vector<std::array<int, 3>> F;
  auto vertex = [&](const Eigen::Vector3d& p) {
    for (std::size_t i = 0; i < V.size(); ++i)
      if ((V[i] - p).norm() < 1e-12) return int(i);
    V.push_back(p);
    return int(V.size() - 1);
  };
  for (const auto& f : face) {
    auto at = [&](int i, int j) {
      return vertex(corner[f[0]] + (corner[f[1]] - corner[f[0]]) * i / n + (corner[f[2]] - corner[f[0]]) * j / n);
    };
    for (int i = 0; i < n; ++i)
      for (int j = 0; i + j < n; ++j) {
        F.push_back({at(i, j), at(i + 1, j), at(i, j + 1)});
        if (i + j < n - 1) F.push_back({at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)});
      }
  }
  std::ofstream out(path);
  out << std::setprecision(17) << "OFF\n" << V.size() << ' ' << F.size() << " 0\n";
  for (const Eigen::Vector3d& p : V) out << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
  for (const auto& t : F) out << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
  return path.string();
}

TEST(Pipeline, SourceSmallerThanAVoxelFallsBackToTheClosestPointProjection) {
  // A sphere a hundredth of a voxel across leaves no extracted A to invert; the run still labels B (every trace
  // a fallback) and says which projection it used.
  PipelineOptions o = small_options("sphere:size=0.01,center=0/0/0", "torus", "cg-amg");
  o.morph.voxels = 12;
  o.extract.time_steps = 4;
  const PipelineResult r = run_pipeline(o);
  EXPECT_GT(r.target.V.rows(), 0);
  const nlohmann::json report = nlohmann::json::parse(r.report_json);
  EXPECT_EQ(report["projection"]["method"], "closest");
  EXPECT_EQ(report["projection"]["requested"], "inverse");
  EXPECT_TRUE(r.target_labels.allFinite());
}

TEST(Pipeline, ShapeMorphedToItselfMapsItsOwnVerticesToThemselves) {
  // --target-mesh enters B through the closest points of the user's vertices on the extracted B; the inverse source
  // projection undoes that on A, so the identity morph of a mesh onto itself gives every vertex its own position.
  // Taking the closest point of A instead moves the vertices near the rounded edges (the old behaviour).
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "identity_octahedron";
  std::filesystem::create_directories(dir);
  const std::string octahedron = write_subdivided_octahedron(dir / "octahedron.off");
  auto run = [&](const std::string& projection) {
    PipelineOptions o = small_options(octahedron, octahedron, "cg-amg");
    o.target_mesh = octahedron;
    o.morph.voxels = 12;
    o.extract.time_steps = 4;
    o.source_projection = projection;
    return run_pipeline(o);
  };
  for (const std::string projection : {"inverse", "closest"}) {
    const PipelineResult r = run(projection);
    ASSERT_EQ(r.target.V.rows(), 146) << projection;
    ASSERT_EQ(r.target_labels.rows(), 146) << projection;
    const double diagonal = bounding_box(r.target.V).diagonal().norm();
    double worst = 0.0;
    int exact = 0;
    for (Eigen::Index v = 0; v < r.target.V.rows(); ++v) {
      const double error = (r.target_labels.row(v) - r.target.V.row(v)).norm();
      worst = std::max(worst, error);
      exact += error < 1e-8 * diagonal;
    }
    const nlohmann::json report = nlohmann::json::parse(r.report_json);
    EXPECT_EQ(report["projection"]["method"], projection);
    if (projection == "inverse") {
      // Measured: 142 of 146; the other 4 (1e-3 away) sit where the moved copies of A's faces overlap (the
      // extraction's small bumps on a flat face fold the closest-point map), and the lowest-numbered face wins.
      EXPECT_GE(exact, 139);
      EXPECT_LT(worst, 0.01 * diagonal);
      EXPECT_GT(report["projection"]["largest_offset_voxels"].get<double>(), 0.0);
    } else {
      EXPECT_LE(exact, 73) << "the closest point of A to the rounded extraction is the vertex only on flat parts";
    }
  }
}

TEST(Pipeline, TargetMeshFarFromTheTargetIsWarnedAbout) {
  // --target-mesh takes its labels through closest points on the extracted B: the target's own mesh lies within about
  // a voxel of it, a mesh in other coordinates far away, whose closest points correspond to nothing. That was silent.
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "far_target_mesh";
  std::filesystem::create_directories(dir);
  const std::string octahedron = write_subdivided_octahedron(dir / "octahedron.off");
  Surface moved = read_surface(octahedron);
  moved.V.col(0).array() += 3.0 * bounding_box(moved.V).diagonal().norm();
  const std::string far = (dir / "far.obj").string();
  write_obj(far, moved.V, moved.F, Eigen::MatrixXd(), Eigen::MatrixXi(), "");
  for (const std::string& mesh : {octahedron, far}) {
    PipelineOptions o = small_options("sphere", octahedron, "cg-amg");
    o.target_mesh = mesh;
    o.morph.voxels = 12;
    o.extract.time_steps = 4;
    const nlohmann::json inputs = nlohmann::json::parse(run_pipeline(o).report_json)["inputs"];
    const double largest = inputs["target_mesh_distance_voxels"]["max"].get<double>();
    if (mesh == octahedron) {
      EXPECT_LT(largest, 1.5);
      EXPECT_TRUE(inputs["warnings"].empty()) << inputs["warnings"];
    } else {
      EXPECT_GT(largest, 20.0);
      ASSERT_EQ(inputs["warnings"].size(), 1u);
      EXPECT_NE(inputs["warnings"][0].get<std::string>().find("far.obj"), std::string::npos);
    }
  }
  std::filesystem::remove_all(dir);
}

// Angles between each target vertex and its preimage on concentric spheres (the exact map is radial): mean and max.
std::pair<double, double> radial_errors(const std::string& method, int voxels) {
  PipelineOptions o =
      small_options("sphere:size=0.5,center=0/0/0,res=128", "sphere:size=0.8,center=0/0/0,res=128", "cg");
  o.method = method;
  o.morph.voxels = voxels;
  // Refining the lattice in time as in space keeps the hypersurface (time is a length: c stays fixed).
  o.extract.time_steps = voxels / 4;
  o.extract.time_scale = 0.3;
  const PipelineResult r = run_pipeline(o);
  const nlohmann::json report = nlohmann::json::parse(r.report_json);
  if (method == "upwind") {
    EXPECT_EQ(report["transport"]["fallback_unreached"].get<int>(), 0);
  }
  double sum = 0.0, worst = 0.0;
  for (Eigen::Index v = 0; v < r.target.V.rows(); ++v) {
    const Eigen::Vector3d q = r.target.V.row(v).transpose(), label = r.target_labels.row(v).transpose();
    const double angle = std::acos(std::clamp(q.normalized().dot(label.normalized()), -1.0, 1.0));
    sum += angle;
    worst = std::max(worst, angle);
  }
  return {sum / double(r.target.V.rows()), worst};
}

class PipelineMethods : public ::testing::TestWithParam<std::string> {};

TEST_P(PipelineMethods, ConcentricSphereErrorFallsAtLeastLinearlyWithTheVoxelSize) {
  const auto coarse = radial_errors(GetParam(), 12), fine = radial_errors(GetParam(), 24);
  EXPECT_GT(coarse.first, 0.0);
  EXPECT_LE(fine.first, 0.5 * coarse.first) << "mean angle " << coarse.first << " -> " << fine.first;
  EXPECT_LE(fine.second, 0.5 * coarse.second) << "max angle " << coarse.second << " -> " << fine.second;
}

INSTANTIATE_TEST_SUITE_P(Methods, PipelineMethods, ::testing::Values("trace", "upwind"));

TEST(Pipeline, SphereToTorusLabelsEveryTargetVertexAndTransfersUv) {
  PipelineOptions o = small_options("sphere", "torus", "cholmod");
  o.slices = {0.5};
  const PipelineResult r = run_pipeline(o);
  const nlohmann::json report = nlohmann::json::parse(r.report_json);
  ASSERT_GT(r.target.F.rows(), 100);
  EXPECT_EQ(r.target_labels.rows(), r.target.V.rows());
  EXPECT_TRUE(r.target_labels.allFinite());
  ASSERT_EQ(r.target_uv.rows(), r.target.V.rows());
  EXPECT_GE(r.target_uv.minCoeff(), -1e-9);
  EXPECT_LE(r.target_uv.maxCoeff(), 1.0 + 1e-9);
  // The extracted torus is closed, oriented outward and of genus 1 (Euler characteristic 0).
  const SurfaceCheck check = check_surface(r.target.F, r.target.V.rows());
  EXPECT_TRUE(check.closed());
  EXPECT_TRUE(check.manifold());
  EXPECT_GT(signed_volume(r.target.V, r.target.F), 0.0);
  const std::int64_t euler = r.target.V.rows() - r.target.F.rows() * 3 / 2 + r.target.F.rows();
  EXPECT_EQ(euler, 0);
  for (const char* key : {"load", "morph", "extract", "laplace", "gradient", "map", "transfer", "total"})
    EXPECT_TRUE(report["seconds"].contains(key)) << key;
  EXPECT_EQ(report["counts"]["tets"].get<std::int64_t>(), r.mesh_tets);
  EXPECT_LT(report["solver"]["residual"].get<double>(), 1e-8);
}

TEST(Pipeline, StageSecondsAccountForTheWholeRun) {
  // report.json's stages are disjoint and cover the run: their sum is its total, less only the moments between
  // stages. The traced map's set-up (face neighbours, vertex normals) once fell between two stages and was 4% of
  // cow -> horse's total that no stage counted.
  PipelineOptions o = small_options("sphere", "torus", "cg-amg");
  o.slices = {0.5};
  const PipelineResult r = run_pipeline(o);
  const nlohmann::json seconds = nlohmann::json::parse(r.report_json)["seconds"];
  double sum = 0.0;
  for (const auto& [stage, value] : seconds.items())
    if (stage != "total") sum += value.get<double>();
  const double total = seconds["total"].get<double>();
  EXPECT_LE(sum, total * (1.0 + 1e-9));
  EXPECT_GE(sum, 0.99 * total) << seconds.dump();
}

TEST(Pipeline, AlignBboxReturnsOutputsInEachInputsFrame) {
  // A small sphere far from a large torus: --align bbox morphs them in a common frame, then the
  // target comes back in the torus' coordinates and the preimages in the sphere's.
  PipelineOptions o = small_options("sphere:size=0.5,center=10/0/0,res=48", "torus:size=3,center=-5/2/1", "cg");
  o.align = "bbox";
  const PipelineResult r = run_pipeline(o);
  const nlohmann::json report = nlohmann::json::parse(r.report_json);
  const Eigen::AlignedBox3d box = bounding_box(r.target.V);
  // The extracted surface lies within one voxel of the torus box (voxel in the torus frame: 3 / unit frame).
  const double tolerance = 3.0 * report["options"]["voxel_size"].get<double>();
  EXPECT_NEAR(box.min().x(), -8.0, tolerance);
  EXPECT_NEAR(box.max().x(), -2.0, tolerance);
  EXPECT_NEAR(box.center().y(), 2.0, tolerance);
  EXPECT_NEAR(box.center().z(), 1.0, tolerance);
  for (Eigen::Index v = 0; v < r.target_labels.rows(); ++v)
    ASSERT_NEAR((r.target_labels.row(v) - Eigen::RowVector3d(10, 0, 0)).norm(), 0.5, 5e-3);  // facet sag of a 48-gon
}

TEST(Pipeline, LabelsFileHoldsEveryLabelAsPrintfsSeventeenDigits) {
  // labels.txt: one line per vertex of target.obj, three numbers each in "%.17g" (what the stream with
  // setprecision(17) wrote before std::to_chars), so every label reads back to the same double.
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "labels_text";
  std::filesystem::remove_all(dir);
  PipelineOptions o = small_options("sphere:res=24", "torus", "cg-amg");
  o.output_dir = dir.string();
  const PipelineResult r = run_pipeline(o);
  std::ifstream in(dir / "labels.txt");
  ASSERT_TRUE(in);
  std::string line;
  Eigen::Index lines = 0;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string token;
    int count = 0;
    while (fields >> token) {
      const double value = std::strtod(token.c_str(), nullptr);
      char expected[40];
      std::snprintf(expected, sizeof expected, "%.17g", value);
      ASSERT_EQ(token, expected) << "line " << lines + 1;
      ++count;
    }
    ASSERT_EQ(count, 3) << "line " << lines + 1 << ": " << line;
    ++lines;
  }
  EXPECT_EQ(lines, r.target_seams.V.rows());
  EXPECT_GT(lines, 100);
  std::filesystem::remove_all(dir);
}

TEST(Pipeline, SlicesAtNearbyTimesGetTheirOwnFilesAndRepeatsOne) {
  // Slice names were the time to six digits: 0.3 and 0.3000001 both wrote slice_0.3.obj, the second over the first,
  // and report.json listed both. A time given twice wrote and listed the same file twice.
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "slice_names";
  std::filesystem::remove_all(dir);
  PipelineOptions o = small_options("sphere:res=24", "torus", "cg-amg");
  o.output_dir = dir.string();
  o.slices = {0.3, 0.3000001, 0.3};
  run_pipeline(o);
  const nlohmann::json report = nlohmann::json::parse(std::ifstream(dir / "report.json"));
  ASSERT_EQ(report["slices"].size(), 2u);
  EXPECT_EQ(report["slices"][0]["file"], "slice_0.3.obj");
  EXPECT_EQ(report["slices"][1]["file"], "slice_0.3000001.obj");
  for (const auto& slice : report["slices"]) {
    const Surface s = read_surface((dir / slice["file"].get<std::string>()).string());
    EXPECT_GT(s.F.rows(), 100) << slice["file"];
  }
  std::filesystem::remove_all(dir);
}

// Writes the built-in sphere (res 24, with its UVs) as `name`.obj naming `name`.mtl, whose map_Kd is `texture`.
std::string write_textured_sphere(const std::filesystem::path& dir, const std::string& name,
                                  const std::string& texture) {
  const Surface sphere = make_shape(parse_shape_spec("sphere:res=24"), std::nullopt);
  const std::string obj = (dir / (name + ".obj")).string();
  write_obj(obj, sphere.V, sphere.F, sphere.UV, sphere.FUV, name + ".mtl");
  std::ofstream(dir / (name + ".mtl")) << "newmtl m\nmap_Kd " << texture << "\n";
  return obj;
}

TEST(Pipeline, MissingTextureIsAWarningAndAnUnreadableOneAnError) {
  // An MTL naming an image that is not there: the map goes on, with the UVs and a warning in report.json (before, the
  // texture vanished without one). An image that cannot be read (a truncated download) is refused before any work: it
  // was copied into the outputs and named by target.mtl.
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "mtl_textures";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  PipelineOptions o = small_options(write_textured_sphere(dir, "missing", "nothere.png"), "torus", "cg-amg");
  o.morph.voxels = 12;
  o.output_dir = (dir / "out").string();
  run_pipeline(o);
  const nlohmann::json report = nlohmann::json::parse(std::ifstream(dir / "out" / "report.json"));
  ASSERT_EQ(report["inputs"]["warnings"].size(), 1u);
  EXPECT_NE(report["inputs"]["warnings"][0].get<std::string>().find("nothere.png"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(dir / "out" / "target.mtl"));
  EXPECT_TRUE(read_surface((dir / "out" / "target.obj").string()).has_uv());

  // Two materials with their own images: one is carried for every face, and the run says which it is not.
  write_textured_sphere(dir, "two", "first.png");
  write_png((dir / "first.png").string(), checkerboard(8, 2));
  write_png((dir / "second.png").string(), checkerboard(8, 4));
  {
    std::ifstream in(dir / "two.obj");
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::size_t faces = text.find("usemtl morphmap");
    ASSERT_NE(faces, std::string::npos);
    const std::size_t half = text.find("\nf ", (faces + text.size()) / 2);
    ASSERT_NE(half, std::string::npos);
    text.insert(half + 1, "usemtl n\n");
    std::ofstream(dir / "two.obj") << text;
    std::ofstream(dir / "two.mtl") << "newmtl morphmap\nmap_Kd first.png\nnewmtl n\nmap_Kd second.png\n";
  }
  o.source = (dir / "two.obj").string();
  o.output_dir = (dir / "out3").string();
  run_pipeline(o);
  const nlohmann::json two = nlohmann::json::parse(std::ifstream(dir / "out3" / "report.json"));
  ASSERT_EQ(two["inputs"]["warnings"].size(), 1u) << two["inputs"]["warnings"];
  EXPECT_NE(two["inputs"]["warnings"][0].get<std::string>().find("second.png"), std::string::npos);

  std::ofstream(dir / "broken.png") << "\x89PNG\r\n\x1a\n";  // a PNG signature and nothing after it
  o.source = write_textured_sphere(dir, "broken", "broken.png");
  o.output_dir = (dir / "out2").string();
  try {
    run_pipeline(o);
    FAIL() << "an unreadable texture was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("broken.obj"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("broken.png"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out2"));
  std::filesystem::remove_all(dir);
}

TEST(Pipeline, PlyHoldsTheObjsTrianglesWithTheirCornerUvs) {
  // target.ply is target.obj's seam-split mesh with per-vertex UVs: every triangle's corners carry the OBJ's
  // per-corner UVs. (It held the unsplit B before, whose triangles across the sphere's longitude-0 seam took UVs from
  // both sides of the texture.)
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "ply_uvs";
  std::filesystem::remove_all(dir);
  PipelineOptions o = small_options("sphere:res=24", "torus", "cg-amg");
  o.output_dir = dir.string();
  o.write_ply = true;
  const PipelineResult r = run_pipeline(o);
  const Surface obj = read_surface((dir / "target.obj").string());
  const Surface ply = read_surface((dir / "target.ply").string());
  ASSERT_TRUE(obj.has_uv());
  ASSERT_TRUE(ply.has_uv());
  ASSERT_EQ(ply.F.rows(), obj.F.rows());
  EXPECT_GT(r.target_seams.texture_split, 0);
  EXPECT_GT(ply.V.rows(), obj.V.rows());  // vertices on the texture seam, once per side
  double worst = 0.0;
  for (Eigen::Index f = 0; f < obj.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) {
      worst = std::max(worst, (ply.V.row(ply.F(f, c)) - obj.V.row(obj.F(f, c))).cwiseAbs().maxCoeff());
      worst = std::max(worst, (ply.UV.row(ply.FUV(f, c)) - obj.UV.row(obj.FUV(f, c))).cwiseAbs().maxCoeff());
    }
  EXPECT_LT(worst, 1e-6);  // PLY stores u, v as float
  std::filesystem::remove_all(dir);
}

TEST(Pipeline, SourceWithInwardFacesMapsAsTheSameSolid) {
  // A source mesh whose faces wind inward: its normals pointed into the solid, and every preimage counted as folded
  // (bunny_closed.obj reversed: 12852 folded triangles instead of 135). It is turned outward at load and reported.
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "inward";
  std::filesystem::create_directories(dir);
  const Surface torus = make_shape(parse_shape_spec("torus:res=32"), std::nullopt);
  const TriIndices outward = torus.F, inward = torus.F.rowwise().reverse();
  write_obj((dir / "out.obj").string(), torus.V, outward, Eigen::MatrixXd(), TriIndices(), "");
  write_obj((dir / "in.obj").string(), torus.V, inward, Eigen::MatrixXd(), TriIndices(), "");
  std::map<std::string, nlohmann::json> reports;
  for (const char* name : {"out.obj", "in.obj"}) {
    const PipelineResult r = run_pipeline(small_options((dir / name).string(), "sphere", "cg-amg"));
    reports[name] = nlohmann::json::parse(r.report_json);
  }
  EXPECT_FALSE(reports["out.obj"]["inputs"]["source_reoriented"].get<bool>());
  EXPECT_TRUE(reports["in.obj"]["inputs"]["source_reoriented"].get<bool>());
  const auto folded = [&](const char* name) { return reports[name]["stretch"]["folded"].get<std::int64_t>(); };
  const auto triangles = [&](const char* name) { return reports[name]["stretch"]["triangles"].get<std::int64_t>(); };
  // The turned faces start each triangle at another corner, which moves a few borderline folds (torus -> sphere
  // changes topology, and its seams fold a few triangles either way); without the turn nearly all fold.
  EXPECT_LT(folded("in.obj"), triangles("in.obj") / 20) << folded("out.obj");
  EXPECT_LT(folded("out.obj"), triangles("out.obj") / 20);
  const auto coverage = [&](const char* name) { return reports[name]["stretch"]["coverage"].get<double>(); };
  EXPECT_NEAR(coverage("in.obj"), coverage("out.obj"), 0.05);
  // The same for the user's own target mesh (--target-mesh, possibly open: its winding is compared with the
  // extracted target's), which keeps its vertices: the turned mesh is measured exactly as the outward one.
  std::map<std::string, nlohmann::json> user;
  for (const char* name : {"out.obj", "in.obj"}) {
    PipelineOptions o = small_options("sphere", "torus", "cg-amg");
    o.target_mesh = (dir / name).string();
    user[name] = nlohmann::json::parse(run_pipeline(o).report_json);
  }
  EXPECT_FALSE(user["out.obj"]["inputs"]["target_mesh_reoriented"].get<bool>());
  EXPECT_TRUE(user["in.obj"]["inputs"]["target_mesh_reoriented"].get<bool>());
  EXPECT_EQ(user["in.obj"]["stretch"]["folded"], user["out.obj"]["stretch"]["folded"]);
  EXPECT_EQ(user["in.obj"]["stretch"]["coverage"], user["out.obj"]["stretch"]["coverage"]);
  std::filesystem::remove_all(dir);
}

TEST(Pipeline, TriangleSoupIsWeldedAndMapsLikeTheMesh) {
  // A mesh exported as a triangle soup (every face with its own three vertices) is the same closed surface: it is
  // welded at load, reported, and maps exactly as the shared-vertex mesh does. Welding that cannot close it leaves
  // the error about the mesh as read.
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) / "soup";
  std::filesystem::create_directories(dir);
  const Surface torus = make_shape(parse_shape_spec("torus:res=24"), std::nullopt);
  Eigen::MatrixXd V(3 * torus.F.rows(), 3);
  TriIndices F(torus.F.rows(), 3);
  for (Eigen::Index f = 0; f < torus.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) {
      V.row(3 * f + c) = torus.V.row(torus.F(f, c));
      F(f, c) = int(3 * f + c);
    }
  write_obj((dir / "soup.obj").string(), V, F, Eigen::MatrixXd(), TriIndices(), "");
  write_obj((dir / "mesh.obj").string(), torus.V, torus.F, Eigen::MatrixXd(), TriIndices(), "");
  const PipelineResult soup = run_pipeline(small_options("sphere", (dir / "soup.obj").string(), "cg-amg"));
  const PipelineResult mesh = run_pipeline(small_options("sphere", (dir / "mesh.obj").string(), "cg-amg"));
  EXPECT_EQ(nlohmann::json::parse(soup.report_json)["inputs"]["target_welded_vertices"].get<std::int64_t>(),
            V.rows() - torus.V.rows());
  EXPECT_EQ(nlohmann::json::parse(mesh.report_json)["inputs"]["target_welded_vertices"].get<std::int64_t>(), 0);
  ASSERT_EQ(soup.target_labels.rows(), mesh.target_labels.rows());
  EXPECT_EQ(soup.target_labels, mesh.target_labels);
  // One face short: welding leaves three boundary edges, and the message counts the soup's own.
  write_obj((dir / "open.obj").string(), V, F.topRows(F.rows() - 1), Eigen::MatrixXd(), TriIndices(), "");
  try {
    run_pipeline(small_options("sphere", (dir / "open.obj").string(), "cg-amg"));
    ADD_FAILURE() << "an open soup was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("not closed (" + std::to_string(3 * (F.rows() - 1)) + " boundary edges)"),
              std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace morphmap
