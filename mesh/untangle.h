// Fold repair of a label map B -> A (beyond the paper: its §6.3 measures stretch but leaves folds in place). Where
// the morph sends a patch of B onto A mirrored (the two faces of a thin ear onto one patch of the sphere) or onto a
// point (characteristics squeezed through one join), the vertices of those triangles and a few rings around them
// move on A: first each cluster of them that is a disk is laid out again in one chart (a Tutte embedding with B's
// mean value weights inside its fixed boundary, Floater 2003; untangled in that chart where the boundary is not convex
// and the layout folds, mesh/chart_untangle.h), then each vertex with an inverted or flat triangle to
// where its smallest triangle (in the tangent plane of A at its label) is largest (local optimisation untangling,
// Freitag and Plassmann 2000), the region growing while that rights triangles; then the region, the triangles
// stretched beyond UntangleOptions::stretch_seed (though not folded) and a few more rings around both descend the
// symmetric Dirichlet energy of their triangles, which keeps every positive triangle positive and spreads the squeezed
// patches. Last, the parts of the map around triangles compressed beyond UntangleOptions::compression_seed are
// relieved (Newton steps of the same energy, then each vertex to where its worst triangle is least compressed), each
// part kept only where its figures improve. Where B has handles that the source lacks, some folds are forced (README,
// Riemann-Hurwitz) and stay.
#pragma once

#include <Eigen/Core>
#include <cstdint>

#include "mesh/surface.h"
#include "mesh/tet_mesh4.h"
#include "mesh/transfer.h"

namespace morphmap {

struct UntangleOptions {
  /// On by default since 2026-12-06: on four of the five Table II morphs it lowers the max stretch, the mean, the
  /// variance and the folds, and the fifth (sphere -> torus at 13 voxels) has nothing to repair (README, "Fold
  /// repair"), for 0.2-0.6 s there and 1.3 s on cow -> horse at 63 voxels (Table II's jobs turn it off: the paper's
  /// pipeline has no such stage). Off, the labels are only classified.
  bool enabled = true;
  /// Rings of B around the bad triangles' vertices that move with them in the first round; each further round adds
  /// `grow_rings` rings while bad triangles remain.
  int rings = 1;
  int grow_rings = 1;  ///< rings added per round
  int max_rounds = 8;  ///< rounds of growing the region
  /// Growing stops after a round that leaves more than (1 - this) times the bad triangles it started with.
  double min_round_gain = 0.05;
  int sweeps = 8;  ///< sweeps over the region per round (fewer when one moves nothing)
  /// A triangle whose labels lie farther apart than this times A's bounding-box diagonal spans a topological seam
  /// (SeamOptions::label_threshold, the same value): the seam split cuts it, so it is neither repaired nor crossed.
  double seam_threshold = 0.25;
  /// A vertex of the region moves only while its smallest triangle (in the chart) is below this fraction of their
  /// mean area: inverted, collapsed or nearly so.
  double flat_fraction = 0.05;
  int smoothing_rings = 4;  ///< rings added to the untangled region for the smoothing
  /// Triangles whose L2 stretch (DESIGN.md's, as measure_stretch normalises it) exceeds this also join the smoothing
  /// with `smoothing_rings` rings, though nothing folds there: a patch the morph squeezed (an ear tip whose traces all
  /// stalled, filled from a boundary that itself converged) or a sliver beside a seam sets the max stretch, and the
  /// symmetric Dirichlet descent spreads it like any other. 0 turns it off. Measured with smooth_seam_sides on
  /// sphere -> bunny at 24, 28, 30, 32, 36, 40, 44, 48, 56 voxels: max stretch 75.8, 18.9, 11.0, 24.7, 9.0, 18.8,
  /// 19.5, 19.2, 22.6 against 1354, 71, 34.6, 30.6, 126, 18.8, -, 32.7, 798 without (README, "Fold repair").
  double stretch_seed = 8.0;
  /// Relief of compression, after the smoothing: where a good triangle's sigma2 (DESIGN.md's compression, as
  /// measure_stretch normalises it) is below this, its corners and `compression_rings` rings around them (leaving
  /// out the vertices of seam, folded or collapsed triangles) descend the symmetric Dirichlet energy with Newton steps
  /// (`compression_smoothing_sweeps` sweeps), then each vertex moves, one at a time, to where its worst triangle is
  /// least compressed (`compression_sweeps` sweeps at most). Each connected part of that region is kept only where
  /// its smallest sigma2 does not fall, its smallest sigma2 rises or its largest sigma1 falls, its largest sigma1
  /// stays at most max(before, the map's largest, 1 / compression_seed), its mean L2 rises by at most
  /// compression_mean_tolerance and none of its triangles turns bad or spans a seam; otherwise it is put back.
  /// Measured at the defaults on sphere -> bunny (README, "Relieving compression"): min compression 0.048 -> 0.187,
  /// mean 1.233 -> 1.222, variance 0.213 -> 0.152, p99 3.26 -> 2.75, coverage 1.017 -> 1.003, for 2 s more repair.
  /// 0 turns it off.
  double compression_seed = 0.25;
  /// Rings around the compressed triangles' corners. On sphere -> bunny at the defaults (seed 0.25) 4, 6, 8, 10, 12,
  /// 16 rings gave min compression 0.145, 0.166, 0.181, 0.180, 0.187, 0.200 and variance 0.217, 0.202, 0.175, 0.160,
  /// 0.152, 0.151 (with 4000 vertices at most per part; 16 rings needed 8000).
  int compression_rings = 12;
  int compression_smoothing_sweeps = 1000;  ///< Newton sweeps of the symmetric Dirichlet smoothing over each part
  int compression_sweeps = 200;             ///< sweeps of the worst-triangle moves over each part
  /// Parts larger than this are left as they are: on cow -> horse (63 voxels) the squeezed legs make one part of
  /// 16 k vertices, and such parts next to folds were put back anyway (Buddha, spot -> horse, sphere -> horse at 8000:
  /// 2-5 s more repair for no change kept but the Buddha's mean 1.294 -> 1.234).
  std::int64_t max_compression_vertices = 4000;
  double compression_mean_tolerance = 0.01;  ///< how far (relative) a part's mean L2 may rise in a kept relief
  /// The vertices of a stretched triangle move in the smoothing even where they belong to a seam triangle (which
  /// the untangling keeps in place), with the seam triangles left out of the energy and no step letting a side of
  /// the seam cross the other (a positive seam triangle turning over). The slivers beside the ear's seam on sphere
  /// -> bunny have every corner on one. Freeing every seam vertex, not only these, took the bunny's maxima lower
  /// still (7.5-19.2) but let the splitting sphere's halves spread over each other (coverage 1.05 -> 1.23).
  bool smooth_seam_sides = true;
  /// Rounds of smoothing: each further round adds the triangles still stretched (and their corners on seams) with
  /// `smoothing_rings` rings, and smooths again.
  int stretch_rounds = 3;
  /// A further round runs only when at most this fraction of the last round's stretched triangles is still stretched.
  double stretch_round_fraction = 0.5;
  int smoothing_sweeps = 150;  ///< sweeps of symmetric Dirichlet descent over the region after the untangling
  /// Sweeps per round instead when a seam was healed. Each sweep moves a vertex one damped Newton step, so a healed
  /// patch (an ear laid out again inside its loop) spreads its squeeze slowly: on sphere -> bunny, 150 / 400 / 1000 /
  /// 3000 sweeps gave variance 0.28 / 0.25 / 0.20 / 0.17, p99 3.77 / 3.62 / 3.21 / 2.94, min compression 0.011 /
  /// 0.010 / 0.022 / 0.073, for a repair of 1.4 / 1.5 / 2.0 / 4.2 s (measured before the last seam closed, with 42
  /// collapsed pieces). Every repair that long took cow -> horse's (63 voxels, nothing healed) from 2.5 to 8-10 s.
  int healed_smoothing_sweeps = 1000;
  /// A smoothing step counts as a move (its vertex's neighbours are visited in the next sweep) when its squared length
  /// exceeds this times the mean area of the vertex's triangles. Measured on sphere -> bunny at 40 voxels (300 sweeps,
  /// the cap, and 1.0 M moves over 4.3 k vertices at 1e-6): 1e-4 took the repair 0.97 -> 0.55 s but max 10.5 -> 13.8,
  /// p99 2.09 -> 2.18; 1e-3 0.28 s, max 44.6, p99 2.91.
  double smoothing_tolerance = 1e-6;
  double max_region_fraction = 0.25;  ///< the region stops growing at this fraction of B's vertices
  double collapse_ratio = 1e-12;      ///< StretchOptions::collapse_ratio: what counts as collapsed
  /// Before the local untangling, each cluster of bad triangles (sharing vertices) with `patch_rings` rings around
  /// it is laid out again in one chart of A when it is a disk: its boundary stays, its inside takes Floater's mean
  /// value weights of B's own shape (a Tutte embedding, one sparse solve), and the layout is kept when it rights
  /// enough of the patch's bad triangles without squeezing any (below); otherwise the patch doubles its rings, up
  /// to `max_patch_rings`. Measured on sphere -> bunny at 40 voxels (with --thin-features): max stretch 1.2e9 ->
  /// 33, variance 4e12 -> 0.086, folded 88 -> 60 (63 with the smoothing's sliver guard; README, "Fold repair").
  bool rebuild_patches = true;
  /// A patch layout that turns triangles over in its chart (a boundary that is not convex) is untangled there before
  /// it is judged (mesh/chart_untangle.h: Garanzha et al.'s foldover-free energy, the boundary fixed).
  bool untangle_layouts = true;
  /// Triangles that span a topological seam also seed patch layouts, like folded ones: where a patch around them is a
  /// disk whose boundary is a simple loop in one chart, the seam is a fan of the traced map that the ends' topology
  /// does not force (an ear born as a bubble of the morph and joined to the head, sphere -> bunny), and laying the
  /// patch out again inside its loop closes it. Around a seam the topology forces (sphere -> torus, a sphere splitting
  /// in two) the patch is an annulus or its loop crosses itself, and nothing changes. With it, a layout that closes
  /// every seam of its patch is kept though it leaves folds (the local untangling rights them), and the parts of B a
  /// patch cuts off join it (an ear beyond the rings around its base). Measured on sphere -> bunny at the defaults
  /// (README, "Healing seams"): coverage 1.066 -> 1.017, folded 12 -> 0, collapsed 186 -> 0, min 0.020 -> 0.048, at
  /// the cost of the mean (1.165 -> 1.233) and the variance (0.111 -> 0.213); at 32 and 48 voxels the seams close
  /// only in charts of directions (direction_charts, off by default).
  bool heal_seams = true;
  int patch_rings = 2;
  int max_patch_rings = 8;                 ///< rings of the largest patch tried
  std::int64_t max_patch_vertices = 2000;  ///< patches stop growing at this many vertices
  /// The same two limits for a cluster that holds seam triangles. The ear's seam on sphere -> bunny closes at 16
  /// rings, with the ear's tip enclosed: when the rings around a cluster cut B in pieces, the pieces other than the
  /// largest (the part of an ear beyond a ring around its base) join the patch, so that it is a disk. Growing every
  /// cluster that far took the repair of sphere -> bunny at 48 voxels from 2 to 11-29 s and cow -> horse's (63
  /// voxels) to 16 s.
  int max_seam_patch_rings = 16;
  /// A patch near a seam whose loop no tangent plane holds as a simple polygon (a point's normal turns too far from
  /// the axis, or the loop crosses itself or turns the wrong way there) is tried again in a stereographic chart of
  /// the directions from A's centre, which holds almost all of A where A is star-shaped (every point of the patch must
  /// be the only crossing of A on its ray from the centre). Off by default: on sphere -> bunny (README, "Healing
  /// seams") it took 32 voxels from 12 folded, 174 collapsed, coverage 1.049 to 0, 0, 1.005 and 48 voxels from 84,
  /// 231, 1.143 to 2, 0, 1.005, the defaults (40 voxels) unchanged, but Table I's tuned variational row went from max
  /// stretch 10.1 to 2.4e8 (one triangle the repair left stretched) and its 10-sweep row from 7.4e8 to 1.7e8.
  bool direction_charts = false;
  std::int64_t max_seam_patch_vertices = 4000;
  double max_patch_bad_fraction = 0.25;  ///< a layout may leave at most this fraction of the patch's bad triangles
  double min_patch_area_ratio = 0.01;    ///< nor any triangle below this fraction of its (scaled) area on B
};

/// Stereographic chart of the directions from a centre, with its pole opposite `axis` (the fold repair's chart for
/// patches that no tangent plane holds; UntangleOptions::direction_charts). Conformal, and one to one on every
/// direction but the pole.
struct DirectionChart {
  Eigen::Vector3d centre, axis, e1, e2;  ///< axis, e1, e2: orthonormal, right-handed
  DirectionChart(const Eigen::Vector3d& centre, const Eigen::Vector3d& axis);
  /// The chart point of the direction from the centre to p; false within about 1e-3 of the pole.
  bool to(const Eigen::Vector3d& p, Eigen::Vector2d& x) const;
  /// The unit direction of chart point x.
  Eigen::Vector3d direction(const Eigen::Vector2d& x) const;
};

struct UntangleResult {
  std::int64_t folded_before = 0, collapsed_before = 0;  ///< bad triangles (seam triangles not counted)
  std::int64_t folded_after = 0, collapsed_after = 0;
  std::int64_t seam_triangles = 0;  ///< triangles spanning a topological seam, left to the seam split
  std::int64_t stretched_before = 0, stretched_after = 0;  ///< good triangles with L2 above stretch_seed
  std::int64_t region_vertices = 0;                        ///< vertices of the region at the end
  std::int64_t vertices_moved = 0;                         ///< distinct vertices whose label changed
  std::int64_t moves = 0;                                  ///< vertex moves, over all sweeps
  std::int64_t smoothing_moves = 0;                        ///< vertex moves of the smoothing, over all sweeps
  int smoothing_sweeps = 0;                                ///< sweeps of the smoothing, over all its rounds
  std::int64_t patches_tried = 0;                          ///< clusters of bad triangles a rebuild was tried on
  std::int64_t patches_rebuilt = 0;       ///< of those, clusters laid out again (in a patch free of bad triangles)
  std::int64_t seams_healed = 0;          ///< of those, patches whose cluster held seam triangles
  std::int64_t seam_triangles_after = 0;  ///< triangles still spanning a topological seam at the end
  std::int64_t patch_vertices = 0;        ///< inner vertices of the rebuilt patches
  std::int64_t compression_parts = 0;     ///< connected parts of the relief's region
  std::int64_t compression_parts_relieved = 0;  ///< of those, parts whose relief was kept
  std::int64_t compression_moves = 0;           ///< worst-triangle moves, over all sweeps (kept or not)
  int compression_sweeps = 0;                   ///< sweeps of the worst-triangle moves, over all parts
  std::int64_t layouts_untangled = 0;  ///< patch layouts that folded in their chart and were untangled (kept or not)
  int rounds = 0;                      ///< rounds run
  int sweeps = 0;                      ///< sweeps run, over all rounds
  double seconds = 0.0;
};

/// Repairs folded and collapsed triangles of the map that sends vertex i of B (V #V by 3, F #F by 3, outward) to
/// labels.row(i) (#V by 3, points of A's surface). `locator` answers closest-point queries on A. Labels of the
/// repaired region are replaced in place by points of A. Each sweep moves colour classes of vertices that share no
/// triangle in parallel, so the result does not depend on the thread count.
UntangleResult untangle_labels(const Surface& A, const SurfaceLocator& locator, const Eigen::MatrixXd& V,
                               const TriIndices& F, Eigen::MatrixXd& labels, const UntangleOptions& options = {});

}  // namespace morphmap
