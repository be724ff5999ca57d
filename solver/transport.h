// Transport of position labels along the flow T (paper §7, equation 6: grad L . T = 0), as one
// causal upwind sweep over vertices in increasing s.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>

#include "mesh/tet_mesh4.h"

namespace morphmap {

struct TransportOptions {
  double barycentric_tolerance = 1e-9;  ///< a ray counts as entering a tet when every barycentric weight is above -tolerance
  bool record_upwind = false;           ///< fill TransportResult::upwind (debugging and causality tests)
};

struct TransportResult {
  Eigen::MatrixXd labels;                   ///< #V by 3: point of A (in A's coordinates) carried to each vertex
  std::int64_t upwind_exact = 0;            ///< vertices whose -T ray enters a tet with all opposite vertices done
  std::int64_t fallback_projected = 0;      ///< no exact tet: best done tet with clamped barycentrics
  std::int64_t fallback_neighbours = 0;     ///< no done tet: mean of done neighbours (local minimum of s)
  std::int64_t fallback_unreached = 0;      ///< no done neighbour at all (component born mid-morph): `unreached` callback
  std::int64_t fallbacks() const { return fallback_projected + fallback_neighbours + fallback_unreached; }
  double seconds = 0.0;
  /// #V by 3 upwind vertices of each label (-1 unused; the first 3 of a neighbour mean); only with record_upwind.
  Eigen::MatrixXi upwind;
};

/// Labels of A vertices are their own positions. `unreached(x)` gives the label for a vertex with no
/// labelled neighbour (for example the closest point of A to x, the vertex's spatial position).
TransportResult transport_labels(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                                 const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& unreached,
                                 const TransportOptions& options = {});

}  // namespace morphmap
