// Vertex -> incident tets of the 4D tet mesh (paper §7: the star of a vertex), shared by the upwind sweep
// and the characteristic tracer.
#pragma once

#include <cstdint>
#include <vector>

#include "mesh/tet_mesh4.h"

namespace morphmap {

/// Incident tets of every vertex in compressed rows; each vertex's tets are in increasing tet index, so a
/// choice among equally good tets is deterministic.
struct VertexTets {
  std::vector<std::int64_t> offset;  ///< #V + 1: tets of vertex v are tets[offset[v] .. offset[v + 1])
  std::vector<int> tets;             ///< 4 * #T tet indices

  std::int64_t first(int v) const { return offset[std::size_t(v)]; }
  std::int64_t last(int v) const { return offset[std::size_t(v) + 1]; }
  int tet(std::int64_t j) const { return tets[std::size_t(j)]; }
};

VertexTets build_vertex_tets(const TetIndices& T, Eigen::Index vertex_count);

}  // namespace morphmap
