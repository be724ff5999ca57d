// Small TetMesh4 inputs for tests that must not depend on the extraction stage (paper §5.2 builds the real
// mesh): a structured box [0,1]^2 x [0,H] cut into Kuhn tets and embedded in R^4 as (x, y, 0, z), plus
// helpers to rotate, bend or merge such meshes. Header-only and self-contained.
#pragma once

#include <Eigen/Core>
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <random>

#include "mesh/tet_mesh4.h"

namespace morphmap::test {

/// A box of nx * ny * nz cubes. Vertex (i, j, k) sits at origin + (sx i/nx, sy j/ny, 0, height k/nz), so tau
/// (column 3) runs along the box's third axis; column 2 is the direction normal to the flat hypersurface.
struct BoxSpec {
  int nx = 2, ny = 2, nz = 2;
  double sx = 1.0, sy = 1.0;
  double height = 1.0;  ///< extent along tau
  Eigen::Vector4d origin = Eigen::Vector4d::Zero();
  bool flag_ends = true;    ///< k = 0 -> side A, k = nz -> side B; else all Interior
  double time_scale = 0.0;  ///< c of the mesh; 0 means "height", so t = k / nz
};

/// Structured Kuhn (Freudenthal) tetrahedralisation: 6 tets per cube along the monotone paths from corner 000
/// to 111, conforming across cubes. Tets are oriented so that cross4 of their edges points along +column 2
/// (the flat embedding's normal), matching TetMesh4's convention with "outside" = +column 2.
inline TetMesh4 make_box_mesh(const BoxSpec& spec) {
  const int nx = spec.nx, ny = spec.ny, nz = spec.nz;
  auto id = [&](int i, int j, int k) { return (k * (ny + 1) + j) * (nx + 1) + i; };
  TetMesh4 mesh;
  const int vertex_count = (nx + 1) * (ny + 1) * (nz + 1);
  mesh.V.resize(vertex_count, 4);
  mesh.side.assign(static_cast<std::size_t>(vertex_count), VertexSide::Interior);
  for (int k = 0; k <= nz; ++k) {
    for (int j = 0; j <= ny; ++j) {
      for (int i = 0; i <= nx; ++i) {
        const int v = id(i, j, k);
        mesh.V.row(v) =
            spec.origin.transpose() + Eigen::RowVector4d(spec.sx * i / nx, spec.sy * j / ny, 0.0, spec.height * k / nz);
        if (spec.flag_ends && k == 0) mesh.side[static_cast<std::size_t>(v)] = VertexSide::A;
        if (spec.flag_ends && k == nz) mesh.side[static_cast<std::size_t>(v)] = VertexSide::B;
      }
    }
  }
  const std::array<std::array<int, 3>, 6> permutations = {
      {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
  mesh.T.resize(6 * nx * ny * nz, 4);
  int t = 0;
  for (int k = 0; k < nz; ++k) {
    for (int j = 0; j < ny; ++j) {
      for (int i = 0; i < nx; ++i) {
        for (const auto& perm : permutations) {
          std::array<int, 3> corner = {i, j, k};
          std::array<int, 4> tet{};
          tet[0] = id(corner[0], corner[1], corner[2]);
          for (int step = 0; step < 3; ++step) {
            ++corner[static_cast<std::size_t>(perm[static_cast<std::size_t>(step)])];
            tet[static_cast<std::size_t>(step) + 1] = id(corner[0], corner[1], corner[2]);
          }
          const Eigen::Vector4d v0 = mesh.V.row(tet[0]).transpose();
          const Eigen::Vector4d n = cross4(mesh.V.row(tet[1]).transpose() - v0, mesh.V.row(tet[2]).transpose() - v0,
                                           mesh.V.row(tet[3]).transpose() - v0);
          if (n(2) < 0.0) std::swap(tet[2], tet[3]);
          mesh.T.row(t++) << tet[0], tet[1], tet[2], tet[3];
        }
      }
    }
  }
  mesh.source_cell.assign(static_cast<std::size_t>(mesh.T.rows()), 0);
  mesh.time_scale = spec.time_scale > 0.0 ? spec.time_scale : spec.height;
  mesh.voxel_size = spec.sx / nx;
  mesh.time_steps = nz;
  return mesh;
}

/// The slab [0,1]^2 x [0,height], side A at tau = 0, side B at tau = height, time_scale = height.
inline TetMesh4 make_slab_mesh(int n, int nz, double height = 1.0) {
  BoxSpec spec;
  spec.nx = spec.ny = n;
  spec.nz = nz;
  spec.height = height;
  return make_box_mesh(spec);
}

/// A uniformly random rotation of R^4 (determinant +1), reproducible from the seed.
inline Eigen::Matrix4d random_rotation(unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) M(r, c) = normal(rng);
  }
  Eigen::HouseholderQR<Eigen::Matrix4d> qr(M);
  Eigen::Matrix4d Q = qr.householderQ();
  // Fix the column signs by R's diagonal (Haar measure), then the determinant by one column.
  const Eigen::Matrix4d R = qr.matrixQR().triangularView<Eigen::Upper>();
  for (int c = 0; c < 4; ++c) {
    if (R(c, c) < 0.0) Q.col(c) *= -1.0;
  }
  if (Q.determinant() < 0.0) Q.col(0) *= -1.0;
  return Q;
}

/// Applies p -> R p + shift to every vertex. Sides and time_scale are kept: the labels stay those of the
/// unrotated box, so tests compare against values computed before the rotation.
inline void transform_embedding(TetMesh4& mesh, const Eigen::Matrix4d& R,
                                const Eigen::Vector4d& shift = Eigen::Vector4d::Zero()) {
  mesh.V = (mesh.V * R.transpose()).rowwise() + shift.transpose();
}

/// Bends the mesh into a curved 3-manifold: interior (non-A, non-B) vertices move by up to `amplitude` along
/// `normal_column` (the direction out of the flat hypersurface) and by up to amplitude/4 along the others.
inline void perturb_interior(TetMesh4& mesh, double amplitude, unsigned seed, int normal_column = 2) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    if (mesh.side[static_cast<std::size_t>(i)] != VertexSide::Interior) continue;
    for (int c = 0; c < 4; ++c) {
      mesh.V(i, c) += (c == normal_column ? amplitude : 0.25 * amplitude) * uniform(rng);
    }
  }
}

/// Disjoint union: b's vertices and tets are appended after a's. time_scale, voxel_size and time_steps are a's.
inline TetMesh4 merge_meshes(const TetMesh4& a, const TetMesh4& b) {
  TetMesh4 m = a;
  const Eigen::Index va = a.V.rows();
  m.V.resize(va + b.V.rows(), 4);
  m.V.topRows(va) = a.V;
  m.V.bottomRows(b.V.rows()) = b.V;
  m.T.resize(a.T.rows() + b.T.rows(), 4);
  m.T.topRows(a.T.rows()) = a.T;
  m.T.bottomRows(b.T.rows()) = b.T.array() + static_cast<int>(va);
  m.side.insert(m.side.end(), b.side.begin(), b.side.end());
  m.source_cell.insert(m.source_cell.end(), b.source_cell.begin(), b.source_cell.end());
  return m;
}

}  // namespace morphmap::test
