// Mesh quality for the Laplace stage (Dinh, Yezzi, Turk, TOG 2005, §10: obtuse dihedral angles make the
// cotangent weights of equation 4 negative and the diffusion unstable). Every tet is measured in its own 3D
// hull; the assembled stiffness of every edge is summed in an order fixed by the mesh alone.
#include "mesh/quality.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <utility>

#include "mesh/adjacency.h"
#include "mesh/errors.h"
#include "mesh/stopwatch.h"

namespace morphmap {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Relative to the mean, so the criterion does not depend on the mesh's units.
constexpr double kDegenerateVolumeRatio = 1e-12;

// 6 * volume (cross4 or QR) carries an absolute error of a few ulps of |e1| |e2| |e3|, its Hadamard bound; below
// this ratio it is rounding noise. Needed besides the mean test, which cannot flag a mesh whose tets are all flat.
constexpr double kRoundoffVolumeRatio = 1e-13;

// An assembled K_ij that is zero in exact arithmetic (cube edges of Kuhn tets, whose opposite dihedrals are
// right angles) comes out as a few ulps of the entries' scale with either sign; it is not a negative weight.
constexpr double kRoundoffZeroRatio = 1e-14;

// Same reason for the angles: an exact right dihedral must not count as obtuse at the default threshold.
constexpr double kAngleSlackDegrees = 1e-9;

// Fixed chunk sizes: every per-chunk partial result is merged in chunk order, so the result does not depend
// on how TBB schedules the chunks or on the thread count.
constexpr Eigen::Index kChunkTets = 8192;
constexpr Eigen::Index kChunkVertices = 4096;

// The six edges (i, j) of a tet and, at the same index, the opposite edge (k, l) whose faces meet at (i, j).
constexpr int kEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
constexpr int kOpposite[6][2] = {{2, 3}, {1, 3}, {1, 2}, {0, 3}, {0, 2}, {0, 1}};

std::size_t to_size(Eigen::Index i) { return static_cast<std::size_t>(i); }

void check_input(const TetMesh4& mesh, const QualityOptions& options) {
  if (!(options.histogram_bins >= 1 && options.histogram_bins <= 1000000)) {
    throw InvalidInput("measure_quality: histogram_bins must lie in [1, 1000000]");
  }
  if (!(options.obtuse_threshold_degrees >= 0.0 && options.obtuse_threshold_degrees <= 180.0)) {
    throw InvalidInput("measure_quality: obtuse_threshold_degrees must lie in [0, 180]");
  }
  if (mesh.V.size() > 0 && !mesh.V.allFinite()) throw InvalidInput("measure_quality: non-finite vertex coordinate");
  if (mesh.T.size() == 0) return;
  const auto [lo, hi] = index_range(mesh.T);
  if (lo < 0 || hi >= mesh.V.rows()) {
    std::ostringstream msg;
    msg << "measure_quality: tet vertex index " << (lo < 0 ? lo : hi) << " outside [0, " << mesh.V.rows() << ")";
    throw InvalidInput(msg.str());
  }
}

/// R factor of the QR factorisation of E = [v1 - v0, v2 - v0, v3 - v0] (4 by 3): its columns are the edge vectors in
/// an orthonormal frame of the tet's hull. A sliver's volume is the small R(2, 2), which QR gets to an ulp of the
/// edge lengths while det(E^T E) loses it to rounding. Modified Gram-Schmidt because only R is used, and MGS's R is
/// backward stable like Householder's (Bjorck 1967; it is Householder QR of [0; E]); only its Q drifts.
Eigen::Matrix3d hull_coordinates(const Points4& V, const TetIndices& T, Eigen::Index t) {
  const Eigen::Vector4d v0 = V.row(T(t, 0)).transpose();
  Eigen::Vector4d a = V.row(T(t, 1)).transpose() - v0;
  Eigen::Vector4d b = V.row(T(t, 2)).transpose() - v0;
  Eigen::Vector4d c = V.row(T(t, 3)).transpose() - v0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
  // A zero pivot leaves the later columns unprojected: R(k, k) = 0 already makes the volume 0, without NaN.
  R(0, 0) = a.norm();
  if (R(0, 0) > 0.0) {
    a /= R(0, 0);
    R(0, 1) = a.dot(b);
    b -= R(0, 1) * a;
    R(0, 2) = a.dot(c);
    c -= R(0, 2) * a;
  }
  R(1, 1) = b.norm();
  if (R(1, 1) > 0.0) {
    b /= R(1, 1);
    R(1, 2) = b.dot(c);
    c -= R(1, 2) * b;
  }
  R(2, 2) = c.norm();
  return R;
}

/// Signed 6 * volume of a tet from its hull coordinates.
double hull_determinant(const Eigen::Matrix3d& R) { return R(0, 0) * R(1, 1) * R(2, 2); }

/// 3-volume from the hull coordinates, or 0 where it is rounding noise (or overflowed): such a tet has nothing to
/// measure. R(k, k) carries an absolute error of a few ulps of the edge lengths, so the product's error is a few ulps
/// of |e1| |e2| |e3| (its Hadamard bound), read off R's columns.
double measurable_volume(const Eigen::Matrix3d& R) {
  const double det = std::abs(hull_determinant(R));
  const double hadamard = R.col(0).norm() * R.col(1).norm() * R.col(2).norm();
  return det > kRoundoffVolumeRatio * hadamard && std::isfinite(det) ? det / 6.0 : 0.0;
}

/// Number of leading entries of the decreasing array edge_cos[0 .. count) that are >= c, i.e. the histogram
/// bin of a dihedral with cosine c, from a table over [-1, 1] and a step or two along the edges from its guess: the
/// branch-free halving search it replaces was half of the angle pass (10 M cosines on cow -> horse). Exact for any
/// guess (the steps end where the edges cross c); NaN and cosines outside [-1, 1] take the halving search.
class BinTable {
 public:
  explicit BinTable(const std::vector<double>& edge_cos) : edge_(edge_cos), guess_(kCells) {
    for (int j = 0; j < kCells; ++j) guess_[std::size_t(j)] = halving(-1.0 + 2.0 * (j + 0.5) / kCells);
  }
  int operator()(double c) const {
    if (!(c >= -1.0 && c <= 1.0)) return halving(c);
    int b = guess_[std::size_t(std::min(kCells - 1, int((c + 1.0) * (0.5 * kCells))))];
    const int count = int(edge_.size());
    while (b > 0 && edge_[std::size_t(b - 1)] < c) --b;
    while (b < count && edge_[std::size_t(b)] >= c) ++b;
    return b;
  }

 private:
  static constexpr int kCells = 4096;
  int halving(double c) const {
    const int count = int(edge_.size());
    if (count == 0) return 0;
    const double* base = edge_.data();
    for (int len = count; len > 1;) {
      const int half = len / 2;
      base += base[half] >= c ? half : 0;
      len -= half;
    }
    return int(base - edge_.data()) + (*base >= c ? 1 : 0);
  }
  std::vector<double> edge_;
  std::vector<int> guess_;
};

/// w_k = det * grad(lambda_k) for the four hats, from cross products of the hull coordinates (vertex 0 at the
/// origin): w_1 = p2 x p3 etc., and w_0 from the opposite face's own edges rather than as -(w_1 + w_2 + w_3),
/// which cancels badly for slivers.
void scaled_gradients(const Eigen::Matrix3d& R, Eigen::Vector3d w[4]) {
  const Eigen::Vector3d p1 = R.col(0), p2 = R.col(1), p3 = R.col(2);
  w[0] = (p3 - p1).cross(p2 - p1);
  w[1] = p2.cross(p3);
  w[2] = p3.cross(p1);
  w[3] = p1.cross(p2);
}

struct ChunkStats {
  double min_volume = std::numeric_limits<double>::infinity();
  double min_positive_volume = std::numeric_limits<double>::infinity();
  double volume_sum = 0.0;
};

/// Dihedral extremes are chosen by cosine (cheap, monotone) and evaluated with atan2 only at the end.
struct ChunkAngles {
  double smallest_cos = 2.0;  ///< cosine of the largest dihedral (cos decreases on [0, pi])
  double largest_cos = -2.0;  ///< cosine of the smallest dihedral
  Eigen::Index largest_tet = -1, smallest_tet = -1;
  int largest_edge = 0, smallest_edge = 0;
  std::int64_t obtuse = 0;
  std::int64_t measured_tets = 0;
};

/// Dihedral at local edge e of tet t, in degrees: pi minus the angle between the gradients of the other two hats
/// (inward face normals); atan2 keeps it accurate near 0 and 180 degrees, where acos is not.
double dihedral_degrees(const Points4& V, const TetIndices& T, Eigen::Index t, int e) {
  Eigen::Vector3d w[4];
  scaled_gradients(hull_coordinates(V, T, t), w);
  const Eigen::Vector3d& wk = w[kOpposite[e][0]];
  const Eigen::Vector3d& wl = w[kOpposite[e][1]];
  return std::atan2(wk.cross(wl).norm(), -wk.dot(wl)) * (180.0 / kPi);
}

struct ChunkEdges {
  std::int64_t edges = 0;
  double abs_sum = 0.0;
};

/// Every figure of measure_quality but the edge ones, over a source of per-tet figures: measure(t, floor, cosines)
/// returns the tet's 3-volume (0 when it is rounding noise) and, when that exceeds floor, writes the cosines of its six
/// dihedrals (kEdge order). `usable` (#T) receives which tets are not degenerate, the ones the edge figures sum over.
template <class Measure>
QualityResult angle_figures(const TetMesh4& mesh, const QualityOptions& options, Measure&& measure,
                            std::vector<std::uint8_t>& usable) {
  const Points4& V = mesh.V;
  const TetIndices& T = mesh.T;
  const Eigen::Index tets = T.rows();
  const int bins = options.histogram_bins;

  QualityResult result;
  result.tets = tets;
  result.dihedral_histogram.assign(std::size_t(bins), 0);
  usable.assign(to_size(tets), 0);
  if (tets == 0) return result;

  // One pass over the tets: volume, angles and histogram of every tet whose volume is not rounding noise. Degenerate
  // also means 3-volume <= kDegenerateVolumeRatio * the mean, which is known only after the pass: the chunks holding
  // such a tet (none on the Table II morphs) are measured again without it.
  const Eigen::Index tet_chunks = (tets + kChunkTets - 1) / kChunkTets;
  // Not zeroed: measure_chunk writes every tet's volume, in parallel (a serial zeroing was the first write to 13 MB).
  const std::unique_ptr<double[]> volume(new double[to_size(tets)]);
  std::vector<ChunkStats> volume_stats(to_size(tet_chunks));

  // Angles are classified by cosine against precomputed bin edges, which saves six atan2 per tet; near the
  // classification boundaries (well inside (0, 180)) the cosine is as accurate as the angle.
  std::vector<double> bin_edge_cos(std::size_t(bins - 1));  // cos of the upper edge of bins 0 .. bins-2, decreasing
  for (int b = 1; b < bins; ++b) bin_edge_cos[std::size_t(b - 1)] = std::cos(kPi * b / bins);
  const BinTable bin_of(bin_edge_cos);
  const double obtuse_above = options.obtuse_threshold_degrees + kAngleSlackDegrees;
  const double obtuse_cos =
      obtuse_above >= 180.0 ? -std::numeric_limits<double>::infinity() : std::cos(obtuse_above * (kPi / 180.0));
  const double right_angle_cos = std::sin(kAngleSlackDegrees * (kPi / 180.0));
  std::vector<ChunkAngles> angle_stats(to_size(tet_chunks));
  std::vector<std::int64_t> chunk_histogram(to_size(tet_chunks) * std::size_t(bins), 0);
  // Measures chunk `chunk` (its angle statistics from scratch) over the tets with volume above `floor`.
  auto measure_chunk = [&](Eigen::Index chunk, double floor) {
    ChunkAngles& s = angle_stats[to_size(chunk)];
    s = ChunkAngles{};
    std::int64_t* histogram = chunk_histogram.data() + to_size(chunk) * std::size_t(bins);
    std::fill(histogram, histogram + bins, std::int64_t(0));
    const Eigen::Index end = std::min(tets, (chunk + 1) * kChunkTets);
    double cosines[6];
    for (Eigen::Index t = chunk * kChunkTets; t < end; ++t) {
      volume[to_size(t)] = measure(t, floor, cosines);
      if (!(volume[to_size(t)] > floor)) continue;
      ++s.measured_tets;
      for (int e = 0; e < 6; ++e) {
        // An exact right angle (lattice tets have many) is binned as 90 degrees, not by its rounding noise.
        const double c = std::abs(cosines[e]) < right_angle_cos ? 0.0 : cosines[e];
        if (c < s.smallest_cos) {
          s.smallest_cos = c;
          s.largest_tet = t;
          s.largest_edge = e;
        }
        if (c > s.largest_cos) {
          s.largest_cos = c;
          s.smallest_tet = t;
          s.smallest_edge = e;
        }
        s.obtuse += c < obtuse_cos ? 1 : 0;
        histogram[bin_of(c)] += 1;
      }
    }
    ChunkStats& v = volume_stats[to_size(chunk)];
    v = ChunkStats{};
    for (Eigen::Index t = chunk * kChunkTets; t < end; ++t) {
      const double vol = volume[to_size(t)];
      v.min_volume = std::min(v.min_volume, vol);
      v.volume_sum += vol;
      if (vol > 0.0) v.min_positive_volume = std::min(v.min_positive_volume, vol);
    }
  };
  tbb::parallel_for(Eigen::Index(0), tet_chunks, [&](Eigen::Index chunk) { measure_chunk(chunk, 0.0); });
  double volume_sum = 0.0, min_volume = std::numeric_limits<double>::infinity();
  for (const ChunkStats& s : volume_stats) {
    volume_sum += s.volume_sum;
    min_volume = std::min(min_volume, s.min_volume);
  }
  const double mean_volume = volume_sum / double(tets);
  result.min_volume_ratio = mean_volume > 0.0 ? min_volume / mean_volume : 0.0;
  const double degenerate_volume = kDegenerateVolumeRatio * mean_volume;
  // The volumes do not change when a chunk is measured again, so neither does the mean.
  for (Eigen::Index chunk = 0; chunk < tet_chunks; ++chunk)
    if (!(volume_stats[to_size(chunk)].min_positive_volume > degenerate_volume))
      measure_chunk(chunk, degenerate_volume);
  // Strict: in an all-flat mesh (bound 0) every tet is degenerate, so nothing divides by a zero volume.
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, tets, kChunkTets),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      for (Eigen::Index t = r.begin(); t < r.end(); ++t)
                        usable[to_size(t)] = volume[to_size(t)] > degenerate_volume;
                    });

  // Chunk order and strict comparisons: the first extreme in tet order wins, for any thread count.
  std::int64_t measured_tets = 0;
  ChunkAngles extremes;
  for (Eigen::Index chunk = 0; chunk < tet_chunks; ++chunk) {
    const ChunkAngles& s = angle_stats[to_size(chunk)];
    measured_tets += s.measured_tets;
    result.obtuse_dihedrals += s.obtuse;
    if (s.smallest_cos < extremes.smallest_cos) {
      extremes.smallest_cos = s.smallest_cos;
      extremes.largest_tet = s.largest_tet;
      extremes.largest_edge = s.largest_edge;
    }
    if (s.largest_cos > extremes.largest_cos) {
      extremes.largest_cos = s.largest_cos;
      extremes.smallest_tet = s.smallest_tet;
      extremes.smallest_edge = s.smallest_edge;
    }
    for (int b = 0; b < bins; ++b) {
      result.dihedral_histogram[std::size_t(b)] += chunk_histogram[to_size(chunk) * std::size_t(bins) + std::size_t(b)];
    }
  }
  result.degenerate_tets = tets - measured_tets;
  if (measured_tets > 0) {
    result.min_dihedral_degrees = dihedral_degrees(V, T, extremes.smallest_tet, extremes.smallest_edge);
    result.max_dihedral_degrees = dihedral_degrees(V, T, extremes.largest_tet, extremes.largest_edge);
    result.obtuse_dihedral_fraction = double(result.obtuse_dihedrals) / (6.0 * double(measured_tets));
  }
  return result;
}

/// The edge figures of `result` (edges, negative_cotangent_*): K_ij summed per unique edge (a, b), a < b, at row a,
/// as cotangent_stiffness does: each row walks its vertex's usable tets in tet order (its star, build_vertex_tets),
/// so every sum has one order whatever the thread count; edge(t, e) is tet t's stiffness on its edge e. With `rows`,
/// a vertex that has a row there takes its sums to greater unknowns from it instead of walking its star: the
/// assembly walked the same star in the same order (and (i, j) and (j, i) add the same doubles in the same order,
/// since both stars list the edge's tets in tet order), so those are the same sums, bitwise, whichever end summed
/// them; the vertices without a row (fixed or floating, a few percent of them) walk their stars for every edge to
/// an unknown and to a greater vertex without a row. The sums walked are kept (in row order) until the tolerance,
/// which needs all of them, is known; the rows' are read twice instead.
template <class Edge>
void edge_figures(QualityResult& result, const TetIndices& T, Eigen::Index n, const VertexTets& adj,
                  const std::vector<std::uint8_t>& usable, Edge&& edge, const AssembledRows* rows) {
  const std::vector<int>* row_of = rows != nullptr ? rows->row_of : nullptr;
  auto row = [&](Eigen::Index v) { return row_of != nullptr ? (*row_of)[to_size(v)] : -1; };
  // Entries of row u to columns above u (ascending columns, so a tail of the row): the edges to greater unknowns.
  auto upper_begin = [&](int u) {
    const int* begin = rows->inner + rows->outer[u];
    return int(std::upper_bound(begin, rows->inner + rows->outer[u + 1], u) - rows->inner);
  };
  const Eigen::Index vertex_chunks = (n + kChunkVertices - 1) / kChunkVertices;
  std::vector<std::vector<double>> sums(to_size(vertex_chunks));
  std::vector<ChunkEdges> edge_stats(to_size(vertex_chunks));
  struct Scratch {
    std::vector<int> slot;
    std::vector<std::pair<int, double>> row;
  };
  tbb::enumerable_thread_specific<Scratch> scratch([&] { return Scratch{std::vector<int>(to_size(n), -1), {}}; });
  tbb::parallel_for(Eigen::Index(0), vertex_chunks, [&](Eigen::Index chunk) {
    Scratch& w = scratch.local();
    ChunkEdges& s = edge_stats[to_size(chunk)];
    std::vector<double>& out = sums[to_size(chunk)];
    const Eigen::Index end = std::min(n, (chunk + 1) * kChunkVertices);
    for (Eigen::Index a = chunk * kChunkVertices; a < end; ++a) {
      const int u = row(a);
      if (u >= 0) {
        for (int k = upper_begin(u); k < rows->outer[u + 1]; ++k) {
          s.abs_sum += std::abs(rows->value[k]);
          ++s.edges;
        }
        continue;
      }
      w.row.clear();
      for (std::int64_t q = adj.first(int(a)); q < adj.last(int(a)); ++q) {
        const int t = adj.tet(q);
        if (!usable[std::size_t(t)]) continue;
        for (int e = 0; e < 6; ++e) {
          const int vi = T(t, kEdge[e][0]), vj = T(t, kEdge[e][1]);
          const int b = vi == a ? vj : vj == a ? vi : -1;
          // Not an edge of a, or one that another row sums: b's (the smaller end's), or the assembly's.
          if (b < 0 || (b < a && row(b) < 0)) continue;
          const double value = edge(t, e);
          int& slot = w.slot[std::size_t(b)];
          if (slot < 0) {
            slot = int(w.row.size());
            w.row.emplace_back(b, value);
          } else {
            w.row[std::size_t(slot)].second += value;
          }
        }
      }
      for (const auto& edge : w.row) {
        w.slot[std::size_t(edge.first)] = -1;
        out.push_back(edge.second);
        s.abs_sum += std::abs(edge.second);
      }
      s.edges += std::int64_t(w.row.size());
    }
  });
  double abs_sum = 0.0;
  for (const ChunkEdges& s : edge_stats) {
    result.edges += s.edges;
    abs_sum += s.abs_sum;
  }
  if (result.edges > 0) {
    const double tolerance = kRoundoffZeroRatio * abs_sum / double(result.edges);
    result.negative_cotangent_edges = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, sums.size()), std::int64_t(0),
        [&](const tbb::blocked_range<std::size_t>& r, std::int64_t count) {
          for (std::size_t c = r.begin(); c < r.end(); ++c) {
            for (double v : sums[c]) count += v > tolerance ? 1 : 0;
            if (row_of == nullptr) continue;
            const Eigen::Index end = std::min(n, Eigen::Index(c + 1) * kChunkVertices);
            for (Eigen::Index a = Eigen::Index(c) * kChunkVertices; a < end; ++a) {
              const int u = row(a);
              if (u < 0) continue;
              for (int k = upper_begin(u); k < rows->outer[u + 1]; ++k) count += rows->value[k] > tolerance ? 1 : 0;
            }
          }
          return count;
        },
        [](std::int64_t x, std::int64_t y) { return x + y; });  // integer sum: exact in any order
    result.negative_cotangent_fraction = double(result.negative_cotangent_edges) / double(result.edges);
  }
}

/// measure_quality over a source of per-tet figures (angle_figures' measure, edge_figures' edge).
template <class Measure, class Edge>
QualityResult measure_with(const TetMesh4& mesh, const QualityOptions& options, const SharedStars& stars,
                           Clock::time_point start, Measure&& measure, Edge&& edge) {
  std::vector<std::uint8_t> usable;
  QualityResult result = angle_figures(mesh, options, measure, usable);
  if (mesh.T.rows() > 0) {
    const SharedStars shared = stars_or_build(stars, mesh.T, mesh.V.rows());
    edge_figures(result, mesh.T, mesh.V.rows(), *shared, usable, edge, nullptr);
  }
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace

QualityResult measure_quality(const TetMesh4& mesh, const QualityOptions& options, const SharedStars& stars) {
  const auto start = Clock::now();
  check_input(mesh, options);
  // Each tet's six edge stiffnesses vol * grad(lambda_i) . grad(lambda_j), in kEdge order, written in tet order
  // by the angle pass and summed per edge. Left uninitialised: only usable tets' entries are written and read, so
  // zeroing them (a serial pass over 48 bytes a tet, 80 MB on cow -> horse) would buy nothing.
  const std::unique_ptr<double[]> edge_value(new double[to_size(mesh.T.rows()) * 6]);
  auto measure = [&](Eigen::Index t, double floor, double* cosines) {
    const Eigen::Matrix3d R = hull_coordinates(mesh.V, mesh.T, t);
    const double volume = measurable_volume(R);
    if (!(volume > floor)) return volume;
    Eigen::Vector3d w[4];
    scaled_gradients(R, w);
    const double inverse_norm[4] = {1.0 / w[0].norm(), 1.0 / w[1].norm(), 1.0 / w[2].norm(), 1.0 / w[3].norm()};
    // vol * grad_i . grad_j = (|det| / 6) * (w_i . w_j) / det^2.
    const double stiffness_scale = 1.0 / (6.0 * std::abs(hull_determinant(R)));
    for (int e = 0; e < 6; ++e) {
      const int k = kOpposite[e][0], l = kOpposite[e][1];
      cosines[e] = -w[k].dot(w[l]) * inverse_norm[k] * inverse_norm[l];
      edge_value[to_size(t) * 6 + std::size_t(e)] = w[kEdge[e][0]].dot(w[kEdge[e][1]]) * stiffness_scale;
    }
    return volume;
  };
  auto edge = [&](Eigen::Index t, int e) { return edge_value[to_size(t) * 6 + std::size_t(e)]; };
  return measure_with(mesh, options, stars, start, measure, edge);
}

namespace {

void check_stiffness(const TetMesh4& mesh, const PackedStiffness& stiffness, const Eigen::VectorXd* volume,
                     const std::vector<std::uint8_t>* usable, const char* who) {
  const Eigen::Index tets = mesh.T.rows();
  if (stiffness.rows() != tets || (volume != nullptr && volume->size() != tets) ||
      (usable != nullptr && Eigen::Index(usable->size()) != tets)) {
    std::ostringstream msg;
    msg << who << ": " << stiffness.rows() << " stiffness rows and "
        << (volume != nullptr ? volume->size() : Eigen::Index(usable->size()))
        << (volume != nullptr ? " volumes" : " usable flags") << " for " << tets << " tets";
    throw InvalidInput(msg.str());
  }
}

/// The cosines from the stiffness: the gradients' dot products are the stiffness over the volume, which cancels:
/// cos(dihedral at e) = -g_k . g_l / (|g_k| |g_l|) = -K_kl / sqrt(K_kk K_ll) for the opposite edge (k, l).
auto stiffness_measure(const PackedStiffness& stiffness, const Eigen::VectorXd& volume) {
  return [&stiffness, &volume](Eigen::Index t, double floor, double* cosines) {
    const double v = volume(t);
    if (!(v > floor)) return v;
    double K[4][4];
    unpack_stiffness(stiffness.row(t).data(), K);
    const double inverse_norm[4] = {1.0 / std::sqrt(K[0][0]), 1.0 / std::sqrt(K[1][1]), 1.0 / std::sqrt(K[2][2]),
                                    1.0 / std::sqrt(K[3][3])};
    for (int e = 0; e < 6; ++e) {
      const int k = kOpposite[e][0], l = kOpposite[e][1];
      cosines[e] = -K[k][l] * inverse_norm[k] * inverse_norm[l];
    }
    return v;
  };
}

auto stiffness_edge(const PackedStiffness& stiffness) {
  return [&stiffness](Eigen::Index t, int e) {
    return stiffness_entry(stiffness.row(t).data(), kEdge[e][0], kEdge[e][1]);
  };
}

}  // namespace

QualityResult quality_from_stiffness(const TetMesh4& mesh, const PackedStiffness& stiffness,
                                     const Eigen::VectorXd& volume, const QualityOptions& options,
                                     const SharedStars& stars) {
  const auto start = Clock::now();
  check_input(mesh, options);
  check_stiffness(mesh, stiffness, &volume, nullptr, "quality_from_stiffness");
  return measure_with(mesh, options, stars, start, stiffness_measure(stiffness, volume), stiffness_edge(stiffness));
}

QualityResult quality_angles_from_stiffness(const TetMesh4& mesh, const PackedStiffness& stiffness,
                                            const Eigen::VectorXd& volume, std::vector<std::uint8_t>& usable,
                                            const QualityOptions& options) {
  const auto start = Clock::now();
  check_input(mesh, options);
  check_stiffness(mesh, stiffness, &volume, nullptr, "quality_angles_from_stiffness");
  QualityResult result = angle_figures(mesh, options, stiffness_measure(stiffness, volume), usable);
  result.seconds = seconds_since(start);
  return result;
}

void add_edge_figures(QualityResult& result, const TetMesh4& mesh, const PackedStiffness& stiffness,
                      const std::vector<std::uint8_t>& usable, const SharedStars& stars, const AssembledRows* rows) {
  const auto start = Clock::now();
  check_stiffness(mesh, stiffness, nullptr, &usable, "add_edge_figures");
  if (rows != nullptr && (rows->row_of == nullptr || Eigen::Index(rows->row_of->size()) != mesh.V.rows())) {
    throw InvalidInput("add_edge_figures: the assembled rows need one row index per vertex");
  }
  result.edges = 0;
  result.negative_cotangent_edges = 0;
  result.negative_cotangent_fraction = 0.0;
  if (mesh.T.rows() > 0) {
    const SharedStars shared = stars_or_build(stars, mesh.T, mesh.V.rows());
    edge_figures(result, mesh.T, mesh.V.rows(), *shared, usable, stiffness_edge(stiffness), rows);
  }
  result.seconds += seconds_since(start);
}

}  // namespace morphmap
