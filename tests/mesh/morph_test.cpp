// The distance-field morph's lattice values (mesh/morph.h): analytic shapes sampled exactly everywhere, meshes of the
// right sign everywhere and, where the morph can change sign, exact beyond OpenVDB's band and close inside it.
#include "mesh/morph.h"

#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <utility>

#include "mesh/shapes.h"
#include "mesh/transfer.h"

namespace morphmap {
namespace {

Surface shape(const std::string& spec, const std::optional<Eigen::AlignedBox3d>& fit = std::nullopt) {
  return make_shape(parse_shape_spec(spec), fit);
}

TEST(DistanceMorph, AnalyticShapesAreSampledExactlyAndMeshesExactlyBeyondTheBand) {
  const Surface A = shape("sphere:size=0.6,center=0/0/0");
  Surface B = shape("torus:size=1,center=0.1/0/0");
  const auto torus = B.signed_distance;
  ASSERT_TRUE(A.signed_distance && torus);
  B.signed_distance = nullptr;  // B as a plain mesh: voxelised and queried
  MorphOptions options;
  options.voxels = 24;
  const MorphResult morph = build_morph(A, B, options);
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
        // OpenVDB's band, within a fifth of a voxel inside it (measured: 14% at most).
        if ((f.dA[q] < 0.0f) != (f.dB[q] < 0.0f)) {
          ++crossing_points;
          const double truth = mesh_b.closest(x).distance;
          const bool beyond_band = truth > (options.band + 0.5) * f.voxel_size;
          EXPECT_NEAR(std::abs(f.dB[q]), truth, beyond_band ? 1e-5 : 0.2 * f.voxel_size) << x.transpose();
          beyond += beyond_band ? 1 : 0;
        }
      }
  EXPECT_GT(crossing_points, 100);
  EXPECT_GT(beyond, 10);
}

TEST(DistanceMorph, MeshValuesDoNotDependOnTheUnitsOrWhereTheShapeSits) {
  // The same two meshes in units a million times smaller (OpenVDB refused a voxel under 1.4e-5: "Non-zero scale values
  // required") and moved to x = 1e5 (where a float's step is 0.008, half a voxel of these shapes at 16 voxels): the
  // lattice values are the unit ones, scaled, to a small fraction of a voxel.
  Surface A = shape("sphere:size=0.6,center=0/0/0,res=32"), B = shape("torus:size=1,center=0.1/0/0,res=32");
  A.signed_distance = nullptr;
  B.signed_distance = nullptr;
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
