// Mesh quality for the Laplace stage (Dinh, Yezzi, Turk, TOG 2005, §10: obtuse dihedral angles make the
// cotangent weights of equation 4 negative and the diffusion unstable). Every tet is measured in its own 3D
// hull; the assembled stiffness of every edge is summed in an order fixed by the mesh alone.
#include "mesh/quality.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <utility>

#include "mesh/errors.h"

namespace morphmap {
namespace {

using Clock = std::chrono::steady_clock;

constexpr double kPi = 3.14159265358979323846;

// Relative to the mean, so the criterion does not depend on the mesh's units.
constexpr double kDegenerateVolumeRatio = 1e-12;

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
  if (!(options.histogram_bins >= 1)) throw InvalidInput("measure_quality: histogram_bins must be at least 1");
  if (!(options.obtuse_threshold_degrees >= 0.0 && options.obtuse_threshold_degrees <= 180.0)) {
    throw InvalidInput("measure_quality: obtuse_threshold_degrees must lie in [0, 180]");
  }
  if (mesh.V.size() > 0 && !mesh.V.allFinite()) throw InvalidInput("measure_quality: non-finite vertex coordinate");
  if (mesh.T.size() == 0) return;
  const int lo = mesh.T.minCoeff();
  const int hi = mesh.T.maxCoeff();
  if (lo < 0 || hi >= mesh.V.rows()) {
    std::ostringstream msg;
    msg << "measure_quality: tet vertex index " << (lo < 0 ? lo : hi) << " outside [0, " << mesh.V.rows() << ")";
    throw InvalidInput(msg.str());
  }
}

/// R factor of the Householder QR of E = [v1 - v0, v2 - v0, v3 - v0]: its columns are the edge vectors in an
/// orthonormal frame of the tet's hull. Householder rather than the Gram matrix because a sliver's volume is
/// the small R(2, 2), which Householder gets to an ulp of the edge lengths, while det(E^T E) loses it.
Eigen::Matrix3d hull_coordinates(const Points4& V, const TetIndices& T, Eigen::Index t) {
  Eigen::Matrix<double, 4, 3> A;
  for (int c = 0; c < 3; ++c) A.col(c) = (V.row(T(t, c + 1)) - V.row(T(t, 0))).transpose();
  for (int k = 0; k < 3; ++k) {
    const int m = 4 - k;
    const double norm = A.col(k).tail(m).norm();
    if (norm == 0.0) continue;  // column already zero below the diagonal: R(k, k) = 0, nothing to reflect
    // alpha has the opposite sign of x(0) so that v = x - alpha e_0 suffers no cancellation (and v != 0).
    const double alpha = A(k, k) > 0.0 ? -norm : norm;
    Eigen::Vector4d v = Eigen::Vector4d::Zero();
    v.head(m) = A.col(k).tail(m);
    v(0) -= alpha;
    const double vv = v.head(m).squaredNorm();
    for (int j = k + 1; j < 3; ++j) {
      const double scale = 2.0 * v.head(m).dot(A.col(j).tail(m)) / vv;
      A.col(j).tail(m) -= scale * v.head(m);
    }
    A(k, k) = alpha;
  }
  Eigen::Matrix3d R = A.topRows<3>();
  R(1, 0) = R(2, 0) = R(2, 1) = 0.0;
  return R;
}

/// Signed 6 * volume of a tet from its hull coordinates.
double hull_determinant(const Eigen::Matrix3d& R) { return R(0, 0) * R(1, 1) * R(2, 2); }

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
  double volume_sum = 0.0;
};

struct ChunkAngles {
  double min_dihedral = std::numeric_limits<double>::infinity();
  double max_dihedral = -std::numeric_limits<double>::infinity();
  std::int64_t obtuse = 0;
  std::int64_t measured_tets = 0;
};

struct ChunkEdges {
  std::int64_t edges = 0;
  double abs_sum = 0.0;
};

}  // namespace

QualityResult measure_quality(const TetMesh4& mesh, const QualityOptions& options) {
  const auto start = Clock::now();
  check_input(mesh, options);
  const Points4& V = mesh.V;
  const TetIndices& T = mesh.T;
  const Eigen::Index tets = T.rows();
  const Eigen::Index n = V.rows();
  const int bins = options.histogram_bins;

  QualityResult result;
  result.tets = tets;
  result.dihedral_histogram.assign(std::size_t(bins), 0);
  if (tets == 0) {
    result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    return result;
  }

  // Volumes first: the degenerate threshold needs the mean over the whole mesh.
  const Eigen::Index tet_chunks = (tets + kChunkTets - 1) / kChunkTets;
  std::vector<double> volume(to_size(tets));
  std::vector<ChunkStats> volume_stats(to_size(tet_chunks));
  tbb::parallel_for(Eigen::Index(0), tet_chunks, [&](Eigen::Index chunk) {
    ChunkStats& s = volume_stats[to_size(chunk)];
    const Eigen::Index end = std::min(tets, (chunk + 1) * kChunkTets);
    for (Eigen::Index t = chunk * kChunkTets; t < end; ++t) {
      double vol = std::abs(hull_determinant(hull_coordinates(V, T, t))) / 6.0;
      if (!std::isfinite(vol)) vol = 0.0;  // overflow of huge coordinates: nothing usable to measure
      volume[to_size(t)] = vol;
      s.min_volume = std::min(s.min_volume, vol);
      s.volume_sum += vol;
    }
  });
  double volume_sum = 0.0, min_volume = std::numeric_limits<double>::infinity();
  for (const ChunkStats& s : volume_stats) {
    volume_sum += s.volume_sum;
    min_volume = std::min(min_volume, s.min_volume);
  }
  const double mean_volume = volume_sum / double(tets);
  result.min_volume_ratio = mean_volume > 0.0 ? min_volume / mean_volume : 0.0;
  const double degenerate_volume = kDegenerateVolumeRatio * mean_volume;
  // Written as !(vol > bound) so that an all-flat mesh (bound 0) has only degenerate tets and no division by 0.
  auto usable = [&](Eigen::Index t) { return volume[to_size(t)] > degenerate_volume; };

  // Bucket every tet edge (a, b), a < b, under its smaller vertex a: a counting sort keyed by a, so that
  // summing K_ij needs only small per-vertex sorts instead of one global sort of all tet edges.
  std::unique_ptr<std::atomic<std::int32_t>[]> fill(new std::atomic<std::int32_t>[to_size(n)]);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, n), [&](const tbb::blocked_range<Eigen::Index>& r) {
    for (Eigen::Index i = r.begin(); i < r.end(); ++i) fill[to_size(i)].store(0, std::memory_order_relaxed);
  });
  tbb::parallel_for(Eigen::Index(0), tet_chunks, [&](Eigen::Index chunk) {
    const Eigen::Index end = std::min(tets, (chunk + 1) * kChunkTets);
    for (Eigen::Index t = chunk * kChunkTets; t < end; ++t) {
      if (!usable(t)) continue;
      for (const auto& e : kEdge) {
        fill[to_size(std::min(T(t, e[0]), T(t, e[1])))].fetch_add(1, std::memory_order_relaxed);
      }
    }
  });
  std::vector<std::int64_t> offset(to_size(n) + 1, 0);
  for (Eigen::Index i = 0; i < n; ++i) {
    offset[to_size(i) + 1] = offset[to_size(i)] + fill[to_size(i)].load(std::memory_order_relaxed);
    fill[to_size(i)].store(0, std::memory_order_relaxed);
  }
  // Structure of arrays: 12 bytes per tet edge instead of a padded 16-byte pair.
  std::vector<int> other(std::size_t(offset.back()));
  std::vector<double> value(std::size_t(offset.back()));

  // Angles, histogram and the per-tet stiffness. The slot order inside a bucket depends on the scheduling;
  // the per-vertex sort below removes that before anything is summed.
  std::vector<ChunkAngles> angle_stats(to_size(tet_chunks));
  std::vector<std::int64_t> chunk_histogram(to_size(tet_chunks) * std::size_t(bins), 0);
  const double obtuse_above = options.obtuse_threshold_degrees + kAngleSlackDegrees;
  tbb::parallel_for(Eigen::Index(0), tet_chunks, [&](Eigen::Index chunk) {
    ChunkAngles& s = angle_stats[to_size(chunk)];
    std::int64_t* histogram = chunk_histogram.data() + to_size(chunk) * std::size_t(bins);
    const Eigen::Index end = std::min(tets, (chunk + 1) * kChunkTets);
    Eigen::Vector3d w[4];
    for (Eigen::Index t = chunk * kChunkTets; t < end; ++t) {
      if (!usable(t)) continue;
      const Eigen::Matrix3d R = hull_coordinates(V, T, t);
      scaled_gradients(R, w);
      // vol * grad_i . grad_j = (|det| / 6) * (w_i . w_j) / det^2.
      const double stiffness_scale = 1.0 / (6.0 * std::abs(hull_determinant(R)));
      ++s.measured_tets;
      for (int e = 0; e < 6; ++e) {
        // The dihedral at edge ij is pi minus the angle between the gradients of the other two hats (the
        // inward face normals); atan2 keeps it accurate near 0 and 180 degrees, where acos is not.
        const Eigen::Vector3d& wk = w[kOpposite[e][0]];
        const Eigen::Vector3d& wl = w[kOpposite[e][1]];
        const double dihedral = std::atan2(wk.cross(wl).norm(), -wk.dot(wl)) * (180.0 / kPi);
        s.min_dihedral = std::min(s.min_dihedral, dihedral);
        s.max_dihedral = std::max(s.max_dihedral, dihedral);
        s.obtuse += dihedral > obtuse_above ? 1 : 0;
        histogram[std::min(bins - 1, int(dihedral * bins / 180.0))] += 1;

        const int vi = T(t, kEdge[e][0]), vj = T(t, kEdge[e][1]);
        const int a = std::min(vi, vj);
        const std::int64_t slot = offset[to_size(a)] + fill[to_size(a)].fetch_add(1, std::memory_order_relaxed);
        other[std::size_t(slot)] = std::max(vi, vj);
        value[std::size_t(slot)] = w[kEdge[e][0]].dot(w[kEdge[e][1]]) * stiffness_scale;
      }
    }
  });

  std::int64_t measured_tets = 0;
  result.min_dihedral_degrees = std::numeric_limits<double>::infinity();
  result.max_dihedral_degrees = -std::numeric_limits<double>::infinity();
  for (Eigen::Index chunk = 0; chunk < tet_chunks; ++chunk) {
    const ChunkAngles& s = angle_stats[to_size(chunk)];
    measured_tets += s.measured_tets;
    result.obtuse_dihedrals += s.obtuse;
    result.min_dihedral_degrees = std::min(result.min_dihedral_degrees, s.min_dihedral);
    result.max_dihedral_degrees = std::max(result.max_dihedral_degrees, s.max_dihedral);
    for (int b = 0; b < bins; ++b) {
      result.dihedral_histogram[std::size_t(b)] += chunk_histogram[to_size(chunk) * std::size_t(bins) + std::size_t(b)];
    }
  }
  result.degenerate_tets = tets - measured_tets;
  if (measured_tets == 0) {
    result.min_dihedral_degrees = result.max_dihedral_degrees = 0.0;
  } else {
    result.obtuse_dihedral_fraction = double(result.obtuse_dihedrals) / (6.0 * double(measured_tets));
  }

  // Assemble K_ij per unique edge: sort each bucket by (b, value) -- a total order, so the summation order is
  // fixed by the values alone -- and sum runs, writing the sums compacted to the front of the bucket.
  const Eigen::Index vertex_chunks = (n + kChunkVertices - 1) / kChunkVertices;
  std::vector<ChunkEdges> edge_stats(to_size(vertex_chunks));
  tbb::parallel_for(Eigen::Index(0), vertex_chunks, [&](Eigen::Index chunk) {
    ChunkEdges& s = edge_stats[to_size(chunk)];
    std::vector<std::pair<int, double>> bucket;  // one allocation per chunk, reused for each vertex
    const Eigen::Index end = std::min(n, (chunk + 1) * kChunkVertices);
    for (Eigen::Index a = chunk * kChunkVertices; a < end; ++a) {
      const std::size_t begin = std::size_t(offset[to_size(a)]), stop = std::size_t(offset[to_size(a) + 1]);
      bucket.clear();
      for (std::size_t k = begin; k < stop; ++k) bucket.emplace_back(other[k], value[k]);
      std::sort(bucket.begin(), bucket.end());
      std::size_t out = begin;
      for (std::size_t k = 0; k < bucket.size();) {
        double sum = 0.0;
        const int b = bucket[k].first;
        for (; k < bucket.size() && bucket[k].first == b; ++k) sum += bucket[k].second;
        other[out] = b;
        value[out] = sum;
        ++out;
        s.abs_sum += std::abs(sum);
      }
      s.edges += std::int64_t(out - begin);
      fill[to_size(a)].store(std::int32_t(out - begin), std::memory_order_relaxed);
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
        tbb::blocked_range<Eigen::Index>(0, n), std::int64_t(0),
        [&](const tbb::blocked_range<Eigen::Index>& r, std::int64_t count) {
          for (Eigen::Index a = r.begin(); a < r.end(); ++a) {
            const std::size_t begin = std::size_t(offset[to_size(a)]);
            const std::size_t stop = begin + std::size_t(fill[to_size(a)].load(std::memory_order_relaxed));
            for (std::size_t k = begin; k < stop; ++k) count += value[k] > tolerance ? 1 : 0;
          }
          return count;
        },
        [](std::int64_t x, std::int64_t y) { return x + y; });  // integer sum: exact in any order
    result.negative_cotangent_fraction = double(result.negative_cotangent_edges) / double(result.edges);
  }
  result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return result;
}

}  // namespace morphmap
