// Tests of the mesh quality stage (dihedral angles and cotangent signs, paper §10) on tets whose angles and
// stiffness are known in closed form, and on an extracted mesh against the Laplace stage's own operator.
#include "mesh/quality.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numeric>
#include <random>
#include <vector>

#include "mesh/errors.h"
#include "mesh/extract.h"
#include "solver/laplace.h"

namespace morphmap {
namespace {

constexpr double kPi = 3.14159265358979323846;

double degrees(double radians) { return radians * 180.0 / kPi; }

/// A random rotation of R^4 (Q of a Gaussian matrix, fixed seed): every tet then has a generic 3-plane as hull,
/// so right angles and zero weights come out with rounding noise instead of exactly.
Eigen::Matrix4d random_rotation(unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal;
  Eigen::Matrix4d M;
  for (int i = 0; i < 16; ++i) M(i / 4, i % 4) = normal(rng);
  return Eigen::HouseholderQR<Eigen::Matrix4d>(M).householderQ();
}

/// Mesh from 3D points (placed in the tau = 0 hyperplane, then rotated and shifted in R^4) and tets.
TetMesh4 embedded_mesh(const std::vector<Eigen::Vector3d>& points, const std::vector<std::array<int, 4>>& tets,
                       unsigned seed) {
  const Eigen::Matrix4d Q = random_rotation(seed);
  const Eigen::Vector4d shift(0.3, -1.7, 2.2, 0.9);
  TetMesh4 mesh;
  mesh.V.resize(Eigen::Index(points.size()), 4);
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector4d p(points[i].x(), points[i].y(), points[i].z(), 0.0);
    mesh.V.row(Eigen::Index(i)) = (Q * p + shift).transpose();
  }
  mesh.T.resize(Eigen::Index(tets.size()), 4);
  for (std::size_t t = 0; t < tets.size(); ++t) {
    for (int q = 0; q < 4; ++q) mesh.T(Eigen::Index(t), q) = tets[t][std::size_t(q)];
  }
  mesh.side.assign(points.size(), VertexSide::Interior);
  return mesh;
}

std::int64_t histogram_total(const QualityResult& r) {
  return std::accumulate(r.dihedral_histogram.begin(), r.dihedral_histogram.end(), std::int64_t(0));
}

TEST(QualityRegularTet, AllDihedralsAreAcosOneThird) {
  const TetMesh4 mesh = embedded_mesh({{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}}, {{0, 1, 2, 3}}, 7);
  const QualityResult r = measure_quality(mesh);
  const double expected = degrees(std::acos(1.0 / 3.0));  // 70.53
  EXPECT_EQ(r.tets, 1);
  EXPECT_EQ(r.degenerate_tets, 0);
  EXPECT_NEAR(r.min_dihedral_degrees, expected, 1e-9);
  EXPECT_NEAR(r.max_dihedral_degrees, expected, 1e-9);
  EXPECT_EQ(r.obtuse_dihedrals, 0);
  EXPECT_EQ(r.obtuse_dihedral_fraction, 0.0);
  EXPECT_EQ(r.edges, 6);
  EXPECT_EQ(r.negative_cotangent_edges, 0);
  EXPECT_EQ(r.negative_cotangent_fraction, 0.0);
  EXPECT_NEAR(r.min_volume_ratio, 1.0, 1e-12);
  ASSERT_EQ(r.dihedral_histogram.size(), 18u);
  EXPECT_EQ(r.dihedral_histogram[7], 6);  // [70, 80) degrees
  EXPECT_EQ(histogram_total(r), 6);
}

TEST(QualityRightCorner, ThreeRightAnglesAndThreeOfAcosInverseSqrt3) {
  const TetMesh4 mesh = embedded_mesh({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{0, 1, 2, 3}}, 11);
  const QualityResult r = measure_quality(mesh);
  const double small = degrees(std::acos(1.0 / std::sqrt(3.0)));  // 54.74, at the edges of the slanted face
  EXPECT_NEAR(r.min_dihedral_degrees, small, 1e-9);
  EXPECT_NEAR(r.max_dihedral_degrees, 90.0, 1e-9);
  EXPECT_EQ(r.dihedral_histogram[5], 3);                            // [50, 60)
  EXPECT_EQ(r.dihedral_histogram[8] + r.dihedral_histogram[9], 3);  // 90 sits on a bin boundary
  EXPECT_EQ(histogram_total(r), 6);
  // The right angles are exactly at the default threshold and must not count as obtuse.
  EXPECT_EQ(r.obtuse_dihedrals, 0);
  // K_ij = 0 in exact arithmetic for the three edges between e1, e2, e3: rounding noise is not a negative weight.
  EXPECT_EQ(r.edges, 6);
  EXPECT_EQ(r.negative_cotangent_edges, 0);

  QualityOptions lower;
  lower.obtuse_threshold_degrees = 80.0;
  lower.histogram_bins = 4;
  const QualityResult q = measure_quality(mesh, lower);
  EXPECT_EQ(q.obtuse_dihedrals, 3);
  EXPECT_DOUBLE_EQ(q.obtuse_dihedral_fraction, 0.5);
  ASSERT_EQ(q.dihedral_histogram.size(), 4u);
  EXPECT_EQ(q.dihedral_histogram[1], 3);  // [45, 90)
  EXPECT_EQ(q.dihedral_histogram[0] + q.dihedral_histogram[3], 0);
}

TEST(QualityObtuseTet, ApexOverTheBaseGivesObtuseDihedralsAndPositiveOffDiagonals) {
  const TetMesh4 mesh = embedded_mesh({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.3, 0.3, 0.01}}, {{0, 1, 2, 3}}, 13);
  const QualityResult r = measure_quality(mesh);

  // By hand: the point (x, y, z) has lambda_3 = 100 z, lambda_1 = x - 30 z, lambda_2 = y - 30 z and
  // lambda_0 = 1 - x - y - 40 z, so the gradients are these, and vol * g_i . g_j has the sign of g_i . g_j:
  // g0.g1 = g0.g2 = 1199, g1.g2 = 900 > 0 (the base edges), the other three are negative.
  const std::array<Eigen::Vector3d, 4> g = {Eigen::Vector3d(-1, -1, -40), Eigen::Vector3d(1, 0, -30),
                                            Eigen::Vector3d(0, 1, -30), Eigen::Vector3d(0, 0, 100)};
  std::vector<double> dihedral;
  for (int k = 0; k < 4; ++k) {
    for (int l = k + 1; l < 4; ++l) {
      dihedral.push_back(180.0 - degrees(std::acos(g[k].normalized().dot(g[l].normalized()))));
    }
  }
  EXPECT_NEAR(r.min_dihedral_degrees, *std::min_element(dihedral.begin(), dihedral.end()), 1e-8);
  EXPECT_NEAR(r.max_dihedral_degrees, *std::max_element(dihedral.begin(), dihedral.end()), 1e-8);
  EXPECT_GT(r.max_dihedral_degrees, 170.0);
  EXPECT_EQ(r.obtuse_dihedrals, 3);  // at the three apex edges, opposite the base edges
  EXPECT_DOUBLE_EQ(r.obtuse_dihedral_fraction, 0.5);
  EXPECT_EQ(r.negative_cotangent_edges, 3);
  EXPECT_DOUBLE_EQ(r.negative_cotangent_fraction, 0.5);

  // The Laplace stage's operator (Gram-matrix gradients, another code path) agrees on the signs.
  const SparseMatrixD K = cotangent_stiffness(mesh.V, mesh.T);
  int positive = 0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) positive += K.coeff(i, j) > 0.0 ? 1 : 0;
  EXPECT_EQ(positive, 3);
}

/// The unit cube split into the 6 Kuhn tets (0, e_a, e_a + e_b, 1) that share the main diagonal, its points
/// mapped by x -> A x. Vertex id = x + 2 y + 4 z.
TetMesh4 kuhn_cube(const Eigen::Matrix3d& A, unsigned seed) {
  std::vector<Eigen::Vector3d> points;
  for (int id = 0; id < 8; ++id) points.push_back(A * Eigen::Vector3d(id & 1, (id >> 1) & 1, (id >> 2) & 1));
  std::vector<std::array<int, 4>> tets;
  std::array<int, 3> axis = {0, 1, 2};
  do {
    const int a = 1 << axis[0], b = 1 << axis[1];
    tets.push_back({0, a, a + b, 7});
  } while (std::next_permutation(axis.begin(), axis.end()));
  return embedded_mesh(points, tets, seed);
}

TEST(QualityKuhnCube, RightAnglesAndZeroWeightsAreNotCounted) {
  // By hand, tet (0, e_x, e_x + e_y, 1): lambda = (1 - x, x - y, y - z, z), gradients (-e_x, e_x - e_y, e_y - e_z,
  // e_z). Opposite-gradient angles give dihedrals 45 (edges 01, 23), 60 (edge 03, the diagonal: 6 x 60 = 360)
  // and 90 (edges 02, 12, 13). Off-diagonals vol g_i.g_j: -1/6 on the three path edges (cube edges), 0 on the
  // face diagonals and the main diagonal. Assembled: 12 cube edges < 0, 6 face diagonals + 1 diagonal = 0.
  QualityOptions options;
  options.histogram_bins = 7;  // 25.7 degree bins keep 45, 60 and 90 off the bin boundaries
  const QualityResult r = measure_quality(kuhn_cube(Eigen::Matrix3d::Identity(), 17), options);
  EXPECT_EQ(r.tets, 6);
  EXPECT_EQ(r.degenerate_tets, 0);
  EXPECT_NEAR(r.min_dihedral_degrees, 45.0, 1e-9);
  EXPECT_NEAR(r.max_dihedral_degrees, 90.0, 1e-9);
  EXPECT_EQ(r.obtuse_dihedrals, 0);
  EXPECT_EQ(r.edges, 19);
  EXPECT_EQ(r.negative_cotangent_edges, 0);
  EXPECT_NEAR(r.min_volume_ratio, 1.0, 1e-12);
  EXPECT_EQ(r.dihedral_histogram, (std::vector<std::int64_t>{0, 12, 6, 18, 0, 0, 0}));
}

TEST(QualityKuhnCube, ShearedCubeHasThreeNegativeWeightsOfNineteen) {
  // Shear x += z. Gradients map by A^-T, so with X = A^-T e_x = (1, 0, -1), Y = e_y, Z = e_z the dot products
  // are X.X = 2, X.Z = -1, Y.Y = Z.Z = 1, others 0. Per tet (a, b, c) the six products follow from
  // g = (-a, a - b, b - c, c); assembled over the six tets, 6 * K_ij is
  //   -5 (0,1)  -2 (0,2)  -1 (0,3)  -3 (0,4)  +2 (0,5)  -1 (0,6)  +2 (0,7)   0 (1,3)  -2 (1,5)  -1 (1,7)
  //   -3 (2,3)  -2 (2,6)  +2 (2,7)  -3 (3,7)  -3 (4,5)   0 (4,6)  -1 (4,7)  -2 (5,7)  -5 (6,7)
  // (vertex 0 row: -8 off the diagonal, +8 = sum of |g_0|^2 on it). Each tet has one positive product between
  // the gradients opposite an edge (6 obtuse dihedrals of 36: 135, 120, 125.26 degrees), the largest 135
  // (cos 1/sqrt 2); the smallest dihedral is acos(3 / sqrt 10) = 18.43 (products -3 with norms^2 2 and 5).
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  A(0, 2) = 1.0;
  const QualityResult r = measure_quality(kuhn_cube(A, 19));
  EXPECT_EQ(r.edges, 19);
  EXPECT_EQ(r.negative_cotangent_edges, 3);
  EXPECT_DOUBLE_EQ(r.negative_cotangent_fraction, 3.0 / 19.0);
  EXPECT_EQ(r.obtuse_dihedrals, 6);
  EXPECT_DOUBLE_EQ(r.obtuse_dihedral_fraction, 6.0 / 36.0);
  EXPECT_NEAR(r.max_dihedral_degrees, 135.0, 1e-9);
  EXPECT_NEAR(r.min_dihedral_degrees, degrees(std::acos(3.0 / std::sqrt(10.0))), 1e-9);
  EXPECT_EQ(histogram_total(r), 36);
}

TEST(QualityDegenerate, FlatTetIsCountedAndLeftOutWithoutNaN) {
  // A regular tet plus a flat square (four coplanar points): the flat one has no hull to measure.
  const TetMesh4 mesh =
      embedded_mesh({{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}, {3, 0, 0}, {4, 0, 0}, {3, 1, 0}, {4, 1, 0}},
                    {{0, 1, 2, 3}, {4, 5, 6, 7}}, 23);
  const QualityResult r = measure_quality(mesh);
  EXPECT_EQ(r.tets, 2);
  EXPECT_EQ(r.degenerate_tets, 1);
  const double expected = degrees(std::acos(1.0 / 3.0));
  EXPECT_NEAR(r.min_dihedral_degrees, expected, 1e-9);
  EXPECT_NEAR(r.max_dihedral_degrees, expected, 1e-9);
  EXPECT_EQ(r.edges, 6);  // the flat tet's edges are not part of the operator
  EXPECT_EQ(r.negative_cotangent_fraction, 0.0);
  EXPECT_EQ(r.obtuse_dihedral_fraction, 0.0);
  EXPECT_LE(r.min_volume_ratio, 1e-12);
  EXPECT_TRUE(std::isfinite(r.min_volume_ratio));
  EXPECT_EQ(histogram_total(r), 6);

  // Only the flat tet: nothing to measure, and still no NaN.
  const TetMesh4 flat = embedded_mesh({{3, 0, 0}, {4, 0, 0}, {3, 1, 0}, {4, 1, 0}}, {{0, 1, 2, 3}}, 29);
  const QualityResult f = measure_quality(flat);
  EXPECT_EQ(f.degenerate_tets, 1);
  EXPECT_EQ(f.edges, 0);
  for (double x : {f.min_dihedral_degrees, f.max_dihedral_degrees, f.obtuse_dihedral_fraction,
                   f.negative_cotangent_fraction, f.min_volume_ratio}) {
    EXPECT_TRUE(std::isfinite(x));
  }
  EXPECT_EQ(histogram_total(f), 0);
}

// The histogram against dihedral angles computed here from face normals in 3D, over 2000 random tets and bin counts
// whose edges lie from far apart (7) to closer together than the bin table's cells near 0 and 180 degrees (1000):
// every dihedral binned where its angle falls. Angles within 1e-7 degrees of a bin edge are not drawn.
TEST(QualityRandomTets, HistogramBinsEveryDihedralWhereItsAngleFalls) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> coordinate(-1.0, 1.0);
  std::vector<Eigen::Vector3d> points;
  std::vector<std::array<int, 4>> tets;
  std::vector<double> angles;  // six a tet
  while (tets.size() < 2000) {
    std::array<Eigen::Vector3d, 4> p;
    for (auto& q : p) q = Eigen::Vector3d(coordinate(rng), coordinate(rng), coordinate(rng));
    if (std::abs((p[1] - p[0]).dot((p[2] - p[0]).cross(p[3] - p[0]))) < 1e-3) continue;
    std::vector<double> six;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        // The dihedral at edge ab, between the faces through ab and each of the other two vertices.
        int c = 0;
        while (c == a || c == b) ++c;
        int d = 0;
        while (d == a || d == b || d == c) ++d;
        const Eigen::Vector3d e = (p[b] - p[a]).normalized();
        Eigen::Vector3d u = p[c] - p[a], v = p[d] - p[a];
        u -= u.dot(e) * e;
        v -= v.dot(e) * e;
        six.push_back(degrees(std::acos(std::clamp(u.normalized().dot(v.normalized()), -1.0, 1.0))));
      }
    bool near_edge = false;
    for (const int bins : {7, 18, 1000})
      for (const double angle : six) {
        const double x = angle * bins / 180.0;
        near_edge = near_edge || std::abs(x - std::round(x)) * 180.0 / bins < 1e-7;
      }
    if (near_edge) continue;
    const int base = int(points.size());
    for (const auto& q : p) points.push_back(q);
    tets.push_back({base, base + 1, base + 2, base + 3});
    angles.insert(angles.end(), six.begin(), six.end());
  }
  const TetMesh4 mesh = embedded_mesh(points, tets, 5);
  for (const int bins : {7, 18, 1000}) {
    QualityOptions options;
    options.histogram_bins = bins;
    const QualityResult r = measure_quality(mesh, options);
    std::vector<std::int64_t> expected(std::size_t(bins), 0);
    for (const double angle : angles) ++expected[std::size_t(std::min(bins - 1, int(angle * bins / 180.0)))];
    EXPECT_EQ(r.dihedral_histogram, expected) << bins << " bins";
  }
}

TEST(QualityInput, RejectsBadIndicesAndOptions) {
  TetMesh4 mesh = embedded_mesh({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{0, 1, 2, 3}}, 31);
  QualityOptions no_bins;
  no_bins.histogram_bins = 0;
  EXPECT_THROW(measure_quality(mesh, no_bins), InvalidInput);
  mesh.T(0, 2) = 4;
  EXPECT_THROW(measure_quality(mesh), InvalidInput);
}

// An extracted morph mesh (sphere to torus), as in tests/mesh/extract_test.cpp: tens of thousands of tets,
// several chunks, and the slivers iso-surfacing makes.
TetMesh4 extracted_mesh() {
  using Sdf = std::function<double(const Eigen::Vector3d&)>;
  const Sdf a = [](const Eigen::Vector3d& p) { return p.norm() - 0.8; };
  const Sdf b = [](const Eigen::Vector3d& p) {
    return Eigen::Vector2d(p.head<2>().norm() - 0.55, p.z()).norm() - 0.22;
  };
  MorphField field;
  field.voxel_size = 0.1;
  const int n = 23;
  field.dims = Eigen::Vector3i(n, n, n);
  field.origin = Eigen::Vector3d::Constant(-1.1);
  field.dA.resize(std::size_t(n) * n * n);
  field.dB.resize(field.dA.size());
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        field.dA[std::size_t(field.index(i, j, k))] = float(a(field.point(i, j, k)));
        field.dB[std::size_t(field.index(i, j, k))] = float(b(field.point(i, j, k)));
      }
  ExtractOptions options;
  options.time_steps = 6;
  return extract_hypersurface(field, options).mesh;
}

/// What measure() returns when TBB may use at most `threads` threads.
template <class Measure>
QualityResult with_threads(int threads, const Measure& measure) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
  return measure();
}

TEST(QualityExtracted, SameResultForOneAndTwoThreadsAndAgreesWithLaplaceOperator) {
  const TetMesh4 mesh = extracted_mesh();
  ASSERT_GT(mesh.tet_count(), 3 * 8192);  // several tet chunks
  const QualityResult one = with_threads(1, [&] { return measure_quality(mesh); });
  const QualityResult two = with_threads(2, [&] { return measure_quality(mesh); });
  EXPECT_EQ(one.degenerate_tets, two.degenerate_tets);
  EXPECT_EQ(one.min_dihedral_degrees, two.min_dihedral_degrees);
  EXPECT_EQ(one.max_dihedral_degrees, two.max_dihedral_degrees);
  EXPECT_EQ(one.obtuse_dihedrals, two.obtuse_dihedrals);
  EXPECT_EQ(one.edges, two.edges);
  EXPECT_EQ(one.negative_cotangent_edges, two.negative_cotangent_edges);
  EXPECT_EQ(one.min_volume_ratio, two.min_volume_ratio);
  EXPECT_EQ(one.dihedral_histogram, two.dihedral_histogram);
  EXPECT_EQ(histogram_total(one), 6 * (one.tets - one.degenerate_tets));
  EXPECT_GT(one.obtuse_dihedrals, 0);  // marching pentatopes is not acute

  // Reference from the Laplace stage's assembled operator and its barycentric gradients (acos, Gram inverse).
  Eigen::MatrixXd G;
  Eigen::VectorXd vol;
  barycentric_gradients(mesh.V, mesh.T, G, vol);
  const std::int64_t laplace_degenerate = (vol.array() <= 0.0).count();
  ASSERT_EQ(one.degenerate_tets, laplace_degenerate) << "the two degeneracy criteria differ on this mesh";
  double min_dihedral = 180.0, max_dihedral = 0.0;
  std::int64_t obtuse = 0;
  for (Eigen::Index t = 0; t < mesh.tet_count(); ++t) {
    if (!(vol(t) > 0.0)) continue;
    for (int k = 0; k < 4; ++k)
      for (int l = k + 1; l < 4; ++l) {
        const Eigen::Vector4d gk = G.row(4 * t + k).normalized(), gl = G.row(4 * t + l).normalized();
        const double dihedral = 180.0 - degrees(std::acos(std::clamp(gk.dot(gl), -1.0, 1.0)));
        min_dihedral = std::min(min_dihedral, dihedral);
        max_dihedral = std::max(max_dihedral, dihedral);
        obtuse += dihedral > 90.0 + 1e-6 ? 1 : 0;
      }
  }
  EXPECT_NEAR(one.min_dihedral_degrees, min_dihedral, 1e-5);
  EXPECT_NEAR(one.max_dihedral_degrees, max_dihedral, 1e-5);
  EXPECT_NEAR(double(one.obtuse_dihedrals), double(obtuse), 0.0005 * double(obtuse) + 2);

  const SparseMatrixD K = cotangent_stiffness(mesh.V, mesh.T);
  std::int64_t edges = 0, positive = 0;
  double abs_sum = 0.0;
  for (int c = 0; c < K.outerSize(); ++c)
    for (SparseMatrixD::InnerIterator it(K, c); it; ++it)
      if (it.row() < it.col()) {
        ++edges;
        abs_sum += std::abs(it.value());
      }
  for (int c = 0; c < K.outerSize(); ++c)
    for (SparseMatrixD::InnerIterator it(K, c); it; ++it)
      if (it.row() < it.col()) positive += it.value() > 1e-14 * abs_sum / double(edges) ? 1 : 0;
  EXPECT_EQ(one.edges, edges);
  EXPECT_NEAR(double(one.negative_cotangent_edges), double(positive), 0.0005 * double(positive) + 2);
  EXPECT_GT(one.negative_cotangent_edges, 0);
}

// The pipeline's quality stage reads the Laplace stage's local stiffness instead of measuring the geometry again:
// the same counts on an extracted morph (its slivers included), whatever the thread count.
TEST(QualityExtracted, FromStiffnessAgreesWithMeasureQuality) {
  const TetMesh4 mesh = extracted_mesh();
  const QualityResult reference = measure_quality(mesh);
  auto from_stiffness = [&] {
    QualityResult quality;
    dirichlet_system(mesh, nullptr, &quality);
    return quality;
  };
  const QualityResult one = with_threads(1, from_stiffness);
  const QualityResult two = with_threads(2, from_stiffness);
  EXPECT_EQ(one.dihedral_histogram, two.dihedral_histogram);
  EXPECT_EQ(one.negative_cotangent_edges, two.negative_cotangent_edges);
  EXPECT_EQ(one.min_dihedral_degrees, two.min_dihedral_degrees);
  EXPECT_EQ(one.tets, reference.tets);
  EXPECT_EQ(one.degenerate_tets, reference.degenerate_tets);
  EXPECT_EQ(one.edges, reference.edges);
  EXPECT_EQ(one.negative_cotangent_edges, reference.negative_cotangent_edges);
  EXPECT_EQ(one.obtuse_dihedrals, reference.obtuse_dihedrals);
  EXPECT_EQ(one.dihedral_histogram, reference.dihedral_histogram);
  EXPECT_NEAR(one.min_dihedral_degrees, reference.min_dihedral_degrees, 1e-9);
  EXPECT_NEAR(one.max_dihedral_degrees, reference.max_dihedral_degrees, 1e-9);
  EXPECT_NEAR(one.min_volume_ratio, reference.min_volume_ratio, 1e-12);
  EXPECT_GT(one.negative_cotangent_edges, 0);
  EXPECT_GT(one.dihedral_histogram[std::size_t(one.dihedral_histogram.size() / 2)], 0);  // right angles, 90 degrees

  PackedStiffness short_stiffness(mesh.tet_count() - 1, 6);
  EXPECT_THROW(quality_from_stiffness(mesh, short_stiffness, Eigen::VectorXd::Ones(mesh.tet_count())), InvalidInput);
}

// The two parts the Laplace stage runs around its assembly: the first leaves the edge figures to the second, which
// reads rows only when each vertex has a row entry, and both reject arrays of the wrong size.
TEST(QualityExtracted, AngleAndEdgePartsCheckTheirInputs) {
  const TetMesh4 mesh = extracted_mesh();
  const PackedStiffness stiffness = PackedStiffness::Zero(mesh.tet_count(), 6);
  const Eigen::VectorXd volume = Eigen::VectorXd::Zero(mesh.tet_count());  // every tet degenerate: nothing to sum
  std::vector<std::uint8_t> usable;
  QualityResult r = quality_angles_from_stiffness(mesh, stiffness, volume, usable);
  ASSERT_EQ(Eigen::Index(usable.size()), mesh.tet_count());
  EXPECT_EQ(std::count(usable.begin(), usable.end(), 1), 0);
  EXPECT_EQ(r.degenerate_tets, mesh.tet_count());
  EXPECT_EQ(r.edges, 0);
  add_edge_figures(r, mesh, stiffness, usable, nullptr);
  EXPECT_EQ(r.edges, 0);

  const std::vector<std::uint8_t> short_usable(usable.size() - 1, 1);
  EXPECT_THROW(add_edge_figures(r, mesh, stiffness, short_usable, nullptr), InvalidInput);
  const std::vector<int> short_rows(std::size_t(mesh.vertex_count() - 1), -1);
  const AssembledRows rows{&short_rows, nullptr, nullptr, nullptr};
  EXPECT_THROW(add_edge_figures(r, mesh, stiffness, usable, nullptr, &rows), InvalidInput);
  EXPECT_THROW(quality_angles_from_stiffness(mesh, stiffness, Eigen::VectorXd::Zero(3), usable), InvalidInput);
}

// The packed stiffness's unpacked forms, which the assembly and the quality stage read, agree bit for bit: a row
// alone, an entry alone and the whole matrix (rows summing to zero up to rounding), on values of mixed sign and size.
TEST(PackedStiffness, RowAndEntryAreBitwiseTheUnpackedMatrix) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> value(-3.0, 3.0);
  for (int trial = 0; trial < 200; ++trial) {
    double packed[6];
    for (double& p : packed) p = value(rng) * std::pow(10.0, int(rng() % 7) - 3);
    double K[4][4];
    unpack_stiffness(packed, K);
    for (int i = 0; i < 4; ++i) {
      double row[4];
      stiffness_row(packed, i, row);
      double sum = 0.0, scale = 0.0;
      for (int j = 0; j < 4; ++j) {
        EXPECT_EQ(row[j], K[i][j]) << "row " << i << " column " << j;
        EXPECT_EQ(K[i][j], K[j][i]);
        if (j != i) {
          EXPECT_EQ(stiffness_entry(packed, i, j), K[i][j]);
        }
        sum += K[i][j];
        scale += std::abs(K[i][j]);
      }
      EXPECT_LE(std::abs(sum), 1e-14 * scale);
    }
  }
}

}  // namespace
}  // namespace morphmap
