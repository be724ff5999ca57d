// Vertex -> incident tets (see adjacency.h).
#include "mesh/adjacency.h"

namespace morphmap {

VertexTets build_vertex_tets(const TetIndices& T, Eigen::Index vertex_count) {
  VertexTets adj;
  adj.offset.assign(static_cast<std::size_t>(vertex_count) + 1, 0);
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) ++adj.offset[static_cast<std::size_t>(T(t, k)) + 1];
  for (std::size_t i = 1; i < adj.offset.size(); ++i) adj.offset[i] += adj.offset[i - 1];
  adj.tets.resize(static_cast<std::size_t>(adj.offset.back()));
  std::vector<std::int64_t> fill(adj.offset.begin(), adj.offset.end() - 1);
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) adj.tets[static_cast<std::size_t>(fill[static_cast<std::size_t>(T(t, k))]++)] = int(t);
  return adj;
}

}  // namespace morphmap
