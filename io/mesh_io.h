// Mesh files: OBJ (per-corner UVs, texture named by the MTL), OFF, PLY (ASCII and binary little-endian).
#pragma once

#include <Eigen/Core>
#include <string>

#include "mesh/surface.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

/// Reads a surface by extension (.obj, .off, .ply, case-insensitive). Polygons are fan-triangulated.
/// Throws IoError (missing/unreadable) or InvalidInput (malformed, empty, NaN/Inf, index out of range),
/// each a one-line message starting with the path. Does not check closedness (validate_surface does).
Surface read_surface(const std::string& path);

/// Writes an OBJ. UV may be empty (no vt), per vertex (#V rows, FUV empty) or per corner (FUV #F by 3).
/// `mtl_name` (a file name beside the OBJ, may be empty) is referenced with mtllib/usemtl.
void write_obj(const std::string& path, const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& UV,
               const TriIndices& FUV, const std::string& mtl_name);

/// Writes an MTL with one material "morphmap" whose map_Kd is `texture_name` (a file name beside it).
void write_mtl(const std::string& path, const std::string& texture_name);

/// Writes a binary little-endian PLY of the triangles (with per-vertex u, v when UV has #V rows).
void write_ply(const std::string& path, const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& UV);

}  // namespace morphmap
