// Validation and measures of the input surfaces A and B (DESIGN.md, stage "load"): the morph's distance fields
// need closed, manifold, consistently oriented triangle meshes with finite coordinates.
#include "mesh/surface.h"

#include <tbb/parallel_sort.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>
#include <tuple>
#include <vector>

#include "mesh/errors.h"

namespace morphmap {

namespace {

// One directed face edge, keyed by its undirected vertex pair so that sorting groups the faces of an edge.
struct EdgeUse {
  std::uint64_t key;
  int face;
  int local;  // the edge runs from corner `local` to corner (local + 1) % 3 of `face`
};

int find_root(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

void unite(std::vector<int>& parent, int a, int b) {
  a = find_root(parent, a);
  b = find_root(parent, b);
  if (a == b) return;
  // Keep the smaller index as root so the result does not depend on the order of unions.
  if (a < b) {
    parent[b] = a;
  } else {
    parent[a] = b;
  }
}

std::string display_name(const Surface& surface) { return surface.name.empty() ? "surface" : surface.name; }

}  // namespace

SurfaceCheck check_surface(const Eigen::MatrixXi& F, std::int64_t vertex_count) {
  SurfaceCheck check;
  const int face_count = static_cast<int>(F.rows());
  if (F.cols() != 3) throw InvalidInput("check_surface: F must have 3 columns, has " + std::to_string(F.cols()));

  std::vector<EdgeUse> uses;
  uses.reserve(3 * static_cast<std::size_t>(face_count));
  std::vector<char> degenerate(face_count, 0);
  for (int f = 0; f < face_count; ++f) {
    const int a = F(f, 0), b = F(f, 1), c = F(f, 2);
    if (a == b || b == c || c == a) {
      // A repeated index has no well-defined edges; counting them would report spurious non-manifold edges.
      degenerate[f] = 1;
      ++check.degenerate_faces;
      continue;
    }
    for (int k = 0; k < 3; ++k) {
      const auto u = static_cast<std::uint32_t>(F(f, k));
      const auto v = static_cast<std::uint32_t>(F(f, (k + 1) % 3));
      const std::uint64_t key = (static_cast<std::uint64_t>(std::min(u, v)) << 32) | std::max(u, v);
      uses.push_back({key, f, k});
    }
  }
  // Sorted by (key, face, local), which makes the corner unions below deterministic. The order is total (no two uses
  // share a face and a corner), so any sort gives the same sequence: a counting sort by the edge's lower vertex, whose
  // buckets receive their uses in (face, local) order and hold a handful each, then an insertion sort of each bucket
  // by the upper vertex (horse.obj's 291 k uses: a third of its 15 ms check was tbb::parallel_sort). Indices outside
  // [0, vertex_count) have no bucket: the general sort takes them.
  auto before = [](const EdgeUse& x, const EdgeUse& y) {
    return x.key != y.key ? x.key < y.key : (x.face != y.face ? x.face < y.face : x.local < y.local);
  };
  bool in_range = vertex_count > 0 && vertex_count <= std::numeric_limits<std::int32_t>::max();
  for (const EdgeUse& u : uses) in_range = in_range && std::int64_t(u.key & 0xffffffffu) < vertex_count;
  if (in_range) {
    std::vector<std::int64_t> bucket(static_cast<std::size_t>(vertex_count) + 1, 0);
    for (const EdgeUse& u : uses) ++bucket[std::size_t(u.key >> 32) + 1];
    for (std::size_t v = 0; v + 1 < bucket.size(); ++v) bucket[v + 1] += bucket[v];
    std::vector<EdgeUse> sorted(uses.size());
    std::vector<std::int64_t> fill(bucket.begin(), bucket.end() - 1);
    for (const EdgeUse& u : uses) sorted[std::size_t(fill[std::size_t(u.key >> 32)]++)] = u;
    for (std::size_t v = 0; v + 1 < bucket.size(); ++v)
      for (std::int64_t i = bucket[v] + 1; i < bucket[v + 1]; ++i)
        for (std::int64_t j = i; j > bucket[v] && before(sorted[std::size_t(j)], sorted[std::size_t(j - 1)]); --j)
          std::swap(sorted[std::size_t(j)], sorted[std::size_t(j - 1)]);
    uses.swap(sorted);
  } else {
    tbb::parallel_sort(uses.begin(), uses.end(), before);
  }

  // Corners (3 f + k) of one vertex are joined when their faces share an edge at that vertex; every vertex
  // should end up with exactly one group (one fan).
  std::vector<int> parent(3 * static_cast<std::size_t>(face_count));
  std::iota(parent.begin(), parent.end(), 0);
  auto join_faces = [&](const EdgeUse& x, const EdgeUse& y) {
    const int x0 = 3 * x.face + x.local, x1 = 3 * x.face + (x.local + 1) % 3;
    const int y0 = 3 * y.face + y.local, y1 = 3 * y.face + (y.local + 1) % 3;
    const bool same_direction = F(x.face, x.local) == F(y.face, y.local);
    if (same_direction) {
      unite(parent, x0, y0);
      unite(parent, x1, y1);
    } else {
      unite(parent, x0, y1);
      unite(parent, x1, y0);
    }
    return same_direction;
  };

  for (std::size_t i = 0; i < uses.size();) {
    std::size_t j = i + 1;
    while (j < uses.size() && uses[j].key == uses[i].key) ++j;
    const std::size_t n = j - i;
    if (n == 1) {
      ++check.boundary_edges;
    } else if (n == 2) {
      if (join_faces(uses[i], uses[i + 1])) ++check.inconsistent_edges;
    } else {
      ++check.nonmanifold_edges;
      // Joining all sheets keeps a vertex on a non-manifold edge from being reported a second time.
      for (std::size_t m = i + 1; m < j; ++m) join_faces(uses[i], uses[m]);
    }
    i = j;
  }

  std::vector<int> fans(static_cast<std::size_t>(std::max<std::int64_t>(vertex_count, 0)), 0);
  for (int f = 0; f < face_count; ++f) {
    if (degenerate[f]) continue;
    for (int k = 0; k < 3; ++k) {
      const int corner = 3 * f + k;
      const int v = F(f, k);
      if (find_root(parent, corner) == corner && v >= 0 && v < vertex_count) ++fans[v];
    }
  }
  for (int n : fans) {
    if (n > 1) ++check.nonmanifold_vertices;
  }

  for (std::size_t i = 0; i < uses.size(); ++i) check.edges += (i == 0 || uses[i].key != uses[i - 1].key) ? 1 : 0;
  check.faces = face_count - check.degenerate_faces;
  std::vector<int> component(static_cast<std::size_t>(std::max<std::int64_t>(vertex_count, 0)));
  std::iota(component.begin(), component.end(), 0);
  std::vector<char> used(component.size(), 0);
  for (int f = 0; f < face_count; ++f)
    for (int k = 0; k < 3; ++k) {
      const int v = F(f, k);
      if (v < 0 || v >= vertex_count) continue;
      used[std::size_t(v)] = 1;
      if (k > 0 && F(f, 0) >= 0 && F(f, 0) < vertex_count) unite(component, F(f, 0), v);
    }
  for (std::int64_t v = 0; v < vertex_count; ++v) {
    if (!used[std::size_t(v)]) continue;
    ++check.vertices;
    if (find_root(component, int(v)) == int(v)) ++check.components;
  }
  return check;
}

SurfaceCheck validate_surface(const Surface& surface, bool require_closed) {
  const std::string name = display_name(surface);
  const Eigen::MatrixXd& V = surface.V;
  const Eigen::MatrixXi& F = surface.F;
  if (F.rows() == 0) throw InvalidInput(name + ": mesh has no faces");
  if (V.cols() != 3) throw InvalidInput(name + ": vertices must have 3 coordinates, have " + std::to_string(V.cols()));
  if (F.cols() != 3) throw InvalidInput(name + ": faces must have 3 corners, have " + std::to_string(F.cols()));
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    if (!V.row(i).allFinite())
      throw InvalidInput(name + ": vertex " + std::to_string(i) + " has a non-finite coordinate");
  }
  const Eigen::Index n = V.rows();
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      if (F(f, k) < 0 || F(f, k) >= n) {
        throw InvalidInput(name + ": face " + std::to_string(f) + " has vertex index " + std::to_string(F(f, k)) +
                           " out of range [0, " + std::to_string(n) + ")");
      }
    }
  }
  if (surface.FUV.rows() > 0) {
    if (surface.FUV.rows() != F.rows() || surface.FUV.cols() != 3) {
      throw InvalidInput(name + ": texture faces must be #F by 3 (" + std::to_string(F.rows()) + " by 3), are " +
                         std::to_string(surface.FUV.rows()) + " by " + std::to_string(surface.FUV.cols()));
    }
    if (surface.UV.cols() != 2) {
      throw InvalidInput(name + ": texture coordinates must have 2 columns, have " + std::to_string(surface.UV.cols()));
    }
    const Eigen::Index m = surface.UV.rows();
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
      for (int k = 0; k < 3; ++k) {
        if (surface.FUV(f, k) < 0 || surface.FUV(f, k) >= m) {
          throw InvalidInput(name + ": face " + std::to_string(f) + " has texture index " +
                             std::to_string(surface.FUV(f, k)) + " out of range [0, " + std::to_string(m) + ")");
        }
      }
    }
    for (Eigen::Index i = 0; i < m; ++i) {
      if (!surface.UV.row(i).allFinite()) {
        throw InvalidInput(name + ": texture coordinate " + std::to_string(i) + " is not finite");
      }
    }
  }
  if (!require_closed) return {};

  const SurfaceCheck check = check_surface(F, n);
  if (!check.closed()) {
    throw InvalidInput(name + ": surface is not closed (" + std::to_string(check.boundary_edges) + " boundary edges)");
  }
  if (!check.manifold()) {
    std::ostringstream problem;
    problem << name << ": surface is not manifold (" << check.nonmanifold_edges << " edges with more than two faces, "
            << check.nonmanifold_vertices << " non-manifold vertices, " << check.degenerate_faces
            << " degenerate faces)";
    throw InvalidInput(problem.str());
  }
  // Inside/outside, and with it the sign of the distance fields, is undefined without a consistent orientation.
  if (check.inconsistent_edges > 0) {
    throw InvalidInput(name + ": surface is not consistently oriented (" + std::to_string(check.inconsistent_edges) +
                       " edges traversed in the same direction by both faces)");
  }
  return check;
}

Eigen::AlignedBox3d bounding_box(const Eigen::MatrixXd& V) {
  Eigen::AlignedBox3d box;  // constructed empty
  for (Eigen::Index i = 0; i < V.rows(); ++i) box.extend(Eigen::Vector3d(V(i, 0), V(i, 1), V(i, 2)));
  return box;
}

std::int64_t weld_coincident_vertices(Surface& surface) {
  const Eigen::Index n = surface.V.rows();
  std::vector<Eigen::Index> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), Eigen::Index(0));
  const auto key = [&](Eigen::Index i) {
    return std::make_tuple(surface.V(i, 0), surface.V(i, 1), surface.V(i, 2), i);
  };
  std::sort(order.begin(), order.end(), [&](Eigen::Index a, Eigen::Index b) { return key(a) < key(b); });
  std::vector<int> target(static_cast<std::size_t>(n));
  std::int64_t merged = 0;
  for (std::size_t r = 0; r < order.size(); ++r) {
    const Eigen::Index i = order[r];
    const bool same = r > 0 && surface.V.row(i) == surface.V.row(order[r - 1]);
    target[std::size_t(i)] = same ? target[std::size_t(order[r - 1])] : int(i);  // the run's lowest index
    merged += same;
  }
  if (merged == 0) return 0;
  std::vector<int> renumber(static_cast<std::size_t>(n), -1);
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) renumber[std::size_t(target[std::size_t(surface.F(f, c))])] = 0;
  int next = 0;
  for (auto& r : renumber)
    if (r == 0) r = next++;
  Eigen::MatrixXd V(next, 3);
  for (Eigen::Index i = 0; i < n; ++i)
    if (renumber[std::size_t(i)] >= 0) V.row(renumber[std::size_t(i)]) = surface.V.row(i);
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) surface.F(f, c) = renumber[std::size_t(target[std::size_t(surface.F(f, c))])];
  surface.V = std::move(V);
  return merged;
}

bool orient_outward(Surface& surface) {
  if (!(signed_volume(surface.V, surface.F) < 0.0)) return false;
  surface.F.col(1).swap(surface.F.col(2));
  if (surface.FUV.rows() == surface.F.rows()) surface.FUV.col(1).swap(surface.FUV.col(2));
  return true;
}

double signed_volume(const Eigen::MatrixXd& V, const Eigen::MatrixXi& F) {
  if (F.rows() == 0) return 0.0;
  // The enclosed volume does not depend on the origin; the box centre keeps the triple products small.
  const Eigen::Vector3d o = bounding_box(V).center();
  double six_volume = 0.0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)).transpose() - o;
    const Eigen::Vector3d b = V.row(F(f, 1)).transpose() - o;
    const Eigen::Vector3d c = V.row(F(f, 2)).transpose() - o;
    six_volume += a.dot(b.cross(c));
  }
  return six_volume / 6.0;
}

double surface_area(const Eigen::MatrixXd& V, const Eigen::MatrixXi& F) {
  double twice_area = 0.0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = V.row(F(f, 0)).transpose();
    const Eigen::Vector3d b = V.row(F(f, 1)).transpose();
    const Eigen::Vector3d c = V.row(F(f, 2)).transpose();
    twice_area += (b - a).cross(c - a).norm();
  }
  return 0.5 * twice_area;
}

}  // namespace morphmap
