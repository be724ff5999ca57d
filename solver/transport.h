// Transport of position labels along the flow T (paper §7, equation 6: grad L . T = 0), as one
// causal upwind sweep. Every vertex first finds its upwind face (where its -T ray leaves its star);
// vertices are then processed in wavefronts of that dependency graph, ties and cycles resolved in
// increasing s, so each label is computed once from labels that are already final.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>

#include "mesh/adjacency.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

struct TransportOptions {
  double barycentric_tolerance =
      1e-9;                    ///< a ray counts as entering a tet when every barycentric weight is above -tolerance
  bool record_upwind = false;  ///< fill TransportResult::upwind (debugging and causality tests)
  /// Project the whole star of a vertex onto one tangent space (normal = sum of its tets' 4D normals, paper §7.1)
  /// before locating -T; false projects -T into each tet's own hull, which leaves gaps where the star bends.
  bool star_tangent_space = true;
};

struct TransportResult {
  Eigen::MatrixXd labels;         ///< #V by 3: point of A (in A's coordinates) carried to each vertex
  std::int64_t upwind_exact = 0;  ///< vertices labelled from the face their -T ray leaves through
  std::int64_t fallback_projected =
      0;  ///< no usable exact face (none, or on a dependency cycle): best done tet, clamped weights
  std::int64_t fallback_neighbours = 0;  ///< no done tet: mean of done neighbours (local minimum of s)
  std::int64_t fallback_unreached = 0;   ///< no done neighbour at all (component born mid-morph): `unreached` callback
  std::int64_t fallbacks() const { return fallback_projected + fallback_neighbours + fallback_unreached; }
  std::int64_t cycle_breaks = 0;  ///< vertices on upwind dependency cycles, labelled by fallback (included above)
  std::int64_t wavefronts = 0;    ///< sequential steps of the sweep (each step is parallel over its vertices)
  double seconds = 0.0;
  /// #V by 3 upwind vertices of each label (-1 unused; the first 3 of a neighbour mean); only with record_upwind.
  Eigen::MatrixXi upwind;
  /// #V wavefront in which each vertex was labelled (sources: 0); only with record_upwind. Causality
  /// means wave(u) < wave(v) for every upwind vertex u that v's label reads.
  Eigen::VectorXi wave;
};

/// Labels of A vertices are their own positions. `unreached(x)` gives the label for a vertex with no
/// labelled neighbour (for example the closest point of A to x, the vertex's spatial position). `stars`: the mesh's
/// vertex stars when the caller has them (built here otherwise).
TransportResult transport_labels(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                                 const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& unreached,
                                 const TransportOptions& options = {}, const SharedStars& stars = nullptr);

/// The same sweep for any attribute: `source` is #V by k and is read at side-A vertices only; the
/// result's `labels` is #V by k. `unreached(x)` returns a 1 by k row for vertices nothing flows into.
TransportResult transport_values(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                                 const Eigen::MatrixXd& source,
                                 const std::function<Eigen::RowVectorXd(const Eigen::Vector3d&)>& unreached,
                                 const TransportOptions& options = {}, const SharedStars& stars = nullptr);

}  // namespace morphmap
