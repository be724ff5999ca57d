// Distance-field morph d(x, t) = (1 - t) dA(x) + t dB(x) (Payne and Toga 1992; paper §5.1),
// sampled on a regular lattice, as dense arrays: closest-point queries (or, on request, OpenVDB's signed distance
// grids, which no other translation unit includes) give a mesh's distances near its surface.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/surface.h"

namespace morphmap {

/// Thin parts kept on the lattice (mesh/thin_features.h).
struct ThinFeatureOptions {
  bool enabled = true;  ///< off: the samples are left as they are (thin parts may open handles or split off)
};

struct ThinFeatureResult {
  std::int64_t sign_disagreements = 0;  ///< lattice points whose sign the surface's winding number contradicts
  std::int64_t sign_flips = 0;          ///< of those, points given the winding's sign (kept groups)
  std::int64_t grazing_lines = 0;       ///< lattice lines whose crossings' directions do not sum to zero (no vote)
  std::int64_t edges_tested = 0;   ///< Kuhn edges close enough to the surface to hide two crossings (|d_a| + |d_b| <
                                   ///< their length), each cast against the surface
  std::int64_t thin_edges = 0;     ///< of those, edges with ends of one sign crossing the surface twice or more
  std::int64_t moved_inside = 0;   ///< points moved inside (kept groups): an edge from them crosses a thin solid part
  std::int64_t moved_outside = 0;  ///< points moved outside (kept groups): an edge from them crosses a thin gap
  std::int64_t groups = 0;         ///< groups of candidate points (joined by Kuhn edges), each kept or not as a whole
  std::int64_t groups_kept = 0;    ///< groups that brought the zero set's topology nearer the surface's
  /// The zero set's Euler characteristic and components as sampled (OpenVDB's signs) and as kept.
  std::int64_t sampled_euler = 0, sampled_components = 0, kept_euler = 0, kept_components = 0;
};

struct MorphOptions {
  int voxels = 40;          ///< lattice voxels across the larger side of the union bounding box (demo: 2.4M tets, 10 s)
  double voxel_size = 0.0;  ///< explicit voxel size h; overrides `voxels` when > 0
  int padding = 2;          ///< voxels of margin around the union bounding box (d > 0 there)
  /// Narrow-band half width in voxels (0: the method's own, band_voxels()): distances inside it come from the
  /// `distances` method, exact ones are filled in beyond it where the morph can change sign. The extraction and the
  /// thin-feature pass read values only within sqrt(3) voxels of a surface, so with exact distances any band over that
  /// gives the same values there; OpenVDB's band values are a few percent off, and its 3 voxels were kept as measured.
  double band = 0.0;
  /// How a mesh's distances inside the band and its signs are found: "exact" (closest-point queries at the lattice
  /// points within the band, signs from the winding number along the lattice lines) or "openvdb" (OpenVDB's
  /// meshToVolume, its values up to 4-14% of a voxel off and its signs flood-filled; 3-4 times slower on meshes of
  /// many small triangles, measured on the horse and the Buddha).
  std::string distances = "exact";

  /// The band's half width in voxels: `band`, or 2 for "exact" distances and 3 for "openvdb" when it is 0.
  double band_voxels() const { return band > 0.0 ? band : distances == "openvdb" ? 3.0 : 2.0; }
  ThinFeatureOptions thin;  ///< sheets, rods and gaps thinner than a voxel kept on the lattice (meshes only)
};

/// Signed distances of A and B (negative inside) on the lattice points origin + h * (i, j, k).
/// Signs are right everywhere; at every corner of a cube where d can change sign for some t (near the
/// surfaces and over the symmetric difference of the solids) distances are exact inside the band (with
/// MorphOptions::distances "openvdb": OpenVDB's, up to 4-14% of a voxel off, see fill_exact_distances in morph.cpp)
/// and exact beyond it; clamped to +-band voxels elsewhere, where they cannot influence the zero set. A surface with
/// an analytic signed_distance (built-in shapes) is sampled from it, exactly, at every lattice point.
struct MorphField {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  ///< world position of lattice point (0, 0, 0)
  double voxel_size = 0.0;                           ///< h
  double extent = 0.0;  ///< larger side of the union bounding box of A and B (0: unknown), the default time scale
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();  ///< lattice points along x, y, z
  std::vector<float> dA;  ///< dims.prod() values, x fastest: index = i + dims.x * (j + dims.y * k)
  std::vector<float> dB;  ///< same layout as dA
  /// Empty for the distance-field morph, whose d(x, t) = (1 - t) dA + t dB is a function of dA and dB. A morph that
  /// is not (the variational implicit morph, mesh/vim.h) is sampled at every time level t = l / (time_levels - 1)
  /// instead: time_levels * dims.prod() values, level after level (index = l * dims.prod() + index(i, j, k)); dA
  /// and dB then hold its first and last levels. Extraction needs time_levels = its time steps + 1.
  std::vector<float> levels;
  int time_levels = 0;

  /// Lattice points, dims.x * dims.y * dims.z, in 64 bits (dims.prod() is an int, which 1291 points a side
  /// overflow).
  std::int64_t point_count() const { return std::int64_t(dims.x()) * dims.y() * dims.z(); }

  std::int64_t index(int i, int j, int k) const {
    return i + std::int64_t(dims.x()) * (j + std::int64_t(dims.y()) * k);
  }
  Eigen::Vector3d point(int i, int j, int k) const { return origin + voxel_size * Eigen::Vector3d(i, j, k); }
  /// The distance-field morph (1 - t) dA + t dB at lattice point q: the one formula the extraction and the resampling
  /// of mesh/morph_topology.h share, so that a point they both evaluate gets the same bits.
  double linear_value(std::int64_t q, double t) const {
    return (1.0 - t) * dA[std::size_t(q)] + t * dB[std::size_t(q)];
  }
};

struct MorphResult {
  MorphField field;
  double seconds = 0.0;  ///< wall time of the stage
  std::int64_t lattice_points = 0;
  std::int64_t band_queries = 0;     ///< closest-point queries made for the band ("exact" distances)
  std::int64_t exact_queries = 0;    ///< closest-point queries made beyond the narrow band
  std::string method = "distance";   ///< "distance" (build_morph) or "vim" (build_vim_morph)
  ThinFeatureResult thin_a, thin_b;  ///< thin parts of A and B put back on the lattice (distance morph of meshes)
  std::int64_t rbf_centres = 0;      ///< vim: basis functions of the 4D implicit function
  double fit_residual = 0.0;         ///< vim: largest |G(c_i) - f_i| over the constraints, in length units
  double fit_seconds = 0.0;          ///< vim: sampling, constraint system and its solve (the rest is evaluation)
};

/// The lattice of a morph between A and B: origin, voxel size, extent and dims as build_morph chooses them (the
/// union bounding box plus padding), with no values. Throws InvalidInput for invalid options or an empty box.
MorphField morph_lattice(const Surface& A, const Surface& B, const MorphOptions& options);

/// Builds dA and dB on a lattice covering both (closed, manifold) surfaces plus padding. `checks`, when given, is
/// A's and B's check_surface (two entries, e.g. as validate_surface returned them while loading): the topology the
/// thin features keep; computed here otherwise.
MorphResult build_morph(const Surface& A, const Surface& B, const MorphOptions& options,
                        const SurfaceCheck* checks = nullptr);

/// Samples analytic signed distances on a cubic lattice of n^3 points spanning [-extent, extent]^3:
/// exact fields for tests and benchmarks of the stages after the morph.
MorphField sample_morph(const SignedDistance& dA, const SignedDistance& dB, double extent, int n);

}  // namespace morphmap
