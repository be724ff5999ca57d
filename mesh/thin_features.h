// A surface's topology kept on the lattice (paper §5.1: the morph's ends are the surfaces' distance fields sampled at
// lattice points, and §5.2 extracts the zero set of the samples). Two things open handles there that the surface
// does not have. (1) OpenVDB's signs are wrong at some points near thin parts (measured: 152 lattice points of the
// bunny at 40 voxels, all within two voxels of its ears); the surface's winding number along the lattice lines
// decides inside and outside instead. (2) A sheet or rod thinner than a voxel, or a gap narrower than one, can
// fall between lattice points, so no point lies inside the ear there and the extracted zero set has a hole (or joins
// two parts across the gap). An edge of the lattice's Kuhn triangulation whose ends have one sign and which crosses
// the surface twice passes through such a part; moving its end nearer the surface to the other side puts the part
// back on the lattice, less than a voxel from where it is. With both, the bunny at 40 voxels extracts as a sphere
// (Euler characteristic 2; -10 without, -6 with (1) alone, -4 with (2) alone).
#pragma once

#include <cstdint>
#include <vector>

#include "mesh/morph.h"
#include "mesh/transfer.h"

namespace morphmap {

/// Topology of the zero set that marching the Kuhn triangulation extracts from lattice values.
struct LatticeTopology {
  std::int64_t euler = 0;       ///< Euler characteristic: twice the inside's (the full subcomplex on points with d < 0)
  std::int64_t components = 0;  ///< closed surfaces: inside + outside components - 1 (the regions form a tree)
};

/// The zero set's topology. The lattice's boundary points must be outside (the morph's padding).
LatticeTopology lattice_topology(const MorphField& field, const std::vector<float>& values);

/// Inside/outside votes of every lattice point from the winding number of the surface along its three lattice lines
/// (one ray per line, each line writing only its own points): the signed count of crossings before the point, which
/// is nonzero inside, also where parts of a surface overlap (parity would call that outside). A line whose crossings
/// do not sum to zero has missed or doubled one (it grazes an edge) and does not vote.
struct WindingVotes {
  std::vector<std::uint8_t> inside;  ///< point_count() entries: lines through the point that put it inside (0-3)
  std::vector<std::uint8_t> votes;   ///< point_count() entries: lines through the point that vote (0-3)
  std::int64_t grazing_lines = 0;    ///< lattice lines that do not vote
};

/// The votes of the lattice lines of `field` on the surface `locator` is built on. The lattice's boundary points must
/// be outside the surface (the morph's padding).
WindingVotes winding_votes(const SurfaceLocator& locator, const MorphField& field);

/// Corrects the signs of `values` (field.dims.prod() entries in MorphField's layout: dA or dB of `field`) by the
/// winding number along the lattice lines through each point (the majority of the three axes; a line whose crossings'
/// directions do not sum to zero, which grazes the surface, does not vote), then moves lattice points across thin
/// parts: of every Kuhn edge ((i, j, k) + d, d in {0, 1}^3 \ 0, the triangulation extract_hypersurface uses) whose ends
/// have one sign and which crosses the surface twice or more, the end nearer the surface (smaller |d|; the lower index
/// on a tie) is a candidate to take the other sign. A value changes sign only (|d| is the distance either way), or
/// becomes
/// +-1e-6 h when it is zero. `locator` is built on `surface`. The result does not depend on the thread count. Sign
/// corrections (kept unless they take the topology further away) and thin parts are moved one group at a time (points
/// joined by Kuhn edges), and a group is kept only when it brings the zero set's topology nearer `target` (the
/// surface's own: |Euler difference| + |components difference| falls), so a rod thinner than a voxel, whose moved ends
/// would ring it with a handle, is left as it was.
ThinFeatureResult keep_thin_features(const SurfaceLocator& locator, const MorphField& field, std::vector<float>& values,
                                     const LatticeTopology& target, const ThinFeatureOptions& options = {},
                                     const WindingVotes* winding = nullptr);

}  // namespace morphmap
