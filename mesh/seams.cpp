// Topological seams (paper §8.1) and texture seams (§8.2), see seams.h. Both passes keep the mesh
// watertight in position: a cut point on an edge is computed from that edge alone (canonical direction,
// lower vertex id first) and shared by the two triangles that use the edge.
#include "mesh/seams.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <numeric>
#include <string>
#include <tuple>
#include <unordered_map>

#include "mesh/errors.h"
#include "mesh/stopwatch.h"

namespace morphmap {

namespace {

struct UnionFind {
  std::vector<int> parent;
  explicit UnionFind(int n) : parent(std::size_t(n)) { std::iota(parent.begin(), parent.end(), 0); }
  int find(int x) {
    while (parent[std::size_t(x)] != x) x = parent[std::size_t(x)] = parent[std::size_t(parent[std::size_t(x)])];
    return x;
  }
  void unite(int a, int b) { parent[std::size_t(find(a))] = find(b); }
};

// Barycentric weights of the point of triangle (a, b, c) closest to p (Ericson, Real-Time Collision
// Detection §5.1.5): convex, so interpolated UVs stay inside the face's UV triangle.
Eigen::Vector3d closest_barycentric(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return {1.0, 0.0, 0.0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return {0.0, 1.0, 0.0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double v = d1 / (d1 - d3);
    return {1.0 - v, v, 0.0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return {0.0, 0.0, 1.0};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double w = d2 / (d2 - d6);
    return {1.0 - w, 0.0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0.0, 1.0 - w, w};
  }
  const double sum = va + vb + vc;
  if (!(sum > 0.0)) return {1.0, 0.0, 0.0};  // degenerate face: any corner is as close as rounding allows
  const double v = vb / sum, w = vc / sum;
  return {1.0 - v - w, v, w};
}

double max_span(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return std::max({(a - b).norm(), (b - c).norm(), (c - a).norm()});
}

// Intermediate mesh after the topological pass: positions by id (shared across a seam) and vertices
// (position id + label; a seam position has one vertex per side).
struct LabelledMesh {
  std::vector<Eigen::Vector3d> positions;
  std::vector<int> vertex_position;
  std::vector<Eigen::Vector3d> vertex_label;
  std::vector<std::array<int, 3>> faces;
  std::vector<int> source_face;
  std::vector<std::array<int, 2>> cut_edges;    // position ids
  std::vector<char> cut_position;               // per position: lies on a topological cut
  std::vector<std::array<int, 3>> split_faces;  // corners (input vertex ids) of the input triangles that were cut
};

// A vertex of a polygon being clipped: barycentric in the input triangle and whether a cut created it.
struct PolygonVertex {
  Eigen::Vector3d b;
  bool cut = false;
};

using Polygon = std::vector<PolygonVertex>;

// Sutherland-Hodgman against g(b) >= 0 for affine g; a vertex exactly on the line is kept once.
Polygon clip(const Polygon& polygon, const Eigen::Vector3d& g) {
  Polygon out;
  const std::size_t n = polygon.size();
  for (std::size_t i = 0; i < n; ++i) {
    const PolygonVertex& p = polygon[i];
    const PolygonVertex& q = polygon[(i + 1) % n];
    const double gp = g.dot(p.b), gq = g.dot(q.b);
    if (gp >= 0.0) out.push_back(p);
    if ((gp > 0.0 && gq < 0.0) || (gp < 0.0 && gq > 0.0)) {
      const double t = gp / (gp - gq);
      out.push_back({(1.0 - t) * p.b + t * q.b, true});
    }
  }
  return out;
}

double polygon_area2(const Polygon& polygon) {
  double area = 0.0;
  for (std::size_t i = 0; i < polygon.size(); ++i) {
    const Eigen::Vector3d& p = polygon[i].b;
    const Eigen::Vector3d& q = polygon[(i + 1) % polygon.size()].b;
    area += p(1) * q(2) - p(2) * q(1);
  }
  return std::abs(area);
}

class TopologicalPass {
 public:
  TopologicalPass(const SliceMesh& slice, const Eigen::MatrixXd& slice_labels, const TetMesh4& mesh,
                  const std::function<Eigen::Vector3d(int)>& label_of, double threshold, double diagonal,
                  const std::vector<char>& relabelled)
      : slice_(slice),
        slice_labels_(slice_labels),
        mesh_(mesh),
        label_of_(label_of),
        threshold_(threshold),
        quantum_(1e-10 * diagonal),
        relabelled_(relabelled) {
    const Eigen::Index nv = slice.V.rows();
    for (Eigen::Index v = 0; v < nv; ++v) out_.positions.emplace_back(slice.V.row(v).transpose());
    original_vertex_.assign(std::size_t(nv), -1);
  }

  LabelledMesh run(bool enabled, SeamResult& result) {
    for (Eigen::Index f = 0; f < slice_.F.rows(); ++f) {
      const int tet = slice_.source_tet[std::size_t(f)];
      if (!enabled || repaired_whole(f) || !split_face(f, tet, result)) {
        std::array<int, 3> face{};
        for (int k = 0; k < 3; ++k) face[std::size_t(k)] = original(slice_.F(f, k));
        add_face(face, int(f));
      }
    }
    out_.cut_position.assign(out_.positions.size(), 0);
    for (const auto& e : out_.cut_edges)
      for (const int p : e) out_.cut_position[std::size_t(p)] = 1;
    return std::move(out_);
  }

 private:
  int original(int v) {
    int& id = original_vertex_[std::size_t(v)];
    if (id < 0) id = new_vertex(v, slice_labels_.row(v).transpose());
    return id;
  }

  int new_vertex(int position, const Eigen::Vector3d& label) {
    out_.vertex_position.push_back(position);
    out_.vertex_label.push_back(label);
    return int(out_.vertex_label.size()) - 1;
  }

  // One vertex per (position, label): both triangles beside a cut reach the same vertex from the same side.
  int vertex_at(int position, const Eigen::Vector3d& label) {
    const auto key = std::make_tuple(position, std::llround(label(0) / quantum_), std::llround(label(1) / quantum_),
                                     std::llround(label(2) / quantum_));
    const auto [it, inserted] = vertex_of_.emplace(key, -1);
    if (inserted) it->second = new_vertex(position, label);
    return it->second;
  }

  void add_face(const std::array<int, 3>& face, int source) {
    if (face[0] == face[1] || face[1] == face[2] || face[2] == face[0]) return;
    out_.faces.push_back(face);
    out_.source_face.push_back(source);
  }

  // Whether face f's corners were all relabelled after the transport and its labels span no seam (see split_seams).
  bool repaired_whole(Eigen::Index f) const {
    if (relabelled_.empty()) return false;
    for (int k = 0; k < 3; ++k) {
      if (!relabelled_[std::size_t(slice_.F(f, k))]) return false;
      if ((slice_labels_.row(slice_.F(f, k)) - slice_labels_.row(slice_.F(f, (k + 1) % 3))).norm() > threshold_)
        return false;
    }
    return true;
  }

  // Cuts face f by the critical plane(s) of its source tet; false when the tet spans no seam.
  bool split_face(Eigen::Index f, int tet, SeamResult& result) {
    std::array<int, 4> q{};
    std::array<Eigen::Vector3d, 4> L;
    for (int i = 0; i < 4; ++i) {
      q[std::size_t(i)] = mesh_.T(tet, i);
      L[std::size_t(i)] = label_of_(q[std::size_t(i)]);
    }
    // Clusters by complete linkage: merge the closest groups while every pair across them is within the
    // threshold, so no cluster (and no piece, whose labels are convex combinations of one cluster's) spans it.
    std::array<std::array<double, 4>, 4> distance{};
    bool far = false;
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) {
        distance[std::size_t(i)][std::size_t(j)] = (L[std::size_t(i)] - L[std::size_t(j)]).norm();
        far = far || distance[std::size_t(i)][std::size_t(j)] > threshold_;
      }
    if (!far) return false;
    std::array<int, 4> group{0, 1, 2, 3};
    for (;;) {
      int best_a = -1, best_b = -1;
      double best = threshold_;
      for (int a = 0; a < 4; ++a)
        for (int b = a + 1; b < 4; ++b) {
          if (group[std::size_t(a)] != a || group[std::size_t(b)] != b) continue;  // a, b name their groups
          double linkage = 0.0;
          for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
              if (group[std::size_t(i)] == a && group[std::size_t(j)] == b)
                linkage = std::max(linkage, distance[std::size_t(i)][std::size_t(j)]);
          if (linkage <= best) best = linkage, best_a = a, best_b = b;
        }
      if (best_a < 0) break;
      for (int& g : group)
        if (g == best_b) g = best_a;
    }
    std::array<int, 4> cluster{};
    int cluster_count = 0;
    std::array<int, 4> number{-1, -1, -1, -1};
    for (int i = 0; i < 4; ++i) {
      int& n = number[std::size_t(group[std::size_t(i)])];
      if (n < 0) n = cluster_count++;
      cluster[std::size_t(i)] = n;
    }
    if (cluster_count < 2) return false;  // far pairs joined through a third vertex: no separable sides
    ++result.seam_tets;

    // Each corner's weights over the tet's vertices, from the mesh edge that holds it.
    std::array<Eigen::Vector4d, 3> beta;
    std::array<int, 3> corner{};
    for (int k = 0; k < 3; ++k) {
      const int v = slice_.F(f, k);
      corner[std::size_t(k)] = v;
      const int a = slice_.source_edge(v, 0), b = slice_.source_edge(v, 1);
      const double w = slice_.edge_weight(v);
      beta[std::size_t(k)].setZero();
      for (int i = 0; i < 4; ++i) {
        if (q[std::size_t(i)] == a) beta[std::size_t(k)](i) += a == b ? 1.0 : 1.0 - w;
        if (q[std::size_t(i)] == b && a != b) beta[std::size_t(k)](i) += w;
      }
      if (std::abs(beta[std::size_t(k)].sum() - 1.0) > 1e-9) return false;  // corner not on this tet: leave as is
    }
    // phi[c](k): share of cluster c in corner k's weights; affine over the triangle.
    std::vector<Eigen::Vector3d> phi(std::size_t(cluster_count), Eigen::Vector3d::Zero());
    for (int k = 0; k < 3; ++k)
      for (int i = 0; i < 4; ++i) phi[std::size_t(cluster[std::size_t(i)])](k) += beta[std::size_t(k)](i);

    int pieces = 0;
    for (int c = 0; c < cluster_count; ++c) {
      // The region where cluster c has the largest share; for two clusters, its side of the critical plane.
      Polygon polygon{{Eigen::Vector3d(1, 0, 0)}, {Eigen::Vector3d(0, 1, 0)}, {Eigen::Vector3d(0, 0, 1)}};
      for (int d = 0; d < cluster_count && polygon.size() >= 3; ++d)
        if (d != c) polygon = clip(polygon, phi[std::size_t(c)] - phi[std::size_t(d)]);
      if (polygon.size() < 3 || polygon_area2(polygon) < 1e-12) continue;
      ++pieces;
      std::vector<int> ids;
      std::vector<int> position_ids;
      for (const PolygonVertex& p : polygon) {
        const int position = position_of(p.b, corner, f);
        position_ids.push_back(position);
        // A corner whose whole mesh edge lies on this side keeps the slice's own label, as its neighbours do.
        int own = -1;
        for (int k = 0; k < 3; ++k)
          if (position == corner[std::size_t(k)]) {
            own = k;
            for (int i = 0; i < 4; ++i)
              if (beta[std::size_t(k)](i) != 0.0 && cluster[std::size_t(i)] != c) own = -1;
          }
        ids.push_back(own >= 0 ? original(position) : vertex_at(position, side_label(p.b, beta, cluster, c, L)));
      }
      for (std::size_t i = 0; i < polygon.size(); ++i) {
        const std::size_t j = (i + 1) % polygon.size();
        // An edge between two cut vertices lies on the critical plane unless both sit on one triangle edge.
        const bool same_edge = ((polygon[i].b.array() == 0.0) && (polygon[j].b.array() == 0.0)).any();
        if (polygon[i].cut && polygon[j].cut && !same_edge)
          out_.cut_edges.push_back({position_ids[i], position_ids[j]});
      }
      for (std::size_t i = 1; i + 1 < ids.size(); ++i) add_face({ids[0], ids[i], ids[i + 1]}, int(f));
    }
    if (pieces > 1) {
      ++result.topological_split;
      out_.split_faces.push_back({corner[0], corner[1], corner[2]});
    }
    return true;
  }

  // Label of a point (barycentric b in the triangle) seen from cluster c: the tet's weights renormalised
  // over c's vertices, so the label is a convex combination of labels from one side only.
  static Eigen::Vector3d side_label(const Eigen::Vector3d& b, const std::array<Eigen::Vector4d, 3>& beta,
                                    const std::array<int, 4>& cluster, int c, const std::array<Eigen::Vector3d, 4>& L) {
    const Eigen::Vector4d w = b(0) * beta[0] + b(1) * beta[1] + b(2) * beta[2];
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double total = 0.0;
    for (int i = 0; i < 4; ++i)
      if (cluster[std::size_t(i)] == c) {
        sum += w(i) * L[std::size_t(i)];
        total += w(i);
      }
    if (total <= 0.0) {  // only on a degenerate sliver: fall back to the cluster's mean
      int n = 0;
      sum.setZero();
      for (int i = 0; i < 4; ++i)
        if (cluster[std::size_t(i)] == c) sum += L[std::size_t(i)], ++n;
      return sum / double(std::max(n, 1));
    }
    return sum / total;
  }

  // Position id of a polygon vertex: an input corner, a point on an input edge (shared with the
  // neighbour, keyed by the edge's vertex ids and the parameter from the lower id), or a new interior point.
  int position_of(const Eigen::Vector3d& b, const std::array<int, 3>& corner, Eigen::Index face) {
    int nonzero = 0;
    for (int k = 0; k < 3; ++k) nonzero += b(k) != 0.0;
    for (int k = 0; k < 3; ++k)
      if (b(k) == 1.0 || (nonzero == 1 && b(k) != 0.0)) return corner[std::size_t(k)];
    Eigen::Vector3d x = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) x += b(k) * slice_.V.row(corner[std::size_t(k)]).transpose();
    if (nonzero == 2) {
      int i = -1, j = -1;
      for (int k = 0; k < 3; ++k)
        if (b(k) != 0.0) (i < 0 ? i : j) = k;
      int lo = corner[std::size_t(i)], hi = corner[std::size_t(j)];
      double s = b(j);
      if (lo > hi) std::swap(lo, hi), s = b(i);
      const auto key = std::make_tuple(lo, hi, std::llround(s * 1073741824.0));
      const auto [it, inserted] = position_on_edge_.emplace(key, -1);
      if (inserted) {
        it->second = int(out_.positions.size());
        out_.positions.push_back((1.0 - s) * slice_.V.row(lo).transpose() + s * slice_.V.row(hi).transpose());
      }
      return it->second;
    }
    // Inside the triangle (where three clusters meet): shared by the pieces of this triangle only.
    const auto key = std::make_tuple(face, std::llround(b(0) * 1073741824.0), std::llround(b(1) * 1073741824.0));
    const auto [it, inserted] = position_inside_.emplace(key, -1);
    if (inserted) {
      it->second = int(out_.positions.size());
      out_.positions.push_back(x);
    }
    return it->second;
  }

  const SliceMesh& slice_;
  const Eigen::MatrixXd& slice_labels_;
  const TetMesh4& mesh_;
  const std::function<Eigen::Vector3d(int)>& label_of_;
  double threshold_;
  double quantum_;
  const std::vector<char>& relabelled_;
  LabelledMesh out_;
  std::vector<int> original_vertex_;
  std::map<std::tuple<int, long long, long long, long long>, int> vertex_of_;
  std::map<std::tuple<int, int, long long>, int> position_on_edge_;
  std::map<std::tuple<Eigen::Index, long long, long long>, int> position_inside_;
};

// UV continuity between two faces of A: the same face, or faces sharing a vertex with the same UV there
// (an edge is a texture seam only when both its corners' UVs differ, so a cone corner such as the sphere's
// pole, where only one corner differs, does not count).
class Atlas {
 public:
  explicit Atlas(const Surface& A) : A_(A) {
    if (!A.has_uv()) return;
    const std::int64_t nv = A.V.rows();
    std::unordered_map<std::int64_t, int> half_edge;  // (a, b) -> 3 f + k, k the corner opposite the edge
    for (Eigen::Index f = 0; f < A.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) half_edge.emplace(A.F(f, (k + 1) % 3) * nv + A.F(f, (k + 2) % 3), int(3 * f + k));
    neighbour_.assign(std::size_t(3 * A.F.rows()), -1);
    for (Eigen::Index f = 0; f < A.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) {
        const int a = A.F(f, (k + 1) % 3), b = A.F(f, (k + 2) % 3);
        const auto it = half_edge.find(std::int64_t(b) * nv + a);
        if (it == half_edge.end()) continue;
        const int g = it->second / 3;
        if (!seam_between(int(f), g)) neighbour_[std::size_t(3 * f + k)] = g;
      }
  }

  // Faces sharing an edge are separated by a texture seam when the UVs differ at both shared corners.
  bool seam_between(int f, int g) const {
    int differing = 0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (A_.F(f, i) == A_.F(g, j) &&
            (A_.UV.row(A_.FUV(f, i)) - A_.UV.row(A_.FUV(g, j))).cwiseAbs().maxCoeff() > 1e-12)
          ++differing;
    return differing >= 2;
  }

  // From face f, walk across non-seam edges towards p (the edge opposite the most negative barycentric of
  // p's projection) until p projects inside the face, then descend to the neighbour whose closest point to p is
  // nearer while there is one: the face of f's chart that holds p's closest point. The projection walk alone
  // stops between two faces that each project p outside towards the other (a concave fold, where labels lie
  // off A, as in spot's head), short of the closest point: the UVs there under-estimated a triangle's image.
  int walk(int f, const Eigen::Vector3d& p) const {
    int previous = -1;
    for (int step = 0; step < 64; ++step) {
      const Eigen::Vector3d a = corner(f, 0), e1 = corner(f, 1) - a, e2 = corner(f, 2) - a, d = p - a;
      const double g11 = e1.squaredNorm(), g12 = e1.dot(e2), g22 = e2.squaredNorm();
      const double det = g11 * g22 - g12 * g12;
      if (!(det > 0.0)) break;
      const double u = (g22 * e1.dot(d) - g12 * e2.dot(d)) / det, v = (g11 * e2.dot(d) - g12 * e1.dot(d)) / det;
      const Eigen::Vector3d w(1.0 - u - v, u, v);
      Eigen::Index k = 0;
      if (w.minCoeff(&k) >= 0.0) break;
      const int g = neighbour_[std::size_t(3 * f + k)];
      if (g < 0 || g == previous) break;
      previous = f;
      f = g;
    }
    double best = squared_distance(f, p);
    for (int step = 0; step < 64; ++step) {
      int next = -1;
      for (int k = 0; k < 3; ++k) {
        const int g = neighbour_[std::size_t(3 * f + k)];
        if (g < 0) continue;
        const double d = squared_distance(g, p);
        if (d < best * (1.0 - 1e-12)) {
          best = d;
          next = g;
        }
      }
      if (next < 0) break;
      f = next;
    }
    return f;
  }

  double squared_distance(int f, const Eigen::Vector3d& p) const {
    const Eigen::Vector3d w = closest_barycentric(p, corner(f, 0), corner(f, 1), corner(f, 2));
    return (w(0) * corner(f, 0) + w(1) * corner(f, 1) + w(2) * corner(f, 2) - p).squaredNorm();
  }

  bool continuous(int fa, int fb) const {
    if (fa == fb) return true;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (A_.F(fa, i) == A_.F(fb, j) &&
            (A_.UV.row(A_.FUV(fa, i)) - A_.UV.row(A_.FUV(fb, j))).cwiseAbs().maxCoeff() <= 1e-12)
          return true;
    return false;
  }

  Eigen::Vector3d corner(int f, int k) const { return A_.V.row(A_.F(f, k)).transpose(); }

  // UV of the point of face f closest to label, and that point.
  Eigen::Vector2d uv_on(int f, const Eigen::Vector3d& label, Eigen::Vector3d& point) const {
    const Eigen::Vector3d w = closest_barycentric(label, corner(f, 0), corner(f, 1), corner(f, 2));
    point = w(0) * corner(f, 0) + w(1) * corner(f, 1) + w(2) * corner(f, 2);
    Eigen::Vector2d uv = Eigen::Vector2d::Zero();
    for (int k = 0; k < 3; ++k) uv += w(k) * A_.UV.row(A_.FUV(f, k)).transpose();
    return uv;
  }

 private:
  const Surface& A_;
  std::vector<int> neighbour_;  // 3 f + k: face across the edge opposite corner k, -1 across a seam
};

struct EdgeCrossings {
  std::vector<double> s;  // parameters from the lower vertex id, ascending
  bool unresolved = false;
};

// Where the label segment la -> lb crosses a texture seam of A (or a jump of the closest-point map):
// bisection between samples whose A faces are not UV-continuous.
EdgeCrossings find_crossings(const Eigen::Vector3d& la, const Eigen::Vector3d& lb, const SurfaceLocator& locator,
                             const Atlas& atlas, const SeamOptions& options) {
  EdgeCrossings out;
  auto face_at = [&](double s) { return locator.closest((1.0 - s) * la + s * lb).face; };
  struct Interval {
    double sa, sb;
    int fa, fb;
  };
  std::vector<Interval> stack{{0.0, 1.0, face_at(0.0), face_at(1.0)}};
  int queries = 2;
  while (!stack.empty()) {
    const Interval iv = stack.back();
    stack.pop_back();
    if (atlas.continuous(iv.fa, iv.fb)) continue;
    if (iv.sb - iv.sa <= options.crossing_tolerance) {
      out.s.push_back(0.5 * (iv.sa + iv.sb));
      continue;
    }
    if (queries >= options.max_queries_per_edge) {
      out.unresolved = true;
      continue;
    }
    const double sm = 0.5 * (iv.sa + iv.sb);
    const int fm = face_at(sm);
    ++queries;
    stack.push_back({sm, iv.sb, fm, iv.fb});  // right half below left: left is processed first
    stack.push_back({iv.sa, sm, iv.fa, fm});
  }
  return out;
}

}  // namespace

std::int64_t count_curves(const std::vector<std::array<int, 2>>& edges) {
  std::map<int, int> index;
  for (const auto& e : edges)
    for (const int v : e) index.emplace(v, int(index.size()));
  UnionFind uf(int(index.size()));
  for (const auto& e : edges) uf.unite(index[e[0]], index[e[1]]);
  std::int64_t curves = 0;
  for (int i = 0; i < int(index.size()); ++i) curves += uf.find(i) == i;
  return curves;
}

namespace {

/// An undirected edge as one 64-bit key (its lower vertex in the high word), and its hash (splitmix64's finaliser:
/// the identity hash of libstdc++ would put the keys of one vertex, which differ only in the low word, in
/// neighbouring buckets).
std::uint64_t edge_key(int a, int b) {
  return (std::uint64_t(std::uint32_t(std::min(a, b))) << 32) | std::uint32_t(std::max(a, b));
}
struct EdgeKeyHash {
  std::size_t operator()(std::uint64_t x) const {
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return std::size_t(x ^ (x >> 31));
  }
};

}  // namespace

SeamResult split_seams(const SliceMesh& slice, const TetMesh4& mesh, const Eigen::MatrixXd& labels, const Surface& A,
                       const SurfaceLocator& locator, const SeamOptions& options, const std::vector<char>& relabelled,
                       const Eigen::MatrixXd* closest_labels) {
  const auto start = Clock::now();
  if (slice.labels.rows() != slice.V.rows() || slice.labels.cols() != 3)
    throw InvalidInput("split_seams: the slice has no labels");
  if (labels.rows() != mesh.vertex_count() || labels.cols() != 3)
    throw InvalidInput("split_seams: labels must be #mesh.V by 3");
  if (slice.source_tet.size() != std::size_t(slice.F.rows()) || slice.source_edge.rows() != slice.V.rows())
    throw InvalidInput("split_seams: the slice lacks provenance (source_tet, source_edge)");
  if (!relabelled.empty() && relabelled.size() != std::size_t(slice.V.rows()))
    throw InvalidInput("split_seams: relabelled must have one flag per slice vertex");
  if (closest_labels != nullptr && (closest_labels->rows() != slice.V.rows() || closest_labels->cols() != 3))
    throw InvalidInput("split_seams: closest_labels must be #slice.V by 3");

  SeamResult result;
  const double diagonal = bounding_box(A.V).diagonal().norm();
  // Labels are compared and interpolated as their closest points on A: transport leaves a band of labels
  // inside A where trajectories from both sides of a seam met (interpolated between the poles, §8.1's
  // "erroneous" labels); on A they fall to one side or the other, which makes the two populations separate.
  const Eigen::MatrixXd slice_labels =
      closest_labels != nullptr ? *closest_labels : points_of(locator.closest_all(slice.labels));
  // The closest points on A of the labels at the vertices of the faces' source tets, which the topological pass
  // reads: queried up front, in parallel and in vertex order, instead of one by one as that serial pass met them
  // (half of the seam stage's time on cow -> horse, with the other core idle). The same hits (closest_all). A slice
  // vertex that is a mesh vertex carrying that vertex's label (B's vertices on the target) has its closest point in
  // closest_labels already: 18.5 k of cow -> horse's 28 k queries.
  std::vector<int> projected_row;
  Eigen::MatrixXd projected;
  if (options.topological) {
    const std::size_t nv = std::size_t(mesh.vertex_count());
    projected_row.assign(nv, -1);
    for (const int t : slice.source_tet)
      for (int k = 0; k < 4; ++k) projected_row[std::size_t(mesh.T(t, k))] = 0;
    std::vector<int> known(nv, -1);  // the slice vertex whose closest label is this mesh vertex's
    if (closest_labels != nullptr)
      for (Eigen::Index i = 0; i < slice.V.rows(); ++i) {
        const int v = slice.source_edge(i, 0);
        if (v == slice.source_edge(i, 1) && projected_row[std::size_t(v)] == 0 && labels.row(v) == slice.labels.row(i))
          known[std::size_t(v)] = int(i);
      }
    Eigen::Index rows = 0;
    std::vector<int> query_vertex;
    for (std::size_t v = 0; v < nv; ++v) {
      if (projected_row[v] < 0) continue;
      projected_row[v] = int(rows++);
      if (known[v] < 0) query_vertex.push_back(int(v));
    }
    Eigen::MatrixXd queries(Eigen::Index(query_vertex.size()), 3);
    for (std::size_t q = 0; q < query_vertex.size(); ++q) queries.row(Eigen::Index(q)) = labels.row(query_vertex[q]);
    const Eigen::MatrixXd found = points_of(locator.closest_all(queries));
    projected.resize(rows, 3);
    for (std::size_t q = 0; q < query_vertex.size(); ++q)
      projected.row(projected_row[std::size_t(query_vertex[q])]) = found.row(Eigen::Index(q));
    for (std::size_t v = 0; v < nv; ++v)
      if (known[v] >= 0) projected.row(projected_row[v]) = closest_labels->row(known[v]);
  }
  const std::function<Eigen::Vector3d(int)> label_of = [&](int v) {
    return Eigen::Vector3d(projected.row(projected_row[std::size_t(v)]).transpose());
  };
  result.threshold = options.label_threshold * diagonal;
  result.span_bin_edges = {0.0, 0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.4, 0.5, 0.75, 1.0};
  result.span_histogram.assign(result.span_bin_edges.size(), 0);
  for (Eigen::Index f = 0; f < slice.F.rows(); ++f) {
    const double span =
        max_span(slice_labels.row(slice.F(f, 0)).transpose(), slice_labels.row(slice.F(f, 1)).transpose(),
                 slice_labels.row(slice.F(f, 2)).transpose()) /
        diagonal;
    std::size_t bin = 0;
    while (bin + 1 < result.span_bin_edges.size() && span >= result.span_bin_edges[bin + 1]) ++bin;
    ++result.span_histogram[bin];
  }

  // Topological pass.
  LabelledMesh mid = TopologicalPass(slice, slice_labels, mesh, label_of, result.threshold, diagonal, relabelled)
                         .run(options.topological, result);
  result.topological_seam_curves = count_curves(mid.cut_edges);
  {
    // Regions: cut triangles joined through shared corners. Where a neck pinches off, the labels around the
    // pinch point come from the whole waist ring, and the cuts there form a star of short curves; a region
    // counts it once.
    std::vector<std::array<int, 2>> links;
    for (const auto& f : mid.split_faces)
      for (int k = 0; k < 3; ++k) links.push_back({f[std::size_t(k)], f[std::size_t((k + 1) % 3)]});
    result.topological_seam_regions = count_curves(links);
  }
  {
    std::vector<int> points;
    for (std::size_t p = 0; p < mid.positions.size(); ++p)
      if (mid.cut_position[p]) points.push_back(int(p));
    result.topological_seam_points.resize(Eigen::Index(points.size()), 3);
    for (std::size_t i = 0; i < points.size(); ++i)
      result.topological_seam_points.row(Eigen::Index(i)) = mid.positions[std::size_t(points[i])].transpose();
  }

  // Output vertices start as the labelled mesh's vertices; texture cuts append shared vertices.
  std::vector<Eigen::Vector3d> positions, vertex_labels;
  for (std::size_t v = 0; v < mid.vertex_label.size(); ++v) {
    positions.push_back(mid.positions[std::size_t(mid.vertex_position[v])]);
    vertex_labels.push_back(mid.vertex_label[v]);
  }
  std::vector<std::array<int, 3>> faces;
  std::vector<int> source_face;
  const bool with_uv = A.has_uv();
  const Atlas atlas(A);

  if (with_uv && options.texture) {
    // Unique edges, their crossings in parallel (each edge alone, so the result is thread-independent). The edge
    // tables are hashed, not ordered: only looked up, never walked, so their order changes nothing (the Buddha's seam
    // stage 0.068 -> 0.063 s against std::map, medians of 5 interleaved runs; target.obj byte-identical).
    std::unordered_map<std::uint64_t, int, EdgeKeyHash> edge_index;
    edge_index.reserve(3 * mid.faces.size());
    std::vector<std::pair<int, int>> edges;
    for (const auto& f : mid.faces)
      for (int k = 0; k < 3; ++k) {
        const int a = f[std::size_t(k)], b = f[std::size_t((k + 1) % 3)];
        const auto key = std::minmax(a, b);
        if (edge_index.emplace(edge_key(key.first, key.second), int(edges.size())).second) edges.push_back(key);
      }
    std::vector<EdgeCrossings> crossings(edges.size());
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, edges.size(), 64), [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t e = r.begin(); e != r.end(); ++e)
            crossings[e] = find_crossings(vertex_labels[std::size_t(edges[e].first)],
                                          vertex_labels[std::size_t(edges[e].second)], locator, atlas, options);
        });
    // Crossing vertices of every edge (ordered from its lower vertex id, with their parameters from it), keyed
    // by (lower id, higher id). Edges made by splitting join as they appear.
    struct EdgeSplit {
      std::vector<int> vertices;
      std::vector<double> s;
    };
    // References to its entries stay valid while it grows (split_of returns one).
    std::unordered_map<std::uint64_t, EdgeSplit, EdgeKeyHash> edge_splits;
    edge_splits.reserve(6 * mid.faces.size());
    auto add_vertex = [&](int lo, int hi, double s) {
      positions.push_back((1.0 - s) * positions[std::size_t(lo)] + s * positions[std::size_t(hi)]);
      vertex_labels.push_back((1.0 - s) * vertex_labels[std::size_t(lo)] + s * vertex_labels[std::size_t(hi)]);
      return int(positions.size()) - 1;
    };
    for (std::size_t e = 0; e < edges.size(); ++e) {
      result.texture_crossings += std::int64_t(crossings[e].s.size());
      result.unresolved_edges += crossings[e].unresolved;
      EdgeSplit& split = edge_splits[edge_key(edges[e].first, edges[e].second)];
      for (const double s : crossings[e].s) {
        split.vertices.push_back(add_vertex(edges[e].first, edges[e].second, s));
        split.s.push_back(s);
      }
    }
    // A cut, or a piece of an edge between consecutive crossings, crosses nothing by construction: testing it
    // again would only find its own end points' seams.
    auto mark_clean = [&](int a, int b) { edge_splits.emplace(edge_key(a, b), EdgeSplit{}); };
    // Edges inside an input triangle (fan spokes and diagonals) are tested when first used: the label map is
    // affine over the triangle but the seams and closest-point jumps it pulls back from A are curves, which
    // can cross a spoke although they enter and leave through the crossings the spoke's fan was built from.
    auto split_of = [&](int a, int b) -> const EdgeSplit& {
      const std::pair<int, int> key(std::min(a, b), std::max(a, b));
      const auto it = edge_splits.find(edge_key(key.first, key.second));
      if (it != edge_splits.end()) return it->second;
      const EdgeCrossings c = find_crossings(vertex_labels[std::size_t(key.first)],
                                             vertex_labels[std::size_t(key.second)], locator, atlas, options);
      result.unresolved_edges += c.unresolved;
      EdgeSplit split;
      for (const double s : c.s) {
        // An end point on a seam (a crossing vertex) shows its own seam within rounding of the bisection.
        if (s < options.corner_margin || s > 1.0 - options.corner_margin) continue;
        ++result.texture_crossings;
        split.vertices.push_back(add_vertex(key.first, key.second, s));
        split.s.push_back(s);
      }
      return edge_splits.emplace(edge_key(key.first, key.second), std::move(split)).first->second;
    };

    std::vector<std::array<int, 2>> texture_edges;
    // Splits triangle c (depth 0: an input triangle, deeper: one of its pieces) at the crossings of its edges,
    // and each piece again until its edges cross nothing.
    std::function<void(const std::array<int, 3>&, int, int)> split_piece = [&](const std::array<int, 3>& c, int source,
                                                                               int depth) {
      // The last level's edges are its parent's cuts, pieces of its parent's edges or edges shared only with
      // its siblings, so keeping it untested leaves no crossing vertex unused on a neighbour's edge.
      if (depth >= options.max_split_depth) {
        if (c[0] != c[1] && c[1] != c[2] && c[2] != c[0]) {
          faces.push_back(c);
          source_face.push_back(source);
        }
        return;
      }
      // Boundary of the triangle with the crossings in order, and the triangle-barycentric of every point.
      std::vector<int> ring;
      std::vector<Eigen::Vector3d> ring_b;
      std::vector<int> crossing_at;  // positions in `ring` that are crossings
      std::vector<int> crossing_edge;
      for (int k = 0; k < 3; ++k) {
        const int a = c[std::size_t(k)], b = c[std::size_t((k + 1) % 3)];
        ring.push_back(a);
        ring_b.push_back(Eigen::Vector3d::Unit(k));
        const EdgeSplit& split = split_of(a, b);
        const int n = int(split.s.size());
        for (int i = 0; i < n; ++i) {
          const int idx = a < b ? i : n - 1 - i;  // walk from a to b
          const double s = a < b ? split.s[std::size_t(idx)] : 1.0 - split.s[std::size_t(idx)];
          crossing_at.push_back(int(ring.size()));
          crossing_edge.push_back(k);
          ring.push_back(split.vertices[std::size_t(idx)]);
          ring_b.push_back((1.0 - s) * Eigen::Vector3d::Unit(k) + s * Eigen::Vector3d::Unit((k + 1) % 3));
        }
      }
      const std::size_t m = ring.size();
      if (crossing_at.empty()) {
        if (c[0] != c[1] && c[1] != c[2] && c[2] != c[0]) {
          faces.push_back(c);
          source_face.push_back(source);
        }
        return;
      }
      if (depth == 0) ++result.texture_split;
      for (std::size_t i = 0; i < m; ++i) mark_clean(ring[i], ring[(i + 1) % m]);
      auto piece = [&](int a, int b, int d) { split_piece({a, b, d}, source, depth + 1); };
      if (crossing_at.size() == 2 && crossing_edge[0] != crossing_edge[1]) {
        // One seam through the triangle: cut along the chord between the two crossings, fan each side.
        const int x = crossing_at[0], y = crossing_at[1];
        mark_clean(ring[std::size_t(x)], ring[std::size_t(y)]);
        for (const auto& [from, to] : {std::pair<int, int>{x, y}, std::pair<int, int>{y, x + int(m)}})
          for (int i = from + 1; i < to; ++i)
            piece(ring[std::size_t(from) % m], ring[std::size_t(i) % m], ring[std::size_t(i + 1) % m]);
        texture_edges.push_back({ring[std::size_t(x)], ring[std::size_t(y)]});
        return;
      }
      if (depth > 0 && crossing_at.size() == 1) {
        // A piece's corners are mostly crossings, on a seam: one entering through an edge of the piece leaves
        // through the opposite corner (the piece's other edges cross nothing), so the cut ends there.
        const int x = crossing_at[0], k = crossing_edge[0];
        const int p = ring[std::size_t(x)], opposite = c[std::size_t((k + 2) % 3)];
        mark_clean(p, opposite);
        piece(c[std::size_t(k)], p, opposite);
        piece(p, c[std::size_t((k + 1) % 3)], opposite);
        texture_edges.push_back({p, opposite});
        return;
      }
      // Seam ends, junctions or a seam leaving through the edge it entered: fan from a point inside.
      if (depth == 0) ++result.texture_fan_splits;
      Eigen::Vector3d b = Eigen::Vector3d::Zero();
      for (const int i : crossing_at) b += ring_b[std::size_t(i)];
      b = 0.5 * b / double(crossing_at.size()) + Eigen::Vector3d::Constant(0.5 / 3.0);  // strictly inside
      Eigen::Vector3d x = Eigen::Vector3d::Zero(), l = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) {
        x += b(k) * positions[std::size_t(c[std::size_t(k)])];
        l += b(k) * vertex_labels[std::size_t(c[std::size_t(k)])];
      }
      const int center = int(positions.size());
      positions.push_back(x);
      vertex_labels.push_back(l);
      for (const int i : crossing_at) texture_edges.push_back({center, ring[std::size_t(i)]});
      for (std::size_t i = 0; i < m; ++i) piece(center, ring[i], ring[(i + 1) % m]);
    };
    for (std::size_t f = 0; f < mid.faces.size(); ++f) split_piece(mid.faces[f], mid.source_face[f], 0);
    result.texture_seam_curves = count_curves(texture_edges);
  } else {
    faces = mid.faces;
    source_face = mid.source_face;
  }

  const Eigen::Index nv = Eigen::Index(positions.size()), nf = Eigen::Index(faces.size());
  result.V.resize(nv, 3);
  result.labels.resize(nv, 3);
  for (Eigen::Index v = 0; v < nv; ++v) {
    result.V.row(v) = positions[std::size_t(v)].transpose();
    result.labels.row(v) = vertex_labels[std::size_t(v)].transpose();
  }
  result.F.resize(nf, 3);
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) result.F(f, k) = faces[std::size_t(f)][std::size_t(k)];
  result.source_face = std::move(source_face);
  for (Eigen::Index f = 0; f < nf; ++f)
    if (max_span(result.labels.row(result.F(f, 0)).transpose(), result.labels.row(result.F(f, 1)).transpose(),
                 result.labels.row(result.F(f, 2)).transpose()) > result.threshold)
      ++result.spans_over_threshold;

  if (with_uv) {
    auto uv_area = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
      return 0.5 * std::abs((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
    };
    auto uv_in_chart = [&](int home, const Eigen::Vector3d& label) {
      Eigen::Vector3d point;
      return atlas.uv_on(atlas.walk(home, label), label, point);
    };
    // UV area of the triangle's true image: the triangle subdivided 4 x 4, every sample's UV taken in the
    // home chart. It is curved where A's UVs are not affine (near the sphere's poles), where a flat UV
    // triangle may legitimately differ from it.
    auto image_uv_area = [&](const std::array<Eigen::Vector3d, 3>& l, int home) {
      constexpr int n = 4;
      Eigen::Vector2d sample[n + 1][n + 1];
      for (int i = 0; i <= n; ++i)
        for (int j = 0; i + j <= n; ++j)
          sample[i][j] = uv_in_chart(home, (double(i) * l[0] + double(j) * l[1] + double(n - i - j) * l[2]) / n);
      double area = 0.0;
      for (int i = 0; i < n; ++i)
        for (int j = 0; i + j < n; ++j) {
          area += uv_area(sample[i][j], sample[i + 1][j], sample[i][j + 1]);
          if (i + j + 1 < n) area += uv_area(sample[i + 1][j], sample[i + 1][j + 1], sample[i][j + 1]);
        }
      return area;
    };

    // Every corner takes its UV in the chart of the A face under its triangle's centroid (walking across
    // non-seam edges only), so no triangle mixes charts, also when a corner lies exactly on a seam.
    result.UV.resize(3 * nf, 2);
    result.FUV.resize(nf, 3);
    std::vector<double> uv(static_cast<std::size_t>(nf)), pre(static_cast<std::size_t>(nf));
    tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, nf, 256), [&](const tbb::blocked_range<Eigen::Index>& r) {
      for (Eigen::Index f = r.begin(); f != r.end(); ++f) {
        std::array<Eigen::Vector3d, 3> l;
        for (int k = 0; k < 3; ++k) l[std::size_t(k)] = result.labels.row(result.F(f, k)).transpose();
        const int home = locator.closest((l[0] + l[1] + l[2]) / 3.0).face;
        for (int k = 0; k < 3; ++k) {
          result.UV.row(3 * f + k) = uv_in_chart(home, l[std::size_t(k)]).transpose();
          result.FUV(f, k) = int(3 * f + k);
        }
        uv[std::size_t(f)] = uv_area(result.UV.row(3 * f), result.UV.row(3 * f + 1), result.UV.row(3 * f + 2));
        pre[std::size_t(f)] = image_uv_area(l, home);
      }
    });
    double mean_pre = 0.0;
    for (const double a : pre) mean_pre += a / double(pre.size());
    result.mean_preimage_uv_area = mean_pre;
    // A triangle across a seam covers a strip of the atlas, tens of mean triangles.
    auto over_by = [&](double uv_f, double pre_f, double tolerance) {
      return uv_f > pre_f + tolerance * std::max(pre_f, mean_pre) + options.uv_area_epsilon;
    };
    auto over = [&](double uv_f, double pre_f) { return over_by(uv_f, pre_f, options.uv_area_tolerance); };
    result.tolerance_sweep = {0.5, 1.0, 2.0, 4.0, 8.0, 16.0};
    result.uv_area_excess_sweep.assign(result.tolerance_sweep.size(), 0);
    result.uv_area_excess_unsplit_sweep.assign(result.tolerance_sweep.size(), 0);
    for (std::size_t t = 0; t < result.tolerance_sweep.size(); ++t)
      for (std::size_t f = 0; f < uv.size(); ++f)
        result.uv_area_excess_sweep[t] += over_by(uv[f], pre[f], result.tolerance_sweep[t]);
    for (Eigen::Index f = 0; f < nf; ++f) {
      if (over(uv[std::size_t(f)], pre[std::size_t(f)])) result.uv_area_excess_faces.push_back(int(f));
      if (pre[std::size_t(f)] > 0.0)
        result.max_uv_area_ratio = std::max(result.max_uv_area_ratio, uv[std::size_t(f)] / pre[std::size_t(f)]);
    }
    result.uv_area_excess = std::int64_t(result.uv_area_excess_faces.size());

    // The same measure before any seam handling: per-vertex closest-point UVs on the input triangles.
    const std::vector<SurfaceHit> hits = locator.closest_all(slice.labels);
    const Eigen::MatrixXd vertex_uv = uv_at(A, hits);
    std::vector<double> unsplit_uv(std::size_t(slice.F.rows())), unsplit_pre(std::size_t(slice.F.rows()));
    tbb::parallel_for(
        tbb::blocked_range<Eigen::Index>(0, slice.F.rows(), 256), [&](const tbb::blocked_range<Eigen::Index>& r) {
          for (Eigen::Index f = r.begin(); f != r.end(); ++f) {
            std::array<Eigen::Vector3d, 3> l;
            for (int k = 0; k < 3; ++k) l[std::size_t(k)] = hits[std::size_t(slice.F(f, k))].point;
            const int home = locator.closest((l[0] + l[1] + l[2]) / 3.0).face;
            const double a =
                uv_area(vertex_uv.row(slice.F(f, 0)), vertex_uv.row(slice.F(f, 1)), vertex_uv.row(slice.F(f, 2)));
            unsplit_uv[std::size_t(f)] = a;
            unsplit_pre[std::size_t(f)] = image_uv_area(l, home);
          }
        });
    for (std::size_t f = 0; f < unsplit_uv.size(); ++f) {
      result.uv_area_excess_unsplit += over(unsplit_uv[f], unsplit_pre[f]);
      for (std::size_t t = 0; t < result.tolerance_sweep.size(); ++t)
        result.uv_area_excess_unsplit_sweep[t] += over_by(unsplit_uv[f], unsplit_pre[f], result.tolerance_sweep[t]);
    }
  }
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace morphmap
