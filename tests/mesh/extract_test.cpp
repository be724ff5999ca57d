// Extraction of the 4D hypersurface from analytic distance fields (no OpenVDB involved).
#include "mesh/extract.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <array>
#include <functional>
#include <map>

#include "mesh/errors.h"
#include "mesh/morph.h"

namespace morphmap {
namespace {

using Sdf = std::function<double(const Eigen::Vector3d&)>;

MorphField analytic_field(const Sdf& a, const Sdf& b, double extent, double h) {
  return sample_morph(a, b, extent, int(std::ceil(2.0 * extent / h)) + 1);
}

Sdf sphere(double r, Eigen::Vector3d c = Eigen::Vector3d::Zero()) {
  return [=](const Eigen::Vector3d& p) { return (p - c).norm() - r; };
}

Sdf torus(double R, double r) {
  return [=](const Eigen::Vector3d& p) { return Eigen::Vector2d(p.head<2>().norm() - R, p.z()).norm() - r; };
}

Sdf two_spheres(double r, double offset) {
  return [=](const Eigen::Vector3d& p) {
    return std::min(sphere(r, Eigen::Vector3d(offset, 0, 0))(p), sphere(r, Eigen::Vector3d(-offset, 0, 0))(p));
  };
}

// Counts how many tets use each triangle (sorted vertex triple).
std::map<std::array<int, 3>, int> face_use(const TetMesh4& mesh) {
  std::map<std::array<int, 3>, int> use;
  for (Eigen::Index t = 0; t < mesh.tet_count(); ++t)
    for (int skip = 0; skip < 4; ++skip) {
      std::array<int, 3> f;
      int n = 0;
      for (int q = 0; q < 4; ++q)
        if (q != skip) f[std::size_t(n++)] = mesh.T(t, q);
      std::sort(f.begin(), f.end());
      ++use[f];
    }
  return use;
}

struct ManifoldCase {
  const char* name;
  Sdf a, b;
  int time_steps;
};

class ExtractManifold : public ::testing::TestWithParam<int> {};

std::vector<ManifoldCase> manifold_cases() {
  return {{"concentric", sphere(0.5), sphere(0.8), 4},
          {"sphere_torus", sphere(0.8), torus(0.55, 0.22), 6},
          {"splitting", sphere(0.75), two_spheres(0.35, 0.45), 6},
          {"identity", sphere(0.6), sphere(0.6), 3}};
}

TEST_P(ExtractManifold, InteriorFacesSharedByTwoTetsBoundaryOnlyAtEnds) {
  const ManifoldCase c = manifold_cases()[std::size_t(GetParam())];
  const double h = 0.1;
  const MorphField field = analytic_field(c.a, c.b, 1.05, h);
  ExtractOptions options;
  options.time_steps = c.time_steps;
  options.record_source_cells = true;
  const ExtractResult result = extract_hypersurface(field, options);
  const TetMesh4& mesh = result.mesh;
  ASSERT_GT(mesh.tet_count(), 100) << c.name;
  EXPECT_EQ(mesh.source_cell.size(), std::size_t(mesh.tet_count()));

  std::int64_t boundary_a = 0, boundary_b = 0;
  for (const auto& [face, count] : face_use(mesh)) {
    ASSERT_LE(count, 2) << c.name << ": face shared by more than two tets";
    if (count == 1) {
      const VertexSide s = mesh.side[std::size_t(face[0])];
      ASSERT_NE(s, VertexSide::Interior) << c.name << ": boundary face away from t = 0 and t = 1";
      ASSERT_EQ(mesh.side[std::size_t(face[1])], s);
      ASSERT_EQ(mesh.side[std::size_t(face[2])], s);
      (s == VertexSide::A ? boundary_a : boundary_b) += 1;
    }
  }
  EXPECT_GT(boundary_a, 0);
  EXPECT_GT(boundary_b, 0);

  // The ends lie within one voxel of the analytic surfaces, at the right time.
  for (Eigen::Index v = 0; v < mesh.vertex_count(); ++v) {
    const Eigen::Vector3d p = mesh.V.row(v).head<3>().transpose();
    if (mesh.side[std::size_t(v)] == VertexSide::A) {
      EXPECT_NEAR(mesh.V(v, 3), 0.0, 1e-12);
      ASSERT_LT(std::abs(c.a(p)), h) << c.name;
    } else if (mesh.side[std::size_t(v)] == VertexSide::B) {
      EXPECT_NEAR(mesh.time_of(v), 1.0, 1e-12);
      ASSERT_LT(std::abs(c.b(p)), h) << c.name;
    }
  }
}

// The lattice's face neighbours are the stars' (face_neighbours), entry for entry: the facet rule of the Kuhn
// triangulation, the prism-internal faces and the ends of the morph (no tet across) all agree.
TEST_P(ExtractManifold, FaceNeighboursFromTheLatticeAreTheStars) {
  const ManifoldCase c = manifold_cases()[std::size_t(GetParam())];
  const MorphField field = analytic_field(c.a, c.b, 1.05, 0.1);
  ExtractOptions options;
  options.time_steps = c.time_steps;
  const ExtractResult plain = extract_hypersurface(field, options);
  EXPECT_FALSE(plain.faces.known());
  EXPECT_FALSE(lattice_face_neighbours(plain.faces, plain.mesh.T).known());
  options.face_neighbours = true;
  const ExtractResult result = extract_hypersurface(field, options);
  const TetMesh4& mesh = result.mesh;
  ASSERT_TRUE((plain.mesh.T.array() == mesh.T.array()).all()) << c.name << ": the mesh changed";
  const FaceNeighbours lattice = lattice_face_neighbours(result.faces, mesh.T);
  ASSERT_TRUE(lattice.known()) << c.name;
  const FaceNeighbours stars = face_neighbours(mesh.T, build_vertex_tets(mesh.T, mesh.vertex_count()));
  ASSERT_TRUE(stars.known());
  std::int64_t differ = 0, boundary = 0, shared = 0;
  for (std::size_t e = 0; e < std::size_t(mesh.tet_count()) * 4; ++e) {
    differ += lattice.across[e] != stars.across[e];
    (stars.across[e] == FaceNeighbours::kNoTet ? boundary : shared) += 1;
  }
  EXPECT_EQ(differ, 0) << c.name;
  EXPECT_GT(boundary, 0) << c.name;
  EXPECT_GT(shared, boundary) << c.name;
  // And the same on one thread.
  tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  const FaceNeighbours serial = lattice_face_neighbours(extract_hypersurface(field, options).faces, mesh.T);
  EXPECT_TRUE(std::equal(serial.across.get(), serial.across.get() + mesh.tet_count() * 4, lattice.across.get()));
  // Faces of another mesh are refused.
  EXPECT_THROW(lattice_face_neighbours(result.faces, plain.mesh.T.topRows(mesh.tet_count() - 1)), InvalidInput);
}

INSTANTIATE_TEST_SUITE_P(Cases, ExtractManifold, ::testing::Range(0, 4));

TEST(Extract, OrientationPointsTowardIncreasingField) {
  // Concentric spheres: outward is radial, so the spatial part of cross4 must point away from the centre.
  const MorphField field = analytic_field(sphere(0.5), sphere(0.8), 1.0, 0.1);
  ExtractOptions options;
  options.time_steps = 4;
  const TetMesh4 mesh = extract_hypersurface(field, options).mesh;
  std::int64_t outward = 0, inward = 0;
  for (Eigen::Index t = 0; t < mesh.tet_count(); ++t) {
    const Eigen::Vector4d v0 = mesh.V.row(mesh.T(t, 0)).transpose();
    const Eigen::Vector4d n =
        cross4(mesh.V.row(mesh.T(t, 1)).transpose() - v0, mesh.V.row(mesh.T(t, 2)).transpose() - v0,
               mesh.V.row(mesh.T(t, 3)).transpose() - v0);
    const Eigen::Vector3d c =
        (mesh.V.row(mesh.T(t, 0)) + mesh.V.row(mesh.T(t, 1)) + mesh.V.row(mesh.T(t, 2)) + mesh.V.row(mesh.T(t, 3)))
            .head<3>()
            .transpose() /
        4.0;
    if (n.norm() < 1e-12) continue;
    (n.head<3>().dot(c) > 0.0 ? outward : inward) += 1;
  }
  EXPECT_EQ(inward, 0);
  EXPECT_GT(outward, 0);
}

TEST(Extract, IdenticalForOneAndTwoThreads) {
  const MorphField field = analytic_field(sphere(0.8), torus(0.55, 0.22), 1.05, 0.1);
  ExtractOptions options;
  options.time_steps = 5;
  options.record_source_cells = true;
  TetMesh4 one, two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = extract_hypersurface(field, options).mesh;
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = extract_hypersurface(field, options).mesh;
  }
  ASSERT_EQ(one.V.rows(), two.V.rows());
  ASSERT_EQ(one.T.rows(), two.T.rows());
  EXPECT_TRUE((one.V.array() == two.V.array()).all());
  EXPECT_TRUE((one.T.array() == two.T.array()).all());
  ASSERT_EQ(one.source_cell.size(), std::size_t(one.tet_count()));
  EXPECT_EQ(one.source_cell, two.source_cell);
}

TEST(Extract, SourceCellsOnlyWhenAsked) {
  const MorphField field = analytic_field(sphere(0.8), torus(0.55, 0.22), 1.05, 0.1);
  ExtractOptions options;
  options.time_steps = 5;
  const TetMesh4 plain = extract_hypersurface(field, options).mesh;
  options.record_source_cells = true;
  const TetMesh4 recorded = extract_hypersurface(field, options).mesh;
  EXPECT_TRUE(plain.source_cell.empty());
  ASSERT_EQ(recorded.source_cell.size(), std::size_t(recorded.tet_count()));
  // Recording changes nothing else.
  ASSERT_EQ(plain.T.rows(), recorded.T.rows());
  EXPECT_TRUE((plain.T.array() == recorded.T.array()).all());
  EXPECT_TRUE((plain.V.array() == recorded.V.array()).all());
  EXPECT_GE(*std::min_element(recorded.source_cell.begin(), recorded.source_cell.end()), 0);
}

TEST(Extract, NoCrossingThrows) {
  const MorphField field = analytic_field(sphere(5.0), sphere(5.0), 1.0, 0.25);  // everything inside
  EXPECT_THROW(extract_hypersurface(field, ExtractOptions{}), TopologyError);
}

TEST(Extract, ExplicitTimeScaleSetsTauRange) {
  const MorphField field = analytic_field(sphere(0.5), sphere(0.7), 1.0, 0.1);
  ExtractOptions options;
  options.time_steps = 3;
  options.time_scale = 2.5;
  const TetMesh4 mesh = extract_hypersurface(field, options).mesh;
  EXPECT_DOUBLE_EQ(mesh.time_scale, 2.5);
  EXPECT_NEAR(mesh.V.col(3).maxCoeff(), 2.5, 1e-12);
  EXPECT_NEAR(mesh.V.col(3).minCoeff(), 0.0, 1e-12);
}

}  // namespace
}  // namespace morphmap
