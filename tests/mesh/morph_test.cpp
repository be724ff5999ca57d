// The distance-field morph's lattice values (mesh/morph.h): analytic shapes sampled exactly everywhere, meshes of the
// right sign everywhere and, where the morph can change sign, exact beyond the band and inside it (close inside it
// with OpenVDB's distances).
#include "mesh/morph.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <utility>

#include "mesh/errors.h"
#include "mesh/shapes.h"
#include "mesh/transfer.h"

namespace morphmap {
namespace {

Surface shape(const std::string& spec, const std::optional<Eigen::AlignedBox3d>& fit = std::nullopt) {
  return make_shape(parse_shape_spec(spec), fit);
}

// "exact" distances: the true distance within the band; beyond it the band's width, or the true distance where the
// morph can change sign (fill_exact_distances).
bool exact_or_clamped(float value, double truth, double band) {
  const double v = std::abs(double(value));
  if (truth < band * (1.0 - 1e-6)) return std::abs(v - truth) < 1e-5;
  return std::abs(v - band) < 1e-5 || std::abs(v - truth) < 1e-5;
}

class DistanceMorphBoth : public ::testing::TestWithParam<std::string> {};

TEST_P(DistanceMorphBoth, AnalyticShapesAreSampledExactlyAndMeshesExactlyBeyondTheBand) {
  const Surface A = shape("sphere:size=0.6,center=0/0/0");
  Surface B = shape("torus:size=1,center=0.1/0/0");
  const auto torus = B.signed_distance;
  ASSERT_TRUE(A.signed_distance && torus);
  B.signed_distance = nullptr;  // B as a plain mesh: voxelised and queried
  MorphOptions options;
  options.voxels = 24;
  options.distances = GetParam();
  const bool exact_band = options.distances == "exact";
  const MorphResult morph = build_morph(A, B, options);
  EXPECT_EQ(morph.band_queries > 0, exact_band);
  const MorphField& f = morph.field;
  EXPECT_GT(morph.exact_queries, 0);
  // Tessellation error of the torus mesh (vertices on the surface, faces inside): well below a voxel.
  const double sagitta = 0.05 * f.voxel_size;
  const SurfaceLocator mesh_b(B);
  int crossing_points = 0, beyond = 0;
  for (int k = 0; k < f.dims.z(); ++k)
    for (int j = 0; j < f.dims.y(); ++j)
      for (int i = 0; i < f.dims.x(); ++i) {
        const Eigen::Vector3d x = f.point(i, j, k);
        const std::size_t q = std::size_t(f.index(i, j, k));
        EXPECT_NEAR(f.dA[q], A.signed_distance(x), 1e-6) << x.transpose();
        const double exact = torus(x);
        if (std::abs(exact) > sagitta) {
          EXPECT_EQ(f.dB[q] < 0.0f, exact < 0.0) << x.transpose();
        }
        // Where the morph can change sign (dA and dB of opposite signs), dB is the mesh's own distance: exact beyond
        // the band; inside it exact too, or with OpenVDB's within a fifth of a voxel (measured: 14% at most).
        const double truth = mesh_b.closest(x).distance;
        if ((f.dA[q] < 0.0f) != (f.dB[q] < 0.0f)) {
          ++crossing_points;
          const bool beyond_band = truth > (options.band_voxels() + 0.5) * f.voxel_size;
          EXPECT_NEAR(std::abs(f.dB[q]), truth, beyond_band || exact_band ? 1e-5 : 0.2 * f.voxel_size) << x.transpose();
          beyond += beyond_band ? 1 : 0;
        } else if (exact_band) {
          EXPECT_TRUE(exact_or_clamped(f.dB[q], truth, options.band_voxels() * f.voxel_size)) << x.transpose();
        }
      }
  EXPECT_GT(crossing_points, 100);
  EXPECT_GT(beyond, 10);
}

INSTANTIATE_TEST_SUITE_P(Distances, DistanceMorphBoth, ::testing::Values("exact", "openvdb"));

// Large triangles (a cube of 12, each side 10 voxels): the band found from samples of each triangle, not only its
// corners, holds every lattice point within the band of a face, and the signs follow the solid.
TEST(DistanceMorph, ExactBandReachesAcrossLargeTrianglesAndSignsFollowTheSolid) {
  Surface cube;
  cube.V.resize(8, 3);
  for (int c = 0; c < 8; ++c) cube.V.row(c) << (c & 1), ((c >> 1) & 1), ((c >> 2) & 1);
  cube.F.resize(12, 3);
  cube.F << 0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4, 2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5;
  Surface tilted = cube;  // turned about two axes, so that no face lies along the lattice
  const Eigen::Matrix3d turn =
      (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  tilted.V = (cube.V.rowwise() - Eigen::RowVector3d::Constant(0.5)) * turn.transpose();
  const Surface sphere = shape("sphere:size=0.4,center=0/0/0");
  MorphOptions options;
  options.voxels = 14;
  const MorphResult morph = build_morph(sphere, tilted, options);
  const MorphField& f = morph.field;
  const SurfaceLocator locator(tilted);
  const double band = options.band_voxels() * f.voxel_size;
  int within = 0;
  for (int k = 0; k < f.dims.z(); ++k)
    for (int j = 0; j < f.dims.y(); ++j)
      for (int i = 0; i < f.dims.x(); ++i) {
        const Eigen::Vector3d x = f.point(i, j, k);
        const float value = f.dB[std::size_t(f.index(i, j, k))];
        const double truth = locator.closest(x).distance;
        const Eigen::Vector3d local = turn.transpose() * x;  // in the cube's own frame, centred
        const bool inside = local.cwiseAbs().maxCoeff() < 0.5;
        if (truth > 1e-6) {
          EXPECT_EQ(value < 0.0f, inside) << x.transpose();
        }
        EXPECT_TRUE(exact_or_clamped(value, truth, band)) << x.transpose();
        within += truth < band;
      }
  EXPECT_GT(within, 1000);
}

// A sphere and a torus as plain meshes (no analytic distance): voxelised or queried.
std::pair<Surface, Surface> mesh_pair(int res) {
  const std::string at = ",res=" + std::to_string(res);
  std::pair<Surface, Surface> pair{shape("sphere:size=0.6,center=0/0/0" + at),
                                   shape("torus:size=1,center=0.1/0/0" + at)};
  pair.first.signed_distance = nullptr;
  pair.second.signed_distance = nullptr;
  return pair;
}

// The band's cells are marked in order and its points found plane by plane: the same values on one thread as on two.
TEST(DistanceMorph, ExactDistancesDoNotDependOnTheThreadCount) {
  const auto [A, B] = mesh_pair(24);
  MorphOptions options;
  options.voxels = 20;
  MorphResult one, two;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    one = build_morph(A, B, options);
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    two = build_morph(A, B, options);
  }
  EXPECT_GT(one.band_queries, 0);
  EXPECT_EQ(one.band_queries, two.band_queries);
  EXPECT_EQ(one.field.dA, two.field.dA);
  EXPECT_EQ(one.field.dB, two.field.dB);
}

// With exact distances the band's width changes no value the extraction reads: at every corner of a cube where the
// morph can change sign the value is exact whatever the width (thin parts moved after the band was filled included).
TEST(DistanceMorph, ExactValuesAtCrossingsDoNotDependOnTheBandWidth) {
  const Surface A = shape("sphere:size=0.6,center=0/0/0");
  Surface B = shape("torus:size=1,r_ratio=0.06,center=0.1/0/0");  // a tube a fifth of a voxel across
  B.signed_distance = nullptr;
  MorphOptions options;
  options.voxels = 16;
  options.band = 1.75;  // just over sqrt(3): the least the thin-feature pass allows
  const MorphResult narrow = build_morph(A, B, options);
  options.band = 4.0;
  const MorphResult wide = build_morph(A, B, options);
  EXPECT_GT(narrow.thin_b.moved_inside + narrow.thin_b.sign_flips, 0);  // the thin tube is put back on the lattice
  const MorphField &f = narrow.field, &g = wide.field;
  ASSERT_EQ(f.dims, g.dims);
  for (std::size_t q = 0; q < f.dB.size(); ++q) ASSERT_EQ(f.dB[q] < 0.0f, g.dB[q] < 0.0f) << q;
  int corners = 0;
  for (int k = 0; k + 1 < f.dims.z(); ++k)
    for (int j = 0; j + 1 < f.dims.y(); ++j)
      for (int i = 0; i + 1 < f.dims.x(); ++i) {
        bool in = false, out = false;
        for (int c = 0; c < 8; ++c) {
          const std::size_t q = std::size_t(f.index(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)));
          for (const float v : {f.dA[q], f.dB[q]}) (v < 0.0f ? in : out) = true;
        }
        if (!(in && out)) continue;
        for (int c = 0; c < 8; ++c) {
          const std::size_t q = std::size_t(f.index(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)));
          EXPECT_EQ(f.dB[q], g.dB[q]) << i << ' ' << j << ' ' << k;
          ++corners;
        }
      }
  EXPECT_GT(corners, 1000);
}

TEST(DistanceMorph, UnknownDistancesAreRejected) {
  MorphOptions options;
  options.distances = "fast";
  EXPECT_THROW(build_morph(shape("sphere"), shape("torus"), options), InvalidInput);
}

TEST(DistanceMorph, MeshValuesDoNotDependOnTheUnitsOrWhereTheShapeSits) {
  // The same two meshes in units a million times smaller (OpenVDB refused a voxel under 1.4e-5: "Non-zero scale values
  // required") and moved to x = 1e5 (where a float's step is 0.008, half a voxel of these shapes at 16 voxels): the
  // lattice values are the unit ones, scaled, to a small fraction of a voxel.
  const auto [A, B] = mesh_pair(32);
  MorphOptions options;
  options.voxels = 16;
  const MorphField unit = build_morph(A, B, options).field;
  for (const auto& [scale, shift] : {std::pair{1e-6, 0.0}, std::pair{1.0, 1e5}}) {
    SCOPED_TRACE(scale);
    Surface a = A, b = B;
    for (Surface* s : {&a, &b}) {
      s->V *= scale;
      s->V.col(0).array() += shift;
    }
    const MorphField moved = build_morph(a, b, options).field;
    ASSERT_EQ(moved.dims, unit.dims);
    EXPECT_NEAR(moved.voxel_size, scale * unit.voxel_size, 1e-9 * scale);
    double worst = 0.0;
    for (std::size_t q = 0; q < unit.dA.size(); ++q) {
      worst = std::max(worst, std::abs(moved.dA[q] / scale - unit.dA[q]));
      worst = std::max(worst, std::abs(moved.dB[q] / scale - unit.dB[q]));
    }
    EXPECT_LT(worst, 1e-3 * unit.voxel_size);
  }
}

TEST(DistanceMorph, TwoAnalyticShapesNeedNoQueries) {
  const Surface A = shape("sphere:size=0.5,center=0/0/0");
  const Surface B = shape("two-spheres:size=1,center=0/0/0");
  MorphOptions options;
  options.voxels = 16;
  const MorphResult morph = build_morph(A, B, options);
  EXPECT_EQ(morph.exact_queries, 0);
  const MorphField& f = morph.field;
  for (int k = 0; k < f.dims.z(); k += 3)
    for (int j = 0; j < f.dims.y(); j += 3)
      for (int i = 0; i < f.dims.x(); i += 3) {
        const Eigen::Vector3d x = f.point(i, j, k);
        EXPECT_NEAR(f.dB[std::size_t(f.index(i, j, k))], B.signed_distance(x), 1e-6);
      }
  // The union's distance: inside either sphere negative, zero on both surfaces.
  EXPECT_LT(B.signed_distance(Eigen::Vector3d(B.V.col(0).minCoeff() + 0.1, 0, 0)), 0.0);
  EXPECT_NEAR(B.signed_distance(B.V.row(0).transpose()), 0.0, 1e-12);
  EXPECT_NEAR(B.signed_distance(B.V.row(B.V.rows() - 1).transpose()), 0.0, 1e-12);
}

}  // namespace
}  // namespace morphmap
