// Sander et al. 2001 texture stretch for the map B -> A (paper §6.3, Table I).
#include "mesh/metrics.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include "mesh/errors.h"
#include "mesh/transfer.h"

namespace morphmap {

namespace {

// Per-triangle pieces of the map from each preimage triangle (on A) to its triangle of B, shared by the
// statistics and the per-triangle values so both use one definition.
struct TriangleMaps {
  Eigen::VectorXd area_b, area_p, sigma1, sigma2;  // sigma NaN where the preimage triangle is flat
  Eigen::MatrixXd centroid;                        // preimage centroids, #F by 3
  std::vector<Eigen::Vector3d> normal_p;           // unnormalised preimage normals
};

void check_stretch_inputs(const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& preimages) {
  if (V.cols() != 3 || preimages.cols() != 3 || preimages.rows() != V.rows())
    throw InvalidInput("measure_stretch: need #V by 3 positions and one preimage per vertex (" +
                       std::to_string(preimages.rows()) + " preimages for " + std::to_string(V.rows()) + " vertices)");
  if (F.rows() > 0 && (F.minCoeff() < 0 || F.maxCoeff() >= V.rows()))
    throw InvalidInput("measure_stretch: face index out of range");
}

TriangleMaps triangle_maps(const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& preimages,
                           double normalise) {
  TriangleMaps m;
  const Eigen::Index n = F.rows();
  m.area_b.resize(n);
  m.area_p.resize(n);
  m.sigma1.resize(n);
  m.sigma2.resize(n);
  m.centroid.resize(n, 3);
  m.normal_p.resize(static_cast<std::size_t>(n));
  Eigen::VectorXd &area_b = m.area_b, &area_p = m.area_p, &sigma1 = m.sigma1, &sigma2 = m.sigma2;
  Eigen::MatrixXd& centroid = m.centroid;
  std::vector<Eigen::Vector3d>& normal_p = m.normal_p;
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, n), [&](const tbb::blocked_range<Eigen::Index>& range) {
    for (Eigen::Index f = range.begin(); f != range.end(); ++f) {
      const Eigen::Vector3d q0 = V.row(F(f, 0)), q1 = V.row(F(f, 1)), q2 = V.row(F(f, 2));
      const Eigen::Vector3d p0 = preimages.row(F(f, 0)), p1 = preimages.row(F(f, 1)), p2 = preimages.row(F(f, 2));
      Eigen::Matrix<double, 3, 2> Ep, Eq;
      Ep << p1 - p0, p2 - p0;
      Eq << q1 - q0, q2 - q0;
      normal_p[std::size_t(f)] = Ep.col(0).cross(Ep.col(1));
      area_p(f) = 0.5 * normal_p[std::size_t(f)].norm();
      area_b(f) = 0.5 * Eq.col(0).cross(Eq.col(1)).norm();
      centroid.row(f) = ((p0 + p1 + p2) / 3.0).transpose();
      const Eigen::Vector2d sigma = triangle_singular_values(Ep, Eq);
      sigma1(f) = sigma(0) / normalise;
      sigma2(f) = sigma(1) / normalise;
    }
  });

  return m;
}

bool collapsed(const TriangleMaps& maps, Eigen::Index f, double mean_preimage_area, const StretchOptions& options) {
  return !(maps.area_p(f) > options.collapse_ratio * mean_preimage_area) || !std::isfinite(maps.sigma1(f));
}

bool degenerate(const TriangleMaps& maps, Eigen::Index f, double mean_area_b, const StretchOptions& options) {
  return !(maps.area_b(f) > options.degenerate_ratio * mean_area_b);
}

}  // namespace

Eigen::Vector2d triangle_singular_values(const Eigen::Matrix<double, 3, 2>& Ep, const Eigen::Matrix<double, 3, 2>& Eq) {
  // Square roots of the eigenvalues of (Ep^T Ep)^-1 Eq^T Eq, i.e. of the generalised symmetric problem
  // Eq^T Eq x = lambda Ep^T Ep x.
  const Eigen::Matrix2d P = Ep.transpose() * Ep, Q = Eq.transpose() * Eq;
  if (!(P.determinant() > 0.0)) return Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
  const Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::Matrix2d> eig(Q, P, Eigen::EigenvaluesOnly);
  const Eigen::Vector2d lambda = eig.eigenvalues().cwiseMax(0.0);
  return Eigen::Vector2d(std::sqrt(lambda(1)), std::sqrt(lambda(0)));
}

StretchResult measure_stretch(const Surface& A, const Eigen::MatrixXd& V, const TriIndices& F,
                              const Eigen::MatrixXd& preimages, const StretchOptions& options,
                              const SurfaceLocator* given_locator) {
  const auto start = std::chrono::steady_clock::now();
  check_stretch_inputs(V, F, preimages);
  StretchResult r;
  r.triangles = F.rows();
  r.area_a = surface_area(A.V, A.F);
  const Eigen::MatrixXi Fi = F.cast<int>();
  r.area_b = surface_area(V, Fi);
  if (!(r.area_a > 0.0) || !(r.area_b > 0.0)) throw InvalidInput("measure_stretch: a surface has zero area");
  const double normalise = std::sqrt(r.area_b / r.area_a);

  const TriangleMaps maps = triangle_maps(V, F, preimages, normalise);
  const Eigen::Index n = F.rows();
  const Eigen::VectorXd &area_b = maps.area_b, &area_p = maps.area_p, &sigma1 = maps.sigma1, &sigma2 = maps.sigma2;
  const Eigen::MatrixXd& centroid = maps.centroid;
  const std::vector<Eigen::Vector3d>& normal_p = maps.normal_p;

  // Folds: the preimage triangle's normal against A's outward normal at its centroid.
  std::optional<SurfaceLocator> own_locator;
  const SurfaceLocator& locator = given_locator != nullptr ? *given_locator : own_locator.emplace(A);
  const std::vector<SurfaceHit> hits = locator.closest_all(centroid);
  const double mean_preimage_area = area_p.sum() / std::max<Eigen::Index>(1, n);
  const double mean_area_b = area_b.sum() / std::max<Eigen::Index>(1, n);
  double weight = 0.0, sum = 0.0, sum2 = 0.0;
  std::vector<std::pair<double, double>> l2_area;  // (L2, B area) of measured triangles, for the quantiles
  r.min_sigma2 = std::numeric_limits<double>::infinity();
  r.max_sigma1 = 0.0;
  for (Eigen::Index f = 0; f < n; ++f) {
    r.coverage += area_p(f);
    if (degenerate(maps, f, mean_area_b, options)) {
      ++r.degenerate;
      continue;
    }
    if (collapsed(maps, f, mean_preimage_area, options)) {
      ++r.collapsed;
      continue;
    }
    const int face = hits[std::size_t(f)].face;
    const Eigen::Vector3d a0 = A.V.row(A.F(face, 0)), a1 = A.V.row(A.F(face, 1)), a2 = A.V.row(A.F(face, 2));
    if (normal_p[std::size_t(f)].dot((a1 - a0).cross(a2 - a0)) < 0.0) ++r.folded;
    ++r.measured;
    r.min_sigma2 = std::min(r.min_sigma2, sigma2(f));
    r.max_sigma1 = std::max(r.max_sigma1, sigma1(f));
    const double l2 = std::sqrt(0.5 * (sigma1(f) * sigma1(f) + sigma2(f) * sigma2(f)));
    weight += area_b(f);
    sum += area_b(f) * l2;
    sum2 += area_b(f) * l2 * l2;
    l2_area.emplace_back(l2, area_b(f));
  }
  if (weight > 0.0) {
    // Pairs equal only when identical, so any sort gives this sequence; in parallel, as it was a tenth of the stage.
    tbb::parallel_sort(l2_area.begin(), l2_area.end());
    double below = 0.0;
    const std::array<double, 3> levels{{0.5, 0.9, 0.99}};
    std::array<double*, 3> quantile{{&r.l2_median, &r.l2_p90, &r.l2_p99}};
    std::size_t next = 0;
    for (const auto& [l2, area] : l2_area) {
      below += area;
      while (next < levels.size() && below >= levels[next] * weight) *quantile[next++] = l2;
      if (l2 > 2.0) r.area_over_2 += area / weight;
      if (l2 > 10.0) r.area_over_10 += area / weight;
    }
    for (; next < levels.size(); ++next) *quantile[next] = l2_area.back().first;
  }
  r.coverage /= r.area_a;
  if (weight > 0.0) {
    r.mean_l2 = sum / weight;
    r.variance_l2 = std::max(0.0, sum2 / weight - r.mean_l2 * r.mean_l2);
    r.sander_l2 = std::sqrt(sum2 / weight);
  }
  if (r.measured == 0) r.min_sigma2 = 0.0;
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return r;
}

Eigen::MatrixX2d singular_values_per_triangle(const Surface& A, const Eigen::MatrixXd& V, const TriIndices& F,
                                              const Eigen::MatrixXd& preimages, const StretchOptions& options) {
  check_stretch_inputs(V, F, preimages);
  const double area_a = surface_area(A.V, A.F), area_b = surface_area(V, F.cast<int>());
  if (!(area_a > 0.0) || !(area_b > 0.0)) throw InvalidInput("singular_values_per_triangle: a surface has zero area");
  const TriangleMaps maps = triangle_maps(V, F, preimages, std::sqrt(area_b / area_a));
  const Eigen::Index n = F.rows();
  const double mean_preimage_area = maps.area_p.sum() / std::max<Eigen::Index>(1, n);
  const double mean_area_b = maps.area_b.sum() / std::max<Eigen::Index>(1, n);
  Eigen::MatrixX2d sigma(n, 2);
  for (Eigen::Index f = 0; f < n; ++f) {
    if (collapsed(maps, f, mean_preimage_area, options) || degenerate(maps, f, mean_area_b, options))
      sigma.row(f).setConstant(std::numeric_limits<double>::quiet_NaN());
    else
      sigma.row(f) << maps.sigma1(f), maps.sigma2(f);
  }
  return sigma;
}

Eigen::VectorXd stretch_per_triangle(const Surface& A, const Eigen::MatrixXd& V, const TriIndices& F,
                                     const Eigen::MatrixXd& preimages, const StretchOptions& options) {
  const Eigen::MatrixX2d sigma = singular_values_per_triangle(A, V, F, preimages, options);
  Eigen::VectorXd l2(sigma.rows());
  for (Eigen::Index f = 0; f < sigma.rows(); ++f)  // NaN rows stay NaN
    l2(f) = std::sqrt(0.5 * (sigma(f, 0) * sigma(f, 0) + sigma(f, 1) * sigma(f, 1)));
  return l2;
}

}  // namespace morphmap
