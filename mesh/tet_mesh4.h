// The tetrahedral 3-manifold in R^4 swept by the morph (paper §5.2): the data every later stage reads.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace morphmap {

/// Which end of the morph a vertex lies on.
enum class VertexSide : std::uint8_t { Interior = 0, A = 1, B = 2 };

/// Row-major arrays so that one vertex's coordinates and one tet's indices share a cache line: every
/// stage after extraction reads them in mesh (random) order.
using Points4 = Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor>;
using TetIndices = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;
using TriIndices = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;

/// Tetrahedral mesh of the hypersurface d(x, t) = 0, 0 <= t <= 1, with time embedded as tau = c * t.
///
/// Orientation convention (written once): for every tet (v0, v1, v2, v3) the 4D cross product
/// cross4(v1 - v0, v2 - v0, v3 - v0) points to where the morph field d increases (outside the
/// solid). Its spatial part is therefore an outward normal of every time slice, which orients the
/// target surface and slices without storing normals.
struct TetMesh4 {
  Points4 V;                              ///< #V by 4: x, y, z, tau (tau = time_scale * t)
  TetIndices T;                           ///< #T by 4 vertex indices, oriented as above
  std::vector<std::int64_t> source_cell;  ///< #T: 24 * (linear index of the 4D lattice cell) + Kuhn simplex 0..23,
                                          ///< or empty (ExtractOptions::record_source_cells)
  std::vector<VertexSide> side;           ///< #V: A for t = 0, B for t = 1, Interior otherwise
  double time_scale = 1.0;                ///< c: length in R^4 of one unit of morph time t
  double voxel_size = 0.0;                ///< h: spatial lattice spacing
  int time_steps = 0;                     ///< K: lattice intervals along t

  Eigen::Index vertex_count() const { return V.rows(); }
  Eigen::Index tet_count() const { return T.rows(); }
  /// Morph time t of vertex i.
  double time_of(Eigen::Index i) const { return V(i, 3) / time_scale; }
};

/// Generalised cross product in R^4: the vector orthogonal to a, b, c with det[a b c n] = |n|^2.
/// Its length is the 3-volume of the parallelepiped (6 times the tet's). Closed form via the 2x2 minors
/// of (b, c), because extraction calls it for every output tet.
inline Eigen::Vector4d cross4(const Eigen::Vector4d& a, const Eigen::Vector4d& b, const Eigen::Vector4d& c) {
  const double m01 = b(0) * c(1) - b(1) * c(0), m02 = b(0) * c(2) - b(2) * c(0), m03 = b(0) * c(3) - b(3) * c(0);
  const double m12 = b(1) * c(2) - b(2) * c(1), m13 = b(1) * c(3) - b(3) * c(1), m23 = b(2) * c(3) - b(3) * c(2);
  // n_i is the cofactor of e_i in det[a b c e_i] (expansion along the last column).
  return Eigen::Vector4d(-(a(1) * m23 - a(2) * m13 + a(3) * m12), a(0) * m23 - a(2) * m03 + a(3) * m02,
                         -(a(0) * m13 - a(1) * m03 + a(3) * m01), a(0) * m12 - a(1) * m02 + a(2) * m01);
}

}  // namespace morphmap
