// Labels for the vertices of B whose characteristic stalled (paper §7 propagates a label along every
// characteristic; it has no answer where one ends inside the morph). A trace stalls at a stagnation point of the
// flow or at a local minimum of the discrete harmonic field (cotangent weights can be negative, so the discrete
// maximum principle fails), and its label used to be the point of A nearest to where it stopped: the stalled
// traces of one sink all took that one point, and every triangle between them collapsed (sphere -> bunny at 40
// voxels: 114 stalled traces, 266 collapsed triangles before the seam split). Here each patch of stalled vertices
// takes the labels of the traced vertices around it, spread inside by a convex combination with Floater's mean
// value weights of B (a Tutte embedding of the patch with its boundary fixed), and projected onto A. The pipeline
// runs it with the fold repair (--stalled-fill auto), whose untangling spread the coincident labels only partly
// (max stretch 1e6-1e10 at 28, 30 and 36 voxels; README, "Stalled traces"); alone, the filled patches enter the
// stretch statistics folded and stretched instead of collapsed.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "mesh/tet_mesh4.h"
#include "mesh/transfer.h"

namespace morphmap {

struct LabelFillOptions {
  bool enabled = true;  ///< off: stalled vertices keep the point of A nearest to where their trace stopped
  /// Also fill the vertices whose label coincides with a neighbour's on B (within coincident_tolerance of the
  /// labels' bounding-box diagonal): characteristics that merged (along a face or an edge into one vertex of the
  /// extracted A) or that the closest point took to one vertex of A. Sphere -> bunny with the repair, 32 voxels:
  /// 82 vertices in 9 groups shared labels, the max stretch was 1.8e8 and is 30.6 with them filled (README).
  bool coincident = true;
  double coincident_tolerance = 1e-12;
};

struct LabelFillResult {
  std::int64_t filled = 0;      ///< stalled vertices given the convex combination of their patch's boundary
  std::int64_t patches = 0;     ///< connected patches of stalled vertices (B's edges) that were filled
  std::int64_t unbounded = 0;   ///< stalled vertices in patches with no traced neighbour (kept as they were)
  std::int64_t coincident = 0;  ///< vertices filled because their label coincided with a neighbour's (not stalled)
  double seconds = 0.0;
};

/// Replaces the labels (#V by 3, points of A) of the vertices of B (V #V by 3, F #F by 3) with `stalled` set (and,
/// with LabelFillOptions::coincident, of those whose label coincides with a neighbour's) by the mean-value convex
/// combination of the labels of the other vertices around their patch, projected onto A by `locator` (closest
/// point). A patch touching no other vertex keeps its labels. Throws InvalidInput when the sizes disagree.
LabelFillResult fill_stalled_labels(const Eigen::MatrixXd& V, const TriIndices& F, const std::vector<char>& stalled,
                                    const SurfaceLocator& locator, Eigen::MatrixXd& labels,
                                    const LabelFillOptions& options = {});

}  // namespace morphmap
