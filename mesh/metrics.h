// Texture stretch of a map B -> A (Sander et al. 2001, as used in the paper's §6.3 and Table I), with
// the definitions of DESIGN.md: singular values of the affine map from each preimage triangle on A to
// its triangle on B, normalised by sqrt(area(B) / area(A)) so that 1 means no distortion.
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "mesh/surface.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

class SurfaceLocator;

struct StretchOptions {
  double collapse_ratio =
      1e-12;  ///< a preimage triangle with area below this times the mean preimage area is collapsed
  /// A triangle of B with area below this times B's mean is degenerate: the seam splits' slivers (measured on the
  /// identity morph of the textured sphere at 40 voxels: 593 pieces below 1e-6 of the mean, where the next is at 1e-4;
  /// sphere -> bunny has none below 1e-4).
  double degenerate_ratio = 1e-6;
};

struct StretchResult {
  std::int64_t triangles = 0;  ///< triangles of B
  std::int64_t measured = 0;   ///< triangles entering the statistics (neither collapsed nor degenerate)
  double min_sigma2 = 0.0;     ///< smallest singular value ("compression"), normalised
  double max_sigma1 = 0.0;     ///< largest singular value ("stretch"), normalised
  double mean_l2 = 0.0;        ///< area-weighted (B areas) mean of L2 = sqrt((s1^2 + s2^2) / 2)
  double variance_l2 = 0.0;    ///< area-weighted variance of L2
  double sander_l2 = 0.0;      ///< Sander's L2 norm: sqrt(sum a L2^2 / sum a)
  std::int64_t folded = 0;     ///< preimage triangles facing against A's outward normal
  std::int64_t collapsed = 0;  ///< preimage triangles of (near) zero area (of triangles with area on B)
  /// Triangles of (near) zero area on B itself (below degenerate_ratio times B's mean): pieces of a seam split whose
  /// cut passed through or next to a vertex. They have no stretch to measure and are left out of every figure but the
  /// coverage; counted as collapsed or measured before 2026-12-06, they gave an identity morph of the textured sphere
  /// 173 collapsed triangles and a min compression of 0.
  std::int64_t degenerate = 0;
  double coverage = 0.0;  ///< sum of preimage areas / area(A)
  /// Area-weighted quantiles of L2 over the measured triangles (B areas): the median, 90th and 99th percentile.
  /// A mean is dominated by a few badly compressed triangles; these say how much of B is how distorted.
  double l2_median = 0.0, l2_p90 = 0.0, l2_p99 = 0.0;
  double area_over_2 = 0.0;   ///< fraction of B's measured area with L2 above 2
  double area_over_10 = 0.0;  ///< fraction of B's measured area with L2 above 10
  double area_a = 0.0, area_b = 0.0;
  double seconds = 0.0;
};

/// Singular values (sigma1 >= sigma2), not normalised, of the affine map from the triangle with edge matrix Ep (3 by
/// 2: p1 - p0, p2 - p0) to the one with Eq; NaN where the first is flat. The one definition every figure uses.
Eigen::Vector2d triangle_singular_values(const Eigen::Matrix<double, 3, 2>& Ep, const Eigen::Matrix<double, 3, 2>& Eq);

/// Stretch of the map that sends each vertex of B (V #V by 3, F #F by 3) to its preimage on A
/// (preimages #V by 3, points of A's surface, in A's coordinates). A's outward face normals at the
/// preimage centroids decide folds. `locator`: a SurfaceLocator of A the caller has already (the map's), or null to
/// build one (an Embree scene of A's triangles for every call).
StretchResult measure_stretch(const Surface& A, const Eigen::MatrixXd& V, const TriIndices& F,
                              const Eigen::MatrixXd& preimages, const StretchOptions& options = {},
                              const SurfaceLocator* locator = nullptr);

/// Per-triangle singular values (sigma1 >= sigma2, columns 0 and 1; #F by 2) of the same map, normalised like
/// measure_stretch; NaN rows for the triangles measure_stretch counts as collapsed or degenerate.
Eigen::MatrixX2d singular_values_per_triangle(const Surface& A, const Eigen::MatrixXd& V, const TriIndices& F,
                                              const Eigen::MatrixXd& preimages, const StretchOptions& options = {});

/// Per-triangle L2 stretch sqrt((s1^2 + s2^2) / 2) of the same map, normalised like measure_stretch (#F values);
/// NaN for the triangles measure_stretch counts as collapsed or degenerate. For stretch heat maps.
Eigen::VectorXd stretch_per_triangle(const Surface& A, const Eigen::MatrixXd& V, const TriIndices& F,
                                     const Eigen::MatrixXd& preimages, const StretchOptions& options = {});

}  // namespace morphmap
