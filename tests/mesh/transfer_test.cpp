// Tests of closest-point location and UV interpolation for texture transfer (paper §8.2).
#include "mesh/transfer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "mesh/errors.h"
#include "tests/mesh/product_mesh.h"

namespace morphmap {
namespace {

Surface to_surface(const test_mesh::TriSurface& s) {
  Surface out;
  out.V = s.V;
  out.F = s.F;
  out.name = "test";
  return out;
}

// Reference closest point on triangle (Ericson, Real-Time Collision Detection §5.1.5).
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

Eigen::MatrixXd random_points(int count, double half_width, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-half_width, half_width);
  Eigen::MatrixXd Q(count, 3);
  for (int i = 0; i < count; ++i) Q.row(i) << u(rng), u(rng), u(rng);
  return Q;
}

TEST(TransferTest, ClosestPointOnOctahedron) {
  const Surface octa = to_surface(test_mesh::octahedron());
  const SurfaceLocator locator(octa);
  const SurfaceHit face_hit = locator.closest(Eigen::Vector3d(1, 1, 1));
  EXPECT_EQ(face_hit.face, 0);
  EXPECT_LE((face_hit.point - Eigen::Vector3d::Constant(1.0 / 3.0)).norm(), 1e-14);
  EXPECT_LE((face_hit.barycentric - Eigen::Vector3d::Constant(1.0 / 3.0)).norm(), 1e-14);
  EXPECT_NEAR(face_hit.distance, 2.0 / std::sqrt(3.0), 1e-14);

  // Outside the x-vertex's normal cone of faces: the vertex itself is closest, whichever face reports it.
  const SurfaceHit vertex_hit = locator.closest(Eigen::Vector3d(2, 0.1, 0.1));
  EXPECT_LE((vertex_hit.point - Eigen::Vector3d(1, 0, 0)).norm(), 1e-14);
  ASSERT_GE(vertex_hit.face, 0);
  for (int k = 0; k < 3; ++k)
    EXPECT_NEAR(vertex_hit.barycentric(k), octa.F(vertex_hit.face, k) == 0 ? 1.0 : 0.0, 1e-14);
}

TEST(TransferTest, AffineUvIsInterpolatedExactlyAtTrueClosestPoints) {
  Surface sphere = to_surface(test_mesh::icosphere(1));
  Eigen::Matrix<double, 2, 3> M;
  M << 0.3, -1.2, 0.7, 2.0, 0.1, -0.4;
  const Eigen::Vector2d offset(0.25, -3.0);
  sphere.UV = (sphere.V * M.transpose()).rowwise() + offset.transpose();
  sphere.FUV = sphere.F;
  const SurfaceLocator locator(sphere);
  const Eigen::MatrixXd Q = random_points(300, 2.0, 7);
  const std::vector<SurfaceHit> hits = locator.closest_all(Q);
  const Eigen::MatrixXd uv = uv_at(sphere, hits);
  const Eigen::MatrixXd P = points_of(hits);
  ASSERT_EQ(uv.rows(), Q.rows());
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    const SurfaceHit& h = hits[std::size_t(i)];
    const Eigen::Vector3d q = Q.row(i);
    double best = std::numeric_limits<double>::infinity();
    for (Eigen::Index f = 0; f < sphere.F.rows(); ++f)
      best = std::min(best, (closest_on_triangle(q, sphere.V.row(sphere.F(f, 0)), sphere.V.row(sphere.F(f, 1)),
                                                 sphere.V.row(sphere.F(f, 2))) -
                             q)
                                .norm());
    EXPECT_NEAR(h.distance, best, 1e-12);
    EXPECT_NEAR((h.point - q).norm(), h.distance, 1e-14);
    EXPECT_NEAR(h.barycentric.sum(), 1.0, 1e-14);
    EXPECT_GE(h.barycentric.minCoeff(), 0.0);
    Eigen::Vector3d rebuilt = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) rebuilt += h.barycentric(k) * sphere.V.row(sphere.F(h.face, k)).transpose();
    EXPECT_LE((rebuilt - h.point).norm(), 1e-12);
    EXPECT_LE((uv.row(i).transpose() - (M * h.point + offset)).norm(), 1e-12);
    EXPECT_EQ(P.row(i), h.point.transpose());
  }
}

TEST(TransferTest, ClosestAllMatchesClosestInOrder) {
  const SurfaceLocator locator(to_surface(test_mesh::icosphere(2)));
  const Eigen::MatrixXd Q = random_points(5000, 1.5, 11);
  const std::vector<SurfaceHit> all = locator.closest_all(Q);
  ASSERT_EQ(all.size(), std::size_t(Q.rows()));
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    const SurfaceHit one = locator.closest(Q.row(i).transpose());
    EXPECT_EQ(all[std::size_t(i)].face, one.face);
    EXPECT_EQ(all[std::size_t(i)].point, one.point);
    EXPECT_EQ(all[std::size_t(i)].barycentric, one.barycentric);
  }
  EXPECT_TRUE(locator.closest_all(Eigen::MatrixXd(0, 3)).empty());
}

TEST(TransferTest, DegenerateTrianglesGiveConvexWeights) {
  Surface s;
  s.V.resize(5, 3);
  s.V << 0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 3, 0, 3, 3, 0;
  s.F.resize(2, 3);
  s.F << 0, 1, 2,  // collinear: a segment
      3, 4, 3;     // a point
  const SurfaceLocator locator(s);
  for (const Eigen::Vector3d& q : {Eigen::Vector3d(0.5, 1, 0), Eigen::Vector3d(1.7, -0.2, 0.3),
                                   Eigen::Vector3d(3.2, 3.1, 1.0), Eigen::Vector3d(-1, 0, 0)}) {
    const SurfaceHit h = locator.closest(q);
    ASSERT_TRUE(h.barycentric.allFinite());
    EXPECT_NEAR(h.barycentric.sum(), 1.0, 1e-14);
    EXPECT_GE(h.barycentric.minCoeff(), 0.0);
    Eigen::Vector3d rebuilt = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) rebuilt += h.barycentric(k) * s.V.row(s.F(h.face, k)).transpose();
    EXPECT_LE((rebuilt - h.point).norm(), 1e-12) << q.transpose();
  }
  EXPECT_LE((locator.closest(Eigen::Vector3d(0.5, 1, 0)).point - Eigen::Vector3d(0.5, 0, 0)).norm(), 1e-14);
  EXPECT_LE((locator.closest(Eigen::Vector3d(3.2, 3.1, 1.0)).point - Eigen::Vector3d(3, 3, 0)).norm(), 1e-14);
}

TEST(TransferTest, RejectsUnusableInput) {
  const Surface octa = to_surface(test_mesh::octahedron());
  const SurfaceLocator locator(octa);
  const std::vector<SurfaceHit> hits = {locator.closest(Eigen::Vector3d(1, 2, 3))};
  EXPECT_THROW(uv_at(octa, hits), InvalidInput);  // no UVs
  EXPECT_THROW(SurfaceLocator(Surface{}), InvalidInput);
  Surface bad = octa;
  bad.F(0, 0) = 17;
  EXPECT_THROW(SurfaceLocator{bad}, InvalidInput);
}

}  // namespace
}  // namespace morphmap
