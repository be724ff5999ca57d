// Test inputs for the label-transport and slicing stages (paper §7, §9) that need no extraction:
// the product of a closed surface with [0, c] in tau, tetrahedralised as prisms, plus small checks.
#pragma once

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "mesh/tet_mesh4.h"

namespace morphmap::test_mesh {

struct TriSurface {
  Eigen::MatrixXd V;  ///< #V by 3
  Eigen::MatrixXi F;  ///< #F by 3, outward
};

/// Unit octahedron, outward faces.
inline TriSurface octahedron() {
  TriSurface s;
  s.V.resize(6, 3);
  s.V << 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1;
  s.F.resize(8, 3);
  s.F << 0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5;
  return s;
}

/// Icosahedron on the unit sphere, each subdivision splitting every triangle in 4 (midpoints projected).
inline TriSurface icosphere(int subdivisions) {
  const double p = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> V = {{-1, p, 0},  {1, p, 0},  {-1, -p, 0}, {1, -p, 0}, {0, -1, p},  {0, 1, p},
                                    {0, -1, -p}, {0, 1, -p}, {p, 0, -1},  {p, 0, 1},  {-p, 0, -1}, {-p, 0, 1}};
  std::vector<std::array<int, 3>> F = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                       {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                       {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                       {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (auto& v : V) v.normalize();
  for (int level = 0; level < subdivisions; ++level) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      V.push_back((V[std::size_t(a)] + V[std::size_t(b)]).normalized());
      return mid[key] = int(V.size()) - 1;
    };
    std::vector<std::array<int, 3>> G;
    for (const auto& f : F) {
      const int ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
      G.push_back({f[0], ab, ca});
      G.push_back({f[1], bc, ab});
      G.push_back({f[2], ca, bc});
      G.push_back({ab, bc, ca});
    }
    F = std::move(G);
  }
  TriSurface s;
  s.V.resize(Eigen::Index(V.size()), 3);
  for (std::size_t i = 0; i < V.size(); ++i) s.V.row(Eigen::Index(i)) = V[i].transpose();
  s.F.resize(Eigen::Index(F.size()), 3);
  for (std::size_t i = 0; i < F.size(); ++i) s.F.row(Eigen::Index(i)) << F[i][0], F[i][1], F[i][2];
  return s;
}

/// Radius factor of the product mesh at morph time t: linear from r0 to r1.
inline double radius_at(double t, double r0, double r1) { return (1.0 - t) * r0 + t * r1; }

/// Product of `surface` (star-shaped about the origin) with tau in [0, c], `layers` prism layers.
/// Vertex k * #S + i is surface vertex i scaled by radius_at(k / layers) at tau = c k / layers.
/// Each prism (a < b < c by id) splits into (a0 b0 c0 a1), (b0 c0 a1 b1), (c0 a1 b1 c1): the side
/// quads are cut from the higher bottom id to the lower top id, so neighbouring prisms agree.
inline TetMesh4 product_mesh(const TriSurface& surface, int layers, double c, double r0 = 1.0, double r1 = 1.0) {
  const Eigen::Index n = surface.V.rows();
  TetMesh4 mesh;
  mesh.time_scale = c;
  mesh.time_steps = layers;
  mesh.voxel_size = 0.0;
  mesh.V.resize((layers + 1) * n, 4);
  mesh.side.resize(std::size_t((layers + 1) * n));
  for (int k = 0; k <= layers; ++k) {
    const double t = double(k) / layers;
    for (Eigen::Index i = 0; i < n; ++i) {
      mesh.V.row(k * n + i) << radius_at(t, r0, r1) * surface.V.row(i), c * t;
      mesh.side[std::size_t(k * n + i)] = k == 0 ? VertexSide::A : (k == layers ? VertexSide::B : VertexSide::Interior);
    }
  }
  mesh.T.resize(3 * layers * surface.F.rows(), 4);
  Eigen::Index row = 0;
  for (int k = 0; k < layers; ++k) {
    for (Eigen::Index f = 0; f < surface.F.rows(); ++f) {
      std::array<int, 3> s = {surface.F(f, 0), surface.F(f, 1), surface.F(f, 2)};
      std::sort(s.begin(), s.end());
      const int a0 = int(k * n) + s[0], b0 = int(k * n) + s[1], c0 = int(k * n) + s[2];
      const int a1 = a0 + int(n), b1 = b0 + int(n), c1 = c0 + int(n);
      const std::array<std::array<int, 4>, 3> tets = {{{a0, b0, c0, a1}, {b0, c0, a1, b1}, {c0, a1, b1, c1}}};
      for (auto tet : tets) {
        const Eigen::Vector4d v0 = mesh.V.row(tet[0]).transpose();
        const Eigen::Vector4d normal = cross4(mesh.V.row(tet[1]).transpose() - v0, mesh.V.row(tet[2]).transpose() - v0,
                                              mesh.V.row(tet[3]).transpose() - v0);
        Eigen::Vector3d centre = Eigen::Vector3d::Zero();
        for (const int v : tet) centre += mesh.V.row(v).head<3>().transpose() / 4.0;
        if (normal.head<3>().dot(centre) < 0.0) std::swap(tet[2], tet[3]);
        mesh.T.row(row++) << tet[0], tet[1], tet[2], tet[3];
      }
    }
  }
  mesh.source_cell.resize(std::size_t(mesh.T.rows()));
  for (std::size_t i = 0; i < mesh.source_cell.size(); ++i) mesh.source_cell[i] = std::int64_t(i);
  return mesh;
}

/// s = t, the Dirichlet data extended linearly: the start of Gauss-Seidel and a harmonic field on products.
inline Eigen::VectorXd time_field(const TetMesh4& mesh) { return mesh.V.col(3) / mesh.time_scale; }

/// `main` with `extra` appended as a second component: extra's tau shifted by `shift`, its x by 5, and every
/// vertex of it not on side `keep` made interior (a component born mid-morph keeps B, a vanishing one A).
inline TetMesh4 with_component(const TetMesh4& main, TetMesh4 extra, double shift, VertexSide keep) {
  extra.V.col(3).array() += shift;
  extra.V.col(0).array() += 5.0;
  for (auto& side : extra.side)
    if (side != keep) side = VertexSide::Interior;
  TetMesh4 mesh = main;
  const Eigen::Index nm = main.vertex_count();
  mesh.V.resize(nm + extra.vertex_count(), 4);
  mesh.V << main.V, extra.V;
  mesh.T.resize(main.tet_count() + extra.tet_count(), 4);
  mesh.T << main.T, (extra.T.array() + int(nm)).matrix();
  mesh.side.insert(mesh.side.end(), extra.side.begin(), extra.side.end());
  return mesh;
}

/// Per-vertex unit field from volume-weighted per-tet gradients of s (affine least-norm form).
inline Eigen::MatrixXd gradient_field(const TetMesh4& mesh, const Eigen::VectorXd& s) {
  Eigen::MatrixXd field = Eigen::MatrixXd::Zero(mesh.vertex_count(), 4);
  for (Eigen::Index t = 0; t < mesh.tet_count(); ++t) {
    Eigen::Matrix<double, 4, 3> E;
    Eigen::Vector3d ds;
    for (int k = 0; k < 3; ++k) {
      E.col(k) = (mesh.V.row(mesh.T(t, k + 1)) - mesh.V.row(mesh.T(t, 0))).transpose();
      ds(k) = s(mesh.T(t, k + 1)) - s(mesh.T(t, 0));
    }
    const Eigen::Matrix3d G = E.transpose() * E;
    const Eigen::Vector4d g = E * G.ldlt().solve(ds);
    const double volume = std::sqrt(std::max(G.determinant(), 0.0)) / 6.0;
    for (int k = 0; k < 4; ++k) field.row(mesh.T(t, k)) += volume * g.transpose();
  }
  for (Eigen::Index v = 0; v < field.rows(); ++v)
    if (field.row(v).norm() > 0.0) field.row(v).normalize();
  return field;
}

/// Edges not used exactly once in each direction (0 for a closed, consistently oriented manifold).
template <typename Faces>
std::int64_t bad_edges(const Faces& F) {
  std::map<std::pair<int, int>, int> directed;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) ++directed[{int(F(f, k)), int(F(f, (k + 1) % 3))}];
  std::int64_t bad = 0;
  for (const auto& [edge, count] : directed) {
    const auto twin = directed.find({edge.second, edge.first});
    if (count != 1 || twin == directed.end() || twin->second != 1) ++bad;
  }
  return bad;
}

template <typename Faces>
double volume_of(const Eigen::MatrixXd& V, const Faces& F) {
  double volume = 0.0;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    volume +=
        Eigen::Vector3d(V.row(F(f, 0))).dot(Eigen::Vector3d(V.row(F(f, 1))).cross(Eigen::Vector3d(V.row(F(f, 2))))) /
        6.0;
  return volume;
}

template <typename Faces>
double area_of(const Eigen::MatrixXd& V, const Faces& F) {
  double area = 0.0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0));
    area += 0.5 * (Eigen::Vector3d(V.row(F(f, 1))) - a).cross(Eigen::Vector3d(V.row(F(f, 2))) - a).norm();
  }
  return area;
}

}  // namespace morphmap::test_mesh
