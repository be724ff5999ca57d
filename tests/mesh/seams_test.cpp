// Seams (paper §8): a hand-built tet straddling a label seam, and small analytic morphs through the
// pipeline (sphere -> torus opens a hole, sphere -> two spheres splits, sphere -> sphere crosses the
// longitude texture seam).
#include "mesh/seams.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "app/pipeline.h"
#include "mesh/errors.h"
#include "mesh/shapes.h"

namespace morphmap {
namespace {

Surface unit_sphere() {
  ShapeSpec spec;
  spec.kind = "sphere";
  spec.resolution = 32;
  return make_shape(spec, std::nullopt);
}

// One tet: vertices 0-2 on B (t = 1), forming B's only triangle, vertex 3 on A.
TetMesh4 one_tet() {
  TetMesh4 mesh;
  mesh.V.resize(4, 4);
  mesh.V << 0, 0, 0, 1,  //
      1, 0, 0, 1,        //
      0, 1, 0, 1,        //
      0.3, 0.3, 0.5, 0;
  mesh.T.resize(1, 4);
  mesh.T << 0, 1, 2, 3;
  mesh.side = {VertexSide::B, VertexSide::B, VertexSide::B, VertexSide::A};
  mesh.time_steps = 1;
  mesh.voxel_size = 1.0;
  return mesh;
}

// B's only triangle of one_tet() with these labels (#4 by 3, the last the tet's vertex on A) split on the unit sphere,
// topological seams only.
SeamResult split_one_tet(const Eigen::MatrixXd& labels, bool topological = true,
                         const std::vector<char>& relabelled = {}) {
  const TetMesh4 mesh = one_tet();
  const Surface A = unit_sphere();
  const SurfaceLocator locator(A);
  const SliceMesh B = target_boundary(mesh, labels);
  EXPECT_EQ(B.F.rows(), 1);
  SeamOptions options;
  options.texture = false;
  options.topological = topological;
  return split_seams(B, mesh, labels, A, locator, options, relabelled);
}

// Labels of one_tet() across a seam: vertex 0 carries the north pole's label, the others the south pole's, so B's
// only triangle straddles a topological seam.
Eigen::MatrixXd pole_labels() {
  Eigen::MatrixXd labels(4, 3);
  labels << 0, 0, 1,  //
      0.05, 0, -1,    //
      0, 0.05, -1,    //
      0, 0, -1;
  return labels;
}

TEST(Seams, TriangleAcrossALabelSeamIsCutAndNoPieceSpansIt) {
  const Eigen::MatrixXd labels = pole_labels();
  const SeamResult r = split_one_tet(labels);
  EXPECT_EQ(r.seam_tets, 1);
  EXPECT_EQ(r.topological_split, 1);
  EXPECT_EQ(r.F.rows(), 3);  // a triangle and a quad
  EXPECT_EQ(r.spans_over_threshold, 0);
  // The cut runs through the midpoints of the two edges leaving vertex 0 (its critical plane meets B there),
  // and both sides keep their own labels: the seam points appear once per side.
  EXPECT_EQ(r.topological_seam_points.rows(), 2);
  EXPECT_EQ(r.V.rows(), 7);
  // Labels are compared on A (closest points): every output label is one pole or the other, none between.
  for (Eigen::Index v = 0; v < r.V.rows(); ++v) EXPECT_NEAR(std::abs(r.labels(v, 2)), 1.0, 0.02) << v;
  for (Eigen::Index i = 0; i < r.topological_seam_points.rows(); ++i) {
    const Eigen::Vector3d p = r.topological_seam_points.row(i).transpose();
    EXPECT_TRUE(p.isApprox(Eigen::Vector3d(0.5, 0, 0)) || p.isApprox(Eigen::Vector3d(0, 0.5, 0))) << p.transpose();
  }
  // Without seam handling the same triangle would stay whole and span the seam.
  const SeamResult off = split_one_tet(labels, false);
  EXPECT_EQ(off.spans_over_threshold, 1);
}

// The closest points of B's labels, when the caller has them, are taken instead of searched for: the hits the
// search would find give the same split, and other points (all at the north pole) give other labels.
TEST(Seams, GivenClosestPointsOfTheLabelsAreUsed) {
  const Eigen::MatrixXd labels = pole_labels();
  const TetMesh4 mesh = one_tet();
  const Surface A = unit_sphere();
  const SurfaceLocator locator(A);
  const SliceMesh B = target_boundary(mesh, labels);
  SeamOptions options;
  options.texture = false;
  const SeamResult searched = split_seams(B, mesh, labels, A, locator, options);
  const Eigen::MatrixXd hits = points_of(locator.closest_all(B.labels));
  const SeamResult given = split_seams(B, mesh, labels, A, locator, options, {}, &hits);
  EXPECT_EQ(given.V, searched.V);
  EXPECT_EQ(given.F, searched.F);
  EXPECT_EQ(given.labels, searched.labels);
  EXPECT_EQ(given.topological_split, 1);
  // Given as the closest points of B's labels, they are also those of the labels of the mesh vertices B's vertices
  // sit on: the tet's three B vertices now agree (all at the north pole), so nothing is cut.
  const Eigen::MatrixXd north = Eigen::RowVector3d(0, 0, 1).replicate(B.V.rows(), 1);
  const SeamResult moved = split_seams(B, mesh, labels, A, locator, options, {}, &north);
  EXPECT_EQ(moved.topological_split, 0);
  ASSERT_EQ(moved.labels.rows(), north.rows());
  EXPECT_EQ(moved.labels, north);
  const Eigen::MatrixXd short_hits = hits.topRows(hits.rows() - 1);
  EXPECT_THROW(split_seams(B, mesh, labels, A, locator, options, {}, &short_hits), InvalidInput);
}

// B's triangle has labels within the seam threshold of each other, but the tet's fourth vertex, near two of them
// and far from the third, makes the linkage put the third alone: the triangle is cut between corners whose labels
// agree. Where the fold repair relabelled all three corners (the fourth vertex's label is one it replaced), the
// triangle stays whole.
TEST(Seams, TriangleWhoseCornersTheRepairRelabelledStaysWhole) {
  Eigen::MatrixXd labels(4, 3);
  const double d = std::sqrt(0.5);
  labels << 0, 0, 1,                                    // p: the pole, 1.0 from s
      d, 0, d,                                          // q: 0.77 from p, 0.26 from s
      Eigen::RowVector3d(0.5, 0.3, 0.81).normalized(),  // r: 0.61 from p, 0.38 from q, 0.57 from s
      std::sqrt(0.75), 0, 0.5;                          // s: the tet's vertex on A
  EXPECT_EQ(split_one_tet(labels).topological_split, 1);
  EXPECT_EQ(split_one_tet(labels, true, {1, 1, 0}).topological_split, 1);
  const SeamResult whole = split_one_tet(labels, true, {1, 1, 1});
  EXPECT_EQ(whole.topological_split, 0);
  EXPECT_EQ(whole.F.rows(), 1);
  EXPECT_EQ(whole.V.rows(), 3);
  EXPECT_THROW(split_one_tet(labels, true, {1, 1}), InvalidInput);
}

PipelineOptions small(const std::string& source, const std::string& target) {
  PipelineOptions o;
  o.source = source;
  o.target = target;
  o.morph.voxels = 16;
  o.extract.time_steps = 4;
  return o;
}

TEST(Seams, SphereToTorusSeamLiesOnTheInnerRing) {
  const PipelineResult r = run_pipeline(small("sphere", "torus"));
  const nlohmann::json report = nlohmann::json::parse(r.report_json);
  const nlohmann::json& seams = report["seams"];
  EXPECT_GT(seams["topological_split"].get<std::int64_t>(), 0);
  EXPECT_EQ(seams["spans_over_threshold"].get<std::int64_t>(), 0);
  EXPECT_EQ(seams["topological_seam_regions"].get<std::int64_t>(), 1);
  EXPECT_GE(seams["topological_seam_curves"].get<std::int64_t>(), 1);
  EXPECT_EQ(seams["uv_area_excess"].get<std::int64_t>(), 0);
  EXPECT_GT(seams["uv_area_excess_unsplit"].get<std::int64_t>(), 0);
  // Torus around z fitted to the sphere's box: R + r = half the x extent, r = half the z extent.
  const Eigen::AlignedBox3d box = bounding_box(r.target.V);
  const double h = report["options"]["voxel_size"].get<double>();
  const double minor = 0.5 * box.sizes().z(), inner = 0.5 * box.sizes().x() - 2.0 * minor;
  const Eigen::Vector3d c = box.center();
  const Eigen::MatrixXd& P = r.target_seams.topological_seam_points;
  ASSERT_GT(P.rows(), 8);
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    const Eigen::Vector3d d = P.row(i).transpose() - c;
    const double ring = std::hypot(std::hypot(d.x(), d.y()) - inner, d.z());
    EXPECT_LT(ring, h) << "seam vertex " << i << " at " << P.row(i);
  }
}

TEST(Seams, SplittingSphereHasOneSeamPerNewSphere) {
  const PipelineResult r = run_pipeline(small("sphere", "two-spheres"));
  const SeamResult& s = r.target_seams;
  // Around each pinch point the cuts form a star of short curves (labels there come from the whole waist
  // ring), so the seams are counted as connected sets of cut triangles.
  EXPECT_EQ(s.topological_seam_regions, 2);
  EXPECT_GE(s.topological_seam_curves, 2);
  EXPECT_EQ(s.spans_over_threshold, 0);
  EXPECT_EQ(s.uv_area_excess, 0);
  // One curve on each sphere: seam points on both sides of the plane between them.
  const Eigen::AlignedBox3d box = bounding_box(r.target.V);
  Eigen::Index axis = 0;
  box.sizes().maxCoeff(&axis);
  int below = 0, above = 0;
  for (Eigen::Index i = 0; i < s.topological_seam_points.rows(); ++i)
    (s.topological_seam_points(i, axis) < box.center()(axis) ? below : above)++;
  EXPECT_GT(below, 0);
  EXPECT_GT(above, 0);
}

TEST(Seams, LongitudeTextureSeamIsSplit) {
  // Same shape, different tessellation: B's triangles straddle A's longitude seam.
  const PipelineResult r = run_pipeline(small("sphere:res=40", "sphere:res=40"));
  const SeamResult& s = r.target_seams;
  EXPECT_EQ(s.seam_tets, 0);
  EXPECT_GT(s.texture_split, 0);
  EXPECT_GT(s.uv_area_excess_unsplit, 0);
  EXPECT_EQ(s.uv_area_excess, 0);
  EXPECT_EQ(s.unresolved_edges, 0);
  ASSERT_EQ(s.FUV.rows(), s.F.rows());
  // Split triangles on the two sides of the seam take u near 0 and near 1 at the same position.
  double low = 1.0, high = 0.0;
  for (Eigen::Index i = 0; i < s.UV.rows(); ++i) {
    low = std::min(low, s.UV(i, 0));
    high = std::max(high, s.UV(i, 0));
  }
  EXPECT_LT(low, 0.01);
  EXPECT_GT(high, 0.99);
}

// Output triangles the longitude seam (half-plane y = 0, x > 0) passes through from edge to edge: corners on both
// sides of y = 0 and the triangle's whole section with y = 0 at x > 0 (a section reaching x <= 0 holds the seam's
// end, the z axis, where no cut can separate the sides).
int crossed_by_longitude_seam(const SeamResult& r, double eps) {
  int crossed = 0;
  for (Eigen::Index f = 0; f < r.F.rows(); ++f) {
    std::array<Eigen::Vector3d, 3> l;
    for (int k = 0; k < 3; ++k) l[std::size_t(k)] = r.labels.row(r.F(f, k)).transpose();
    double low = 0.0, high = 0.0, x_min = 1e9;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& a = l[std::size_t(k)];
      const Eigen::Vector3d& b = l[std::size_t((k + 1) % 3)];
      low = std::min(low, a.y());
      high = std::max(high, a.y());
      if ((a.y() < 0.0) != (b.y() < 0.0)) x_min = std::min(x_min, a.x() + (b.x() - a.x()) * a.y() / (a.y() - b.y()));
    }
    crossed += low < -eps && high > eps && x_min > 0.0;
  }
  return crossed;
}

TEST(Seams, FanPiecesAreSplitWhereTheSeamCrossesTheirSpokes) {
  // One triangle of B whose labels (near A's north pole) surround the end of the longitude seam: it enters
  // through one edge and ends inside, so the triangle is fanned from a point inside. The corners sit so that
  // the seam, on its way to its end, passes through two fan triangles, across the spokes between them.
  const TetMesh4 mesh = one_tet();
  Eigen::MatrixXd labels(4, 3);
  labels.row(0) = Eigen::Vector3d(0.3, 0.075, 0.9).normalized().transpose();
  labels.row(1) = Eigen::Vector3d(-0.15, 0.15, 0.9).normalized().transpose();
  labels.row(2) = Eigen::Vector3d(-0.15, -0.3, 0.9).normalized().transpose();
  labels.row(3) = Eigen::Vector3d(0.0, -0.025, 0.9).normalized().transpose();
  ShapeSpec spec;
  spec.kind = "sphere";
  spec.resolution = 128;  // faces small next to the triangle, so closest points follow the seam closely
  const Surface A = make_shape(spec, std::nullopt);
  const SurfaceLocator locator(A);
  const SliceMesh B = target_boundary(mesh, labels);
  ASSERT_EQ(B.F.rows(), 1);
  SeamOptions options;
  const SeamResult r = split_seams(B, mesh, labels, A, locator, options);
  EXPECT_EQ(r.seam_tets, 0);
  EXPECT_EQ(r.texture_split, 1);
  EXPECT_EQ(r.texture_fan_splits, 1);
  EXPECT_EQ(r.unresolved_edges, 0);
  EXPECT_EQ(crossed_by_longitude_seam(r, 0.01), 0);
  // Splitting only at the crossings of B's own edges leaves fan triangles across the seam.
  options.max_split_depth = 1;
  const SeamResult once = split_seams(B, mesh, labels, A, locator, options);
  EXPECT_EQ(once.texture_fan_splits, 1);
  EXPECT_GT(crossed_by_longitude_seam(once, 0.01), 0);
  EXPECT_LT(once.F.rows(), r.F.rows());
}

TEST(Seams, CornerUvIsTakenAtTheClosestPointPastAConcaveFold) {
  // A sheet folded into a valley (profile x = -2, -1, 0, 1, 2 with z = 0, 0, -1, 0, 0, extruded along y), one
  // UV chart (u, v) = (x, y). Corner 0's label hangs above the valley's left rim: it projects inside the right
  // slope, where the triangle's home face lies, but its closest point is the left rim, x = -1. A walk that
  // stops at the first face p projects into gives u = 0.9 there.
  Surface A;
  const double xs[] = {-2, -1, 0, 1, 2}, zs[] = {0, 0, -1, 0, 0};
  A.V.resize(10, 3);
  for (int i = 0; i < 5; ++i) {
    A.V.row(2 * i) << xs[i], -1, zs[i];
    A.V.row(2 * i + 1) << xs[i], 1, zs[i];
  }
  A.F.resize(8, 3);
  for (int i = 0; i < 4; ++i) {
    A.F.row(2 * i) << 2 * i, 2 * i + 2, 2 * i + 3;
    A.F.row(2 * i + 1) << 2 * i, 2 * i + 3, 2 * i + 1;
  }
  A.UV = A.V.leftCols(2);
  A.FUV = A.F;
  const SurfaceLocator locator(A);
  const TetMesh4 mesh = one_tet();
  Eigen::MatrixXd labels(4, 3);
  labels << -0.2, 0, 1,  //
      0.8, 0.1, -0.2,    //
      0.8, -0.1, -0.2,   //
      0, 0, -1;
  const SliceMesh B = target_boundary(mesh, labels);
  ASSERT_EQ(B.F.rows(), 1);
  SeamOptions options;
  options.texture = false;
  options.topological = false;
  const SeamResult r = split_seams(B, mesh, labels, A, locator, options);
  ASSERT_EQ(r.F.rows(), 1);
  ASSERT_EQ(r.FUV.rows(), 1);
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d label = r.labels.row(r.F(0, k)).transpose();
    const Eigen::Vector3d closest = locator.closest(label).point;  // one chart: its UV is (x, y)
    EXPECT_NEAR(r.UV(r.FUV(0, k), 0), closest.x(), 1e-9) << "corner " << k;
    EXPECT_NEAR(r.UV(r.FUV(0, k), 1), closest.y(), 1e-9) << "corner " << k;
  }
  EXPECT_NEAR(r.UV(r.FUV(0, 0), 0), -1.0, 1e-9);
}

TEST(Seams, CountCurves) {
  EXPECT_EQ(count_curves({}), 0);
  EXPECT_EQ(count_curves({{0, 1}, {1, 2}, {5, 6}}), 2);
  EXPECT_EQ(count_curves({{0, 1}, {1, 2}, {2, 0}}), 1);
}

}  // namespace
}  // namespace morphmap
