// Tests of the target boundary and time slices of the tet mesh (paper §9) on product meshes.
#include "mesh/slice.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>

#include "mesh/errors.h"
#include "tests/mesh/product_mesh.h"

namespace morphmap {
namespace {

using test_mesh::area_of;
using test_mesh::bad_edges;
using test_mesh::icosphere;
using test_mesh::octahedron;
using test_mesh::product_mesh;
using test_mesh::radius_at;
using test_mesh::volume_of;

// A face as a cyclic rotation starting at its smallest index: equal sets mean equal oriented faces.
std::array<int, 3> canonical(int a, int b, int c) {
  if (b < a && b < c) return {b, c, a};
  if (c < a && c < b) return {c, a, b};
  return {a, b, c};
}

std::set<std::array<int, 3>> faces_of(const Eigen::MatrixXi& F) {
  std::set<std::array<int, 3>> out;
  for (Eigen::Index f = 0; f < F.rows(); ++f) out.insert(canonical(F(f, 0), F(f, 1), F(f, 2)));
  return out;
}

// Slice faces renamed to surface vertex ids (every slice vertex must sit on a mesh vertex).
std::set<std::array<int, 3>> surface_faces_of(const SliceMesh& slice, Eigen::Index n) {
  std::set<std::array<int, 3>> out;
  for (Eigen::Index f = 0; f < slice.F.rows(); ++f) {
    int id[3];
    for (int k = 0; k < 3; ++k) {
      const int v = slice.F(f, k);
      EXPECT_EQ(slice.source_edge(v, 0), slice.source_edge(v, 1));
      id[k] = int(slice.source_edge(v, 0) % n);
    }
    out.insert(canonical(id[0], id[1], id[2]));
  }
  return out;
}

TEST(SliceTest, TargetAndSourceBoundariesAreTheEndSurfaces) {
  const test_mesh::TriSurface sphere = icosphere(1);
  const Eigen::Index n = sphere.V.rows();
  const TetMesh4 mesh = product_mesh(sphere, 3, 1.0, 1.0, 1.5);
  const Eigen::MatrixXd labels = 2.0 * mesh.V.leftCols(3);
  for (const bool target : {true, false}) {
    const SliceMesh b = target ? target_boundary(mesh, labels) : source_boundary(mesh, labels);
    const double r = target ? 1.5 : 1.0;
    ASSERT_EQ(b.F.rows(), sphere.F.rows());
    ASSERT_EQ(b.V.rows(), n);
    ASSERT_EQ(b.source_tet.size(), std::size_t(b.F.rows()));
    EXPECT_EQ(b.t, target ? 1.0 : 0.0);
    for (Eigen::Index v = 0; v < n; ++v) {
      const int m = b.source_edge(v, 0);
      EXPECT_EQ(m, b.source_edge(v, 1));
      EXPECT_EQ(mesh.side[std::size_t(m)], target ? VertexSide::B : VertexSide::A);
      if (v > 0) {
        EXPECT_LT(b.source_edge(v - 1, 0), m);  // compact numbering is ascending
      }
      EXPECT_LE((b.V.row(v) - r * sphere.V.row(m % n)).cwiseAbs().maxCoeff(), 1e-12);
      EXPECT_LE((b.labels.row(v) - 2.0 * b.V.row(v)).cwiseAbs().maxCoeff(), 1e-12);
      EXPECT_EQ(b.edge_weight(v), 0.0);
    }
    for (Eigen::Index f = 0; f < b.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) {
        const int tet = b.source_tet[std::size_t(f)];
        const int m = b.source_edge(b.F(f, k), 0);
        EXPECT_TRUE((mesh.T.row(tet).array() == m).any());
      }
    EXPECT_EQ(surface_faces_of(b, n), faces_of(sphere.F));  // same faces, same (outward) orientation
    EXPECT_EQ(bad_edges(b.F), 0);
    EXPECT_GT(volume_of(b.V, b.F), 0.0);
  }
}

TEST(SliceTest, InteriorSliceIsTheScaledSurface) {
  const test_mesh::TriSurface sphere = icosphere(1);
  const double r0 = 1.0, r1 = 1.5, t = 0.37;
  const TetMesh4 mesh = product_mesh(sphere, 4, 2.0, r0, r1);
  const Eigen::MatrixXd labels = mesh.V.leftCols(3);
  const SliceMesh slice = slice_at(mesh, labels, t);
  const double r = radius_at(t, r0, r1);
  EXPECT_EQ(slice.t, t);
  ASSERT_GT(slice.F.rows(), 0);
  EXPECT_EQ(bad_edges(slice.F), 0);
  // Prism cuts add vertices on the surface's edges only, so the shape is exactly the scaled surface.
  EXPECT_NEAR(volume_of(slice.V, slice.F), r * r * r * volume_of(sphere.V, sphere.F), 1e-12);
  EXPECT_NEAR(area_of(slice.V, slice.F), r * r * area_of(sphere.V, sphere.F), 1e-12);
  // Labels are interpolated with the same weights as positions.
  EXPECT_LE((slice.labels - slice.V).cwiseAbs().maxCoeff(), 1e-12);
  // Every surface vertex appears once, on its vertical edge.
  std::int64_t vertical = 0;
  for (Eigen::Index v = 0; v < slice.V.rows(); ++v) {
    const int a = slice.source_edge(v, 0), b = slice.source_edge(v, 1);
    ASSERT_LT(a, b);
    const double w = slice.edge_weight(v);
    EXPECT_GT(w, 0.0);
    EXPECT_LT(w, 1.0);
    EXPECT_LE((slice.V.row(v) - ((1 - w) * mesh.V.row(a) + w * mesh.V.row(b)).head<3>()).cwiseAbs().maxCoeff(), 1e-12);
    if (a % sphere.V.rows() == b % sphere.V.rows()) {
      ++vertical;
      EXPECT_LE((slice.V.row(v) - r * sphere.V.row(a % sphere.V.rows())).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
  EXPECT_EQ(vertical, sphere.V.rows());
  for (Eigen::Index f = 0; f < slice.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const auto tet = mesh.T.row(slice.source_tet[std::size_t(f)]).array();
      EXPECT_TRUE((tet == slice.source_edge(slice.F(f, k), 0)).any() &&
                  (tet == slice.source_edge(slice.F(f, k), 1)).any());
    }
}

TEST(SliceTest, SliceThroughVertexLayerReproducesTheSurface) {
  // t = 0.5 hits layer 2 of 4 exactly: crossings land on vertices and collapsed triangles are dropped.
  const test_mesh::TriSurface sphere = icosphere(1);
  const TetMesh4 mesh = product_mesh(sphere, 4, 1.0, 1.0, 3.0);
  const SliceMesh slice = slice_at(mesh, Eigen::MatrixXd(), 0.5);
  const double r = radius_at(0.5, 1.0, 3.0);
  ASSERT_EQ(slice.F.rows(), sphere.F.rows());
  ASSERT_EQ(slice.V.rows(), sphere.V.rows());
  EXPECT_EQ(slice.labels.size(), 0);
  for (Eigen::Index v = 0; v < slice.V.rows(); ++v)
    EXPECT_LE((slice.V.row(v) - r * sphere.V.row(slice.source_edge(v, 0) % sphere.V.rows())).cwiseAbs().maxCoeff(),
              1e-12);
  EXPECT_EQ(surface_faces_of(slice, sphere.V.rows()), faces_of(sphere.F));
  EXPECT_EQ(bad_edges(slice.F), 0);
}

TEST(SliceTest, OrientationFollowsTheTetConvention) {
  // Reversing every tet reverses the 4D normals, so the slices must turn inside out.
  TetMesh4 mesh = product_mesh(octahedron(), 3, 1.0, 1.0, 2.0);
  const double forward = volume_of(slice_at(mesh, Eigen::MatrixXd(), 0.6).V, slice_at(mesh, Eigen::MatrixXd(), 0.6).F);
  mesh.T.col(2).swap(mesh.T.col(3));
  const SliceMesh flipped = slice_at(mesh, Eigen::MatrixXd(), 0.6);
  EXPECT_GT(forward, 0.0);
  EXPECT_NEAR(volume_of(flipped.V, flipped.F), -forward, 1e-12);
  EXPECT_LT(volume_of(target_boundary(mesh, Eigen::MatrixXd()).V, target_boundary(mesh, Eigen::MatrixXd()).F), 0.0);
}

TEST(SliceTest, ManyTimesGiveClosedSurfaces) {
  const test_mesh::TriSurface sphere = icosphere(2);
  const TetMesh4 mesh = product_mesh(sphere, 5, 0.7, 2.0, 1.0);
  for (const double t : {0.01, 0.2, 0.4, 0.5, 0.63, 0.99}) {
    const SliceMesh slice = slice_at(mesh, Eigen::MatrixXd(), t);
    const double r = radius_at(t, 2.0, 1.0);
    EXPECT_EQ(bad_edges(slice.F), 0) << "t = " << t;
    EXPECT_NEAR(volume_of(slice.V, slice.F), r * r * r * volume_of(sphere.V, sphere.F), 1e-11) << "t = " << t;
  }
}

TEST(SliceTest, RejectsTimesOutsideTheOpenInterval) {
  const TetMesh4 mesh = product_mesh(octahedron(), 2, 1.0);
  for (const double t : {0.0, 1.0, -0.2, 1.5, std::nan("")})
    EXPECT_THROW(slice_at(mesh, Eigen::MatrixXd(), t), InvalidInput);
  EXPECT_THROW(slice_at(mesh, Eigen::MatrixXd::Zero(3, 3), 0.5), InvalidInput);
  EXPECT_THROW(target_boundary(mesh, Eigen::MatrixXd::Zero(3, 3)), InvalidInput);
}

}  // namespace
}  // namespace morphmap
