// Vertex -> incident tets of the 4D tet mesh (paper §7: the star of a vertex), shared by the upwind sweep
// and the characteristic tracer; connected components and what each touches (paper §8: components born or
// vanishing during the morph).
#pragma once

#include <algorithm>
#include <cstdint>
#include <memory>
#include <numeric>
#include <utility>
#include <vector>

#include "mesh/default_init.h"
#include "mesh/tet_mesh4.h"

namespace morphmap {

/// Incident tets of every vertex in compressed rows; each vertex's tets are in increasing tet index, so a
/// choice among equally good tets is deterministic.
struct VertexTets {
  std::vector<std::int64_t> offset;  ///< #V + 1: tets of vertex v are tets[offset[v] .. offset[v + 1])
  UninitialisedVector<int> tets;     ///< 4 * #T tet indices (resized unzeroed: the build writes every one)

  std::int64_t first(int v) const { return offset[std::size_t(v)]; }
  std::int64_t last(int v) const { return offset[std::size_t(v) + 1]; }
  int tet(std::int64_t j) const { return tets[std::size_t(j)]; }
};

VertexTets build_vertex_tets(const TetIndices& T, Eigen::Index vertex_count);
/// The smallest and largest vertex index in T ({0, -1} when T is empty), in one parallel pass: the stages' input
/// checks took them by Eigen's minCoeff and maxCoeff, two serial passes over 27 MB each on cow -> horse, in three
/// stages.
std::pair<int, int> index_range(const TetIndices& T);

/// The stars of a mesh, built once and shared by the stages that walk them (quality, Laplace assembly, gradient,
/// tracing, the upwind sweep): on cow -> horse (1.7M tets) each build took 30-40 ms.
using SharedStars = std::shared_ptr<const VertexTets>;

/// `given` when it is set (it must be the stars of T), else a new build.
SharedStars stars_or_build(const SharedStars& given, const TetIndices& T, Eigen::Index vertex_count);

/// Union-find with path halving; roots are the smallest index of their set so labels are deterministic.
class DisjointSets {
 public:
  explicit DisjointSets(Eigen::Index n) : parent_(static_cast<std::size_t>(n)) {
    std::iota(parent_.begin(), parent_.end(), 0);
  }
  Eigen::Index find(Eigen::Index a) {
    while (parent_[static_cast<std::size_t>(a)] != a) {
      parent_[static_cast<std::size_t>(a)] = parent_[static_cast<std::size_t>(parent_[static_cast<std::size_t>(a)])];
      a = parent_[static_cast<std::size_t>(a)];
    }
    return a;
  }
  void unite(Eigen::Index a, Eigen::Index b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (a < b) std::swap(a, b);
    parent_[static_cast<std::size_t>(a)] = b;
  }

 private:
  std::vector<Eigen::Index> parent_;
};

/// The connected component of every vertex through the tets t with keep(t) (nullptr: every tet), as the smallest
/// vertex index of the component: #V entries, a vertex in no kept tet its own component. Concurrent union-find
/// over the tets: roots are linked only under smaller roots, by compare-and-swap, so the labels are the same for
/// any thread count and schedule. (Serial, each of the two runs over cow -> horse's 1.7 M tets took 20 ms with a
/// core idle.)
std::vector<int> component_labels(const TetIndices& T, Eigen::Index vertex_count,
                                  const std::vector<std::uint8_t>* keep = nullptr);

/// The tet across every face of every tet: across[4 t + k] is the tet that shares t's face opposite T(t, k), what a
/// search of the three face vertices' stars finds: kNoTet where t alone holds the face (the mesh's boundary),
/// kManyTets where more than two tets hold it.
struct FaceNeighbours {
  static constexpr int kNoTet = -1, kManyTets = -3;
  std::unique_ptr<int[]> across;  ///< #T * 4 entries; null when a tet repeats a vertex (its faces are not three
                                  ///< distinct vertices), and then nothing is known
  bool known() const { return across != nullptr; }
};

/// Every face is settled once, by its smallest vertex v, from v's star: the faces of its tets that hold v and no
/// smaller vertex, sorted by their other two vertices so that equal faces meet; every entry is written by one vertex,
/// so the result does not depend on the thread count. Written by hand (no library has face adjacency of a
/// tetrahedral mesh in R^4 from vertex stars).
FaceNeighbours face_neighbours(const TetIndices& T, const VertexTets& stars);

/// Connected components of the 4D mesh (through shared vertices) by the ends of the morph they touch.
struct ComponentCensus {
  std::int64_t through = 0;    ///< touch A and B: the map runs through them
  std::int64_t born = 0;       ///< touch B only: appear during the morph, nothing flows into them from A
  std::int64_t vanishing = 0;  ///< touch A only: disappear during the morph, nothing of them reaches B
  std::int64_t floating = 0;   ///< touch neither end
  std::int64_t born_vertices = 0, vanishing_vertices = 0, floating_vertices = 0;
};

/// `labels`, when given, are component_labels(mesh.T, #V) already computed (the Laplace stage's, when it kept every
/// tet), so the union-find is not run twice; they must be the labels of every tet.
ComponentCensus component_census(const TetMesh4& mesh, const std::vector<int>* labels = nullptr);

}  // namespace morphmap
