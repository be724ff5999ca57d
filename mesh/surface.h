// Closed triangle surfaces: the inputs A and B of the morph (DESIGN.md, stage "load"), their
// validation and bounding boxes.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace morphmap {

/// 8-bit RGB image, rows top to bottom, `pixels.size() == 3 * width * height`.
struct RgbImage {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;
};

/// Signed distance (negative inside) of an analytic shape.
using SignedDistance = std::function<double(const Eigen::Vector3d&)>;

/// A triangle surface with optional per-corner texture coordinates.
/// Faces are counter-clockwise seen from outside (outward normals).
struct Surface {
  Eigen::MatrixXd V;                        ///< #V by 3 vertex positions
  Eigen::MatrixXi F;                        ///< #F by 3 vertex indices per triangle
  Eigen::MatrixXd UV;                       ///< #UV by 2 texture coordinates; empty when the surface has none
  Eigen::MatrixXi FUV;                      ///< #F by 3 indices into UV per triangle corner; empty when UV is empty
  std::string texture_path;                 ///< image file named by the MTL (map_Kd), empty if none
  std::shared_ptr<const RgbImage> texture;  ///< in-memory texture (built-in shapes), null if none
  std::string name;                         ///< file path or built-in spec, used in messages
  /// Built-in analytic shapes: the exact signed distance (negative inside) of the shape the triangles approximate
  /// (their vertices lie on it). The distance-field morph samples it instead of the mesh's distance. Empty for meshes.
  SignedDistance signed_distance;
  /// The image the MTL names when no such file exists (texture_path is then empty): the pipeline warns.
  std::string missing_texture;
  /// Further images that the OBJ's faces' materials name (in the order of first use): only texture_path's is carried.
  std::vector<std::string> other_textures;

  bool has_uv() const { return UV.rows() > 0 && FUV.rows() == F.rows(); }
  bool has_texture() const { return texture != nullptr || !texture_path.empty(); }
};

/// Edge-based topology facts of a triangle surface.
struct SurfaceCheck {
  std::int64_t boundary_edges = 0;        ///< edges used by exactly one face
  std::int64_t nonmanifold_edges = 0;     ///< edges used by more than two faces
  std::int64_t inconsistent_edges = 0;    ///< edges whose two faces traverse them in the same direction
  std::int64_t degenerate_faces = 0;      ///< faces with a repeated vertex index
  std::int64_t nonmanifold_vertices = 0;  ///< vertices whose incident faces form more than one fan
  std::int64_t vertices = 0;              ///< vertices some face uses
  std::int64_t edges = 0;                 ///< distinct edges of the non-degenerate faces
  std::int64_t faces = 0;                 ///< non-degenerate faces
  std::int64_t components = 0;            ///< connected components (vertices joined by faces)
  /// V - E + F: 2 per sphere, 0 per torus, 2 - 2g per component of genus g (closed orientable surfaces).
  std::int64_t euler() const { return vertices - edges + faces; }
  bool closed() const { return boundary_edges == 0; }
  bool manifold() const { return nonmanifold_edges == 0 && nonmanifold_vertices == 0 && degenerate_faces == 0; }
};

/// Counts boundary, non-manifold and inconsistently oriented edges, and the surface's vertices, edges, faces and
/// components. Indices must be in range.
SurfaceCheck check_surface(const Eigen::MatrixXi& F, std::int64_t vertex_count);

/// Throws InvalidInput ("<name>: <problem>") unless the surface is non-empty, finite, has face indices
/// in range, and (when `require_closed`) is closed and manifold; then returns its check_surface (otherwise an
/// empty SurfaceCheck).
SurfaceCheck validate_surface(const Surface& surface, bool require_closed);

/// Merges vertices at bitwise-equal positions into the one of lowest index and drops the vertices no face uses then,
/// keeping the rest in order (texture coordinates, indexed per corner, are untouched): a mesh exported with its
/// vertices split at texture or normal seams, or as a triangle soup, becomes the closed surface it describes. Returns
/// how many vertices were merged away.
std::int64_t weld_coincident_vertices(Surface& surface);

/// Turns a closed surface whose faces wind inward (negative enclosed volume) outward: every face's corners, and its
/// texture corners, in reverse order. Returns whether it did. Inside and outside, the distance fields' sign, the
/// source's normals and with them the fold counts and the repair all take the faces' winding as outward.
bool orient_outward(Surface& surface);

/// Axis-aligned bounding box of the vertices.
Eigen::AlignedBox3d bounding_box(const Eigen::MatrixXd& V);

/// Signed volume enclosed by a closed surface (positive when faces are outward).
double signed_volume(const Eigen::MatrixXd& V, const Eigen::MatrixXi& F);

/// Total area of the triangles.
double surface_area(const Eigen::MatrixXd& V, const Eigen::MatrixXi& F);

/// Floater's mean value weights (2003) at corner k of triangle f: for the edges from F(f, k) to F(f, k + 1) and to
/// F(f, k + 2), tan(alpha / 2) / |edge| with alpha the corner's angle, paired with the vertex at the edge's far end.
/// Summed over the two triangles beside an edge they give w_ij, positive, so a Tutte embedding with them is one to
/// one inside a convex boundary and reproduces the surface's shape where it is flat. NaN for a zero-length edge.
template <class Faces>
std::array<std::pair<int, double>, 2> mean_value_weights(const Eigen::MatrixXd& V, const Faces& F, Eigen::Index f,
                                                         int k) {
  const int i = int(F(f, k)), j = int(F(f, (k + 1) % 3)), l = int(F(f, (k + 2) % 3));
  const Eigen::Vector3d vi = V.row(i), a = V.row(j).transpose() - vi, b = V.row(l).transpose() - vi;
  const double half_tan = std::tan(0.5 * std::atan2(a.cross(b).norm(), a.dot(b)));
  return {{{j, half_tan / a.norm()}, {l, half_tan / b.norm()}}};
}

}  // namespace morphmap
