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
};

struct LabelFillResult {
  std::int64_t filled = 0;     ///< stalled vertices given the convex combination of their patch's boundary
  std::int64_t patches = 0;    ///< connected patches of stalled vertices (B's edges) that were filled
  std::int64_t unbounded = 0;  ///< stalled vertices in patches with no traced neighbour (kept as they were)
  double seconds = 0.0;
};

/// Replaces the labels (#V by 3, points of A) of the vertices of B (V #V by 3, F #F by 3) with `stalled` set by
/// the mean-value convex combination of the labels of the traced vertices around their patch, projected onto A
/// by `locator` (closest point). A patch touching no traced vertex keeps its labels. Throws InvalidInput when the
/// sizes disagree.
LabelFillResult fill_stalled_labels(const Eigen::MatrixXd& V, const TriIndices& F, const std::vector<char>& stalled,
                                    const SurfaceLocator& locator, Eigen::MatrixXd& labels,
                                    const LabelFillOptions& options = {});

}  // namespace morphmap
