// Fold repair of the label map (see untangle.h). Written by hand: libigl and CGAL untangle or parameterise whole
// disks with fixed boundaries in the plane; none repairs patches of a map into a curved surface in place, keeping
// the rest of the map, which is what the morph's correspondence needs.
#include "mesh/untangle.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <Eigen/Sparse>
#include <Eigen/SparseLU>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include "mesh/chart_untangle.h"
#include "mesh/errors.h"
#include "mesh/metrics.h"

namespace morphmap {

namespace {

enum : char { kGood = 0, kFolded = 1, kCollapsed = 2, kSeam = 3 };

bool bad(char state) { return state == kFolded || state == kCollapsed; }

/// Triangles of each vertex (compressed rows).
struct VertexFaces {
  std::vector<int> start, faces;
  VertexFaces(const TriIndices& F, Eigen::Index vertex_count) : start(std::size_t(vertex_count) + 1, 0) {
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) ++start[std::size_t(F(f, k)) + 1];
    std::partial_sum(start.begin(), start.end(), start.begin());
    faces.resize(std::size_t(start.back()));
    std::vector<int> cursor(start.begin(), start.end() - 1);
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) faces[std::size_t(cursor[std::size_t(F(f, k))]++)] = int(f);
  }
  int begin(int v) const { return start[std::size_t(v)]; }
  int end(int v) const { return start[std::size_t(v) + 1]; }
  int face(int j) const { return faces[std::size_t(j)]; }
};

/// Signed area of the triangle (0, a, b) in a chart.
double area(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return 0.5 * (a.x() * b.y() - a.y() * b.x()); }

/// A vertex's triangles in the chart of its label: the tangent plane of A there, origin at the label. a[k], b[k]
/// are the other corners of its k-th triangle, counter-clockwise after it. The smoothing also keeps each
/// triangle's shape on B (scaled to A's area) and whether it is positive in the chart.
struct Ring {
  Eigen::Vector3d origin, e1, e2;
  std::vector<Eigen::Vector2d> a, b;
  std::vector<Eigen::Matrix2d> inverse_shape;  // P^-1, P the triangle's B edges from the vertex in its own plane
  std::vector<double> shape_det, shape_area;
  std::vector<char> active;
  std::vector<char> seam;  // the triangle spans a topological seam: outside the energy, its corners maybe off the chart
};

/// The position x that maximises the smallest signed area of the triangles (x, a_k, b_k), each area c_k + g_k . x
/// linear in x: the best of the points where three areas are equal (the maximum of a minimum of linear functions
/// lies at a vertex of their upper envelope, bounded here since the areas of a closed ring sum to a constant).
/// `best` starts at the current position; returns the smallest area at the result.
double max_min_area(const Ring& ring, Eigen::Vector2d& best) {
  const std::size_t m = ring.a.size();
  std::vector<Eigen::Vector2d> g(m);
  std::vector<double> c(m);
  for (std::size_t k = 0; k < m; ++k) {
    // 2 area(x, a, b) = (a - x) x (b - x) = a x b + x . (a_y - b_y, b_x - a_x)
    c[k] = area(ring.a[k], ring.b[k]);
    g[k] = 0.5 * Eigen::Vector2d(ring.a[k].y() - ring.b[k].y(), ring.b[k].x() - ring.a[k].x());
  }
  auto smallest = [&](const Eigen::Vector2d& x) {
    double low = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < m; ++k) low = std::min(low, c[k] + g[k].dot(x));
    return low;
  };
  double best_value = smallest(best);
  for (std::size_t i = 0; i < m; ++i)
    for (std::size_t j = i + 1; j < m; ++j)
      for (std::size_t l = j + 1; l < m; ++l) {
        Eigen::Matrix2d M;
        M.row(0) = (g[i] - g[j]).transpose();
        M.row(1) = (g[i] - g[l]).transpose();
        if (!(std::abs(M.determinant()) > 1e-300)) continue;
        const Eigen::Vector2d x = M.inverse() * Eigen::Vector2d(c[j] - c[i], c[l] - c[i]);
        if (!x.allFinite()) continue;
        const double value = smallest(x);
        if (value > best_value) {
          best_value = value;
          best = x;
        }
      }
  return best_value;
}

/// Symmetric Dirichlet energy of the active triangles' maps from B (scaled) to the chart with the vertex at x,
/// area(B)-weighted: |J|^2 + |J^-1|^2, which grows without bound as a triangle flattens (infinite once one is not
/// positive). With `gradient`, also its gradient and a bound of its curvature along any direction, for the step.
double dirichlet(const Ring& ring, const Eigen::Vector2d& x, Eigen::Vector2d* gradient, double* curvature,
                 Eigen::Matrix2d* hessian = nullptr) {
  double total = 0.0;
  if (hessian) hessian->setZero();
  if (gradient) gradient->setZero();
  if (curvature) *curvature = 0.0;
  for (std::size_t k = 0; k < ring.a.size(); ++k) {
    if (!ring.active[k]) continue;
    Eigen::Matrix2d Q;
    Q.col(0) = ring.a[k] - x;
    Q.col(1) = ring.b[k] - x;
    const double d = Q.determinant();
    if (!(d > 0.0)) return std::numeric_limits<double>::infinity();
    const Eigen::Matrix2d J = Q * ring.inverse_shape[k];
    // det J = d / det P, and |J^-1|^2 = |J|^2 / det(J)^2 for 2 by 2.
    const double N = J.squaredNorm(), ratio = ring.shape_det[k] * ring.shape_det[k] / (d * d);
    const double w = ring.shape_area[k];
    total += w * N * (1.0 + ratio);
    if (gradient) {
      // J = J0 - x m^T with m the column sums of P^-1; grad d from d = (a - x) x (b - x).
      const Eigen::Vector2d m = ring.inverse_shape[k].row(0).transpose() + ring.inverse_shape[k].row(1).transpose();
      const Eigen::Vector2d grad_d(ring.a[k].y() - ring.b[k].y(), ring.b[k].x() - ring.a[k].x());
      const Eigen::Vector2d grad_n = -2.0 * (J * m);  // of N = |J|^2
      *gradient += w * (grad_n * (1.0 + ratio) - 2.0 * N * ratio / d * grad_d);
      if (curvature)
        *curvature += w * (2.0 * m.squaredNorm() * (1.0 + ratio) + 6.0 * N * ratio / (d * d) * grad_d.squaredNorm());
      if (hessian) {
        *hessian += w * (2.0 * m.squaredNorm() * (1.0 + ratio) * Eigen::Matrix2d::Identity() -
                         2.0 * ratio / d * (grad_n * grad_d.transpose() + grad_d * grad_n.transpose()) +
                         6.0 * N * ratio / (d * d) * grad_d * grad_d.transpose());
      }
    }
  }
  return total;
}

class Untangler {
 public:
  Untangler(const Surface& A, const SurfaceLocator& locator, const Eigen::MatrixXd& V, const TriIndices& F,
            Eigen::MatrixXd& labels, const UntangleOptions& options)
      : A_(A), locator_(locator), V_(V), F_(F), labels_(labels), options_(options), vf_(F, V.rows()) {}

  UntangleResult run() {
    UntangleResult result;
    const Eigen::Index nf = F_.rows();
    classify_all();
    auto count = [&](char which) { return std::int64_t(std::count(state_.begin(), state_.end(), which)); };
    result.folded_before = count(kFolded);
    result.collapsed_before = count(kCollapsed);
    result.seam_triangles = count(kSeam);
    const std::vector<int> stretched = stretched_faces();
    result.stretched_before = std::int64_t(stretched.size());
    const std::int64_t seams_to_heal = options_.heal_seams && options_.rebuild_patches ? result.seam_triangles : 0;
    if (!options_.enabled ||
        result.folded_before + result.collapsed_before + result.stretched_before + seams_to_heal == 0) {
      if (options_.enabled && options_.compression_seed > 0.0) {
        // Only compression to relieve, maybe: relieve_compression() needs what the repair sets up.
        prepare();
        relieve_compression(result);
        result.vertices_moved = std::int64_t(std::count(moved_.begin(), moved_.end(), char(1)));
      }
      result.folded_after = result.folded_before;
      result.collapsed_after = result.collapsed_before;
      result.seam_triangles_after = result.seam_triangles;
      return result;
    }
    prepare();
    std::vector<int> rebuilt;
    if (options_.rebuild_patches) rebuilt = rebuild_patches(result);

    // The region: the bad triangles' vertices and `rings` rings around them, growing by `grow_rings` a round
    // while rounds right enough triangles; the rebuilt patches' inner vertices join it for the smoothing.
    for (const int v : rebuilt)
      if (!in_region_[std::size_t(v)]) {
        in_region_[std::size_t(v)] = 1;
        frontier_.push_back(v);
      }
    for (Eigen::Index f = 0; f < nf; ++f)
      if (bad(state_[std::size_t(f)]))
        for (int k = 0; k < 3; ++k) {
          const int v = F_(f, k);
          if (in_region_[std::size_t(v)] || wall_[std::size_t(v)]) continue;
          in_region_[std::size_t(v)] = 1;
          frontier_.push_back(v);
        }
    region_ = frontier_;
    grow(options_.rings);

    // Untangling (local optimisation, Freitag and Plassmann 2000): each vertex with an inverted or nearly flat
    // triangle moves to where its smallest triangle is largest.
    std::int64_t previous = result.folded_before + result.collapsed_before;
    for (int round = 0; round < options_.max_rounds && !region_.empty(); ++round) {
      result.rounds = round + 1;
      const auto classes = colour_classes();
      const std::vector<char> everyone(std::size_t(V_.rows()), 1);
      for (int sweep = 0; sweep < options_.sweeps; ++sweep) {
        ++result.sweeps;
        const std::int64_t moves =
            run_sweep(classes, everyone, nullptr, [&](int v, Ring& ring) { return untangle_vertex(v, ring); });
        result.moves += moves;
        if (moves == 0) break;
      }
      const std::int64_t now = reclassify_region();
      // Growing on pays only while rounds right triangles (where B has handles, some folds are forced).
      if (now == 0 || double(now) > (1.0 - options_.min_round_gain) * double(previous)) break;
      previous = now;
      grow(options_.grow_rings);
    }
    // Stretched triangles join the smoothing (not the untangling: nothing is inverted there). Where some stay
    // stretched, their corners join in another round, seam vertices among them freed one round at a time.
    std::vector<int> seeds = stretched;
    for (int round = 0; round < std::max(1, options_.stretch_rounds); ++round) {
      if (round > 0) {
        reclassify_region();
        const std::size_t before = seeds.size();
        seeds = stretched_faces();
        // Another round pays only while rounds spread most of what they seed (a squeezed part born during the morph
        // stays squeezed: cow -> horse's legs, 3915 of 4407 stretched triangles left after the first round).
        if (seeds.empty() || double(seeds.size()) > options_.stretch_round_fraction * double(before)) break;
        frontier_.clear();
      }
      for (const int f : seeds)
        for (int k = 0; k < 3; ++k) {
          const int v = F_(f, k);
          if (options_.smooth_seam_sides) wall_[std::size_t(v)] = 0;
          if (in_region_[std::size_t(v)] || wall_[std::size_t(v)]) continue;
          in_region_[std::size_t(v)] = 1;
          region_.push_back(v);
          frontier_.push_back(v);
        }
      grow(options_.smoothing_rings);
      smooth(result, result.seams_healed > 0 ? options_.healed_smoothing_sweeps : options_.smoothing_sweeps);
    }
    relieve_compression(result);
    result.region_vertices = std::int64_t(region_.size());
    reclassify_region();
    result.stretched_after = std::int64_t(stretched_faces().size());
    result.folded_after = count(kFolded);
    result.seam_triangles_after = count(kSeam);
    result.collapsed_after = count(kCollapsed);
    result.vertices_moved = std::int64_t(std::count(moved_.begin(), moved_.end(), char(1)));
    return result;
  }

 private:
  /// What the untangling, the smoothing and the relief read: the walls (vertices of seam triangles), each label's
  /// face, B's shapes and A's unit normals, the area scale, A's centre and reach.
  void prepare() {
    const Eigen::Index nv = V_.rows(), nf = F_.rows();
    // Vertices of seam triangles stay where they are: the seam split reads their labels on either side.
    wall_.assign(std::size_t(nv), 0);
    for (Eigen::Index f = 0; f < nf; ++f)
      if (state_[std::size_t(f)] == kSeam)
        for (int k = 0; k < 3; ++k) wall_[std::size_t(F_(f, k))] = 1;
    moved_.assign(std::size_t(nv), 0);
    face_of_.resize(std::size_t(nv));
    shapes_.resize(vf_.faces.size());
    shape_state_.assign(std::size_t(nv), 0);
    unit_normal_.resize(std::size_t(A_.F.rows()));
    tbb::parallel_for(Eigen::Index(0), A_.F.rows(),
                      [&](Eigen::Index f) { unit_normal_[std::size_t(f)] = face_normal(int(f)).normalized(); });
    const std::vector<SurfaceHit> hits = locator_.closest_all(labels_);
    for (Eigen::Index v = 0; v < nv; ++v) face_of_[std::size_t(v)] = hits[std::size_t(v)].face;
    scale_ = std::sqrt(surface_area(A_.V, A_.F) / surface_area(V_, F_.cast<int>()));
    centre_ = A_.V.colwise().mean().transpose();
    reach_ = 2.0 * bounding_box(A_.V).diagonal().norm();
    in_region_.assign(std::size_t(nv), 0);
  }

  /// Smoothing: symmetric Dirichlet descent, vertex by vertex, of the triangles positive in each chart; no step
  /// that keeps them positive folds one, and the squeezed patches the untangling righted spread out.
  /// Each sweep visits only the vertices next to one that moved in the sweep before: the patches far from the
  /// squeezed ones settle within a few sweeps, and those take many.
  void smooth(UntangleResult& result, int sweeps) {
    const auto classes = colour_classes();
    std::vector<char> active(std::size_t(V_.rows()), 1), next(std::size_t(V_.rows()), 0);
    for (int sweep = 0; sweep < sweeps; ++sweep) {
      const std::int64_t moves =
          run_sweep(classes, active, &next, [&](int v, Ring& ring) { return smooth_vertex(v, ring); });
      result.smoothing_moves += moves;
      ++result.smoothing_sweeps;
      if (moves == 0) break;
      active.swap(next);
      std::fill(next.begin(), next.end(), 0);
    }
  }

  /// The good triangles whose L2 stretch exceeds UntangleOptions::stretch_seed, in order.
  std::vector<int> stretched_faces() const {
    std::vector<int> faces;
    if (!(options_.stretch_seed > 0.0)) return faces;
    const Eigen::VectorXd l2 = stretch_per_triangle(A_, V_, F_, labels_, {options_.collapse_ratio});
    for (Eigen::Index f = 0; f < F_.rows(); ++f)
      if (state_[std::size_t(f)] == kGood && l2(f) > options_.stretch_seed) faces.push_back(int(f));
    return faces;
  }

  /// Unnormalised outward normal of A's face f.
  Eigen::Vector3d face_normal(int f) const {
    const Eigen::Vector3d a0 = A_.V.row(A_.F(f, 0)), a1 = A_.V.row(A_.F(f, 1)), a2 = A_.V.row(A_.F(f, 2));
    return (a1 - a0).cross(a2 - a0);
  }

  /// DESIGN.md's tests as measure_stretch applies them: collapsed below collapse_ratio times the mean preimage
  /// area, folded when the preimage's normal opposes that of A's face nearest its centroid.
  char classify(Eigen::Index f) const {
    const Eigen::Vector3d p0 = labels_.row(F_(f, 0)), p1 = labels_.row(F_(f, 1)), p2 = labels_.row(F_(f, 2));
    const Eigen::Vector3d n = (p1 - p0).cross(p2 - p0);
    if (!(0.5 * n.norm() > collapse_area_)) return kCollapsed;
    return n.dot(face_normal(locator_.closest((p0 + p1 + p2) / 3.0).face)) < 0.0 ? kFolded : kGood;
  }

  /// Whether triangle f's labels lie farther apart than the seam threshold (the seam split cuts it).
  bool spans_seam(Eigen::Index f) const {
    const Eigen::Vector3d p0 = labels_.row(F_(f, 0)), p1 = labels_.row(F_(f, 1)), p2 = labels_.row(F_(f, 2));
    return (p1 - p0).norm() > seam_length_ || (p2 - p1).norm() > seam_length_ || (p0 - p2).norm() > seam_length_;
  }

  void classify_all() {
    const Eigen::Index nf = F_.rows();
    seam_length_ = options_.seam_threshold * bounding_box(A_.V).diagonal().norm();
    state_.assign(std::size_t(nf), kGood);
    double area_sum = 0.0;
    for (Eigen::Index f = 0; f < nf; ++f) {
      const Eigen::Vector3d p0 = labels_.row(F_(f, 0)), p1 = labels_.row(F_(f, 1)), p2 = labels_.row(F_(f, 2));
      area_sum += 0.5 * (p1 - p0).cross(p2 - p0).norm();
      if (spans_seam(f)) state_[std::size_t(f)] = kSeam;
    }
    collapse_area_ = options_.collapse_ratio * area_sum / double(std::max<Eigen::Index>(nf, 1));
    tbb::parallel_for(Eigen::Index(0), nf, [&](Eigen::Index f) {
      if (state_[std::size_t(f)] != kSeam) state_[std::size_t(f)] = classify(f);
    });
  }

  /// The triangles of the given vertices, sorted, each once.
  std::vector<int> faces_around(const std::vector<int>& vertices) const {
    std::vector<int> faces;
    for (const int v : vertices)
      for (int j = vf_.begin(v); j < vf_.end(v); ++j) faces.push_back(vf_.face(j));
    std::sort(faces.begin(), faces.end());
    faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
    return faces;
  }

  /// Classifies the triangles of the region's vertices again; returns the bad triangles of B.
  std::int64_t reclassify_region() {
    const std::vector<int> faces = faces_around(region_);
    tbb::parallel_for(std::size_t(0), faces.size(), [&](std::size_t i) {
      if (state_[std::size_t(faces[i])] != kSeam) state_[std::size_t(faces[i])] = classify(faces[i]);
    });
    return std::int64_t(std::count_if(state_.begin(), state_.end(), bad));
  }

  void grow(int rings) {
    const std::int64_t limit = std::int64_t(options_.max_region_fraction * double(V_.rows()));
    for (int ring = 0; ring < rings && std::int64_t(region_.size()) < limit; ++ring) {
      std::vector<int> next;
      for (const int v : frontier_)
        for (int j = vf_.begin(v); j < vf_.end(v); ++j) {
          const int f = vf_.face(j);
          if (state_[std::size_t(f)] == kSeam) continue;
          for (int k = 0; k < 3; ++k) {
            const int u = F_(f, k);
            if (in_region_[std::size_t(u)] || wall_[std::size_t(u)]) continue;
            in_region_[std::size_t(u)] = 1;
            next.push_back(u);
          }
        }
      region_.insert(region_.end(), next.begin(), next.end());
      frontier_ = std::move(next);
    }
    std::sort(region_.begin(), region_.end());
  }

  /// The region's vertices by colour, greedily in vertex order: no two of a class share a triangle, so a class
  /// moves in parallel with each vertex seeing the same neighbours as in any order, and the result does not depend
  /// on the thread count.
  std::vector<std::vector<int>> colour_classes() const {
    std::vector<int> colour(std::size_t(V_.rows()), -1);
    std::vector<std::vector<int>> classes;
    std::vector<char> taken;
    for (const int v : region_) {
      taken.assign(classes.size() + 1, 0);
      for (int j = vf_.begin(v); j < vf_.end(v); ++j)
        for (int k = 0; k < 3; ++k) {
          const int c = colour[std::size_t(F_(vf_.face(j), k))];
          if (c >= 0) taken[std::size_t(c)] = 1;
        }
      const int c = int(std::find(taken.begin(), taken.end(), 0) - taken.begin());
      colour[std::size_t(v)] = c;
      if (c == int(classes.size())) classes.emplace_back();
      classes[std::size_t(c)].push_back(v);
    }
    return classes;
  }

  /// One sweep over the vertices of `classes` with active[v] set: each class in parallel, the classes in order.
  /// step(v, ring) returns whether v moved (enough to count). The vertices sharing a triangle with one that moved
  /// are set in `next` (when given), the active set of the next sweep. Returns the moves.
  template <class Step>
  std::int64_t run_sweep(const std::vector<std::vector<int>>& classes, const std::vector<char>& active,
                         std::vector<char>* next, const Step& step) {
    std::int64_t moves = 0;
    for (const std::vector<int>& members : classes) {
      std::vector<char> moved(members.size(), 0);
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, members.size(), 64),
                        [&](const tbb::blocked_range<std::size_t>& range) {
                          Ring ring;
                          for (std::size_t i = range.begin(); i < range.end(); ++i)
                            if (active[std::size_t(members[i])]) moved[i] = step(members[i], ring) ? 1 : 0;
                        });
      for (std::size_t i = 0; i < members.size(); ++i) {
        if (!moved[i]) continue;
        ++moves;
        if (!next) continue;
        const int v = members[i];
        for (int j = vf_.begin(v); j < vf_.end(v); ++j)
          for (int k = 0; k < 3; ++k) (*next)[std::size_t(F_(vf_.face(j), k))] = 1;
      }
    }
    return moves;
  }

  /// u's label in the plane through `origin` normal to the unit `axis`, entered along u's own A normal (the inverse of
  /// the closest-point lift that takes a point of the plane back to A), in the plane's axes e1, e2; false where that
  /// normal turns away from the axis (no chart holds u).
  bool to_chart(int u, const Eigen::Vector3d& origin, const Eigen::Vector3d& axis, const Eigen::Vector3d& e1,
                const Eigen::Vector3d& e2, Eigen::Vector2d& out) const {
    const Eigen::Vector3d q = labels_.row(u).transpose();
    const Eigen::Vector3d& n = unit_normal_[std::size_t(face_of_[std::size_t(u)])];
    const double along = n.dot(axis);
    const Eigen::Vector3d x = q + ((origin - q).dot(axis) / along) * n - origin;
    out = Eigen::Vector2d(x.dot(e1), x.dot(e2));
    return along > 0.2;
  }

  /// The point of A for chart point x (origin + x(0) e1 + x(1) e2): its closest point, except where that is a
  /// vertex or an edge of A and x lies off A: outside a convex A the closest point maps a whole cone (a wedge) of
  /// the plane onto one vertex (edge), and two vertices moved there took one label (sphere -> bunny at 32 voxels:
  /// two labels 8e-16 apart, max stretch 4e9). There A is crossed along the chart's axis instead, nearest the plane.
  SurfaceHit lift(const Eigen::Vector3d& origin, const Eigen::Vector3d& e1, const Eigen::Vector3d& e2,
                  const Eigen::Vector2d& x, int hint) const {
    const Eigen::Vector3d point = origin + x.x() * e1 + x.y() * e2;
    const SurfaceHit hit = locator_.closest_near(point, hint);
    if (!(hit.barycentric.minCoeff() <= 0.0) || !(hit.distance > 0.0)) return hit;
    const Eigen::Vector3d axis = e1.cross(e2);
    const double reach = 2.0 * (hit.distance + x.norm());
    const Eigen::Vector3d a = point + reach * axis, b = point - reach * axis;
    double best = -1.0;
    for (const double t : locator_.crossings(a, b, 8, 1e-9))
      if (best < 0.0 || std::abs(t - 0.5) < std::abs(best - 0.5)) best = t;
    return best < 0.0 ? hit : locator_.closest_near(a + best * (b - a), hit.face);
  }

  /// Fills ring.a and ring.b for v; false where a corner's A normal turns away from v's (no chart holds them). The
  /// corners enter the plane along their own A normals, the inverse of the closest-point lift that takes a point
  /// of the plane back to A.
  bool chart(int v, Ring& ring) const {
    ring.origin = labels_.row(v).transpose();
    const Eigen::Vector3d axis = unit_normal_[std::size_t(face_of_[std::size_t(v)])];
    ring.e1 = axis.unitOrthogonal();
    ring.e2 = axis.cross(ring.e1);
    ring.a.clear();
    ring.b.clear();
    ring.seam.clear();
    bool ok = true;
    for (int j = vf_.begin(v); j < vf_.end(v) && ok; ++j) {
      const int f = vf_.face(j);
      int k = 0;
      while (F_(f, k) != v) ++k;
      Eigen::Vector2d a = Eigen::Vector2d::Zero(), b = Eigen::Vector2d::Zero();
      const bool seam = state_[std::size_t(f)] == kSeam;
      ok = to_chart(F_(f, (k + 1) % 3), ring.origin, axis, ring.e1, ring.e2, a) &&
           to_chart(F_(f, (k + 2) % 3), ring.origin, axis, ring.e1, ring.e2, b);
      ok = ok || seam;
      ring.a.push_back(a);
      ring.b.push_back(b);
      ring.seam.push_back(seam);
    }
    return ok;
  }

  /// The point of A for v's chart point x (see lift).
  SurfaceHit lifted(int v, const Ring& ring, const Eigen::Vector2d& x) const {
    return lift(ring.origin, ring.e1, ring.e2, x, face_of_[std::size_t(v)]);
  }

  void move(int v, const SurfaceHit& hit) {
    labels_.row(v) = hit.point.transpose();
    face_of_[std::size_t(v)] = hit.face;
    moved_[std::size_t(v)] = 1;
  }

  bool untangle_vertex(int v, Ring& ring) {
    if (!chart(v, ring)) return false;
    double now = std::numeric_limits<double>::infinity(), largest = 0.0, sum = 0.0;
    int inverted = 0;
    for (std::size_t k = 0; k < ring.a.size(); ++k) {
      const double s = area(ring.a[k], ring.b[k]);
      now = std::min(now, s);
      largest = std::max(largest, std::abs(s));
      sum += s;
      inverted += s <= 0.0;
    }
    // Only a vertex with an inverted or nearly flat triangle (in its chart, or by the exact test of the last
    // classification: a long triangle can be positive in the chart of one corner) moves; the rest of the map stays
    // the morph's.
    bool flagged = false;
    for (int j = vf_.begin(v); j < vf_.end(v); ++j) flagged = flagged || bad(state_[std::size_t(vf_.face(j))]);
    if (!flagged && !(now <= options_.flat_fraction * sum / double(ring.a.size()))) return false;
    Eigen::Vector2d x = Eigen::Vector2d::Zero();
    const double best = max_min_area(ring, x);
    if (!(best > now + 1e-9 * largest)) return false;
    int inverted_after = 0;
    for (std::size_t k = 0; k < ring.a.size(); ++k) inverted_after += area(ring.a[k] - x, ring.b[k] - x) <= 0.0;
    if (inverted_after > inverted) return false;
    move(v, lifted(v, ring, x));
    return true;
  }

  /// True when v moved by more than a thousandth of its ring's size (smaller steps are convergence).
  bool smooth_vertex(int v, Ring& ring) {
    if (!chart(v, ring)) return false;
    if (!shapes_of(v)) return false;
    ring.inverse_shape.clear();
    ring.shape_det.clear();
    ring.shape_area.clear();
    ring.active.clear();
    double ring_area = 0.0;
    for (int j = vf_.begin(v); j < vf_.end(v); ++j) {
      const Shape& shape = shapes_[std::size_t(j)];
      ring.inverse_shape.push_back(shape.inverse);
      ring.shape_det.push_back(shape.det);
      ring.shape_area.push_back(shape.area);
      const std::size_t i = ring.active.size();
      // Triangles the untangling could not right are left out, so that their neighbours can still spread.
      ring.active.push_back(area(ring.a[i], ring.b[i]) > 0.0 && !ring.seam[i]);
      if (!ring.seam[i]) ring_area += std::abs(area(ring.a[i], ring.b[i]));
    }
    Eigen::Vector2d gradient;
    double curvature = 0.0;
    Eigen::Matrix2d hessian;
    const double now = dirichlet(ring, Eigen::Vector2d::Zero(), &gradient, &curvature, newton_ ? &hessian : nullptr);
    if (!std::isfinite(now) || !(curvature > 0.0)) return false;
    Eigen::Vector2d step = -gradient / curvature;
    // Newton's step where the relief asks for it (relieve_compression): the curvature bound is that of the stiffest
    // direction, and a fan squeezed in one direction barely moves under it. Only where the Hessian is positive
    // definite; the line search below keeps the energy falling either way.
    if (newton_) {
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(hessian);
      if (eigen.eigenvalues()(0) > 0.0) {
        const Eigen::Vector2d newton = -eigen.eigenvectors() * (eigen.eigenvalues().cwiseInverse().asDiagonal() *
                                                                (eigen.eigenvectors().transpose() * gradient));
        if (newton.allFinite()) step = newton;
      }
    }
    for (int halving = 0; halving < 20; ++halving, step *= 0.5) {
      if (!(dirichlet(ring, step, nullptr, nullptr) < now - 1e-4 * gradient.dot(-step))) continue;
      // A triangle left out of the energy (not positive) must not become a sliver: positive but far below its
      // ring's mean, where it would count as a triangle of extreme stretch instead of a collapsed one.
      bool sliver = false;
      for (std::size_t k = 0; k < ring.a.size() && !sliver; ++k) {
        if (ring.active[k] || ring.seam[k]) continue;
        const double after = area(ring.a[k] - step, ring.b[k] - step);
        sliver = after > 0.0 && after < options_.flat_fraction * ring_area / double(ring.a.size());
      }
      if (sliver) continue;
      const SurfaceHit to = lifted(v, ring, step);
      if (crosses_seam(v, ring, to)) continue;
      move(v, to);
      return step.squaredNorm() > options_.smoothing_tolerance * ring_area / double(ring.a.size());
    }
    return false;
  }

  /// Whether moving v to `to` (its step lifted to A) turns one of its seam triangles, positive on A, over: v would
  /// cross the far side's edge, and the two sides of the seam would cover the same part of A (the smoothing leaves seam
  /// triangles out of its energy, so nothing else holds a side back).
  bool crosses_seam(int v, const Ring& ring, const SurfaceHit& to) const {
    std::size_t k = 0;
    for (int j = vf_.begin(v); j < vf_.end(v); ++j, ++k) {
      if (!ring.seam[k]) continue;
      const int f = vf_.face(j);
      int i = 0;
      while (F_(f, i) != v) ++i;
      const int u = F_(f, (i + 1) % 3), w = F_(f, (i + 2) % 3);
      const Eigen::Vector3d a = labels_.row(u).transpose(), b = labels_.row(w).transpose();
      // A's normal for a triangle this large: the sum of the unit normals at its corners. The closest face to its
      // centroid, which lies deep inside A, is a search that visits most of A's faces (on sphere -> torus, 10 s).
      const Eigen::Vector3d corners =
          unit_normal_[std::size_t(face_of_[std::size_t(u)])] + unit_normal_[std::size_t(face_of_[std::size_t(w)])];
      auto positive = [&](const Eigen::Vector3d& x, int face) {
        return (a - x).cross(b - x).dot(corners + unit_normal_[std::size_t(face)]) > 0.0;
      };
      if (positive(labels_.row(v).transpose(), face_of_[std::size_t(v)]) && !positive(to.point, to.face)) return true;
    }
    return false;
  }

  /// The shapes of v's triangles on B (scaled to A's area) in their own planes, for the smoothing's energy: computed
  /// at v's first visit (a vertex is smoothed hundreds of times; only v's entries are written, so a colour class can
  /// run in parallel). False when one of them is degenerate.
  bool shapes_of(int v) {
    char& state = shape_state_[std::size_t(v)];
    if (state == 0) {
      state = 1;
      for (int j = vf_.begin(v); j < vf_.end(v) && state == 1; ++j) {
        const int f = vf_.face(j);
        int k = 0;
        while (F_(f, k) != v) ++k;
        const Eigen::Vector3d e = scale_ * (V_.row(F_(f, (k + 1) % 3)) - V_.row(v)).transpose();
        const Eigen::Vector3d g = scale_ * (V_.row(F_(f, (k + 2) % 3)) - V_.row(v)).transpose();
        const double length = e.norm(), cross = e.cross(g).norm();
        if (!(length > 0.0) || !(cross > 0.0)) {
          state = 2;
          break;
        }
        Eigen::Matrix2d P;
        P << length, e.dot(g) / length, 0.0, cross / length;
        shapes_[std::size_t(j)] = {P.inverse(), P.determinant(), 0.5 * cross};
      }
    }
    return state == 1;
  }

  /// Adds to the patch (`inside`, flagged in `member`) every part of B that the patch cuts off from the largest part
  /// outside it, so that rings around an ear's base take the ear beyond them and make a disk, not an annulus. Each
  /// part beside the patch is explored only up to `limit` vertices (a larger one could not join it anyway), so the
  /// cost is that of the small parts, not of B.
  void enclose(std::vector<int>& inside, std::vector<char>& member, std::int64_t limit) {
    if (part_of_.size() != std::size_t(V_.rows())) part_of_.assign(std::size_t(V_.rows()), -1);
    std::vector<std::vector<int>> parts;
    std::vector<char> large;
    for (std::size_t a = 0, n = inside.size(); a < n; ++a)
      for (int j = vf_.begin(inside[a]); j < vf_.end(inside[a]); ++j)
        for (int k = 0; k < 3; ++k) {
          const int start = F_(vf_.face(j), k);
          if (member[std::size_t(start)] || part_of_[std::size_t(start)] >= 0) continue;
          const int id = int(parts.size());
          parts.emplace_back(std::vector<int>{start});
          large.push_back(0);
          part_of_[std::size_t(start)] = id;
          for (std::size_t next = 0; next < parts.back().size() && !large.back(); ++next) {
            const int v = parts.back()[next];
            for (int i = vf_.begin(v); i < vf_.end(v) && !large.back(); ++i)
              for (int m = 0; m < 3; ++m) {
                const int u = F_(vf_.face(i), m);
                if (member[std::size_t(u)] || part_of_[std::size_t(u)] == id) continue;
                // A vertex of an earlier part: the two are one, and that one was large (or this would be it).
                if (part_of_[std::size_t(u)] >= 0 || std::int64_t(parts.back().size()) >= limit) {
                  large.back() = 1;
                  break;
                }
                part_of_[std::size_t(u)] = id;
                parts.back().push_back(u);
              }
          }
        }
    std::size_t keep = parts.size();  // the part that stays outside when none is large (a small component of B)
    if (std::find(large.begin(), large.end(), char(1)) == large.end())
      for (std::size_t c = 0; c < parts.size(); ++c)
        if (keep == parts.size() || parts[c].size() > parts[keep].size()) keep = c;
    for (std::size_t c = 0; c < parts.size(); ++c) {
      if (!large[c] && c != keep) {
        for (const int u : parts[c]) member[std::size_t(u)] = 1;
        inside.insert(inside.end(), parts[c].begin(), parts[c].end());
      }
    }
    for (const std::vector<int>& part : parts)
      for (const int u : part) part_of_[std::size_t(u)] = -1;
  }

  /// The cluster of triangles `flagged` that holds f0, joined through shared vertices: its vertices, in the order
  /// found. `tried` (per triangle) marks the cluster's triangles; `seen` (per vertex) is all zero before and after.
  /// visit(f) is called for each of its triangles.
  template <class Flagged, class Visit>
  std::vector<int> cluster_of(int f0, Flagged&& flagged, std::vector<char>& tried, std::vector<char>& seen,
                              Visit&& visit) const {
    std::vector<int> vertices, stack{f0};
    tried[std::size_t(f0)] = 1;
    while (!stack.empty()) {
      const int f = stack.back();
      stack.pop_back();
      visit(f);
      for (int k = 0; k < 3; ++k) {
        const int v = F_(f, k);
        if (seen[std::size_t(v)]) continue;
        seen[std::size_t(v)] = 1;
        vertices.push_back(v);
        for (int j = vf_.begin(v); j < vf_.end(v); ++j) {
          const int g = vf_.face(j);
          if (flagged(g) && !tried[std::size_t(g)]) {
            tried[std::size_t(g)] = 1;
            stack.push_back(g);
          }
        }
      }
    }
    for (const int v : vertices) seen[std::size_t(v)] = 0;
    return vertices;
  }

  /// Adds the ring of B's vertices around `frontier` to `inside` (flagged in `member`); the ring becomes the frontier.
  void add_ring(std::vector<int>& frontier, std::vector<char>& member, std::vector<int>& inside) const {
    std::vector<int> next;
    for (const int v : frontier)
      for (int j = vf_.begin(v); j < vf_.end(v); ++j)
        for (int k = 0; k < 3; ++k) {
          const int u = F_(vf_.face(j), k);
          if (member[std::size_t(u)]) continue;
          member[std::size_t(u)] = 1;
          next.push_back(u);
        }
    inside.insert(inside.end(), next.begin(), next.end());
    frontier = std::move(next);
  }

  /// Whether a patch of this many rings is tried: at patch_rings, then at each doubling (2, 4, 8 rings by default).
  bool tried_at(int rings) const {
    const int doublings = rings / options_.patch_rings;
    return rings >= options_.patch_rings && rings % options_.patch_rings == 0 && (doublings & (doublings - 1)) == 0;
  }

  /// The triangles with every corner in the patch (`inside`, flagged in `member`), sorted.
  std::vector<int> faces_within(const std::vector<int>& inside, const std::vector<char>& member) const {
    std::vector<int> faces;
    for (const int v : inside)
      for (int j = vf_.begin(v); j < vf_.end(v); ++j) {
        const int f = vf_.face(j);
        if (member[std::size_t(F_(f, 0))] && member[std::size_t(F_(f, 1))] && member[std::size_t(F_(f, 2))])
          faces.push_back(f);
      }
    std::sort(faces.begin(), faces.end());
    faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
    return faces;
  }

  /// Normalised singular values (DESIGN.md) of triangle f's map from its labels on A to B: (sigma1, sigma2), NaN
  /// where its labels are flat.
  Eigen::Vector2d singular_values(int f) const {
    Eigen::Matrix<double, 3, 2> Ep, Eq;
    for (int k = 1; k < 3; ++k) {
      Ep.col(k - 1) = (labels_.row(F_(f, k)) - labels_.row(F_(f, 0))).transpose();
      Eq.col(k - 1) = (V_.row(F_(f, k)) - V_.row(F_(f, 0))).transpose();
    }
    return scale_ * triangle_singular_values(Ep, Eq);
  }

  /// DESIGN.md's figures over some triangles (those with flat labels left out): the smallest sigma2, the largest
  /// sigma1 and the B-area-weighted mean of L2.
  struct Figures {
    double smallest = std::numeric_limits<double>::infinity(), largest = 0.0, mean_l2 = 0.0;
  };
  Figures figures(const std::vector<int>& faces) const {
    Figures out;
    double weight = 0.0;
    for (const int f : faces) {
      const Eigen::Vector2d sigma = singular_values(f);
      if (!sigma.allFinite()) continue;
      out.smallest = std::min(out.smallest, sigma(1));
      out.largest = std::max(out.largest, sigma(0));
      const Eigen::Vector3d b0 = V_.row(F_(f, 0)), b1 = V_.row(F_(f, 1)), b2 = V_.row(F_(f, 2));
      const double area_b = (b1 - b0).cross(b2 - b0).norm();
      out.mean_l2 += area_b * std::sqrt(0.5 * sigma.squaredNorm());
      weight += area_b;
    }
    if (weight > 0.0) out.mean_l2 /= weight;
    return out;
  }

  /// Some vertices' labels as they were (label, face of A, whether moved), for a trial the relief may undo.
  struct Snapshot {
    std::vector<int> vertices;
    Eigen::MatrixX3d labels;
    std::vector<int> faces;
    std::vector<char> moved;
  };
  Snapshot snapshot(const std::vector<int>& vertices) const {
    Snapshot out{vertices, Eigen::MatrixX3d(Eigen::Index(vertices.size()), 3), {}, {}};
    for (std::size_t i = 0; i < vertices.size(); ++i) {
      out.labels.row(Eigen::Index(i)) = labels_.row(vertices[i]);
      out.faces.push_back(face_of_[std::size_t(vertices[i])]);
      out.moved.push_back(moved_[std::size_t(vertices[i])]);
    }
    return out;
  }
  void restore(const Snapshot& saved) {
    for (std::size_t i = 0; i < saved.vertices.size(); ++i) {
      const int v = saved.vertices[i];
      labels_.row(v) = saved.labels.row(Eigen::Index(i));
      face_of_[std::size_t(v)] = saved.faces[i];
      moved_[std::size_t(v)] = saved.moved[i];
    }
  }

  /// Largest singular value of a 2 by 2 matrix, and (in `smallest`) its smallest.
  static double singular_pair(const Eigen::Matrix2d& M, double& smallest) {
    const double frobenius2 = M.squaredNorm(), det = M.determinant();
    const double root = std::sqrt(std::max(0.0, frobenius2 * frobenius2 - 4.0 * det * det));
    smallest = std::sqrt(std::max(0.0, 0.5 * (frobenius2 - root)));
    return std::sqrt(0.5 * (frobenius2 + root));
  }

  /// The worst compression of v's triangles with v at chart point x: the largest singular value of their maps from B
  /// (scaled) to the chart, i.e. 1 / sigma2 of DESIGN.md's map; `stretch` gets the largest 1 / (smallest singular
  /// value), DESIGN.md's sigma1. Infinite when a triangle is not positive.
  double worst_compression(const Ring& ring, const Eigen::Vector2d& x, double& stretch) const {
    double worst = 0.0;
    stretch = 0.0;
    for (std::size_t k = 0; k < ring.a.size(); ++k) {
      Eigen::Matrix2d Q;
      Q.col(0) = ring.a[k] - x;
      Q.col(1) = ring.b[k] - x;
      if (!(Q.determinant() > 0.0)) return std::numeric_limits<double>::infinity();
      double smallest = 0.0;
      worst = std::max(worst, singular_pair(Q * ring.inverse_shape[k], smallest));
      stretch = std::max(stretch, 1.0 / smallest);
    }
    return worst;
  }

  /// Moves v to where the worst compression of its triangles is least (compass search in its chart: the largest
  /// singular value of an affine map is convex in v's position, and so is their maximum), while their largest
  /// stretch stays at most max(now, 1 / compression_seed); checked again on A after the lift. True when v moved.
  bool relieve_vertex(int v, Ring& ring) {
    if (!chart(v, ring) || !shapes_of(v)) return false;
    ring.inverse_shape.clear();
    for (int j = vf_.begin(v); j < vf_.end(v); ++j) ring.inverse_shape.push_back(shapes_[std::size_t(j)].inverse);
    for (const char seam : ring.seam)
      if (seam) return false;
    double stretch_now = 0.0;
    const double now = worst_compression(ring, Eigen::Vector2d::Zero(), stretch_now);
    // Only while a triangle is compressed beyond the seed: the search targets the worst triangle alone, and moving
    // further than that costs the others' stretch.
    const double enough = 1.0 / options_.compression_seed;
    if (!std::isfinite(now) || now <= enough) return false;
    const double stretch_limit = std::max(stretch_now, 1.0 / options_.compression_seed);
    // The first step: a quarter of the distance to the nearest opposite edge, so that the search starts inside the
    // ring's kernel.
    double reach = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < ring.a.size(); ++k) {
      const Eigen::Vector2d edge = ring.b[k] - ring.a[k];
      if (!(edge.norm() > 0.0)) return false;
      reach = std::min(reach, std::abs(2.0 * area(ring.a[k], ring.b[k])) / edge.norm());
    }
    const double first = 0.25 * reach;
    Eigen::Vector2d x = Eigen::Vector2d::Zero();
    double best = now;
    const double diagonal = std::sqrt(0.5);
    const std::array<Eigen::Vector2d, 8> directions{{{1.0, 0.0},
                                                     {diagonal, diagonal},
                                                     {0.0, 1.0},
                                                     {-diagonal, diagonal},
                                                     {-1.0, 0.0},
                                                     {-diagonal, -diagonal},
                                                     {0.0, -1.0},
                                                     {diagonal, -diagonal}}};
    for (double step = first; step > 1e-3 * first && best > enough;) {
      bool improved = false;
      for (const Eigen::Vector2d& direction : directions) {
        const Eigen::Vector2d y = x + step * direction;
        double stretch = 0.0;
        const double value = worst_compression(ring, y, stretch);
        if (value < best * (1.0 - 1e-9) && stretch <= stretch_limit) {
          x = y;
          best = value;
          improved = true;
        }
      }
      if (!improved) step *= 0.5;
    }
    if (!(best < now * (1.0 - 1e-6))) return false;
    // The exact figures on A, before and after the lift.
    const Figures before = vertex_figures(v);
    const Snapshot saved = snapshot({v});
    // The chart's figures differ from A's by a little: where A's refuse the move, a shorter one (which the convexity
    // above still makes better, if by less) is tried.
    for (int shorter = 0; shorter < 4; ++shorter, x *= 0.5) {
      move(v, lifted(v, ring, x));
      bool good = true;
      for (int j = vf_.begin(v); j < vf_.end(v) && good; ++j)
        good = !spans_seam(vf_.face(j)) && classify(vf_.face(j)) == kGood;
      const Figures after = vertex_figures(v);
      if (good && after.smallest > before.smallest &&
          after.largest <= std::max(before.largest, 1.0 / options_.compression_seed))
        return true;
      restore(saved);
    }
    return false;
  }

  Figures vertex_figures(int v) const { return figures(faces_around({v})); }

  /// Relief of compression (UntangleOptions::compression_seed). The vertices of good triangles whose sigma2 is below
  /// the seed, with compression_rings rings, first descend the symmetric Dirichlet energy with Newton steps (the
  /// smoothing's curvature bound is that of the stiffest direction, and a fan squeezed in one direction barely moves
  /// under it), then each moves to where its worst triangle is least compressed (relieve_vertex), sweep after sweep
  /// in index order while any moves. Each connected part of the region is judged on its own (relieve_part) and put
  /// back unless its figures improve: where the map must fold (a handle of B) the Newton steps can squeeze the folded
  /// triangles, which the energy leaves out.
  void relieve_compression(UntangleResult& result) {
    if (!(options_.compression_seed > 0.0)) return;
    const Eigen::MatrixX2d sigma = singular_values_per_triangle(A_, V_, F_, labels_, {options_.collapse_ratio});
    std::vector<char> member(std::size_t(V_.rows()), 0);
    std::vector<int> inside, frontier;
    double global_largest = 0.0;
    for (Eigen::Index f = 0; f < F_.rows(); ++f) {
      if (std::isfinite(sigma(f, 0)) && state_[std::size_t(f)] != kSeam)
        global_largest = std::max(global_largest, sigma(f, 0));
      if (state_[std::size_t(f)] == kGood && sigma(f, 1) < options_.compression_seed)
        for (int k = 0; k < 3; ++k)
          if (!member[std::size_t(F_(f, k))]) {
            member[std::size_t(F_(f, k))] = 1;
            inside.push_back(F_(f, k));
          }
    }
    if (inside.empty()) return;
    frontier = inside;
    for (int ring = 0; ring < options_.compression_rings; ++ring) add_ring(frontier, member, inside);
    // Vertices of seam, folded or collapsed triangles stay: the smoothing leaves those triangles out of its energy, so
    // nothing would hold them back.
    for (const int v : inside)
      for (int j = vf_.begin(v); j < vf_.end(v) && member[std::size_t(v)]; ++j)
        if (wall_[std::size_t(v)] || state_[std::size_t(vf_.face(j))] != kGood) member[std::size_t(v)] = 0;
    // Each part of the grown region (joined through B's edges) is relieved, and judged, on its own.
    std::sort(inside.begin(), inside.end());
    std::vector<char> done(std::size_t(V_.rows()), 0);
    for (const int v0 : inside) {
      if (!member[std::size_t(v0)] || done[std::size_t(v0)]) continue;
      std::vector<int> part{v0};
      done[std::size_t(v0)] = 1;
      for (std::size_t i = 0; i < part.size(); ++i)
        for (int j = vf_.begin(part[i]); j < vf_.end(part[i]); ++j)
          for (int k = 0; k < 3; ++k) {
            const int u = F_(vf_.face(j), k);
            if (!member[std::size_t(u)] || done[std::size_t(u)]) continue;
            done[std::size_t(u)] = 1;
            part.push_back(u);
          }
      std::sort(part.begin(), part.end());
      ++result.compression_parts;
      if (std::int64_t(part.size()) > options_.max_compression_vertices) continue;
      result.compression_parts_relieved += relieve_part(part, global_largest, result);
    }
  }

  /// relieve_compression() on one part of the region (sorted vertices); true when kept, on UntangleOptions::
  /// compression_seed's terms (its smallest sigma2, largest sigma1, mean L2 and defects).
  bool relieve_part(std::vector<int>& part, double global_largest, UntangleResult& result) {
    const std::vector<int> faces = faces_around(part);
    const auto defects = [&] {
      std::int64_t count = 0;
      for (const int f : faces) count += spans_seam(f) || classify(f) != kGood;
      return count;
    };
    const Figures before = figures(faces);
    const std::int64_t defects_before = defects();
    const Snapshot saved = snapshot(part);

    std::swap(region_, part);
    newton_ = true;
    smooth(result, options_.compression_smoothing_sweeps);
    newton_ = false;
    std::swap(region_, part);
    Ring ring;
    for (int sweep = 0; sweep < options_.compression_sweeps; ++sweep) {
      std::int64_t moves = 0;
      for (const int v : part) moves += relieve_vertex(v, ring);
      result.compression_moves += moves;
      ++result.compression_sweeps;
      if (moves == 0) break;
    }
    const Figures after = figures(faces);
    const bool keep =
        after.smallest >= before.smallest && (after.smallest > before.smallest || after.largest < before.largest) &&
        after.largest <= std::max({before.largest, global_largest, 1.0 / options_.compression_seed}) &&
        after.mean_l2 <= (1.0 + options_.compression_mean_tolerance) * before.mean_l2 && defects() <= defects_before;
    if (keep) {
      for (const int f : faces)
        if (state_[std::size_t(f)] != kSeam) state_[std::size_t(f)] = classify(f);
      for (const int v : part)
        if (!in_region_[std::size_t(v)]) {
          in_region_[std::size_t(v)] = 1;
          region_.push_back(v);
        }
      return true;
    }
    restore(saved);
    return false;
  }

  /// Lays out again, in one chart of A, each cluster of bad triangles with rings around it (see
  /// UntangleOptions::rebuild_patches), cluster by cluster in order of their first triangle. Returns the inner
  /// vertices of the rebuilt patches.
  std::vector<int> rebuild_patches(UntangleResult& result) {
    const Eigen::Index nv = V_.rows(), nf = F_.rows();
    std::vector<char> tried(std::size_t(nf), 0), seen(std::size_t(nv), 0);
    std::vector<int> rebuilt;
    // Seam triangles seed clusters too (UntangleOptions::heal_seams).
    const auto seed = [&](char state) { return bad(state) || (options_.heal_seams && state == kSeam); };
    for (Eigen::Index f0 = 0; f0 < nf; ++f0) {
      if (!seed(state_[std::size_t(f0)]) || tried[std::size_t(f0)]) continue;
      bool seam_cluster = false;
      const std::vector<int> seeds = cluster_of(
          int(f0), [&](int f) { return seed(state_[std::size_t(f)]); }, tried, seen,
          [&](int f) { seam_cluster |= state_[std::size_t(f)] == kSeam; });
      ++result.patches_tried;
      // Rings around the seeds; the patch is the triangles with all corners inside.
      std::vector<int> inside = seeds;
      std::vector<char> member(std::size_t(nv), 0);
      for (const int v : inside) member[std::size_t(v)] = 1;
      std::vector<int> frontier = seeds;
      // A patch that has reached a seam may grow as far as a seam's cluster (UntangleOptions::max_seam_patch_rings).
      bool near_seam = options_.heal_seams && seam_cluster;
      for (int rings = 1; rings <= (near_seam ? options_.max_seam_patch_rings : options_.max_patch_rings); ++rings) {
        add_ring(frontier, member, inside);
        if (std::int64_t(inside.size()) > (near_seam ? options_.max_seam_patch_vertices : options_.max_patch_vertices))
          break;
        if (!tried_at(rings)) continue;
        if (options_.heal_seams) enclose(inside, member, options_.max_seam_patch_vertices);
        // Seam triangles inside count too: where a patch is a disk whose boundary is a simple loop in one chart, the
        // labels that span the seam threshold in it are a fold's jump, not a tear the topology forces.
        const std::vector<int> faces = faces_within(inside, member);
        for (const int f : faces) near_seam = near_seam || (options_.heal_seams && state_[std::size_t(f)] == kSeam);
        std::vector<int> moved;
        // Where no tangent plane holds the patch's loop as a simple polygon, a chart of directions may (near a seam).
        if (lay_out_patch(faces, moved, result) ||
            (chart_failed_ && near_seam && options_.direction_charts && lay_out_patch(faces, moved, result, true))) {
          ++result.patches_rebuilt;
          result.seams_healed += near_seam;
          result.patch_vertices += std::int64_t(moved.size());
          rebuilt.insert(rebuilt.end(), moved.begin(), moved.end());
          break;
        }
      }
    }
    std::sort(rebuilt.begin(), rebuilt.end());
    rebuilt.erase(std::unique(rebuilt.begin(), rebuilt.end()), rebuilt.end());
    return rebuilt;
  }

  /// Where the Tutte layout `x` of a patch (indexed by slot[] of its vertices) turns triangles over in the chart,
  /// which it can where the boundary is not convex, they are untangled with the boundary fixed (chart_untangle.h),
  /// each triangle's reference its shape on B scaled to A's area. True when it ran.
  bool untangle_layout(const std::vector<int>& faces, const std::vector<int>& slot, const std::vector<char>& fixed,
                       std::vector<Eigen::Vector2d>& x) const {
    Eigen::MatrixX3i local(Eigen::Index(faces.size()), 3);
    bool folds = false;
    for (std::size_t a = 0; a < faces.size(); ++a) {
      for (int k = 0; k < 3; ++k) local(Eigen::Index(a), k) = slot[std::size_t(F_(faces[a], k))];
      const Eigen::Vector2d& p0 = x[std::size_t(local(Eigen::Index(a), 0))];
      folds = folds || !(area(x[std::size_t(local(Eigen::Index(a), 1))] - p0,
                              x[std::size_t(local(Eigen::Index(a), 2))] - p0) > 0.0);
    }
    if (!folds) return false;  // most layouts: no references to build
    std::vector<Eigen::Matrix2d> inverse(faces.size());
    std::vector<double> weight(faces.size());
    for (std::size_t a = 0; a < faces.size(); ++a) {
      const int f = faces[a];
      // B's triangle in its own plane: edge 0-1 along the first axis, corner 2 above it.
      const Eigen::Vector3d b0 = V_.row(F_(f, 0)), e = V_.row(F_(f, 1)).transpose() - b0,
                            g = V_.row(F_(f, 2)).transpose() - b0;
      const Eigen::Vector3d u = e.normalized(), v = (e.cross(g)).cross(e).normalized();
      Eigen::Matrix2d R;
      R << e.norm(), g.dot(u), 0.0, g.dot(v);
      R *= scale_;
      if (!(R.determinant() > 0.0) || !R.allFinite()) return false;  // a degenerate triangle of B: no reference
      inverse[a] = R.inverse();
      weight[a] = 0.5 * R.determinant();
    }
    Eigen::MatrixX2d positions(Eigen::Index(x.size()), 2);
    for (std::size_t i = 0; i < x.size(); ++i) positions.row(Eigen::Index(i)) = x[i].transpose();
    untangle_chart(positions, fixed, local, inverse, weight);
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = positions.row(Eigen::Index(i)).transpose();
    return true;
  }

  /// The Tutte layout of one patch (triangles `faces`, sorted) in a chart of A; false, with the labels as they
  /// were, unless the patch is a disk whose boundary is a simple loop in the chart and every triangle comes out
  /// positive there and on A. `moved` gets the inner vertices.
  bool lay_out_patch(const std::vector<int>& faces, std::vector<int>& moved, UntangleResult& result,
                     bool directions = false) {
    chart_failed_ = false;
    // Boundary: half-edges whose twin is not in the patch; a disk has V - E + F = 1 and one boundary loop.
    std::map<std::pair<int, int>, int> half;
    for (const int f : faces)
      for (int k = 0; k < 3; ++k) half[{F_(f, k), F_(f, (k + 1) % 3)}] = f;
    std::map<int, int> next;  // boundary vertex -> the next along the loop
    std::int64_t edges = 0;
    for (const auto& [edge, f] : half) {
      const bool twin = half.count({edge.second, edge.first}) > 0;
      edges += twin ? 1 : 2;  // interior edges are seen from both sides
      if (!twin && !next.emplace(edge.first, edge.second).second) return false;  // a pinched boundary
    }
    edges /= 2;
    std::vector<int> vertices;
    for (const int f : faces)
      for (int k = 0; k < 3; ++k) vertices.push_back(F_(f, k));
    std::sort(vertices.begin(), vertices.end());
    vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
    if (std::int64_t(vertices.size()) - edges + std::int64_t(faces.size()) != 1 || next.empty()) return false;
    std::vector<int> loop{next.begin()->first};
    while (true) {
      const int after = next.at(loop.back());
      if (after == loop.front()) break;
      if (loop.size() > next.size()) return false;
      loop.push_back(after);
    }
    if (loop.size() != next.size()) return false;  // more than one loop

    // The chart: the plane through the loop's labels' mean, normal to the mean of A's normals there; points enter
    // it along their own A normals (the inverse of the closest-point lift, as chart() does).
    Eigen::Vector3d axis = Eigen::Vector3d::Zero(), origin = Eigen::Vector3d::Zero();
    for (const int v : loop) {
      axis += unit_normal_[std::size_t(face_of_[std::size_t(v)])];
      origin += labels_.row(v).transpose();
    }
    if (directions) {  // the loop's mean direction from A's centre
      axis.setZero();
      for (const int v : loop) axis += (labels_.row(v).transpose() - centre_).normalized();
    }
    if (!(axis.norm() > 0.0)) return false;
    axis.normalize();
    origin /= double(loop.size());
    const Eigen::Vector3d e1 = axis.unitOrthogonal(), e2 = axis.cross(e1);
    // The chart of directions from A's centre, for a star-shaped A: it holds almost the whole of A where a tangent
    // plane holds less than half. A point enters it only if the ray from the centre through it meets A once, and a
    // chart point goes back to A where its ray meets A.
    const DirectionChart around(centre_, axis);
    const auto to_directions = [&](int v, Eigen::Vector2d& out) {
      const Eigen::Vector3d p = labels_.row(v).transpose();
      return around.to(p, out) &&
             locator_.crossings(centre_, centre_ + reach_ * (p - centre_).normalized(), 3, 1e-9).size() == 1;
    };
    const auto lift_directions = [&](const Eigen::Vector2d& x, int hint) {
      const Eigen::Vector3d d = around.direction(x);
      const std::vector<double> t = locator_.crossings(centre_, centre_ + reach_ * d, 3, 1e-9);
      return locator_.closest_near(centre_ + (t.empty() ? 1.0 : t.front()) * reach_ * d, hint);
    };
    std::vector<int> slot(std::size_t(V_.rows()), -1);
    const int n = int(vertices.size());
    std::vector<Eigen::Vector2d> x(static_cast<std::size_t>(n));
    std::vector<char> fixed(std::size_t(n), 0);
    for (const int v : loop)
      fixed[std::size_t(std::lower_bound(vertices.begin(), vertices.end(), v) - vertices.begin())] = 1;
    for (int i = 0; i < n; ++i) {
      const int v = vertices[std::size_t(i)];
      slot[std::size_t(v)] = i;
      if (!fixed[std::size_t(i)]) continue;
      if (!(directions ? to_directions(v, x[std::size_t(i)]) : to_chart(v, origin, axis, e1, e2, x[std::size_t(i)]))) {
        chart_failed_ = true;
        return false;
      }
    }
    // The loop, with the patch on its left, must be a simple counter-clockwise polygon in the chart.
    const std::size_t m = loop.size();
    double twice_area = 0.0;
    for (std::size_t a = 0; a < m; ++a) {
      const Eigen::Vector2d& p = x[std::size_t(slot[std::size_t(loop[a])])];
      const Eigen::Vector2d& q = x[std::size_t(slot[std::size_t(loop[(a + 1) % m])])];
      twice_area += p.x() * q.y() - p.y() * q.x();
    }
    chart_failed_ = !(twice_area > 0.0);
    if (chart_failed_) return false;
    for (std::size_t a = 0; a < m; ++a)
      for (std::size_t b = a + 2; b < m; ++b) {
        if (a == 0 && b == m - 1) continue;  // neighbours along the loop
        const Eigen::Vector2d& p0 = x[std::size_t(slot[std::size_t(loop[a])])];
        const Eigen::Vector2d& p1 = x[std::size_t(slot[std::size_t(loop[(a + 1) % m])])];
        const Eigen::Vector2d& q0 = x[std::size_t(slot[std::size_t(loop[b])])];
        const Eigen::Vector2d& q1 = x[std::size_t(slot[std::size_t(loop[(b + 1) % m])])];
        const double d1 = area(p1 - p0, q0 - p0), d2 = area(p1 - p0, q1 - p0);
        const double d3 = area(q1 - q0, p0 - q0), d4 = area(q1 - q0, p1 - q0);
        if (((d1 > 0) != (d2 > 0)) && ((d3 > 0) != (d4 > 0))) {
          chart_failed_ = true;
          return false;
        }
      }

    // Mean value weights of B's own triangles: with a convex boundary the layout is one to one (Tutte).
    std::vector<int> unknown(std::size_t(n), -1);
    int unknowns = 0;
    for (int i = 0; i < n; ++i)
      if (!fixed[std::size_t(i)]) unknown[std::size_t(i)] = unknowns++;
    if (unknowns == 0) return false;
    std::vector<Eigen::Triplet<double>> triplets;
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(unknowns, 2);
    for (const int f : faces)
      for (int k = 0; k < 3; ++k) {
        const int i = slot[std::size_t(F_(f, k))];
        if (fixed[std::size_t(i)]) continue;
        for (const auto& [other, w] : mean_value_weights(V_, F_, f, k)) {
          if (std::isnan(w)) return false;  // a zero-length edge
          const int j = slot[std::size_t(other)];
          triplets.emplace_back(unknown[std::size_t(i)], unknown[std::size_t(i)], w);
          if (fixed[std::size_t(j)])
            rhs.row(unknown[std::size_t(i)]) += w * x[std::size_t(j)].transpose();
          else
            triplets.emplace_back(unknown[std::size_t(i)], unknown[std::size_t(j)], -w);
        }
      }
    Eigen::SparseMatrix<double> L(unknowns, unknowns);
    L.setFromTriplets(triplets.begin(), triplets.end());
    Eigen::SparseLU<Eigen::SparseMatrix<double>> lu(L);
    if (lu.info() != Eigen::Success) return false;
    const Eigen::MatrixXd solution = lu.solve(rhs);
    if (lu.info() != Eigen::Success || !solution.allFinite()) return false;
    for (int i = 0; i < n; ++i)
      if (!fixed[std::size_t(i)]) x[std::size_t(i)] = solution.row(unknown[std::size_t(i)]).transpose();
    if (options_.untangle_layouts && untangle_layout(faces, slot, fixed, x)) ++result.layouts_untangled;
    std::int64_t bad_before = 0, seams_before = 0;
    for (const int f : faces) {
      bad_before += state_[std::size_t(f)] != kGood;
      seams_before += state_[std::size_t(f)] == kSeam;
    }

    // Lift the inner vertices to A; keep the layout only when no triangle of the patch is bad there.
    std::vector<std::pair<Eigen::Vector3d, int>> before;
    moved.clear();
    for (int i = 0; i < n; ++i) {
      if (fixed[std::size_t(i)]) continue;
      const int v = vertices[std::size_t(i)];
      before.emplace_back(labels_.row(v).transpose(), face_of_[std::size_t(v)]);
      const SurfaceHit hit = directions ? lift_directions(x[std::size_t(i)], face_of_[std::size_t(v)])
                                        : lift(origin, e1, e2, x[std::size_t(i)], face_of_[std::size_t(v)]);
      labels_.row(v) = hit.point.transpose();
      face_of_[std::size_t(v)] = hit.face;
      moved.push_back(v);
    }
    // A boundary that is not convex in the chart can leave a few triangles inverted next to it (Tutte's theorem needs
    // a convex one): the layout is kept when it rights all but max_patch_bad_fraction of the patch's bad triangles
    // (the local untangling that follows takes the rest) and squeezes no triangle below min_patch_area_ratio of its
    // area on B (scaled to A's area): measured on cow -> horse, layouts without that guard raised the L2 p99 from
    // 331 to 1.7e4.
    std::vector<char> states(faces.size());
    std::int64_t bad_after = 0, seams_after = 0;
    for (std::size_t a = 0; a < faces.size(); ++a) {
      states[a] = spans_seam(faces[a]) ? char(kSeam) : classify(faces[a]);
      bad_after += states[a] != kGood;
      seams_after += states[a] == kSeam;
    }
    double smallest = std::numeric_limits<double>::infinity();
    for (const int f : faces) {
      const Eigen::Vector3d p0 = labels_.row(F_(f, 0)), p1 = labels_.row(F_(f, 1)), p2 = labels_.row(F_(f, 2));
      const Eigen::Vector3d b0 = V_.row(F_(f, 0)), b1 = V_.row(F_(f, 1)), b2 = V_.row(F_(f, 2));
      const double ratio = (p1 - p0).cross(p2 - p0).norm() / (scale_ * scale_ * (b1 - b0).cross(b2 - b0).norm());
      smallest = std::min(smallest, ratio);
    }
    // A layout that closes every seam of its patch is kept though it leaves folds (the local untangling that follows
    // rights them): on sphere -> bunny the last seam's patch went from 2 seam and 7 folded triangles to none and 8
    // (4 rings), and the map from 42 collapsed pieces of the seam split to none, with no fold left.
    const bool closes_seams = options_.heal_seams && seams_before > 0 && seams_after == 0;
    if ((!closes_seams && double(bad_after) > options_.max_patch_bad_fraction * double(bad_before)) ||
        smallest < options_.min_patch_area_ratio) {
      for (std::size_t a = 0; a < moved.size(); ++a) {
        labels_.row(moved[a]) = before[a].first.transpose();
        face_of_[std::size_t(moved[a])] = before[a].second;
      }
      moved.clear();
      return false;
    }
    for (std::size_t a = 0; a < faces.size(); ++a) state_[std::size_t(faces[a])] = states[a];
    for (const int v : moved) {
      moved_[std::size_t(v)] = 1;
      wall_[std::size_t(v)] = 0;  // its triangles are all in the patch, and none spans a seam now
    }
    return true;
  }

  const Surface& A_;
  const SurfaceLocator& locator_;
  const Eigen::MatrixXd& V_;
  const TriIndices& F_;
  Eigen::MatrixXd& labels_;
  const UntangleOptions& options_;
  const VertexFaces vf_;
  std::vector<char> state_, wall_, moved_, in_region_;
  bool newton_ = false;        // smooth_vertex(): Newton steps (relieve_compression) instead of the curvature bound's
  bool chart_failed_ = false;  // lay_out_patch(): its last failure was the chart's (a point or the loop)
  Eigen::Vector3d centre_ = Eigen::Vector3d::Zero();  // A's vertices' mean: the centre of the direction charts
  double reach_ = 0.0;        // twice A's bounding-box diagonal: rays of the direction charts end beyond A
  std::vector<int> part_of_;  // enclose(): the part of B outside a patch each vertex was found in, -1 between calls
  std::vector<Eigen::Vector3d> unit_normal_;  // A's outward unit face normals (every chart reads them)
  struct Shape {
    Eigen::Matrix2d inverse;  // P^-1, P a triangle's B edges from the vertex in its own plane
    double det = 0.0, area = 0.0;
  };
  std::vector<Shape> shapes_;      // per entry of vf_ (a vertex's triangles), once shape_state_ is 1
  std::vector<char> shape_state_;  // per vertex: 0 not computed, 1 computed, 2 a triangle degenerate
  std::vector<int> face_of_, region_, frontier_;
  double collapse_area_ = 0.0, scale_ = 1.0, seam_length_ = 0.0;
};

}  // namespace

DirectionChart::DirectionChart(const Eigen::Vector3d& c, const Eigen::Vector3d& a)
    : centre(c), axis(a.normalized()), e1(axis.unitOrthogonal()), e2(axis.cross(e1)) {}

bool DirectionChart::to(const Eigen::Vector3d& p, Eigen::Vector2d& x) const {
  const Eigen::Vector3d d = (p - centre).normalized();
  const double below = 1.0 + d.dot(axis);  // 0 at the pole, -axis
  if (!(below > 1e-3)) return false;
  x = Eigen::Vector2d(d.dot(e1), d.dot(e2)) / below;
  return true;
}

Eigen::Vector3d DirectionChart::direction(const Eigen::Vector2d& x) const {
  const double r2 = x.squaredNorm();
  return (2.0 * (x.x() * e1 + x.y() * e2) + (1.0 - r2) * axis) / (1.0 + r2);
}

UntangleResult untangle_labels(const Surface& A, const SurfaceLocator& locator, const Eigen::MatrixXd& V,
                               const TriIndices& F, Eigen::MatrixXd& labels, const UntangleOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (labels.rows() != V.rows() || labels.cols() != 3 || V.cols() != 3)
    throw InvalidInput("untangle_labels: labels must be #V by 3, one per vertex of B (V #V by 3)");
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k)
      if (F(f, k) < 0 || F(f, k) >= V.rows())
        throw InvalidInput("untangle_labels: triangle " + std::to_string(f) + " has a vertex index out of range");
  UntangleResult result;
  if (F.rows() > 0) result = Untangler(A, locator, V, F, labels, options).run();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace morphmap
