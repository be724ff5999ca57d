// The target surface B (the t = 1 boundary of the tet mesh) and slices of the tet mesh at any
// t in (0, 1) (paper §9: "slicing the 4D tetrahedral mesh with a hyperplane"), with labels.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "mesh/tet_mesh4.h"

namespace morphmap {

/// A triangle surface cut from the tet mesh, with per-vertex labels and provenance.
struct SliceMesh {
  Eigen::MatrixXd V;            ///< #V by 3 positions (x, y, z)
  TriIndices F;                 ///< #F by 3, counter-clockwise seen from outside (outward normals)
  Eigen::MatrixXd labels;       ///< #V by 3 labels interpolated from the tet mesh (empty if none given)
  std::vector<int> source_tet;  ///< #F: tet of the mesh the triangle comes from
  Eigen::MatrixXi source_edge;  ///< #V by 2: mesh vertices (a, b) whose edge holds the vertex (a == b on a mesh vertex)
  Eigen::VectorXd edge_weight;  ///< #V: position = (1 - w) * V(a) + w * V(b)
  double t = 1.0;               ///< morph time of the slice
};

/// The boundary of the tet mesh at t = 1 (vertices with side B), i.e. the extracted B. Labels are
/// copied from `labels` (#V by 3, or empty). Every boundary face belongs to exactly one tet.
SliceMesh target_boundary(const TetMesh4& mesh, const Eigen::MatrixXd& labels);

/// The boundary at t = 0 (side A), same conventions.
SliceMesh source_boundary(const TetMesh4& mesh, const Eigen::MatrixXd& labels);

/// Intersection of the tet mesh with the hyperplane tau = c t, 0 < t < 1 (InvalidInput otherwise).
/// Tets cut in a quad give two triangles. Vertices are shared by mesh edge, so the slice is watertight.
SliceMesh slice_at(const TetMesh4& mesh, const Eigen::MatrixXd& labels, double t);

}  // namespace morphmap
