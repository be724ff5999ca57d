// Characteristics of the interpolated flow T (see trace.h; paper §7). Written by hand: no library traces a
// vector field over a simplicial 3-manifold in R^4.
//
// In a simplex with vertices v_0..v_k (k = 1, 2, 3: an edge, a face, a tet) and barycentric weights w, moving
// along d = -sum_j w_j T_j (projected into the simplex's span) changes the weights at the rates
//   dw_i/dtau = grad w_i . d = -sum_j (grad w_i . T_j) w_j = -(A w)_i,
// a linear ODE. The weight gradients come from E = [v_1 - v_0 .. v_k - v_0] (4 by k): grad w_i = E (E^T E)^-1 e_i
// for i >= 1 and grad w_0 = -(their sum), so no embedding of the hull is needed. A piece ends where the first
// weight reaches zero, on a face of the simplex, where the next simplex is chosen.
#include "solver/trace.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <limits>
#include <numeric>
#include <string>

#include "mesh/adjacency.h"
#include "mesh/errors.h"
#include "mesh/extract.h"

namespace morphmap {

namespace {

using Weights = Eigen::Vector4d;

// A simplex (2 to 4 mesh vertices) with what its weight ODE needs: the gradients of its weights (in its span) and
// the field and normals at its vertices.
struct Simplex {
  int size = 0;                                                         ///< vertices: 2 edge, 3 face, 4 tet
  int tet = -1;                                                         ///< the mesh tet (tets only)
  std::array<int, 4> ids{{-1, -1, -1, -1}};                             ///< mesh vertices
  Eigen::Matrix<double, 4, 3> G = Eigen::Matrix<double, 4, 3>::Zero();  ///< grad w_1 .. grad w_(size-1)
  Eigen::Matrix4d T = Eigen::Matrix4d::Zero();                          ///< columns: the field at the vertices
  Eigen::Matrix4d N = Eigen::Matrix4d::Zero();                          ///< columns: vertex normals (tets only)
  Eigen::Vector4d normal = Eigen::Vector4d::Zero();                     ///< the tet's own normal (tets only)
  double normal_norm2 = 0.0;                                            ///< |normal|^2, for every rate evaluation
  double variation = 0.0;  ///< bound on how fast the rates change with w (set_variation)
};

// Weight rates at w (#size entries, zero beyond). In a tet the flow d is moved into the tet's span along the
// interpolated vertex normal N(w), not orthogonally: two tets sharing a face see the same N there, so the flow
// that leaves one through the face enters the other (orthogonal projections of a bent star disagree near the
// face, and sliver tets, whose spans are far from the manifold's tangent space, would bend every trace through
// them). Where N lies nearly in the tet's span (a fold) the orthogonal projection is used.
// K = x.size - 1 as a constant: the tets' evaluations (nearly all) run unrolled.
template <int K>
Weights rates_of(const Simplex& x, const Weights& w) {
  // The fixed-size product: T's columns beyond x.size are zero, and a block of run-time width is not unrolled.
  Eigen::Vector4d v = -(x.T * w);
  if constexpr (K == 3) {
    const Eigen::Vector4d n = x.N * w;
    const double along = x.normal.dot(n);
    // |along| > 0.2 |normal| |n|, squared: no square root in the evaluation.
    if (along * along > 0.04 * x.normal_norm2 * n.squaredNorm()) v -= (x.normal.dot(v) / along) * n;
  }
  Weights r = Weights::Zero();
  double sum = 0.0;
  for (int i = 0; i < K; ++i) {
    r(i + 1) = x.G.col(i).dot(v);
    sum += r(i + 1);
  }
  r(0) = -sum;
  return r;
}

Weights rates(const Simplex& x, const Weights& w) {
  switch (x.size) {
    case 4:
      return rates_of<3>(x, w);
    case 3:
      return rates_of<2>(x, w);
    case 2:
      return rates_of<1>(x, w);
    default:
      return rates_of<0>(x, w);
  }
}

// Forced inline: out of line (once choose() and descend() shared the simplex enumeration) it cost cow -> horse's
// trace 20% more time. Without kFlow only the weight gradients are set: the steepest descent of s needs nothing else
// (with the dedupe in simplices_holding, 5.4% fewer tracer instructions on cow -> horse, callgrind); the vertex field
// is finite (checked), so the test below rejects the same simplices.
template <int K, bool kFlow>
__attribute__((always_inline)) inline bool simplex_system(const TetMesh4& mesh, const Points4& field,
                                                          const Points4& normals, Simplex& x) {
  Eigen::Matrix<double, 4, K> E;
  const Eigen::Vector4d v0 = mesh.V.row(x.ids[0]).transpose();
  for (int j = 0; j < K; ++j) E.col(j) = mesh.V.row(x.ids[std::size_t(j) + 1]).transpose() - v0;
  const Eigen::Matrix<double, K, K> gram = E.transpose() * E;
  double scale = 1.0;
  for (int j = 0; j < K; ++j) scale *= gram(j, j);
  // Hadamard: det <= product of the diagonal, with equality for orthogonal edges. Far below it the simplex is
  // flat, its weights have no gradient, and it is never entered.
  if (!(gram.determinant() > 1e-20 * scale)) return false;
  if constexpr (K < 3) x.G.setZero();  // a tet's three columns are all written
  x.G.leftCols(K) = E * gram.inverse();
  if (!kFlow) return x.G.allFinite();
  for (int j = 0; j <= K; ++j) x.T.col(j) = field.row(x.ids[std::size_t(j)]).transpose();
  if constexpr (K == 3) {
    x.normal = cross4(E.col(0), E.col(1), E.col(2));
    x.normal_norm2 = x.normal.squaredNorm();
    for (int j = 0; j <= K; ++j) x.N.col(j) = normals.row(x.ids[std::size_t(j)]).transpose();
  }
  // x.variation is left to set_variation, for the one simplex a piece enters.
  // T needs no test: the vertex field is finite (checked on entry) and so is its smoothing (unit vectors averaged).
  return x.G.allFinite();
}

// The step bound's variation of x, whose flow system simplex_system has set: computed for the simplex a piece enters
// only, not for every candidate choose() weighs (a trace's first piece weighs every tet of a vertex's star). Maxima
// of squared norms and one square root each: sqrt is monotone and correctly rounded, so this is bitwise the maximum
// of the norms, at 2 square roots a simplex instead of 11 (a tenth of cow -> horse's tracing time).
void set_variation(Simplex& x) {
  const int k = x.size - 1;
  double largest_gradient2 = 0.0, spread2 = 0.0;
  for (int j = 0; j < k; ++j) largest_gradient2 = std::max(largest_gradient2, x.G.col(j).squaredNorm());
  for (int j = 1; j <= k; ++j) spread2 = std::max(spread2, (x.T.col(j) - x.T.col(0)).squaredNorm());
  if (x.size == 4)
    for (int j = 1; j <= k; ++j) spread2 = std::max(spread2, (x.N.col(j) - x.N.col(0)).squaredNorm());
  x.variation = 2.0 * std::sqrt(largest_gradient2) * std::sqrt(spread2);
}

template <bool kFlow>
__attribute__((always_inline)) inline bool system_of(const TetMesh4& mesh, const Points4& field, const Points4& normals,
                                                     Simplex& x) {
  switch (x.size) {
    case 2:
      return simplex_system<1, kFlow>(mesh, field, normals, x);
    case 3:
      return simplex_system<2, kFlow>(mesh, field, normals, x);
    case 4:
      return simplex_system<3, kFlow>(mesh, field, normals, x);
    default:
      return false;
  }
}

// One classical Runge-Kutta step of the weight ODE; k1 = rates(x, w), which the caller has already.
Weights rk4(const Simplex& x, const Weights& w, const Weights& k1, double h) {
  const Weights k2 = rates(x, w + 0.5 * h * k1);
  const Weights k3 = rates(x, w + 0.5 * h * k2);
  const Weights k4 = rates(x, w + h * k3);
  return w + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
}

// The cubic Hermite interpolant on [0, 1] of a weight with values a, b and (step-scaled) slopes da, db at the ends.
double hermite(double a, double b, double da, double db, double u) {
  const double u2 = u * u, u3 = u2 * u;
  return (2 * u3 - 3 * u2 + 1) * a + (u3 - 2 * u2 + u) * da + (-2 * u3 + 3 * u2) * b + (u3 - u2) * db;
}

// The first u in (0, 1] where the Hermite interpolant falls to zero, given that it is positive at 0 and not at 1:
// bracketed Newton on the cubic (no evaluations of the ODE).
double hermite_root(double a, double b, double da, double db) {
  double lo = 0.0, hi = 1.0, u = a / (a - b);
  for (int iteration = 0; iteration < 40; ++iteration) {
    const double value = hermite(a, b, da, db, u);
    if (std::abs(value) <= 1e-15) break;
    if (value > 0.0)
      lo = u;
    else
      hi = u;
    const double u2 = u * u;
    const double slope =
        (6 * u2 - 6 * u) * a + (3 * u2 - 4 * u + 1) * da + (-6 * u2 + 6 * u) * b + (3 * u2 - 2 * u) * db;
    double next = slope != 0.0 ? u - value / slope : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (hi - lo < 1e-14) break;
    u = next;
  }
  return u;
}

// Per vertex, in one walk of its star (every sum in star order, so the result does not depend on the thread count):
// when `normals` is given, the unit vertex normal of the 3-manifold (the sum of the incident tets' normals, each
// |cross4| = 6 x volume); when `smoothed` is given, one pass of neighbour averaging of `field` (#V by 4, see
// TraceOptions::field_smoothing: the normalised mean of the unit vectors at the vertex and at the vertices of its star,
// each counted once per incident tet; zero vectors stay zero). The two read the same rows of T, so the tracer's
// set-up asks for both at once (two walks of the 6.6 M star entries of cow -> horse before).
void star_sums(const TetMesh4& mesh, const VertexTets& adj, const Points4& field, Points4* normals, Points4* smoothed) {
  // Not zeroed here: every row is written below, zero where it has no direction, so the parallel pass is the first
  // touch of both arrays (Eigen's Zero is one serial pass over 9.5 MB each on cow -> horse).
  if (normals != nullptr) normals->resize(mesh.vertex_count(), 4);
  if (smoothed != nullptr) smoothed->resize(field.rows(), 4);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, mesh.vertex_count()), [&](const auto& r) {
    for (Eigen::Index v = r.begin(); v != r.end(); ++v) {
      const bool smooth = smoothed != nullptr && field.row(v).squaredNorm() > 0.0;
      if (smoothed != nullptr && !smooth) smoothed->row(v).setZero();
      if (normals == nullptr && !smooth) continue;
      Eigen::Vector4d normal = Eigen::Vector4d::Zero();
      Eigen::RowVector4d sum = smooth ? Eigen::RowVector4d(field.row(v)) : Eigen::RowVector4d::Zero();
      for (std::int64_t j = adj.first(int(v)); j < adj.last(int(v)); ++j) {
        const int t = adj.tet(j);
        const int row[4] = {mesh.T(t, 0), mesh.T(t, 1), mesh.T(t, 2), mesh.T(t, 3)};
        if (normals != nullptr) {
          const Eigen::Vector4d v0 = mesh.V.row(row[0]).transpose();
          normal += cross4(mesh.V.row(row[1]).transpose() - v0, mesh.V.row(row[2]).transpose() - v0,
                           mesh.V.row(row[3]).transpose() - v0);
        }
        if (smooth)
          for (int k = 0; k < 4; ++k) sum += field.row(row[k]);
      }
      if (normals != nullptr) {
        const double length = normal.norm();
        if (length > 0.0)
          normals->row(v) = (normal / length).transpose();
        else
          normals->row(v).setZero();
      }
      if (smooth) {
        const double length = sum.norm();
        if (length > 0.0)
          smoothed->row(v) = sum / length;
        else
          smoothed->row(v).setZero();
      }
    }
  });
}

// A tet's vertices and the tets across its faces side by side, two tets a cache line: a piece that leaves its tet
// through a face reads the neighbour's index and then that neighbour's vertices, two dependent misses when T and the
// face table were separate arrays.
struct alignas(32) TetRecord {
  int v[4];       // T's row
  int across[4];  // FaceNeighbours::across of the tet (face opposite v[k])
};
struct TetRecords {
  std::unique_ptr<TetRecord[]> records;
  bool known = false;  // FaceNeighbours::known()
  const TetRecord& at(int t) const { return records[std::size_t(t)]; }
};

// The records of T, their neighbours from the extraction's lattice record when there is one, else from the stars.
TetRecords tet_records(const TetIndices& T, const VertexTets& stars, const LatticeFaces* faces) {
  TetRecords out;
  out.records.reset(new TetRecord[std::size_t(T.rows())]);
  const bool lattice = faces != nullptr && faces->known();
  const FaceNeighbours searched = lattice ? FaceNeighbours{} : face_neighbours(T, stars);
  out.known = lattice || searched.known();
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, T.rows()), [&](const tbb::blocked_range<Eigen::Index>& r) {
    for (Eigen::Index t = r.begin(); t != r.end(); ++t) {
      TetRecord& rec = out.records[std::size_t(t)];
      for (int k = 0; k < 4; ++k) rec.v[k] = T(t, k);
      if (lattice) continue;  // written below
      for (int k = 0; k < 4; ++k)
        rec.across[k] =
            searched.known() ? searched.across[std::size_t(t) * 4 + std::size_t(k)] : FaceNeighbours::kManyTets;
    }
  });
  // Written straight into the records (no 16-byte-a-tet table beside them).
  if (lattice) lattice_face_neighbours(*faces, T, &out.records[0].across[0], sizeof(TetRecord) / sizeof(int));
  return out;
}

struct Stats {
  std::int64_t pieces[5] = {0, 0, 0, 0, 0};  // by simplex size
  std::int64_t evaluations = 0;              // of the weight rates, in integrate() and choose(); descent steps
  std::int64_t descent_pieces = 0;           // of those pieces, steps of the steepest descent of s
  std::int64_t total() const { return pieces[2] + pieces[3] + pieces[4]; }
};

class Tracer {
 public:
  Tracer(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& field, const TraceOptions& options,
         const SharedStars& stars, const LatticeFaces* faces)
      : mesh_(mesh),
        s_(s),
        options_(options),
        stars_(stars_or_build(stars, mesh.T, mesh.vertex_count())),
        adj_(*stars_),
        tets_(tet_records(mesh.T, adj_, faces)) {
    // The normals ride along with the first smoothing pass (or walk the stars alone without one).
    field_ = field;
    for (int pass = 0; pass < std::max(1, options.field_smoothing); ++pass) {
      Points4 smoothed;
      star_sums(mesh, adj_, field_, pass == 0 ? &normals_ : nullptr,
                pass < options.field_smoothing ? &smoothed : nullptr);
      if (pass < options.field_smoothing) field_ = std::move(smoothed);
    }
  }

  TraceStatus trace(const MeshPoint& start, MeshPoint& end, Stats& stats) const {
    // The support of the current point: vertices with positive weight.
    std::array<int, 4> ids{{-1, -1, -1, -1}};
    std::array<double, 4> w{{0.0, 0.0, 0.0, 0.0}};
    int n = 0;
    for (int k = 0; k < 4; ++k)
      if (start.ids[std::size_t(k)] >= 0 && start.weights[std::size_t(k)] > options_.weight_epsilon) {
        if (start.ids[std::size_t(k)] >= mesh_.vertex_count()) return TraceStatus::Invalid;
        ids[std::size_t(n)] = start.ids[std::size_t(k)];
        w[std::size_t(n++)] = start.weights[std::size_t(k)];
      }
    end = start;
    if (n == 0 || !held(ids, n)) return TraceStatus::Invalid;
    normalise(w, n);
    TraceStatus status = follow(ids, w, n, stats);
    if (status == TraceStatus::Stalled && options_.descend && descend(ids, w, n, stats))
      status = TraceStatus::Descended;
    end = MeshPoint{};
    for (int k = 0; k < n; ++k) {
      end.ids[std::size_t(k)] = ids[std::size_t(k)];
      end.weights[std::size_t(k)] = w[std::size_t(k)];
    }
    return status;
  }

 private:
  // Follows the interpolated flow from the support (ids, w, n) until it reaches A or stalls; (ids, w, n) end
  // where it stopped.
  TraceStatus follow(std::array<int, 4>& ids, std::array<double, 4>& w, int& n, Stats& stats) const {
    // Supports (sorted ids) before the last two pieces: a piece that returns the point to the support it had two
    // pieces ago (along an edge and back, where the field converges from both ends) is a stagnation point.
    std::array<int, 4> before_last{{-2, -2, -2, -2}}, last{{-2, -2, -2, -2}};
    double s_checkpoint = 0.0;
    int from_tet = -1;  // the tet the last piece crossed, when it ended on one of its faces
    // One simplex a trace, not one a piece: choose() writes every member it reads (zeroing and copying its 424 bytes
    // a piece was a tenth of the tracer's instructions with the copies below).
    Simplex piece;
    for (int step = 0;; ++step) {
      if (on_a(ids, n)) return TraceStatus::Reached;
      if (step >= options_.max_steps) return TraceStatus::Stalled;
      // Only a support of one or two vertices is compared; a larger one gets a key no such support has (sorting it
      // was 2% of the tracer's instructions).
      const std::array<int, 4> key = n < 3 ? support_key(ids, n) : kLargeSupport;
      if (n < 3 && key == before_last) return TraceStatus::Stalled;
      if (step % options_.progress_window == 0) {
        double s_now = 0.0;
        for (int k = 0; k < n; ++k) s_now += w[std::size_t(k)] * s_(ids[std::size_t(k)]);
        if (step > 0 && !(s_now < s_checkpoint - options_.progress)) return TraceStatus::Stalled;
        s_checkpoint = s_now;
      }
      before_last = last;
      last = key;
      Weights pw;
      Weights rate;
      if (!choose(ids, w, n, from_tet, piece, pw, rate, stats)) return TraceStatus::Stalled;
      if (!integrate(piece, pw, rate, stats)) return TraceStatus::Stalled;
      ++stats.pieces[piece.size];
      from_tet = piece.tet;
      if (!take_support(piece, pw, ids, w, n)) return TraceStatus::Stalled;
    }
  }

  static constexpr std::array<int, 4> kLargeSupport{{-3, -3, -3, -3}};  // see follow()

  static std::array<int, 4> support_key(const std::array<int, 4>& ids, int n) {
    // A fixed trip count: a loop to n was a call to memcpy a piece.
    std::array<int, 4> key;
    for (int k = 0; k < 4; ++k) key[std::size_t(k)] = k < n ? ids[std::size_t(k)] : -1;
    for (int i = 1; i < n; ++i)  // insertion sort of at most 4 ids
      for (int j = i; j > 0 && key[std::size_t(j - 1)] > key[std::size_t(j)]; --j)
        std::swap(key[std::size_t(j - 1)], key[std::size_t(j)]);
    return key;
  }

  static void normalise(std::array<double, 4>& w, int n) {
    double sum = 0.0;
    for (int k = 0; k < n; ++k) sum += w[std::size_t(k)];
    for (int k = 0; k < n; ++k) w[std::size_t(k)] /= sum;
  }

  bool contains(int t, int v) const {
    for (int k = 0; k < 4; ++k)
      if (tets_.at(t).v[k] == v) return true;
    return false;
  }

  bool held(const std::array<int, 4>& ids, int n) const {
    for (std::int64_t j = adj_.first(ids[0]); j < adj_.last(ids[0]); ++j) {
      bool all = true;
      for (int k = 1; k < n && all; ++k) all = contains(adj_.tet(j), ids[std::size_t(k)]);
      if (all) return true;
    }
    return false;
  }

  double s_at(const Simplex& x, const Weights& w) const {
    double value = 0.0;
    for (int j = 0; j < x.size; ++j) value += w(j) * s_(x.ids[std::size_t(j)]);
    return value;
  }

  // Follows the weight ODE in x from pw until the first weight that was positive (or leaves zero) reaches zero.
  // pw is #x.size weights (zero beyond). False when the flow stops inside x: s has not fallen by
  // TraceOptions::progress over `stagnation_substeps` steps (a sink or a stagnation point of T inside x; without
  // this test such a trace took 64 steps a piece until the progress window stopped it, half of cow -> horse's
  // evaluations).
  // `rate` is rates(x, pw), which choose() evaluated already.
  bool integrate(const Simplex& x, Weights& pw, const Weights& rate, Stats& stats) const {
    constexpr int stagnation_substeps = 8;
    const int m = x.size;
    // s where the piece starts, read only if it runs to stagnation_substeps steps (few do): kept as its weights.
    const Weights start = pw;
    double s_checkpoint = std::numeric_limits<double>::quiet_NaN();
    // Weights that start at zero enter (choose() demands a positive rate), so they are not taken as leaving
    // while they are still zero; a step too long for one of them to become positive is halved.
    std::array<bool, 4> pinned{{false, false, false, false}};
    for (int j = 0; j < m; ++j) pinned[std::size_t(j)] = pw(j) <= options_.weight_epsilon;
    for (int sub = 0; sub < 64; ++sub) {
      if (sub > 0 && sub % stagnation_substeps == 0) {
        if (sub == stagnation_substeps) s_checkpoint = s_at(x, start);
        const double s_now = s_at(x, pw);
        if (!(s_now < s_checkpoint - options_.progress)) return false;
        s_checkpoint = s_now;
      }
      const Weights r = sub == 0 ? rate : rates(x, pw);
      stats.evaluations += sub == 0 ? 0 : 1;
      double exit_time = std::numeric_limits<double>::infinity();
      for (int j = 0; j < m; ++j)
        if (!pinned[std::size_t(j)] && r(j) < 0.0) exit_time = std::min(exit_time, pw(j) / -r(j));
      double h = exit_time * 1.25;  // overshoot, so that the exit falls inside the step
      if (x.variation > 0.0) h = std::min(h, options_.step_variation / x.variation);
      if (!std::isfinite(h) || !(h > 0.0)) return false;
      // Heun's predictor slope, near the step's end: the end slope of the exit's Hermite interpolant below.
      Weights predicted = Weights::Zero();
      auto step = [&]() -> Weights {
        if (options_.order == 4) {
          stats.evaluations += 3;
          return rk4(x, pw, r, h);
        }
        ++stats.evaluations;
        predicted = rates(x, pw + h * r);
        return pw + (0.5 * h) * (r + predicted);
      };
      Weights next = step();
      for (int halve = 0; halve < 30; ++halve) {
        bool pinned_negative = false;
        for (int j = 0; j < m; ++j) pinned_negative = pinned_negative || (pinned[std::size_t(j)] && next(j) < 0.0);
        if (!pinned_negative) break;
        h *= 0.5;
        next = step();
      }
      pinned.fill(false);
      bool crosses = false;
      for (int j = 0; j < m; ++j) crosses = crosses || next(j) < 0.0;
      if (!crosses) {
        for (int j = 0; j < m; ++j) next(j) = std::max(next(j), 0.0);
        pw = next / next.head(m).sum();
        continue;
      }
      // The first weight to cross zero within the step: the root of its cubic Hermite interpolant (the rates at
      // both ends of the step; as accurate as the RK4 step itself), and the point there from the same interpolant
      // of every weight. Regula falsi on repeated RK4 steps took 8 x as many evaluations for the same exit; a
      // second RK4 step to the root, 3 more evaluations a piece (measured against it: 32% of cow -> horse's
      // evaluations, 14% of its tracing time; sphere -> bunny labels moved by a median 8e-9 and a 99th
      // percentile of 4e-6, the box being 3.1, and no stretch figure but the ear-tip-dominated variance in
      // its third digit).
      Weights r_end;
      if (options_.order == 4) {
        r_end = rates(x, next);
        ++stats.evaluations;
      } else {
        r_end = predicted;
      }
      double theta = 2.0;
      int leaving = -1;
      for (int j = 0; j < m; ++j)
        if (next(j) < 0.0) {
          const double u = hermite_root(pw(j), next(j), h * r(j), h * r_end(j));
          if (u < theta) {
            theta = u;
            leaving = j;
          }
        }
      Weights at = Weights::Zero();
      for (int j = 0; j < m; ++j) at(j) = hermite(pw(j), next(j), h * r(j), h * r_end(j), theta);
      at(leaving) = 0.0;
      for (int j = 0; j < m; ++j) at(j) = std::max(at(j), 0.0);
      const double sum = at.head(m).sum();
      if (!(sum > 0.0)) return false;
      pw = at / sum;
      return true;
    }
    return true;  // a long piece: continue from where it got to
  }

  // Whether v is one of ids[0..n). A loop the compiler keeps inline: std::find over these 3-4 ids was an out-of-line
  // call (std::__find_if, 1.8% of a cow -> horse run's samples) twice a piece.
  static bool among(const std::array<int, 4>& ids, int n, int v) {
    for (int i = 0; i < n; ++i)
      if (ids[std::size_t(i)] == v) return true;
    return false;
  }

  // The tets holding the support, in increasing index. On a face of from_tet (the common case: a piece ended on
  // a face of its tet) they are from_tet and its neighbour across that face (face_neighbours), else the stars'
  // intersection.
  void support_tets(const std::array<int, 4>& ids, int n, int from_tet, std::vector<int>& out) const {
    out.clear();
    if (n == 3 && from_tet >= 0) {
      int k = 0;
      const TetRecord& from = tets_.at(from_tet);
      while (k < 4 && among(ids, 3, from.v[k])) ++k;
      if (k < 4 && tets_.known) {
        const int other = from.across[k];
        if (other != FaceNeighbours::kManyTets) {
          if (other >= 0 && other < from_tet) out.push_back(other);
          out.push_back(from_tet);
          if (other > from_tet) out.push_back(other);
          return;
        }
      }
    }
    star_intersection(ids, n, out);
  }

  // The intersection of the support vertices' stars, which are sorted by tet index, walked in step (reading the
  // star lists only: testing each tet of one star against the others' vertices read a random row of T per tet).
  void star_intersection(const std::array<int, 4>& ids, int n, std::vector<int>& out) const {
    out.clear();
    if (n == 3) {
      face_star_intersection(ids, out);
      return;
    }
    std::array<std::int64_t, 4> at{}, end{};
    int scan = 0;  // the support vertex with the fewest tets
    for (int k = 0; k < n; ++k) {
      at[std::size_t(k)] = adj_.first(ids[std::size_t(k)]);
      end[std::size_t(k)] = adj_.last(ids[std::size_t(k)]);
      if (end[std::size_t(k)] - at[std::size_t(k)] < end[std::size_t(scan)] - at[std::size_t(scan)]) scan = k;
    }
    for (std::int64_t j = at[std::size_t(scan)]; j < end[std::size_t(scan)]; ++j) {
      const int t = adj_.tet(j);
      bool all = true;
      for (int k = 0; k < n && all; ++k) {
        if (k == scan) continue;
        std::int64_t& i = at[std::size_t(k)];
        while (i < end[std::size_t(k)] && adj_.tet(i) < t) ++i;
        all = i < end[std::size_t(k)] && adj_.tet(i) == t;
      }
      if (all) out.push_back(t);
    }
  }

  // star_intersection of a face (the common case: every piece through a tet ends on one), with the three list
  // cursors in registers: the general loop kept them in an indexed array, stored back at every step, and took a
  // fifth of the tracer's instructions on sphere -> torus. Same walk, same result.
  void face_star_intersection(const std::array<int, 4>& ids, std::vector<int>& out) const {
    std::array<const int*, 3> begin{}, end{};
    for (int k = 0; k < 3; ++k) {
      begin[std::size_t(k)] = adj_.tets.data() + adj_.first(ids[std::size_t(k)]);
      end[std::size_t(k)] = adj_.tets.data() + adj_.last(ids[std::size_t(k)]);
    }
    // The shortest star drives the walk; the other two are advanced to each of its tets.
    int scan = 0;
    for (int k = 1; k < 3; ++k)
      if (end[std::size_t(k)] - begin[std::size_t(k)] < end[std::size_t(scan)] - begin[std::size_t(scan)]) scan = k;
    const int* s = begin[std::size_t(scan)];
    const int* const s_end = end[std::size_t(scan)];
    const int* p = begin[std::size_t(scan == 0 ? 1 : 0)];
    const int* const p_end = end[std::size_t(scan == 0 ? 1 : 0)];
    const int* q = begin[std::size_t(scan == 2 ? 1 : 2)];
    const int* const q_end = end[std::size_t(scan == 2 ? 1 : 2)];
    for (; s != s_end; ++s) {
      const int t = *s;
      while (p != p_end && *p < t) ++p;
      if (p == p_end) return;
      if (*p != t) continue;
      while (q != q_end && *q < t) ++q;
      if (q == q_end) return;
      if (*q == t) out.push_back(t);
    }
  }

  // The weight system of tet t through the face ids[0..3) into x, as simplices_holding<true>(ids, 3, {t}, 4, ...)
  // builds it (the face first, then t's fourth vertex), without its subset enumeration and copies; false when t
  // has no system, or does not hold the face by exactly one vertex more (never, for a tet across a face).
  bool tet_through_face(const std::array<int, 4>& ids, int t, Simplex& x) const {
    int other = -1;
    const TetRecord& tet = tets_.at(t);
    for (int k = 0; k < 4; ++k) {
      const int v = tet.v[k];
      if (among(ids, 3, v)) continue;
      if (other >= 0) return false;
      other = v;
    }
    if (other < 0) return false;
    x.size = 4;
    x.tet = t;
    x.ids = {{ids[0], ids[1], ids[2], other}};
    // The piece will leave t through one of its faces: fetch the neighbours' records while it is integrated.
    for (int k = 0; k < 4; ++k)
      if (tet.across[k] >= 0) __builtin_prefetch(&tets_.at(tet.across[k]));
    return simplex_system<3, true>(mesh_, field_, normals_, x);
  }

  // Calls visit(x) for every simplex x of `size` vertices that holds the support (ids[0..n) first in x.ids, in that
  // order) and has a weight system (kFlow: that of the flow, else the weight gradients only; see simplex_system):
  // sub-simplices of the candidate tets, each face or edge once, in candidate order.
  template <bool kFlow, class Visit>
  void simplices_holding(const std::array<int, 4>& ids, int n, const std::vector<int>& candidates, int size,
                         Visit&& visit) const {
    thread_local std::vector<std::array<int, 4>> seen;
    seen.clear();
    for (const int t : candidates) {
      std::array<int, 4> others{{-1, -1, -1, -1}};
      int m = 0;
      const TetRecord& tet = tets_.at(t);
      for (int k = 0; k < 4; ++k) {
        const int v = tet.v[k];
        if (!among(ids, n, v)) others[std::size_t(m++)] = v;
      }
      const int extra = size - n;
      if (extra < 0 || extra > m) continue;
      // Set bits of 0..15: the baseline x86-64 target has no popcount instruction, and __builtin_popcount's libgcc
      // call took 0.4% of cow -> horse's run.
      constexpr int kBits[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};
      for (int mask = 0; mask < (1 << m); ++mask) {  // subsets of `others` with `extra` members
        if (kBits[mask] != extra) continue;
        Simplex x;
        x.size = size;
        if (size == 4) x.tet = t;
        for (int k = 0; k < n; ++k) x.ids[std::size_t(k)] = ids[std::size_t(k)];
        int at = n;
        for (int k = 0; k < m; ++k)
          if (mask & (1 << k)) x.ids[std::size_t(at++)] = others[std::size_t(k)];
        if (size < 4) {
          std::array<int, 4> key = x.ids;
          for (int i = 1; i < size; ++i)  // insertion sort of at most 3 ids
            for (int j = i; j > 0 && key[std::size_t(j - 1)] > key[std::size_t(j)]; --j)
              std::swap(key[std::size_t(j - 1)], key[std::size_t(j)]);
          // Faces and edges have at most 3 ids (the fourth is -1 in every key). Compared by hand: std::array's == is a
          // call to memcmp here, 5% of cow -> horse's tracer instructions (callgrind).
          if (std::any_of(seen.begin(), seen.end(), [&](const std::array<int, 4>& other) {
                return other[0] == key[0] && other[1] == key[1] && other[2] == key[2];
              }))
            continue;
          seen.push_back(key);
        }
        if (!system_of<kFlow>(mesh_, field_, normals_, x)) continue;
        visit(x);
      }
    }
  }

  // simplices_holding over the classes in order, tets first, then faces and edges together (their spans do not nest
  // like a tet's and its faces', and a flow along an edge projects onto a skew face as a feasible but sideways
  // direction); faces and edges only when no tet was found (`found`, which visit sets).
  template <bool kFlow, class Visit>
  void simplices_by_class(const std::array<int, 4>& ids, int n, const std::vector<int>& candidates, const bool& found,
                          Visit&& visit) const {
    for (int size = 4; size >= std::max(2, n) && !(found && size == 3); --size)
      simplices_holding<kFlow>(ids, n, candidates, size, visit);
  }

  // Whether rates r (in x, support first) move the point into x: every weight outside the support grows (a rate
  // near zero means the flow runs along a face of x, which the next class, that face itself, follows) and some
  // weight of the support falls.
  bool feasible(const Weights& r, int size, int n) const {
    double largest = 0.0;  // a loop, not head(size).maxCoeff(), which GCC 12 misreads as out of bounds once inlined
    for (int k = 0; k < size; ++k) largest = std::max(largest, std::abs(r(k)));
    if (!(largest > 0.0)) return false;
    bool moves = false;
    for (int k = 0; k < size; ++k) {
      if (k >= n && r(k) <= options_.rate_tolerance * largest) return false;
      if (k < n && r(k) < 0.0) moves = true;
    }
    return moves;
  }

  // The simplex the point (support ids, weights w, n vertices) moves into: the tets holding the support, else
  // their faces and edges; feasible when every weight outside the support grows and some weight of the support
  // decreases. Tets move the flow along the vertex normal, so in a star that does not fold over its normal
  // exactly one tet is feasible for a generic direction; otherwise the one whose velocity is best aligned with
  // the flow wins, ties to the larger simplex, then to the first found (lowest tet index).
  bool choose(const std::array<int, 4>& ids, const std::array<double, 4>& w, int n, int from_tet, Simplex& best,
              Weights& best_w, Weights& best_r, Stats& stats) const {
    if (!choose_simplex(ids, w, n, from_tet, best, best_w, best_r, stats)) return false;
    set_variation(best);
    return true;
  }

  // choose() before the chosen simplex's step bound (set_variation).
  bool choose_simplex(const std::array<int, 4>& ids, const std::array<double, 4>& w, int n, int from_tet, Simplex& best,
                      Weights& best_w, Weights& best_r, Stats& stats) const {
    Eigen::Vector4d d = Eigen::Vector4d::Zero();
    for (int k = 0; k < n; ++k) d -= w[std::size_t(k)] * field_.row(ids[std::size_t(k)]).transpose();
    bool found = false;
    double best_alignment = 0.0;
    const double d2 = d.squaredNorm();
    if (!(d2 > 0.0)) return false;
    thread_local std::vector<int> candidates;
    support_tets(ids, n, from_tet, candidates);
    Weights xw;
    for (int k = 0; k < 4; ++k) xw(k) = k < n ? w[std::size_t(k)] : 0.0;  // fixed trip count, as in support_key
    auto visit = [&](const Simplex& x) {
      const Weights r = rates(x, xw);
      ++stats.evaluations;
      if (!feasible(r, x.size, n)) return;
      // The projected flow sum_k r_k v_k (rates sum to zero), dotted with d, is its squared length: the
      // fraction of the flow the simplex's span holds. A span that holds d only partly can still pass the
      // feasibility test (the projection of a direction along an edge can point into a skew tet).
      double alignment = 0.0;
      for (int k = 0; k < x.size; ++k) alignment += r(k) * mesh_.V.row(x.ids[std::size_t(k)]).dot(d.transpose());
      alignment /= d2;
      if (!found || alignment > best_alignment + 1e-12) {
        best = x;
        best_w = xw;
        best_r = r;
        best_alignment = alignment;
        found = true;
      }
    };
    if (n == 3 && from_tet >= 0 && candidates.size() == 2) {
      // On the face through which the last piece left from_tet, the flow nearly always enters the tet across it:
      // that one is tried alone first, and from_tet only if it fails (where both are feasible, in a star folded
      // over its normal, the one across now wins instead of the better aligned). A fifth fewer weight systems
      // on cow -> horse.
      // Each tet is built straight into `best` (what visit() would copy there when it is feasible; alone, it needs
      // no alignment to beat).
      auto enter = [&](int t) {
        if (!tet_through_face(ids, t, best)) return false;
        const Weights r = rates(best, xw);
        ++stats.evaluations;
        if (!feasible(r, 4, n)) return false;
        best_w = xw;
        best_r = r;
        return found = true;
      };
      if (enter(candidates[0] == from_tet ? candidates[1] : candidates[0]) || enter(from_tet)) return true;
      simplices_holding<true>(ids, n, candidates, 3, visit);
      return found;
    }
    simplices_by_class<true>(ids, n, candidates, found, visit);
    return found;
  }

  // Steepest descent of s, which is linear in every simplex, from the support (ids, w, n) to A: where the
  // interpolated flow stalls (a sink or an orbit of T, a component whose s is nearly flat), the path of -grad s
  // continues it. In each step the simplex holding the support whose own gradient of s, reversed, enters it and is
  // steepest (tets first, then faces and edges, as in choose()) is crossed in a straight line to the face where
  // it leaves: s falls in every step, so the path cannot circle. False where no simplex descends (s flat, or a
  // local minimum of the discrete s) or after max_steps steps; (ids, w, n) then hold where it stopped.
  bool descend(std::array<int, 4>& ids, std::array<double, 4>& w, int& n, Stats& stats) const {
    thread_local std::vector<int> candidates;
    int from_tet = -1;
    for (int step = 0; step < options_.max_steps; ++step) {
      if (on_a(ids, n)) return true;
      support_tets(ids, n, from_tet, candidates);
      Weights xw = Weights::Zero();
      for (int k = 0; k < n; ++k) xw(k) = w[std::size_t(k)];
      Simplex best;
      Weights best_r;
      double best_slope = 0.0;
      bool found = false;
      simplices_by_class<false>(ids, n, candidates, found, [&](const Simplex& x) {
        Eigen::Vector4d g = Eigen::Vector4d::Zero();  // grad s in x's span
        for (int j = 1; j < x.size; ++j) g += (s_(x.ids[std::size_t(j)]) - s_(x.ids[0])) * x.G.col(j - 1);
        Weights r = Weights::Zero();
        for (int j = 1; j < x.size; ++j) {
          r(j) = -x.G.col(j - 1).dot(g);
          r(0) -= r(j);
        }
        ++stats.evaluations;
        const double slope = g.squaredNorm();
        if (!(slope > 0.0) || !feasible(r, x.size, n)) return;
        if (!found || slope > best_slope * (1.0 + 1e-12)) {
          best = x;
          best_r = r;
          best_slope = slope;
          found = true;
        }
      });
      if (!found) return false;
      // The rates are constant in the simplex: the exit is exact.
      double exit_time = std::numeric_limits<double>::infinity();
      int leaving = -1;
      for (int j = 0; j < n; ++j)
        if (best_r(j) < 0.0 && xw(j) / -best_r(j) < exit_time) {
          exit_time = xw(j) / -best_r(j);
          leaving = j;
        }
      if (leaving < 0) return false;
      Weights next = xw + exit_time * best_r;
      next(leaving) = 0.0;
      for (int j = 0; j < best.size; ++j) next(j) = std::max(next(j), 0.0);
      ++stats.pieces[best.size];
      ++stats.descent_pieces;
      from_tet = best.tet;
      if (!take_support(best, next, ids, w, n)) return false;
    }
    return false;
  }

  // The support (vertices of positive weight, normalised) of the point with weights `weights` in x; false, and
  // (ids, w, n) unchanged, when no weight is positive.
  bool take_support(const Simplex& x, const Weights& weights, std::array<int, 4>& ids, std::array<double, 4>& w,
                    int& n) const {
    int m = 0;
    std::array<int, 4> next_ids{{-1, -1, -1, -1}};
    std::array<double, 4> next_w{{0.0, 0.0, 0.0, 0.0}};
    for (int j = 0; j < x.size; ++j)
      if (weights(j) > options_.weight_epsilon) {
        next_ids[std::size_t(m)] = x.ids[std::size_t(j)];
        next_w[std::size_t(m++)] = weights(j);
      }
    if (m == 0) return false;
    ids = next_ids;
    w = next_w;
    n = m;
    normalise(w, n);
    return true;
  }

  bool on_a(const std::array<int, 4>& ids, int n) const {
    for (int k = 0; k < n; ++k)
      if (mesh_.side[std::size_t(ids[std::size_t(k)])] != VertexSide::A) return false;
    return true;
  }

  const TetMesh4& mesh_;
  const Eigen::VectorXd& s_;
  const TraceOptions& options_;
  Points4 field_;  // #V by 4, smoothed (row-major: a vertex's row in one cache line)
  SharedStars stars_;
  const VertexTets& adj_;
  Points4 normals_;  // #V by 4 unit vertex normals
  // The tet across each face, found up front for every face (face_neighbours, or the extraction's): before 2026-12-07
  // the tracer searched three vertex stars for a face the first time a trace crossed it, 1.31 M searches on cow ->
  // horse (56% of its face crossings, 5% of the run), where settling all 3.3 M faces from the stars takes a fraction
  // of that. Kept beside T's rows (TetRecord): BM_Trace/cow_horse 762-876 -> 721-819 ms, three alternating pairs; and
  // the neighbours' records prefetched on entering a tet (tet_through_face): 718-855 -> 652-750 ms, four pairs.
  // Prefetching also the vertex data beyond the likely exit face, once the piece's first rates are known, was slower
  // (638-697 -> 671-741 ms, four pairs).
  const TetRecords tets_;
};

}  // namespace

std::vector<MeshPoint> edge_points(const Eigen::MatrixXi& edge, const Eigen::VectorXd& w) {
  if (edge.cols() != 2 || edge.rows() != w.size()) throw InvalidInput("edge_points: edge must be #P by 2 and w #P");
  std::vector<MeshPoint> points(static_cast<std::size_t>(edge.rows()));
  for (Eigen::Index i = 0; i < edge.rows(); ++i) {
    MeshPoint& p = points[std::size_t(i)];
    if (edge(i, 0) == edge(i, 1)) {
      p.ids[0] = edge(i, 0);
      p.weights[0] = 1.0;
    } else {
      p.ids = {{edge(i, 0), edge(i, 1), -1, -1}};
      p.weights = {{1.0 - w(i), w(i), 0.0, 0.0}};
    }
  }
  return points;
}

struct CharacteristicTracer::Impl {
  Impl(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& field, const TraceOptions& options,
       const SharedStars& stars, const LatticeFaces* faces)
      : mesh(mesh), options(options), tracer(mesh, s, field, this->options, stars, faces) {}
  const TetMesh4& mesh;
  const TraceOptions options;  // the tracer keeps a reference to this copy
  const Tracer tracer;
  double setup_seconds = 0.0;
};

namespace {

const TetMesh4& checked(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                        const TraceOptions& options) {
  const Eigen::Index nv = mesh.vertex_count();
  if (vertex_field.rows() != nv || vertex_field.cols() != 4)
    throw InvalidInput("trace_to_source: vertex_field must be #V by 4 (" + std::to_string(nv) + " vertices)");
  if (mesh.side.size() != std::size_t(nv)) throw InvalidInput("trace_to_source: mesh.side must have #V entries");
  if (!vertex_field.allFinite()) throw InvalidInput("trace_to_source: vertex_field is not finite");
  if (s.size() != nv || !s.allFinite())
    throw InvalidInput("trace_to_source: s must have one finite value per vertex (" + std::to_string(nv) + ")");
  if (options.progress_window < 1) throw InvalidInput("trace_to_source: progress_window must be at least 1");
  if (options.order != 2 && options.order != 4)
    throw InvalidInput("trace_to_source: order must be 2 or 4 (got " + std::to_string(options.order) + ")");
  return mesh;
}

// The start points in Morton (Z-curve) order of their first vertex's position on a 1024^3 grid over those
// positions' box, ties in start order: neighbouring traces cross the same tets, so a thread that traces them one
// after another finds those tets' rows in its cache (BM_Trace/cow_horse 961-963 -> 942-944 ms, two alternating
// pairs). Only the schedule changes: every trace is independent and stored at its own index.
std::vector<std::size_t> spatial_order(const TetMesh4& mesh, const std::vector<MeshPoint>& starts) {
  const std::size_t count = starts.size();
  std::vector<std::size_t> order(count);
  std::iota(order.begin(), order.end(), std::size_t(0));
  auto vertex_of = [&](std::size_t i) {
    const int v = starts[i].ids[0];
    return v >= 0 && v < mesh.vertex_count() ? v : -1;  // -1: traced as invalid, anywhere in the order
  };
  Eigen::AlignedBox3d box;
  for (std::size_t i = 0; i < count; ++i)
    if (vertex_of(i) >= 0) box.extend(mesh.V.row(vertex_of(i)).head<3>().transpose());
  if (box.isEmpty()) return order;
  const Eigen::Vector3d size = box.sizes();
  std::vector<std::uint32_t> key(count, 0);
  for (std::size_t i = 0; i < count; ++i) {
    const int v = vertex_of(i);
    if (v < 0) continue;
    std::uint32_t cell[3];
    for (int a = 0; a < 3; ++a) {
      const double u = size(a) > 0.0 ? (mesh.V(v, a) - box.min()(a)) / size(a) : 0.0;
      cell[a] = std::uint32_t(std::clamp(u, 0.0, 1.0) * 1023.0);
    }
    std::uint32_t k = 0;
    for (int bit = 9; bit >= 0; --bit)
      for (int a = 0; a < 3; ++a) k = (k << 1) | ((cell[a] >> bit) & 1u);
    key[i] = k;
  }
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key[a] < key[b]; });
  return order;
}

}  // namespace

CharacteristicTracer::CharacteristicTracer(const TetMesh4& mesh, const Eigen::VectorXd& s,
                                           const Eigen::MatrixXd& vertex_field, const TraceOptions& options,
                                           const SharedStars& stars, const LatticeFaces* faces) {
  const auto start_time = std::chrono::steady_clock::now();
  impl_ = std::make_unique<Impl>(checked(mesh, s, vertex_field, options), s, vertex_field, options, stars, faces);
  impl_->setup_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_time).count();
}

CharacteristicTracer::~CharacteristicTracer() = default;

double CharacteristicTracer::setup_seconds() const { return impl_->setup_seconds; }

TraceResult CharacteristicTracer::trace(const std::vector<MeshPoint>& starts) const {
  const auto start_time = std::chrono::steady_clock::now();
  const TetMesh4& mesh = impl_->mesh;
  const Tracer& tracer = impl_->tracer;
  const Eigen::Index nv = mesh.vertex_count();
  const std::size_t count = starts.size();
  TraceResult result;
  result.end = Eigen::MatrixXd::Zero(Eigen::Index(count), 3);
  result.end_point.resize(count);
  result.status.resize(count);
  std::vector<Stats> stats(count);
  const std::vector<std::size_t> order = spatial_order(mesh, starts);
  // Chunks of at most 8 traces (simple_partitioner): a trace takes from a few to 645 pieces, and the auto
  // partitioner's larger chunks left one core idle for the last one on cow -> horse.
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, count, 8),
      [&](const auto& r) {
        for (std::size_t o = r.begin(); o != r.end(); ++o) {
          const std::size_t i = order[o];
          MeshPoint& end = result.end_point[i];
          result.status[i] = tracer.trace(starts[i], end, stats[i]);
          Eigen::Vector3d x = Eigen::Vector3d::Zero();
          for (int k = 0; k < 4; ++k)
            if (end.ids[std::size_t(k)] >= 0 && end.ids[std::size_t(k)] < nv)
              x += end.weights[std::size_t(k)] * mesh.V.row(end.ids[std::size_t(k)]).head<3>().transpose();
          result.end.row(Eigen::Index(i)) = x.transpose();
        }
      },
      tbb::simple_partitioner());
  // Serial sums in start order: the same figures for any thread count.
  for (std::size_t i = 0; i < count; ++i) {
    switch (result.status[i]) {
      case TraceStatus::Reached:
        ++result.reached;
        break;
      case TraceStatus::Stalled:
        ++result.stalled;
        break;
      case TraceStatus::Descended:
        ++result.descended;
        break;
      case TraceStatus::Invalid:
        ++result.invalid;
        break;
    }
    result.edge_pieces += stats[i].pieces[2];
    result.face_pieces += stats[i].pieces[3];
    result.tet_pieces += stats[i].pieces[4];
    result.rate_evaluations += stats[i].evaluations;
    result.descent_pieces += stats[i].descent_pieces;
    result.max_pieces = std::max(result.max_pieces, stats[i].total());
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_time).count();
  return result;
}

TraceResult trace_to_source(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                            const std::vector<MeshPoint>& starts, const TraceOptions& options) {
  const CharacteristicTracer tracer(mesh, s, vertex_field, options);
  TraceResult result = tracer.trace(starts);
  result.seconds += tracer.setup_seconds();
  return result;
}

}  // namespace morphmap
