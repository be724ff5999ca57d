// End-to-end properties of the whole pipeline on analytic inputs (identity morph, concentric spheres).
#include "app/pipeline.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <utility>

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
  const PipelineResult r = run_pipeline(small_options("sphere:res=48", "sphere:res=48", GetParam()));
  ASSERT_GT(r.target.V.rows(), 100);
  const double diagonal = bounding_box(r.target.V).diagonal().norm();
  double worst = 0.0;
  for (Eigen::Index v = 0; v < r.target.V.rows(); ++v)
    worst = std::max(worst, (r.target.labels.row(v) - r.target.V.row(v)).norm());
  EXPECT_LT(worst, 1e-9 * diagonal);
  // The preimage written to labels.txt is the closest point of A's mesh: within a voxel of the vertex.
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

INSTANTIATE_TEST_SUITE_P(Solvers, PipelineSolvers, ::testing::Values("cholmod", "cg"));

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

}  // namespace
}  // namespace morphmap
