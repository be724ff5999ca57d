// Tangent field T = grad s on the tetrahedral 3-manifold in R^4 (paper §6.2). The paper's equation 5 fits a
// linear function through the origin; we fit the affine one inside each tet's hull instead,
// grad s = E (E^T E)^-1 [s1 - s0, s2 - s0, s3 - s0]^T (evaluated through QR), which is exact for affine s and
// independent of where the origin lies. Vertex values are the volume-weighted average of the incident tets, as in the
// paper.
#include "solver/gradient.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>

#include "mesh/adjacency.h"
#include "mesh/errors.h"
#include "solver/laplace.h"

namespace morphmap {
namespace {

// A vertex whose weighted sum is this small relative to the sum of the magnitudes it came from sits where
// the gradients cancel (an extremum or saddle of s): it has no direction, and normalising rounding noise
// would invent one.
constexpr double kCancellationRatio = 1e-12;

/// E (E^T E)^-1 ds for E 4 by 3 of full rank, as Q R^-T ds with E = Q R by Gram-Schmidt with one
/// reorthogonalisation per column ("twice is enough", Giraud et al. 2005: Q orthonormal to rounding level, as
/// Householder's, for any E of numerical full rank). Written out because Eigen's HouseholderQR works on dynamic
/// blocks even at this size and took a tenth of cow -> horse's whole run.
Eigen::Vector4d qr_gradient(const Eigen::Matrix<double, 4, 3>& E, const Eigen::Vector3d& ds) {
  Eigen::Matrix<double, 4, 3> Q;
  Eigen::Matrix3d R = Eigen::Matrix3d::Zero();
  for (int j = 0; j < 3; ++j) {
    Eigen::Vector4d v = E.col(j);
    for (int pass = 0; pass < 2; ++pass)
      for (int i = 0; i < j; ++i) {
        const double c = Q.col(i).dot(v);
        R(i, j) += c;
        v -= c * Q.col(i);
      }
    R(j, j) = v.norm();
    Q.col(j) = v / R(j, j);
  }
  // y = R^-T ds by forward substitution.
  Eigen::Vector3d y;
  for (int i = 0; i < 3; ++i) {
    double sum = ds(i);
    for (int k = 0; k < i; ++k) sum -= R(k, i) * y(k);
    y(i) = sum / R(i, i);
  }
  return Q * y;
}

}  // namespace

GradientResult compute_gradient(const TetMesh4& mesh, const Eigen::VectorXd& s, const SharedStars& stars) {
  const auto start = std::chrono::steady_clock::now();
  const Points4& V = mesh.V;
  const TetIndices& T = mesh.T;
  const Eigen::Index n = V.rows();
  const Eigen::Index tets = T.rows();
  if (V.cols() != 4) throw InvalidInput("compute_gradient: vertex array must have 4 columns (x, y, z, tau)");
  if (s.size() != n) {
    std::ostringstream msg;
    msg << "compute_gradient: s has " << s.size() << " entries for " << n << " vertices";
    throw InvalidInput(msg.str());
  }
  if (const auto [lo, hi] = index_range(T); tets > 0 && (lo < 0 || hi >= n)) {
    throw InvalidInput("compute_gradient: tet vertex index out of range");
  }

  GradientResult result;
  // Sized without zeroing, every row written by the parallel loop: a serial setZero was the first write to 66 MB
  // on cow -> horse, and first writes cost most on these virtual machines (docs/performance_log.md, 2026-12-03).
  result.tet_gradient.resize(tets, 4);
  result.tet_volume.resize(tets);
  tbb::parallel_for(Eigen::Index(0), tets, [&](Eigen::Index t) {
    Eigen::Matrix<double, 4, 3> E;
    double volume = 0.0;
    // Degenerate tets have no hull to take a gradient in: zero gradient, zero weight.
    if (!tet_frame(V, T, t, E, volume)) {
      result.tet_gradient.row(t).setZero();
      result.tet_volume(t) = 0.0;
      return;
    }
    const Eigen::Vector3d ds(s(T(t, 1)) - s(T(t, 0)), s(T(t, 2)) - s(T(t, 0)), s(T(t, 3)) - s(T(t, 0)));
    // With E = Q R, E (E^T E)^-1 ds = Q R^-T ds: the QR form has E's conditioning instead of its square,
    // which matters on the slivers next to lattice points (identity morph: T off by 3e-9 with the Gram inverse).
    result.tet_gradient.row(t) = qr_gradient(E, ds).transpose();
    result.tet_volume(t) = volume;
  });
  // Each tet's |gradient|, once: the vertex pass below reads it from all four of the tet's stars (6.7 M square roots
  // on cow -> horse where 1.7 M do). The same expression as there, so the same bits. Not zeroed: every entry is
  // written.
  const std::unique_ptr<double[]> tet_norm(new double[std::size_t(tets)]);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, tets, 1 << 14), [&](const tbb::blocked_range<Eigen::Index>& r) {
    for (Eigen::Index t = r.begin(); t != r.end(); ++t) tet_norm[std::size_t(t)] = result.tet_gradient.row(t).norm();
  });

  // Each vertex sums its star in tet order (build_vertex_tets): one fixed order whatever the thread count.
  const SharedStars shared = stars_or_build(stars, T, n);
  const VertexTets& adj = *shared;

  // Not zeroed first: every row is written below, so the parallel pass is the first touch of its 9.5 MB (cow -> horse).
  result.vertex_field.resize(n, 4);
  tbb::parallel_for(Eigen::Index(0), n, [&](Eigen::Index i) {
    Eigen::RowVector4d sum = Eigen::RowVector4d::Zero();
    double magnitude = 0.0;
    for (std::int64_t k = adj.first(int(i)); k < adj.last(int(i)); ++k) {
      const Eigen::Index t = adj.tet(k);
      const double w = result.tet_volume(t);
      sum += w * result.tet_gradient.row(t);
      magnitude += w * tet_norm[std::size_t(t)];
    }
    const double norm = sum.norm();
    if (norm > kCancellationRatio * magnitude && std::isfinite(norm))
      result.vertex_field.row(i) = sum / norm;
    else
      result.vertex_field.row(i).setZero();
  });

  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace morphmap
