// Quality of the tetrahedral 3-manifold in R^4 for the Laplace stage. Dinh, Yezzi and Turk (TOG 2005, §10)
// note that obtuse dihedral angles give negative cotangent weights in the Laplace-Beltrami operator
// (equation 4), so the update of s stops being a convex combination and diffusion can become unstable; the
// distance-field morph (DFM, §9) produces more of them. This stage measures how many there are.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <utility>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

struct QualityOptions {
  double obtuse_threshold_degrees = 90.0;  ///< dihedrals above this count as obtuse (90: where the cotangent weight
                                           ///< turns negative). Angles within 1e-9 degrees of it are not counted, so
                                           ///< the exact right angles of lattice (Kuhn) tets do not flip with rounding
  int histogram_bins = 18;                 ///< dihedral histogram over [0, 180] degrees (18: 10 degree bins), 1 .. 1e6
};

struct QualityResult {
  std::int64_t tets = 0;
  std::int64_t degenerate_tets = 0;           ///< 3-volume <= 1e-12 * mean volume, or at rounding level for the tet's
                                              ///< own edges (6 vol <= 1e-13 |e1| |e2| |e3|, then taken as 0): left out
                                              ///< of every statistic below except min_volume_ratio
  double min_dihedral_degrees = 0.0;          ///< over non-degenerate tets (0 if there are none)
  double max_dihedral_degrees = 0.0;          ///< over non-degenerate tets (0 if there are none)
  std::int64_t obtuse_dihedrals = 0;          ///< dihedral angles above the threshold
  double obtuse_dihedral_fraction = 0.0;      ///< obtuse_dihedrals / (6 * non-degenerate tets)
  std::int64_t edges = 0;                     ///< unique vertex pairs of non-degenerate tets
  std::int64_t negative_cotangent_edges = 0;  ///< edges whose assembled off-diagonal K_ij > 1e-14 * mean |K_ij|
  double negative_cotangent_fraction = 0.0;   ///< negative_cotangent_edges / edges. K_ij = sum over the tets of
                                              ///< edge ij of vol grad(lambda_i) . grad(lambda_j) = -(1/6) sum l cot,
                                              ///< so K_ij > 0 is a negative cotangent weight
  double min_volume_ratio = 0.0;              ///< smallest tet 3-volume / mean 3-volume, degenerate tets included
  std::vector<std::int64_t> dihedral_histogram;  ///< histogram_bins counts of the non-degenerate dihedrals; bin b
                                                 ///< holds [b, b + 1) * 180 / bins degrees, 180 in the last bin
  double seconds = 0.0;
};

/// Dihedral angles, degenerate tets and the sign of the assembled cotangent stiffness of every edge.
/// Each tet is measured in its own 3D hull: the R factor of a QR factorisation of E = [v1 - v0, v2 - v0, v3 - v0]
/// (4 by 3) gives 3D coordinates in which the face normals (scaled hat gradients) are cross products, accurate for
/// slivers (the Gram matrix E^T E squares their condition number). Angles are classified by cosine; the reported
/// extremes are evaluated with atan2.
/// TBB-parallel over fixed chunks with reductions in chunk order: the result is the same for any thread count.
/// Temporary memory: 72 bytes per tet (volume, six edge stiffnesses, four incidences) plus 8 bytes per vertex and
/// thread, and 8 bytes per unique edge.
/// The Laplace stage skips tets by a shape test instead (tet_frame); tests/mesh/quality_test.cpp checks on an
/// extracted mesh that both skip the same tets and that the edge signs agree with cotangent_stiffness.
/// Throws InvalidInput for out-of-range indices, non-finite coordinates or invalid options.
/// `stars`: the mesh's vertex stars when the caller has them (built here otherwise).
QualityResult measure_quality(const TetMesh4& mesh, const QualityOptions& options = {},
                              const SharedStars& stars = nullptr);

/// The P1 stiffness of every tet, vol * grad(lambda_i) . grad(lambda_j), as its lower-right 3 by 3 block: #T by 6,
/// (1,1) (1,2) (1,3) (2,2) (2,3) (3,3). The hats sum to one, so every row of a local stiffness sums to zero and row 0
/// follows from the block (unpack_stiffness): 48 bytes a tet instead of the 80 of all ten distinct entries, which on
/// cow -> horse (1.66 M tets) was the largest array of the run, live at its peak.
using PackedStiffness = Eigen::Matrix<double, Eigen::Dynamic, 6, Eigen::RowMajor>;

/// The 4 by 4 local stiffness K of one PackedStiffness row (`packed`, 6 entries): K(0, i) = K(i, 0) = -(K(i, 1) +
/// K(i, 2) + K(i, 3)) and K(0, 0) = -(K(0, 1) + K(0, 2) + K(0, 3)). Bitwise symmetric, so an assembly that reads (i, j)
/// and (j, i) from it stays bitwise symmetric.
inline void unpack_stiffness(const double* packed, double K[4][4]) {
  K[1][1] = packed[0];
  K[1][2] = K[2][1] = packed[1];
  K[1][3] = K[3][1] = packed[2];
  K[2][2] = packed[3];
  K[2][3] = K[3][2] = packed[4];
  K[3][3] = packed[5];
  for (int i = 1; i < 4; ++i) K[0][i] = K[i][0] = -(K[i][1] + K[i][2] + K[i][3]);
  K[0][0] = -(K[0][1] + K[0][2] + K[0][3]);
}

/// Index in a PackedStiffness row of K(a, b), 1 <= a, b <= 3 (kPackedIndex[a - 1][b - 1]).
inline constexpr int kPackedIndex[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};

/// Row i of unpack_stiffness's K alone (`row`: 4 entries), computed as it computes them (the same bits): the assembly
/// reads one row of each tet it meets, and rows 1-3 need one of the four row sums.
inline void stiffness_row(const double* packed, int i, double row[4]) {
  if (i > 0) {
    const int* b = kPackedIndex[i - 1];
    row[1] = packed[b[0]];
    row[2] = packed[b[1]];
    row[3] = packed[b[2]];
    row[0] = -(row[1] + row[2] + row[3]);
    return;
  }
  for (int j = 1; j < 4; ++j)
    row[j] = -(packed[kPackedIndex[j - 1][0]] + packed[kPackedIndex[j - 1][1]] + packed[kPackedIndex[j - 1][2]]);
  row[0] = -(row[1] + row[2] + row[3]);
}

/// Entry (i, j), i != j, of unpack_stiffness's K alone, computed as it computes it (the same bits).
inline double stiffness_entry(const double* packed, int i, int j) {
  if (i > j) std::swap(i, j);
  if (i > 0) return packed[kPackedIndex[i - 1][j - 1]];
  return -(packed[kPackedIndex[j - 1][0]] + packed[kPackedIndex[j - 1][1]] + packed[kPackedIndex[j - 1][2]]);
}

/// measure_quality's figures from the stiffness the Laplace stage computes anyway (solve_harmonic with
/// LaplaceOptions::measure_quality), with no second pass over the tets' geometry: the dihedral at edge e has cosine
/// -K_kl / sqrt(K_kk K_ll) for the opposite edge (k, l), and the edge sums are K's. `volume` (#T) is 0 for the tets
/// the Laplace stage leaves out (tet_frame: det E^T E at rounding level), which with the mean test are
/// degenerate_tets here. The Gram matrix squares a sliver's condition number, so its cosines are less accurate than
/// measure_quality's QR ones; both report the extremes from QR and atan2. On cow -> horse (1.66 M tets) the two agree
/// on every count (tests/mesh/quality_test.cpp checks it on an extracted morph).
QualityResult quality_from_stiffness(const TetMesh4& mesh, const PackedStiffness& stiffness,
                                     const Eigen::VectorXd& volume, const QualityOptions& options = {},
                                     const SharedStars& stars = nullptr);

/// K's rows among the unknowns of a Dirichlet system, as the Laplace stage assembles them: compressed (#rows + 1
/// offsets), every row's columns ascending, both triangles stored, each entry K_ij summed over the row vertex's star
/// in tet order (bitwise what the quality stage's own walk sums).
struct AssembledRows {
  const std::vector<int>* row_of = nullptr;  ///< #V: each vertex's row, -1 for none; increasing with the vertex index
  const int* outer = nullptr;                ///< #rows + 1 offsets into inner and value
  const int* inner = nullptr;                ///< column (row number) of each entry
  const double* value = nullptr;             ///< K_ij of each entry
};

/// quality_from_stiffness in the two parts the Laplace stage runs around its assembly, so that the edge figures
/// can read its assembled rows instead of summing K again (cow -> horse: 0.06 of the stage's 0.12 s). The first
/// is every figure but the edge ones (edges, negative_cotangent_*) and writes into `usable` (#T) the tets they sum
/// over: the non-degenerate ones.
QualityResult quality_angles_from_stiffness(const TetMesh4& mesh, const PackedStiffness& stiffness,
                                            const Eigen::VectorXd& volume, std::vector<std::uint8_t>& usable,
                                            const QualityOptions& options = {});

/// The second: the edge figures into `result` (its seconds grow by this part's). `rows` may be given only when the
/// assembly summed over exactly the `usable` tets; the figures are then those of a walk over every star, but for the
/// summation order of the tolerance's scale (the mean |K_ij|), which can move a count only for an entry within
/// rounding of the tolerance.
void add_edge_figures(QualityResult& result, const TetMesh4& mesh, const PackedStiffness& stiffness,
                      const std::vector<std::uint8_t>& usable, const SharedStars& stars,
                      const AssembledRows* rows = nullptr);

}  // namespace morphmap
