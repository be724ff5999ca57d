// Stretch metrics on maps whose singular values are known in closed form.
#include "mesh/metrics.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "mesh/errors.h"
#include "mesh/shapes.h"

namespace morphmap {
namespace {

TriIndices faces_of(const Surface& s) { return s.F; }

Surface unit_sphere() {
  ShapeSpec spec = parse_shape_spec("sphere:size=1,center=0/0/0,res=32");
  return make_shape(spec, std::nullopt);
}

TEST(Stretch, IdentityMapHasNoDistortion) {
  const Surface A = unit_sphere();
  const StretchResult r = measure_stretch(A, A.V, faces_of(A), A.V);
  EXPECT_EQ(r.measured, A.F.rows());
  EXPECT_NEAR(r.min_sigma2, 1.0, 1e-9);
  EXPECT_NEAR(r.max_sigma1, 1.0, 1e-9);
  EXPECT_NEAR(r.mean_l2, 1.0, 1e-9);
  EXPECT_NEAR(r.variance_l2, 0.0, 1e-9);
  EXPECT_NEAR(r.coverage, 1.0, 1e-12);
  EXPECT_EQ(r.folded, 0);
  EXPECT_EQ(r.collapsed, 0);
  EXPECT_NEAR(r.l2_median, 1.0, 1e-9);
  EXPECT_NEAR(r.l2_p99, 1.0, 1e-9);
  EXPECT_EQ(r.area_over_2, 0.0);
}

TEST(Stretch, UniformScaleIsNormalisedAway) {
  const Surface A = unit_sphere();
  const Eigen::MatrixXd B = 3.0 * A.V;
  const StretchResult r = measure_stretch(A, B, faces_of(A), A.V);
  EXPECT_NEAR(r.min_sigma2, 1.0, 1e-9);
  EXPECT_NEAR(r.max_sigma1, 1.0, 1e-9);
  EXPECT_NEAR(r.sander_l2, 1.0, 1e-9);
}

TEST(Stretch, AnisotropicScaleGivesKnownSingularValues) {
  // B = diag(2, 1, 1) A on a sphere is not uniform per triangle, so use a flat square instead:
  // preimages on the square, B the square stretched by 2 along x. Area ratio 2, so sigma = (2, 1) / sqrt(2).
  Surface A;
  A.V.resize(4, 3);
  A.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  A.F.resize(2, 3);
  A.F << 0, 1, 2, 0, 2, 3;
  Eigen::MatrixXd B = A.V;
  B.col(0) *= 2.0;
  const StretchResult r = measure_stretch(A, B, faces_of(A), A.V);
  EXPECT_NEAR(r.max_sigma1, 2.0 / std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(r.min_sigma2, 1.0 / std::sqrt(2.0), 1e-12);
  EXPECT_NEAR(r.mean_l2, std::sqrt((2.0 + 0.5) / 2.0), 1e-12);
  EXPECT_NEAR(r.variance_l2, 0.0, 1e-12);
}

TEST(Stretch, AreaQuantilesSeparateAFewDistortedTrianglesFromTheRest) {
  // 20 separate right triangles in the plane; B is A except triangle 0, whose preimage is squeezed 40x along x.
  // Every B triangle has the same area, so triangle 0 is 5% of B.
  const int n = 20;
  Surface A;
  A.V.resize(3 * n, 3);
  A.F.resize(n, 3);
  for (int i = 0; i < n; ++i) {
    A.V.row(3 * i) << 2.0 * i, 0, 0;
    A.V.row(3 * i + 1) << 2.0 * i + 1, 0, 0;
    A.V.row(3 * i + 2) << 2.0 * i, 1, 0;
    A.F.row(i) << 3 * i, 3 * i + 1, 3 * i + 2;
  }
  const Eigen::MatrixXd B = A.V;
  Eigen::MatrixXd preimages = A.V;
  preimages(1, 0) = 1.0 / 40.0;
  A.V = preimages;  // A is the surface the preimages lie on
  const StretchResult r = measure_stretch(A, B, faces_of(A), preimages);
  const double normalise = std::sqrt(0.5 * n / (0.5 * (n - 1) + 0.5 / 40.0));
  const double plain = 1.0 / normalise, squeezed = std::sqrt((40.0 * 40.0 + 1.0) / 2.0) / normalise;
  EXPECT_NEAR(r.l2_median, plain, 1e-9);
  EXPECT_NEAR(r.l2_p90, plain, 1e-9);
  EXPECT_NEAR(r.l2_p99, squeezed, 1e-9);
  EXPECT_NEAR(r.area_over_2, 1.0 / n, 1e-12);
  EXPECT_NEAR(r.area_over_10, 1.0 / n, 1e-12);
  EXPECT_NEAR(r.max_sigma1, 40.0 / normalise, 1e-9);
}

TEST(Stretch, FoldedAndCollapsedPreimagesAreCounted) {
  const Surface A = unit_sphere();
  Eigen::MatrixXd pre = A.V;
  TriIndices F = faces_of(A);
  // Collapse one triangle's preimage to a point; reverse another so its preimage faces inward.
  pre.row(F(0, 1)) = pre.row(F(0, 0));
  pre.row(F(0, 2)) = pre.row(F(0, 0));
  TriIndices G = F;
  std::swap(G(F.rows() / 2, 1), G(F.rows() / 2, 2));
  const StretchResult r = measure_stretch(A, A.V, G, pre);
  EXPECT_GE(r.collapsed, 1);
  EXPECT_GE(r.folded, 1);
  EXPECT_EQ(r.measured + r.collapsed + r.degenerate, r.triangles);
}

TEST(Stretch, TrianglesWithoutAreaOnBAreLeftOutNotCollapsed) {
  // A seam split whose cut passes through a vertex leaves a piece of zero area on B; its preimage has none either,
  // and it has no stretch. It was counted as collapsed, and its neighbour-less sigma2 set the min to 0.
  const Surface A = unit_sphere();
  Eigen::MatrixXd B = A.V, pre = A.V;
  TriIndices F = faces_of(A);
  const Eigen::Index last = F.rows();
  F.conservativeResize(last + 1, 3);
  B.conservativeResize(B.rows() + 1, 3);
  pre.conservativeResize(pre.rows() + 1, 3);
  // A new vertex on the middle of triangle 0's first edge, and the flat triangle (edge ends and that point).
  const int mid = int(B.rows()) - 1;
  B.row(mid) = 0.5 * (A.V.row(F(0, 0)) + A.V.row(F(0, 1)));
  pre.row(mid) = B.row(mid);
  F.row(last) << F(0, 0), mid, F(0, 1);
  const StretchResult r = measure_stretch(A, B, F, pre);
  EXPECT_EQ(r.degenerate, 1);
  EXPECT_EQ(r.collapsed, 0);
  EXPECT_EQ(r.measured, A.F.rows());
  EXPECT_NEAR(r.min_sigma2, 1.0, 1e-9);
  EXPECT_TRUE(std::isnan(stretch_per_triangle(A, B, F, pre)(last)));
}

TEST(Stretch, RejectsMismatchedInput) {
  const Surface A = unit_sphere();
  EXPECT_THROW(measure_stretch(A, A.V, faces_of(A), A.V.topRows(3)), InvalidInput);
}

TEST(Stretch, PerTriangleValuesAgreeWithTheStatistics) {
  // A non-uniform map: each vertex pushed outwards by an amount that grows with x, so L2 varies per triangle.
  const Surface A = unit_sphere();
  Eigen::MatrixXd B = A.V;
  for (Eigen::Index i = 0; i < B.rows(); ++i) B.row(i) *= 1.0 + 0.4 * (A.V(i, 0) + 1.0);
  const StretchResult r = measure_stretch(A, B, faces_of(A), A.V);
  const Eigen::VectorXd l2 = stretch_per_triangle(A, B, faces_of(A), A.V);
  ASSERT_EQ(l2.size(), A.F.rows());
  double weight = 0.0, sum = 0.0;
  for (Eigen::Index f = 0; f < A.F.rows(); ++f) {
    ASSERT_TRUE(std::isfinite(l2(f)));
    const Eigen::Vector3d a = B.row(A.F(f, 0)), b = B.row(A.F(f, 1)), c = B.row(A.F(f, 2));
    const double area = 0.5 * (b - a).cross(c - a).norm();
    weight += area;
    sum += area * l2(f);
  }
  EXPECT_NEAR(sum / weight, r.mean_l2, 1e-12);
  EXPECT_GT(l2.maxCoeff() - l2.minCoeff(), 0.05);  // the map really is non-uniform
  // The identity has L2 = 1 everywhere; a collapsed preimage gives NaN.
  Eigen::MatrixXd pre = A.V;
  pre.row(A.F(0, 1)) = pre.row(A.F(0, 0));
  pre.row(A.F(0, 2)) = pre.row(A.F(0, 0));
  const Eigen::VectorXd l2_collapsed = stretch_per_triangle(A, A.V, faces_of(A), pre);
  EXPECT_TRUE(std::isnan(l2_collapsed(0)));
  const Eigen::VectorXd l2_identity = stretch_per_triangle(A, A.V, faces_of(A), A.V);
  EXPECT_NEAR(l2_identity.minCoeff(), 1.0, 1e-9);
  EXPECT_NEAR(l2_identity.maxCoeff(), 1.0, 1e-9);
}

TEST(Stretch, SingularValuesOfAnAffineMap) {
  // The unit right triangle in the plane z = 0, carried by diag(3, 0.5, 1) then rotated: singular values 3 and 0.5.
  Eigen::Matrix<double, 3, 2> Ep, Eq;
  Ep << 1.0, 0.0, 0.0, 1.0, 0.0, 0.0;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1.0, 2.0, -0.5).normalized()).toRotationMatrix();
  Eq = R * Eigen::Vector3d(3.0, 0.5, 1.0).asDiagonal() * Ep;
  const Eigen::Vector2d sigma = triangle_singular_values(Ep, Eq);
  EXPECT_NEAR(sigma(0), 3.0, 1e-12);
  EXPECT_NEAR(sigma(1), 0.5, 1e-12);
  Ep.col(1) = 2.0 * Ep.col(0);  // flat
  EXPECT_TRUE(std::isnan(triangle_singular_values(Ep, Eq)(0)));
  // Per triangle, the columns agree with the statistics' extremes.
  const Surface A = unit_sphere();
  Eigen::MatrixXd B = A.V;
  for (Eigen::Index i = 0; i < B.rows(); ++i) B(i, 0) *= 1.0 + 0.5 * (A.V(i, 2) + 1.0);
  const StretchResult r = measure_stretch(A, B, faces_of(A), A.V);
  const Eigen::MatrixX2d per = singular_values_per_triangle(A, B, faces_of(A), A.V);
  EXPECT_NEAR(per.col(0).maxCoeff(), r.max_sigma1, 1e-12);
  EXPECT_NEAR(per.col(1).minCoeff(), r.min_sigma2, 1e-12);
  EXPECT_TRUE((per.col(0).array() >= per.col(1).array()).all());
}

}  // namespace
}  // namespace morphmap
