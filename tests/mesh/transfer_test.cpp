// Tests of closest-point location and UV interpolation for texture transfer (paper §8.2).
#include "mesh/transfer.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "mesh/errors.h"
#include "mesh/shapes.h"
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

// Independent of the locator's region test: the foot on the plane when it falls inside the triangle, else the
// nearest of the three edges (a zero-area triangle is its edges), all in long double.
using Vec3L = Eigen::Matrix<long double, 3, 1>;

long double segment_distance(const Vec3L& p, const Vec3L& a, const Vec3L& b) {
  const Vec3L ab = b - a;
  const long double length = ab.squaredNorm();
  const long double t = length > 0 ? std::clamp((p - a).dot(ab) / length, 0.0L, 1.0L) : 0.0L;
  return (a + t * ab - p).norm();
}

long double triangle_distance(const Vec3L& p, const Vec3L& a, const Vec3L& b, const Vec3L& c) {
  const Vec3L n = (b - a).cross(c - a);
  const long double area2 = n.squaredNorm();
  if (area2 > 0) {
    const Vec3L foot = p - n * (n.dot(p - a) / area2);
    if (n.dot((b - a).cross(foot - a)) >= 0 && n.dot((c - b).cross(foot - b)) >= 0 &&
        n.dot((a - c).cross(foot - c)) >= 0)
      return (foot - p).norm();
  }
  return std::min({segment_distance(p, a, b), segment_distance(p, b, c), segment_distance(p, c, a)});
}

long double face_distance(const Surface& s, Eigen::Index f, const Eigen::Vector3d& q) {
  return triangle_distance(q.cast<long double>(), s.V.row(s.F(f, 0)).transpose().cast<long double>(),
                           s.V.row(s.F(f, 1)).transpose().cast<long double>(),
                           s.V.row(s.F(f, 2)).transpose().cast<long double>());
}

double brute_force_distance(const Surface& s, const Eigen::Vector3d& q) {
  long double best = std::numeric_limits<long double>::infinity();
  for (Eigen::Index f = 0; f < s.F.rows(); ++f) best = std::min(best, face_distance(s, f, q));
  return double(best);
}

// Queries that stress the search: random points around and inside the surface, points just off random faces,
// exactly on vertices and on edges, and far away (where single-precision node distances lose the most).
Eigen::MatrixXd stress_queries(const Surface& s, int count, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const Eigen::AlignedBox3d box = bounding_box(s.V);
  const double size = box.sizes().maxCoeff();
  auto pick = [&](Eigen::Index n) { return Eigen::Index(std::min(double(n - 1), std::floor(unit(rng) * n))); };
  Eigen::MatrixXd Q(count, 3);
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3d q;
    const Eigen::Index f = pick(s.F.rows());
    const Eigen::Vector3d a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
    switch (i % 6) {
      case 0:  // anywhere in the box grown by half its size each way: outside, near, inside
        q = box.center() + size * Eigen::Vector3d(unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5) * 2.0;
        break;
      case 1: {  // just off a face, on either side
        double u = unit(rng), v = unit(rng);
        if (u + v > 1.0) u = 1.0 - u, v = 1.0 - v;
        const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
        const double offset = size * std::pow(10.0, -1.0 - 6.0 * unit(rng)) * (unit(rng) < 0.5 ? -1.0 : 1.0);
        q = a + u * (b - a) + v * (c - a) + offset * n;
        break;
      }
      case 2:  // exactly a vertex
        q = s.V.row(pick(s.V.rows()));
        break;
      case 3: {  // on an edge (up to rounding)
        const double t = unit(rng);
        q = (1.0 - t) * a + t * b;
        break;
      }
      case 4: {  // far away in a random direction
        const Eigen::Vector3d d = Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng)).normalized();
        q = box.center() + size * std::pow(10.0, 1.0 + 7.0 * unit(rng)) * d;
        break;
      }
      default:  // near the surface: a vertex jittered by up to a few edge lengths
        q = a + 0.05 * size * Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
        break;
    }
    Q.row(i) = q.transpose();
  }
  return Q;
}

// Every hit's distance is the brute-force minimum over all faces to 1e-12 relative, and its point lies on its face.
// The absolute term is double rounding of the coordinates themselves (q - a loses 1e-16 of |q| and |a|), which
// matters on the surface, where the distance is that rounding, and on a mesh far from the origin.
void expect_exact(const Surface& s, const Eigen::MatrixXd& Q, const std::vector<SurfaceHit>& hits) {
  ASSERT_EQ(hits.size(), std::size_t(Q.rows()));
  const double size = bounding_box(s.V).sizes().maxCoeff();
  const double mesh_magnitude = std::max(size, s.V.cwiseAbs().maxCoeff());
  int failures = 0;
  for (Eigen::Index i = 0; i < Q.rows() && failures < 10; ++i) {
    const SurfaceHit& h = hits[std::size_t(i)];
    const Eigen::Vector3d q = Q.row(i);
    const double best = brute_force_distance(s, q);
    const double tolerance = 1e-12 * best + 1e-14 * std::max(mesh_magnitude, q.cwiseAbs().maxCoeff());
    ASSERT_GE(h.face, 0);
    ASSERT_LT(h.face, s.F.rows());
    EXPECT_NEAR(h.distance, best, tolerance) << "query " << i << " at " << q.transpose();
    EXPECT_NEAR(double(face_distance(s, h.face, q)), best, tolerance) << "query " << i << ": face " << h.face;
    EXPECT_EQ(h.distance, (h.point - q).norm());
    Eigen::Vector3d rebuilt = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) rebuilt += h.barycentric(k) * s.V.row(s.F(h.face, k)).transpose();
    EXPECT_LE((rebuilt - h.point).norm(), 1e-12 * mesh_magnitude) << "query " << i;
    if (std::abs(h.distance - best) > tolerance) ++failures;
  }
}

Surface shape(const std::string& spec) { return make_shape(parse_shape_spec(spec), std::nullopt); }

// A shape's vertices moved by up to about a third of an edge: irregular, non-convex, with thin triangles.
Surface perturbed(Surface s, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double edge = (s.V.row(s.F(0, 0)) - s.V.row(s.F(0, 1))).norm();
  for (Eigen::Index v = 0; v < s.V.rows(); ++v) s.V.row(v) += 0.35 * edge * Eigen::RowVector3d(u(rng), u(rng), u(rng));
  return s;
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

// A hint only bounds the search: any face, near or far, gives closest()'s hit. closest_all hints each query with the
// previous one's face, which on a lattice in order (as the morph's exact distances query it) is near.
TEST(TransferTest, HintedQueriesMatchClosest) {
  const Surface surface = to_surface(test_mesh::icosphere(2));
  const SurfaceLocator locator(surface);
  std::vector<Eigen::Vector3d> lattice;
  for (int k = 0; k < 12; ++k)
    for (int j = 0; j < 12; ++j)
      for (int i = 0; i < 12; ++i) lattice.emplace_back(-1.6 + 0.29 * i, -1.6 + 0.29 * j, -1.6 + 0.29 * k);
  Eigen::MatrixXd Q(Eigen::Index(lattice.size()), 3);
  for (std::size_t q = 0; q < lattice.size(); ++q) Q.row(Eigen::Index(q)) = lattice[q].transpose();
  const std::vector<SurfaceHit> all = locator.closest_all(Q);
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    const SurfaceHit one = locator.closest(Q.row(i).transpose());
    EXPECT_EQ(all[std::size_t(i)].face, one.face);
    EXPECT_EQ(all[std::size_t(i)].point, one.point);
    for (const int hint : {0, int(surface.F.rows()) - 1, one.face, -1, int(surface.F.rows()) + 5}) {
      const SurfaceHit hinted = locator.closest_near(Q.row(i).transpose(), hint);
      EXPECT_EQ(hinted.face, one.face) << i << " hint " << hint;
      EXPECT_EQ(hinted.point, one.point) << i << " hint " << hint;
    }
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

// A bound on the search: the unbounded hit when it lies within the bound, none (face -1, infinite distance) beyond.
TEST(TransferTest, BoundedQueriesFindOnlyFacesWithinTheBound) {
  const SurfaceLocator locator(to_surface(test_mesh::icosphere(2)));
  const Eigen::MatrixXd Q = random_points(3000, 1.5, 5);
  const double within = 0.2;
  const std::vector<SurfaceHit> bounded = locator.closest_all(Q, within);
  int found = 0, missed = 0;
  for (Eigen::Index i = 0; i < Q.rows(); ++i) {
    const SurfaceHit one = locator.closest(Q.row(i).transpose());
    const SurfaceHit& hit = bounded[std::size_t(i)];
    if (one.distance < within) {
      ++found;
      EXPECT_EQ(hit.face, one.face) << i;
      EXPECT_EQ(hit.point, one.point) << i;
    } else {
      ++missed;
      EXPECT_EQ(hit.face, -1) << i;
      EXPECT_EQ(hit.distance, std::numeric_limits<double>::infinity()) << i;
    }
  }
  EXPECT_GT(found, 100);
  EXPECT_GT(missed, 100);
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

TEST(TransferTest, ClosestMatchesBruteForceOnShapes) {
  for (const std::string spec : {"torus:res=32", "sphere:res=24"}) {
    SCOPED_TRACE(spec);
    const Surface s = shape(spec);
    const SurfaceLocator locator(s);
    const Eigen::MatrixXd Q = stress_queries(s, 1500, 3);
    expect_exact(s, Q, locator.closest_all(Q));
  }
}

TEST(TransferTest, ClosestMatchesBruteForceOnPerturbedMesh) {
  const Surface s = perturbed(shape("torus:res=32,center=5/-3/1000"), 5);
  const SurfaceLocator locator(s);
  const Eigen::MatrixXd Q = stress_queries(s, 1500, 9);
  expect_exact(s, Q, locator.closest_all(Q));
}

// Zero-area faces (a repeated vertex, collinear corners, all three corners equal) are found like any other: Embree
// 3.13 keeps them in its triangle BVH, and this would catch a version that drops them.
TEST(TransferTest, DegenerateFacesAreFoundByTheSearch) {
  Surface s = shape("sphere:res=16");
  const Eigen::Index n = s.V.rows(), m = s.F.rows();
  s.V.conservativeResize(n + 6, 3);
  s.V.bottomRows(6) << 3, 0, 0, 4, 0, 0, 5, 0, 0,  // collinear, middle corner listed last below
      0, 3, 0, 0, 3, 2,                            // a segment through a repeated vertex
      0, 0, -3;                                    // a point
  s.F.conservativeResize(m + 3, 3);
  s.F.bottomRows(3) << n, n + 2, n + 1, n + 3, n + 4, n + 3, n + 5, n + 5, n + 5;
  s.UV.resize(0, 2);
  s.FUV.resize(0, 3);
  const SurfaceLocator locator(s);
  Eigen::MatrixXd Q(8, 3);
  Q << 4.5, 0.3, -0.2, 5.5, 0, 0, 2.9, 0.01, 0, 0.2, 3.1, 1.0, 0, 3, 2.5, 0.1, -0.1, -3.2, 0, 0, -3, 4, 0, 0;
  const std::vector<SurfaceHit> hits = locator.closest_all(Q);
  expect_exact(s, Q, hits);
  for (const SurfaceHit& h : hits) EXPECT_GE(h.face, m) << "a degenerate face is the closest to every query";
  expect_exact(s, stress_queries(s, 600, 17), locator.closest_all(stress_queries(s, 600, 17)));
}

// The BVH is built and searched in parallel; the answer (the least squared distance, ties to the lower face)
// must not depend on how many threads did it.
TEST(TransferTest, HitsDoNotDependOnThreadCount) {
  const Surface s = perturbed(shape("torus:res=48"), 21);
  Eigen::MatrixXd Q = stress_queries(s, 4000, 23);
  // Vertices are shared by several faces: ties that only the face index breaks.
  Q.topRows(std::min<Eigen::Index>(500, s.V.rows())) = s.V.topRows(std::min<Eigen::Index>(500, s.V.rows()));
  std::vector<SurfaceHit> hits[2];
  for (int threads = 1; threads <= 2; ++threads) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    const SurfaceLocator locator(s);
    hits[threads - 1] = locator.closest_all(Q);
  }
  ASSERT_EQ(hits[0].size(), hits[1].size());
  for (std::size_t i = 0; i < hits[0].size(); ++i) {
    EXPECT_EQ(hits[0][i].face, hits[1][i].face) << i;
    EXPECT_EQ(hits[0][i].point, hits[1][i].point) << i;
    EXPECT_EQ(hits[0][i].barycentric, hits[1][i].barycentric) << i;
    EXPECT_EQ(hits[0][i].distance, hits[1][i].distance) << i;
  }
  // A vertex query reports the lowest-numbered face holding that vertex.
  for (Eigen::Index v = 0; v < std::min<Eigen::Index>(500, s.V.rows()); ++v) {
    Eigen::Index lowest = -1;
    for (Eigen::Index f = 0; f < s.F.rows() && lowest < 0; ++f)
      if (s.F(f, 0) == v || s.F(f, 1) == v || s.F(f, 2) == v) lowest = f;
    EXPECT_EQ(hits[1][std::size_t(v)].face, lowest) << "vertex " << v;
    EXPECT_EQ(hits[1][std::size_t(v)].distance, 0.0);
  }
}

// Past float's range Embree cannot hold the faces or square the distances: such meshes and queries are scanned.
TEST(TransferTest, CoordinatesBeyondFloatRangeAreScanned) {
  Surface huge = perturbed(shape("torus:res=12"), 31);
  huge.V *= 1e20;
  const SurfaceLocator huge_locator(huge);
  const Eigen::MatrixXd Q = stress_queries(huge, 300, 33);
  expect_exact(huge, Q, huge_locator.closest_all(Q));

  const Surface s = perturbed(shape("torus:res=12"), 35);
  const SurfaceLocator locator(s);
  Eigen::MatrixXd far(4, 3);
  far << 1e25, -3e24, 7, 0, 0, -2e18, 1e16, 1e16, -1e16, -5e17, 1, 2;
  expect_exact(s, far, locator.closest_all(far));
}

TEST(TransferTest, RejectsNonFiniteQuery) {
  const SurfaceLocator locator(to_surface(test_mesh::octahedron()));
  EXPECT_THROW(locator.closest(Eigen::Vector3d(0, std::nan(""), 0)), InvalidInput);
  Eigen::MatrixXd Q = Eigen::MatrixXd::Zero(600, 3);
  Q(345, 2) = std::numeric_limits<double>::infinity();
  EXPECT_THROW(locator.closest_all(Q), InvalidInput);
}

TEST(TransferTest, MovedSearchReportsHitsOnTheSurfaceItself) {
  // The search runs on a perturbed copy of a sphere (same faces) and reports on the sphere: a query at a moved vertex
  // finds that vertex, a query at a point of a moved face finds the same face and weights.
  const Surface sphere = to_surface(test_mesh::icosphere(2));
  const Eigen::MatrixXd moved = perturbed(sphere, 7).V;
  const SurfaceLocator locator(sphere, moved);
  const SurfaceLocator plain(sphere);
  const double scale = bounding_box(sphere.V).diagonal().norm();
  for (Eigen::Index v = 0; v < sphere.V.rows(); ++v) {
    const SurfaceHit hit = locator.closest(moved.row(v).transpose());
    EXPECT_LE(hit.distance, 1e-12 * scale);
    EXPECT_LE((hit.point - sphere.V.row(v).transpose()).norm(), 1e-12 * scale) << "vertex " << v;
  }
  int tested = 0, matched = 0;
  for (Eigen::Index f = 0; f < sphere.F.rows(); f += 7) {
    ++tested;
    const Eigen::Vector3d w(0.2, 0.3, 0.5);
    Eigen::Vector3d query = Eigen::Vector3d::Zero(), expected = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) {
      query += w(k) * moved.row(sphere.F(f, k)).transpose();
      expected += w(k) * sphere.V.row(sphere.F(f, k)).transpose();
    }
    const SurfaceHit hit = locator.closest(query);
    EXPECT_LE(hit.distance, 1e-12 * scale);
    if (hit.face != int(f)) continue;  // the moved copy may fold over this point: another face can hold it too
    ++matched;
    EXPECT_LE((hit.barycentric - w).norm(), 1e-9) << "face " << f;
    EXPECT_LE((hit.point - expected).norm(), 1e-12 * scale) << "face " << f;
    // The plain locator, by contrast, answers with the closest point of the sphere itself.
    EXPECT_GT((plain.closest(query).point - expected).norm(), 1e-6 * scale) << "face " << f;
  }
  EXPECT_GE(matched, tested * 3 / 4);
  EXPECT_THROW(SurfaceLocator(sphere, moved.topRows(3)), InvalidInput);
  Eigen::MatrixXd broken = moved;
  broken(0, 0) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(SurfaceLocator(sphere, broken), InvalidInput);
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
