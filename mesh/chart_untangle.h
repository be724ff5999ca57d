// Fold-free layout of a triangulated disk in the plane with its boundary fixed, from a start that may fold (used by
// the fold repair, mesh/untangle.h, after a Tutte layout whose boundary is not convex). The energy and its schedule
// are Garanzha, Kaporin, Kudryavtseva, Protais, Ray and Sokolov, "Foldover-free maps in 50 lines of code" (ACM TOG
// 2021): each triangle's map J from its reference shape costs ((1 - theta) tr(J^T J) + theta (det^2 J + 1)) /
// chi(det J, eps), chi(D, eps) = (D + sqrt(eps^2 + D^2)) / 2, which is finite for inverted triangles and, as eps
// falls, a barrier against them; eps follows the smallest determinant down. Written by hand: libigl's SLIM and
// CGAL's parameterisations need a start that does not fold, and no Debian library untangles.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace morphmap {

struct ChartUntangleOptions {
  /// Weight of the area term against the shape term. The paper's 1/128 left sphere -> bunny (defaults) with 16 folded
  /// triangles, max stretch 26.2 and variance 0.118 after the repair; 0.5 with 12, 10.5 and 0.111 (0.25: 11, 144,
  /// 0.549; 0.75: 18, 141, 0.134; 0.9: 17, 12.0, 0.105; each figure of the whole repair, which decides patch by patch).
  double theta = 0.5;
  int max_rounds = 200;     ///< updates of eps
  int max_iterations = 40;  ///< L-BFGS iterations for each eps
  int history = 8;          ///< L-BFGS correction pairs
  /// Stop once no triangle folds and a round lowered the energy by less than this fraction.
  double tolerance = 1e-5;
};

struct ChartUntangleResult {
  bool untangled = false;          ///< every triangle positive at the end
  int rounds = 0;                  ///< eps updates run
  int iterations = 0;              ///< L-BFGS iterations, over all rounds
  double smallest_det_before = 0;  ///< smallest det J at the start (negative: folded)
  double smallest_det_after = 0;
};

/// Moves the free vertices of the triangles F (#F by 3, indices into x) so that every triangle comes out positive
/// (counter-clockwise) where the fixed boundary allows it. x: #V by 2 positions, updated in place; fixed: #V flags.
/// reference_inverse[f]: the inverse of triangle f's reference edge matrix [r1 - r0, r2 - r0] (2 by 2, positive
/// determinant), reference_area[f] its area, the weight of its energy. Deterministic (sequential).
ChartUntangleResult untangle_chart(Eigen::MatrixX2d& x, const std::vector<char>& fixed, const Eigen::MatrixX3i& F,
                                   const std::vector<Eigen::Matrix2d>& reference_inverse,
                                   const std::vector<double>& reference_area, const ChartUntangleOptions& options = {});

}  // namespace morphmap
