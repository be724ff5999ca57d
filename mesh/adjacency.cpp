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

SharedStars stars_or_build(const SharedStars& given, const TetIndices& T, Eigen::Index vertex_count) {
  if (given) return given;
  return std::make_shared<const VertexTets>(build_vertex_tets(T, vertex_count));
}

ComponentCensus component_census(const TetMesh4& mesh) {
  const Eigen::Index n = mesh.vertex_count();
  DisjointSets sets(n);
  for (Eigen::Index t = 0; t < mesh.tet_count(); ++t)
    for (int k = 1; k < 4; ++k) sets.unite(mesh.T(t, 0), mesh.T(t, k));
  std::vector<std::uint8_t> touches(static_cast<std::size_t>(n), 0);  // per root: bit 1 A, bit 2 B
  std::vector<Eigen::Index> size(static_cast<std::size_t>(n), 0);
  for (Eigen::Index v = 0; v < n; ++v) {
    const auto r = static_cast<std::size_t>(sets.find(v));
    ++size[r];
    if (mesh.side[std::size_t(v)] == VertexSide::A) touches[r] |= 1;
    if (mesh.side[std::size_t(v)] == VertexSide::B) touches[r] |= 2;
  }
  ComponentCensus c;
  for (Eigen::Index v = 0; v < n; ++v) {
    if (sets.find(v) != v) continue;
    const std::size_t r = std::size_t(v);
    switch (touches[r]) {
      case 3:
        ++c.through;
        break;
      case 2:
        ++c.born, c.born_vertices += size[r];
        break;
      case 1:
        ++c.vanishing, c.vanishing_vertices += size[r];
        break;
      default:
        ++c.floating, c.floating_vertices += size[r];
        break;
    }
  }
  return c;
}

}  // namespace morphmap
