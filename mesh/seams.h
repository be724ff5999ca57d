// Topological seams (paper §8.1) and texture seams (§8.2): triangles of B and of every slice whose
// labels straddle a seam are split, so that no output triangle interpolates labels or texture
// coordinates across one.
//
// Topological: a triangle whose source tet's labels fall into clusters far apart in label space is cut
// by the tet's critical plane, the plane through the midpoints of the tet edges that join different
// clusters (the level set 1/2 of the cluster indicator interpolated over the tet). Each piece takes labels
// only from its own cluster's tet vertices. Vertices on the cut are duplicated, one per side, so every
// output vertex carries one label.
// Texture: the label path along every edge is followed on A (closest point, bisection) to find where it
// crosses a seam edge of A's atlas (an edge whose two faces disagree on both shared corners' UVs) or a
// jump of the closest-point map; triangles with crossings are split there, and every output corner takes
// its UV from the A face on its own side. Texture seam vertices are shared; only their UVs (per corner) differ.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

#include "mesh/slice.h"
#include "mesh/surface.h"
#include "mesh/tet_mesh4.h"
#include "mesh/transfer.h"

namespace morphmap {

struct SeamOptions {
  /// A tet (and its triangles) spans a topological seam when two of its vertices' labels (closest points on A)
  /// are farther apart than this, in units of the diagonal of A's bounding box. Measured (report.json
  /// label_span_histogram, sphere -> torus, 40 voxels): 99.6% of B's triangles span < 0.1, the seam
  /// triangles 0.4-0.75 (254), a tail of 74 in 0.1-0.4 from labels smeared across the seam, the fewest
  /// (10) in 0.25-0.4. On spot -> horse ordinary (compressed) triangles reach 0.2-0.3.
  double label_threshold = 0.25;
  bool topological = true;           ///< split along topological seams
  bool texture = true;               ///< split along A's texture seams (needs A's UVs)
  double crossing_tolerance = 1e-7;  ///< bisection along an edge stops at this fraction of the edge's label length
  int max_queries_per_edge = 256;    ///< closest-point queries per edge before the edge is counted unresolved
  /// Levels of texture splitting: 1 splits B's triangles at their edges' crossings only; each further level tests
  /// the inner edges of the last level's pieces (fan spokes, diagonals) and splits those pieces at their crossings.
  /// Measured on spot -> horse: with 1, about 1000 pieces keep a crossed inner edge, one of them across a
  /// closest-point jump in the cow's head (UV area 25 x its image's); 2 resolves it (+13% triangles); deeper
  /// levels do not settle where labels lie far inside A and their closest points jump densely (at 4, twice the
  /// triangles and 6000 pieces still crossed).
  int max_split_depth = 2;
  /// Crossings of an inner edge closer to its ends than this fraction of it are ignored: an end point on a seam
  /// (a crossing vertex) shows its own seam there, and a cut so close to a corner would only leave a sliver.
  double corner_margin = 1e-3;
  /// A UV triangle "exceeds its preimage" when its UV area is larger than the preimage's UV area (its
  /// image, sampled 4 x 4 in one chart) plus this many times the larger of that area and the mean triangle's.
  /// A triangle across a seam covers a strip of the atlas (tens to hundreds of mean triangles). Measured
  /// (report: uv_area_excess_sweep at 0.5 ... 16), split output / unsplit input: spot -> horse 3 / 1147 at 4 and
  /// 0 / 983 at 8; sphere -> torus 0 / 254 and 0 / 173; splitting sphere 0 / 225 and 0 / 206. Of the three spot
  /// triangles over 4, the largest (7.8 x, the margin left at 8) is a last-level fan piece whose spoke crosses a
  /// closest-point jump mid-way, where labels lie 0.18 inside A and its 4 x 4 image estimate is unstable (16 x 16
  /// gives 3 x more); none of 9 other fan centres has clean spokes there, and depth 3 (max 4.7 x) costs +55% folds.
  double uv_area_tolerance = 8.0;
  double uv_area_epsilon = 1e-12;  ///< plus this absolute UV area (rounding on tiny triangles)
};

struct SeamResult {
  Eigen::MatrixXd V;                        ///< #V by 3 positions (topological seam vertices appear once per side)
  TriIndices F;                             ///< #F by 3, oriented like the input
  Eigen::MatrixXd labels;                   ///< #V by 3 raw labels (points near A in the morph frame)
  Eigen::MatrixXd UV;                       ///< #UV by 2 texture coordinates (empty without A's UVs)
  TriIndices FUV;                           ///< #F by 3 indices into UV per corner (empty without A's UVs)
  std::vector<int> source_face;             ///< #F: input triangle each output triangle comes from
  Eigen::MatrixXd topological_seam_points;  ///< #S by 3: positions of the vertices on topological cuts

  double threshold = 0.0;                     ///< absolute label-space threshold used
  std::int64_t seam_tets = 0;                 ///< input triangles whose source tet spans the threshold
  std::int64_t topological_split = 0;         ///< of those, triangles cut in two or more pieces
  std::int64_t topological_seam_curves = 0;   ///< connected curves of cut edges (by position)
  std::int64_t topological_seam_regions = 0;  ///< connected sets of cut triangles (sharing a corner)
  std::int64_t spans_over_threshold = 0;      ///< output triangles whose corner labels still span the threshold
  std::int64_t texture_split = 0;             ///< triangles split at texture seams (or closest-point jumps)
  std::int64_t texture_crossings = 0;         ///< edge crossings found
  std::int64_t texture_fan_splits = 0;        ///< of the split triangles, those with other than two crossings (fanned)
  std::int64_t texture_seam_curves = 0;       ///< connected curves of texture cut edges
  std::int64_t unresolved_edges = 0;          ///< edges whose bisection ran out of queries
  std::int64_t uv_area_excess = 0;            ///< output triangles whose UV area exceeds their preimage's (see options)
  std::vector<int> uv_area_excess_faces;      ///< those triangles (indices into F)
  std::int64_t uv_area_excess_unsplit = 0;    ///< the same count for the input triangles with per-vertex UVs
  std::vector<double> tolerance_sweep;        ///< uv_area_tolerance values of the two sweeps below
  std::vector<std::int64_t> uv_area_excess_sweep;          ///< uv_area_excess at each of those tolerances
  std::vector<std::int64_t> uv_area_excess_unsplit_sweep;  ///< uv_area_excess_unsplit at each of those tolerances
  double max_uv_area_ratio = 0.0;            ///< largest UV area / (preimage UV area) over output triangles
  double mean_preimage_uv_area = 0.0;        ///< mean preimage UV area of the output triangles (tolerance unit)
  std::vector<double> span_bin_edges;        ///< label span histogram bin edges, in A diagonals (last bin open)
  std::vector<std::int64_t> span_histogram;  ///< input triangles per bin of max corner label distance
  double seconds = 0.0;
};

/// Splits `slice` (target_boundary or slice_at of `mesh` with vertex labels `labels`, #mesh.V by 3) along
/// topological seams and, when A has UVs, along A's texture seams. `locator` must be built on A. `relabelled`
/// (empty, or #slice.V flags) marks the slice's vertices whose labels were replaced after the transport (the fold
/// repair): a triangle whose corners are all relabelled and whose own labels span no seam is not cut, since the
/// labels of its source tet's other vertices are the ones the repair replaced. `closest_labels`, when given, are the
/// closest points on A of slice.labels (#slice.V by 3) that the caller has already (the map's own hits of B's labels),
/// so they are not searched for twice; a slice vertex at a mesh vertex whose label in `labels` is its own lends its
/// closest point to that vertex too.
SeamResult split_seams(const SliceMesh& slice, const TetMesh4& mesh, const Eigen::MatrixXd& labels, const Surface& A,
                       const SurfaceLocator& locator, const SeamOptions& options = {},
                       const std::vector<char>& relabelled = {}, const Eigen::MatrixXd* closest_labels = nullptr);

/// Number of connected curves formed by edges (#E by 2 vertex ids).
std::int64_t count_curves(const std::vector<std::array<int, 2>>& edges);

}  // namespace morphmap
