// Gradient field T = grad s on the tetrahedral mesh in R^4 (paper §6.2), with the affine least-norm
// form instead of the paper's linear 4x4 system: grad s = E (E^T E)^-1 [s1 - s0, s2 - s0, s3 - s0]^T.
#pragma once

#include <Eigen/Core>

#include "mesh/adjacency.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

struct GradientResult {
  /// #T by 4, gradient of s in each tet (lies in the tet's hull). Row-major: the vertex pass reads one tet's row per
  /// star entry, in mesh (random) order.
  Points4 tet_gradient;
  Eigen::MatrixXd
      vertex_field;  ///< #V by 4, volume-weighted mean of incident tet gradients, unit length (0 where undefined)
  Eigen::VectorXd tet_volume;  ///< #T 3-volumes
  double seconds = 0.0;
};

/// `stars`: the mesh's vertex stars when the caller has them (built here otherwise).
GradientResult compute_gradient(const TetMesh4& mesh, const Eigen::VectorXd& s, const SharedStars& stars = nullptr);

}  // namespace morphmap
