// The tetrahedral 3-manifold in R^4 swept by the morph (paper §5.2): the data every later stage reads.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace morphmap {

/// Which end of the morph a vertex lies on.
enum class VertexSide : std::uint8_t { Interior = 0, A = 1, B = 2 };

/// Row-major index arrays so that one tet's four indices are contiguous.
using TetIndices = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;
using TriIndices = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;

/// Tetrahedral mesh of the hypersurface d(x, t) = 0, 0 <= t <= 1, with time embedded as tau = c * t.
///
/// Orientation convention (written once): for every tet (v0, v1, v2, v3) the 4D cross product
/// cross4(v1 - v0, v2 - v0, v3 - v0) points to where the morph field d increases (outside the
/// solid). Its spatial part is therefore an outward normal of every time slice, which orients the
/// target surface and slices without storing normals.
struct TetMesh4 {
  Eigen::MatrixXd V;                       ///< #V by 4: x, y, z, tau (tau = time_scale * t)
  TetIndices T;                            ///< #T by 4 vertex indices, oriented as above
  std::vector<std::int64_t> source_cell;   ///< #T: 24 * (linear index of the 4D lattice cell) + Kuhn simplex 0..23
  std::vector<VertexSide> side;            ///< #V: A for t = 0, B for t = 1, Interior otherwise
  double time_scale = 1.0;                 ///< c: length in R^4 of one unit of morph time t
  double voxel_size = 0.0;                 ///< h: spatial lattice spacing
  int time_steps = 0;                      ///< K: lattice intervals along t

  Eigen::Index vertex_count() const { return V.rows(); }
  Eigen::Index tet_count() const { return T.rows(); }
  /// Morph time t of vertex i.
  double time_of(Eigen::Index i) const { return V(i, 3) / time_scale; }
};

/// Generalised cross product in R^4: the vector orthogonal to a, b, c with det[a b c n] = |n|^2.
Eigen::Vector4d cross4(const Eigen::Vector4d& a, const Eigen::Vector4d& b, const Eigen::Vector4d& c);

}  // namespace morphmap
