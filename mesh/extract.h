// Extraction of the hypersurface d(x, t) = 0 in R^4 as tetrahedra (paper §5.2): hypercubes of the
// space-time lattice split into 24 Kuhn (Freudenthal) pentatopes, marching pentatopes inside.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/morph.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

struct ExtractOptions {
  int time_steps = 8;  ///< K: lattice intervals along t in [0, 1]
  /// c (length per unit t); <= 0 selects the default: twice the larger side of the shapes' union bounding box
  /// (field.extent; K * h, cubic cells, when unknown). Measured on sphere -> bunny (scripts/study_bunny.sh, README,
  /// traced map, 40 voxels, 8 steps): c = 8 h (cubic cells) p99 L2 stretch 22, mean 7e4; c = box 3.47, 1.22;
  /// 2 box 3.34, 1.21 (best on every figure); 4 box 3.66, 1.29.
  double time_scale = 0.0;
  /// |d| < zero_snap * h moves to +-zero_snap * h: crossings, and the slivers they make, stay off lattice points.
  /// Measured on concentric spheres (1 -> 2, 40 voxels, traced map): 0.01 leaves 0.01 h triangles whose preimages
  /// fold (58 folded, max stretch 1.5e5), 0.1 none (max 37); the surface moves by at most 0.1 h there.
  double zero_snap = 0.1;
  ///< (1e-3 left slivers that cost the Laplace solve ~100x in conditioning)
  /// Called once the exact tet and vertex counts are known, before the mesh arrays are allocated; may
  /// throw (the pipeline's --max-memory guard does). Empty = no check.
  std::function<void(std::int64_t tets, std::int64_t vertices)> before_allocate;
  /// Also record each tet's lattice cell and Kuhn simplex (TetMesh4::source_cell): 8 bytes a tet, live for the whole
  /// run, that no stage of the pipeline reads (off: source_cell stays empty).
  bool record_source_cells = false;
  /// Also record what lattice_face_neighbours needs to find the tet across every face of every tet
  /// (ExtractResult::faces): 4 bytes a tet and 16 a cell, where the neighbours themselves take 16 a tet.
  bool face_neighbours = false;
};

/// The tets' places in the lattice, from which lattice_face_neighbours finds every face's neighbour. A cell is
/// (candidate cube ordinal) * time_steps + (time level); its tets are consecutive, in Kuhn simplex order.
struct LatticeFaces {
  std::vector<std::uint32_t> code;         ///< #T: Kuhn simplex (bits 0-4); per face k (3 bits at 5 + 3 k) the facet
                                           ///< of the simplex it lies on (0-4), or 7 inside a prism
  std::vector<std::uint64_t> layout;       ///< per cell: the simplices with tets (bits 0-23), cut in a prism (32-55)
  std::vector<std::int64_t> tet_offset;    ///< cells + 1: the first tet of each cell
  std::vector<std::int64_t> candidates;    ///< the lattice cubes where d can change sign, in ordinal order
  std::vector<std::int32_t> cube_ordinal;  ///< per lattice cube: its ordinal among `candidates`, or -1
  std::int64_t cx = 0, cy = 0, cz = 0;     ///< lattice cubes per axis
  int time_steps = 0;                      ///< K
  bool known() const { return !code.empty(); }
};

/// The tet across every face (face_neighbours' result for the extracted mesh T, entry for entry), from the lattice: a
/// face on facet q of its pentatope is held by a tet of the pentatope across that facet, which the Kuhn permutation
/// names, in the same cell or the next along one axis; a face inside a prism by another tet of that prism. Unknown
/// (FaceNeighbours::known() false) when `faces` is empty.
FaceNeighbours lattice_face_neighbours(const LatticeFaces& faces, const TetIndices& T);
/// The same written to across[t * stride + k] (stride >= 4), e.g. into the tracer's per-tet records; throws
/// InvalidInput when `faces` is empty or not T's.
void lattice_face_neighbours(const LatticeFaces& faces, const TetIndices& T, int* across, std::size_t stride);

struct ExtractResult {
  TetMesh4 mesh;
  double seconds = 0.0;
  std::int64_t candidate_cubes =
      0;                            ///< spatial lattice cubes where d can change sign at some t (the only ones visited)
  std::int64_t active_cells = 0;    ///< 4D hypercubes with a sign change
  std::int64_t snapped_values = 0;  ///< values of dA and dB within zero_snap of zero (moved off zero)
  std::int64_t prisms = 0;          ///< pentatopes cut in a prism (2|3 split), 3 tets each
  std::int64_t scratch_bytes = 0;   ///< per-cell tables used besides the output mesh
  LatticeFaces faces;               ///< when ExtractOptions::face_neighbours, else empty
};

/// Extracts the tetrahedral mesh; throws TopologyError when the morph has no zero crossing.
ExtractResult extract_hypersurface(const MorphField& field, const ExtractOptions& options);

}  // namespace morphmap
