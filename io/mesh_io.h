// Mesh files: OBJ (per-corner UVs, texture named by the MTL), OFF, PLY (ASCII and binary little-endian), STL.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "mesh/surface.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

/// Reads a surface by extension (.obj, .off, .ply, .stl, case-insensitive). Polygons are fan-triangulated; STL corners
/// are welded. Throws IoError (missing/unreadable) or InvalidInput (malformed, empty, NaN/Inf, index out of range),
/// each a one-line message starting with the path. Does not check closedness (validate_surface does).
Surface read_surface(const std::string& path);

/// Writes an OBJ. UV may be empty (no vt), per vertex (#V rows, FUV empty) or per corner (FUV #F by 3).
/// `mtl_name` (a file name beside the OBJ, may be empty) is referenced with mtllib/usemtl.
void write_obj(const std::string& path, const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& UV,
               const TriIndices& FUV, const std::string& mtl_name);

/// Writes an MTL with one material "morphmap" whose map_Kd is `texture_name` (a file name beside it).
void write_mtl(const std::string& path, const std::string& texture_name);

/// A mesh with one texture coordinate per vertex, for formats that have no other kind (PLY).
struct PerVertexUvMesh {
  Eigen::MatrixXd V;        ///< #V' by 3
  TriIndices F;             ///< #F by 3, the input's triangles
  Eigen::MatrixXd UV;       ///< #V' by 2
  std::vector<int> vertex;  ///< #V': the input vertex of each output vertex
};

/// Splits each vertex of a mesh with per-corner texture coordinates (UV #T by 2, FUV #F by 3 rows of UV) into one
/// vertex per texture coordinate its corners take, so that no triangle interpolates across a texture seam; vertices
/// in order of their first corner (face by face). Throws InvalidInput on indices out of range.
PerVertexUvMesh per_vertex_uv(const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& UV,
                              const TriIndices& FUV);

/// Writes a binary little-endian PLY of the triangles (with per-vertex u, v when UV has #V rows).
void write_ply(const std::string& path, const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& UV);

}  // namespace morphmap
