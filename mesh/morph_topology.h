// A distance-field morph without topology changes its ends do not need (beyond the paper: §5.1 interpolates the two
// distance fields linearly, and §9.1 notes how the morph shapes the map). Between two shapes of one topology the
// linear interpolation can still open handles and bubbles for a while: on sphere -> bunny at 40 voxels the ears'
// tips appear as separate components from t = 0.85 and the ears' bases carry a handle from t = 0.8 (slices of the
// extracted 4D mesh). Each such event puts a critical point of t, and so mostly of the harmonic s, into the 4D
// mesh, and the characteristics traced back from B part at its separatrix: a seam of the map, folds and collapsed
// triangles on either side of it (README, "Where the folds are").
//
// Here every lattice point that changes sides (inside A and outside B, or the reverse) does so in the order of its
// own crossing time t* = dA / (dA - dB), but only when the change is simple: when the inside's and the outside's
// topology stay as they are (digital topology, as in the topology-preserving level sets of Han, Xu and Prince 2003,
// here on the Kuhn triangulation that the extraction marches). A point whose change is not simple waits until one of
// its neighbours changes and makes it so. The morph is then sampled at the time levels with each point's zero
// crossing moved to when it changed (MorphField::levels), so the extraction sees the same order.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/morph.h"
#include "mesh/thin_features.h"

namespace morphmap {

struct MorphTopologyOptions {
  /// "free": the plain linear interpolation (the paper's morph; default: on sphere -> bunny at 8 time steps "auto"
  /// measured worse, see README "Morph topology"); "auto": keep the topology when the two ends have the same one on
  /// the lattice (Euler characteristic and components of the zero sets of dA and dB); "preserve": always (where the
  /// ends differ, the changes that must happen come last, when no point can change simply: forced_flips).
  std::string mode = "free";
};

struct MorphTopologyResult {
  bool applied = false;              ///< the levels were resampled (mode preserve, or auto with equal ends)
  LatticeTopology source, target;    ///< the zero sets of dA and dB on the lattice (not counted in mode free)
  std::int64_t changing_points = 0;  ///< lattice points whose side differs between dA and dB
  std::int64_t delayed_points = 0;   ///< of those, points that changed after their own crossing time t*
  std::int64_t forced_flips = 0;     ///< changes made although not simple (only where the ends' topologies differ)
  double max_delay = 0.0;            ///< largest delay (t' - t*) in units of the morph time
  /// Time levels whose zero set's topology differs from the source's, in the linear interpolation and as kept
  /// (counted at the K + 1 lattice levels; events between two levels are not seen here).
  std::int64_t levels_changed_free = 0, levels_changed_kept = 0;
  double seconds = 0.0;
};

/// Resamples the distance-field morph `field` (dA, dB set, levels empty) at time_steps + 1 levels so that no level
/// and, as far as the crossing times order them, no time between levels has a topology the ends do not force (see
/// above). Fills field.levels and field.time_levels when applied; leaves the field as it was otherwise (mode "free",
/// or "auto" with ends of different topology). Points that do not change sides keep the linear interpolation's
/// values bit for bit, as do the ones whose change was simple at their own time. Deterministic: one sequential pass
/// ordered by (time, index). Throws InvalidInput for an unknown mode, time_steps < 1 or a field that already has
/// levels.
MorphTopologyResult keep_morph_topology(MorphField& field, int time_steps, const MorphTopologyOptions& options = {});

/// True when adding or removing the point with these inside neighbours keeps the topology of the inside and of the
/// outside: the inside neighbours span a contractible, non-empty proper part of the point's link (a 14-vertex sphere
/// in the Kuhn triangulation). Bit b of `inside_neighbours` is neighbour b of kuhn_neighbour_offsets().
bool simple_lattice_point(std::uint32_t inside_neighbours);

/// The 14 neighbours of a lattice point in the Kuhn triangulation: +-(1,0,0), +-(0,1,0), +-(0,0,1), +-(1,1,0),
/// +-(1,0,1), +-(0,1,1), +-(1,1,1), in that order (each positive offset followed by its negative).
const std::vector<std::array<int, 3>>& kuhn_neighbour_offsets();

}  // namespace morphmap
