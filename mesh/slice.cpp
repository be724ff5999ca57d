// The target surface B and time slices of the tetrahedral mesh in R^4 (paper §9: intermediate shapes
// are "slicing the 4D tetrahedral mesh with a hyperplane"), oriented by the mesh's cross4 convention.
#include "mesh/slice.h"

#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <unordered_map>

#include "mesh/errors.h"

namespace morphmap {

namespace {

void check_labels(const TetMesh4& mesh, const Eigen::MatrixXd& labels, const char* where) {
  if (labels.size() == 0) return;
  if (labels.rows() != mesh.vertex_count() || labels.cols() != 3)
    throw InvalidInput(std::string(where) + ": labels must be empty or #V by 3");
}

// Spatial part of the tet's 4D normal: outward for every slice through the tet, so it orients the
// triangles without storing normals.
Eigen::Vector3d outward_of_tet(const TetMesh4& mesh, Eigen::Index t) {
  const Eigen::Vector4d v0 = mesh.V.row(mesh.T(t, 0)).transpose();
  const Eigen::Vector4d n = cross4(mesh.V.row(mesh.T(t, 1)).transpose() - v0, mesh.V.row(mesh.T(t, 2)).transpose() - v0,
                                   mesh.V.row(mesh.T(t, 3)).transpose() - v0);
  return n.head<3>();
}

SliceMesh boundary_of(const TetMesh4& mesh, const Eigen::MatrixXd& labels, VertexSide side, const char* where) {
  check_labels(mesh, labels, where);
  const Eigen::Index nv = mesh.vertex_count();
  if (mesh.side.size() != static_cast<std::size_t>(nv))
    throw InvalidInput(std::string(where) + ": side must have #V entries");
  auto on_side = [&](int v) { return mesh.side[static_cast<std::size_t>(v)] == side; };

  // The tets are scanned in parallel chunks, each keeping its faces in tet order, concatenated in chunk order: the
  // faces come out in tet order, as a serial scan lists them (serial, the scan was 13 ms of cow -> horse with a core
  // idle, twice a run).
  constexpr Eigen::Index kChunk = 1 << 16;
  const Eigen::Index chunks = (mesh.tet_count() + kChunk - 1) / kChunk;
  std::vector<std::vector<std::array<int, 3>>> chunk_faces(static_cast<std::size_t>(chunks));
  std::vector<std::vector<int>> chunk_tets(static_cast<std::size_t>(chunks));
  tbb::parallel_for(Eigen::Index(0), chunks, [&](Eigen::Index chunk) {
    const Eigen::Index end = std::min(mesh.tet_count(), (chunk + 1) * kChunk);
    for (Eigen::Index t = chunk * kChunk; t < end; ++t) {
      std::array<int, 3> f{};
      int n = 0;
      for (int k = 0; k < 4; ++k)
        if (on_side(mesh.T(t, k))) {
          if (n < 3) f[static_cast<std::size_t>(n)] = mesh.T(t, k);
          ++n;
        }
      if (n != 3) continue;  // four vertices on the boundary would be a flat tet: it has no single boundary face
      const Eigen::Vector3d a = mesh.V.row(f[0]).head<3>();
      const Eigen::Vector3d normal =
          (Eigen::Vector3d(mesh.V.row(f[1]).head<3>()) - a).cross(Eigen::Vector3d(mesh.V.row(f[2]).head<3>()) - a);
      if (normal.dot(outward_of_tet(mesh, t)) < 0.0) std::swap(f[1], f[2]);
      chunk_faces[static_cast<std::size_t>(chunk)].push_back(f);
      chunk_tets[static_cast<std::size_t>(chunk)].push_back(int(t));
    }
  });
  std::vector<std::array<int, 3>> faces;
  std::vector<int> source_tet;
  std::vector<char> used(static_cast<std::size_t>(nv), 0);
  for (Eigen::Index chunk = 0; chunk < chunks; ++chunk) {
    for (const std::array<int, 3>& f : chunk_faces[static_cast<std::size_t>(chunk)]) {
      for (const int v : f) used[static_cast<std::size_t>(v)] = 1;
      faces.push_back(f);
    }
    const std::vector<int>& tets = chunk_tets[static_cast<std::size_t>(chunk)];
    source_tet.insert(source_tet.end(), tets.begin(), tets.end());
  }

  // Compact numbering in ascending mesh vertex id, so the result does not depend on tet order.
  std::vector<int> compact(static_cast<std::size_t>(nv), -1);
  int count = 0;
  for (Eigen::Index v = 0; v < nv; ++v)
    if (used[static_cast<std::size_t>(v)]) compact[static_cast<std::size_t>(v)] = count++;

  SliceMesh out;
  out.t = side == VertexSide::B ? 1.0 : 0.0;
  out.V.resize(count, 3);
  out.source_edge.resize(count, 2);
  out.edge_weight = Eigen::VectorXd::Zero(count);
  if (labels.size() > 0) out.labels.resize(count, 3);
  for (Eigen::Index v = 0; v < nv; ++v) {
    const int i = compact[static_cast<std::size_t>(v)];
    if (i < 0) continue;
    out.V.row(i) = mesh.V.row(v).head<3>();
    out.source_edge.row(i) << int(v), int(v);
    if (labels.size() > 0) out.labels.row(i) = labels.row(v);
  }
  out.F.resize(Eigen::Index(faces.size()), 3);
  for (std::size_t f = 0; f < faces.size(); ++f)
    for (int k = 0; k < 3; ++k) out.F(Eigen::Index(f), k) = compact[static_cast<std::size_t>(faces[f][std::size_t(k)])];
  out.source_tet = std::move(source_tet);
  return out;
}

}  // namespace

SliceMesh target_boundary(const TetMesh4& mesh, const Eigen::MatrixXd& labels) {
  return boundary_of(mesh, labels, VertexSide::B, "target_boundary");
}

SliceMesh source_boundary(const TetMesh4& mesh, const Eigen::MatrixXd& labels) {
  return boundary_of(mesh, labels, VertexSide::A, "source_boundary");
}

SliceMesh slice_at(const TetMesh4& mesh, const Eigen::MatrixXd& labels, double t) {
  if (!(t > 0.0 && t < 1.0)) throw InvalidInput("slice_at: t must be in (0, 1), got " + std::to_string(t));
  check_labels(mesh, labels, "slice_at");
  const bool with_labels = labels.size() > 0;
  const Eigen::Index nv = mesh.vertex_count();
  const double tau_s = mesh.time_scale * t;

  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector3d> vertex_labels;
  std::vector<std::array<int, 2>> edges;
  std::vector<double> weights;
  std::unordered_map<std::int64_t, int> index_of;

  // Slice vertex on edge (below b, above a). An above vertex exactly on the plane is used itself, so
  // all tets around it agree on one slice vertex and the slice stays watertight.
  auto crossing = [&](int b, int a) -> int {
    const double tb = mesh.V(b, 3);
    const double ta = mesh.V(a, 3);
    const double w_ba = (tau_s - tb) / (ta - tb);
    int lo = std::min(a, b);
    int hi = std::max(a, b);
    double w = 0.0;
    if (w_ba >= 1.0) {
      lo = hi = a;
    } else if (w_ba <= 0.0) {
      lo = hi = b;
    } else {
      // Weight measured from the lower id so the same edge always gives bit-identical results.
      w = (tau_s - mesh.V(lo, 3)) / (mesh.V(hi, 3) - mesh.V(lo, 3));
    }
    const std::int64_t key = std::int64_t(lo) * std::int64_t(nv) + hi;
    const auto [it, inserted] = index_of.emplace(key, int(positions.size()));
    if (inserted) {
      positions.push_back((1.0 - w) * mesh.V.row(lo).head<3>().transpose() + w * mesh.V.row(hi).head<3>().transpose());
      if (with_labels) vertex_labels.push_back((1.0 - w) * labels.row(lo).transpose() + w * labels.row(hi).transpose());
      edges.push_back({lo, hi});
      weights.push_back(w);
    }
    return it->second;
  };
  auto key_of = [&](int i) {
    return std::int64_t(edges[std::size_t(i)][0]) * std::int64_t(nv) + edges[std::size_t(i)][1];
  };

  std::vector<std::array<int, 3>> faces;
  std::vector<int> source_tet;
  auto emit = [&](int a, int b, int c, int tet) {
    if (a == b || b == c || c == a) return;  // collapsed by a vertex on the plane
    faces.push_back({a, b, c});
    source_tet.push_back(tet);
  };

  for (Eigen::Index tet = 0; tet < mesh.tet_count(); ++tet) {
    int above[4];
    int below[4];
    int na = 0;
    int nb = 0;
    for (int k = 0; k < 4; ++k) {
      const int v = mesh.T(tet, k);
      if (mesh.V(v, 3) >= tau_s)
        above[na++] = v;
      else
        below[nb++] = v;
    }
    if (na == 0 || nb == 0) continue;

    // Polygon corners in cyclic order around the cut.
    int corner[4];
    int n = 0;
    if (na == 1) {
      for (int k = 0; k < 3; ++k) corner[n++] = crossing(below[k], above[0]);
    } else if (nb == 1) {
      for (int k = 0; k < 3; ++k) corner[n++] = crossing(below[0], above[k]);
    } else {
      corner[n++] = crossing(below[0], above[0]);
      corner[n++] = crossing(below[1], above[0]);
      corner[n++] = crossing(below[1], above[1]);
      corner[n++] = crossing(below[0], above[1]);
    }

    // Orient the whole polygon with its Newell normal before splitting: more robust than orienting
    // two possibly thin triangles separately.
    Eigen::Vector3d newell = Eigen::Vector3d::Zero();
    const Eigen::Vector3d origin = positions[std::size_t(corner[0])];
    for (int k = 1; k + 1 < n; ++k)
      newell += (positions[std::size_t(corner[k])] - origin).cross(positions[std::size_t(corner[k + 1])] - origin);
    if (newell.dot(outward_of_tet(mesh, tet)) < 0.0) std::reverse(corner, corner + n);

    if (n == 3) {
      emit(corner[0], corner[1], corner[2], int(tet));
    } else {
      // The diagonal is interior to the tet, so any rule works; global edge ids make it reproducible.
      int first = 0;
      for (int k = 1; k < 4; ++k)
        if (key_of(corner[k]) < key_of(corner[first])) first = k;
      const int c0 = corner[first];
      const int c1 = corner[(first + 1) % 4];
      const int c2 = corner[(first + 2) % 4];
      const int c3 = corner[(first + 3) % 4];
      emit(c0, c1, c2, int(tet));
      emit(c0, c2, c3, int(tet));
    }
  }

  // Drop vertices left without a triangle (all their triangles collapsed), keeping first-use order.
  std::vector<int> compact(positions.size(), -1);
  int count = 0;
  for (const auto& f : faces)
    for (const int i : f)
      if (compact[std::size_t(i)] < 0) compact[std::size_t(i)] = count++;

  SliceMesh out;
  out.t = t;
  out.V.resize(count, 3);
  out.source_edge.resize(count, 2);
  out.edge_weight.resize(count);
  if (with_labels) out.labels.resize(count, 3);
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const int j = compact[i];
    if (j < 0) continue;
    out.V.row(j) = positions[i].transpose();
    out.source_edge.row(j) << edges[i][0], edges[i][1];
    out.edge_weight(j) = weights[i];
    if (with_labels) out.labels.row(j) = vertex_labels[i].transpose();
  }
  out.F.resize(Eigen::Index(faces.size()), 3);
  for (std::size_t f = 0; f < faces.size(); ++f)
    for (int k = 0; k < 3; ++k) out.F(Eigen::Index(f), k) = compact[std::size_t(faces[f][std::size_t(k)])];
  out.source_tet = std::move(source_tet);
  return out;
}

}  // namespace morphmap
