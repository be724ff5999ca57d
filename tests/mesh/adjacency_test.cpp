// Vertex stars and the component census of the 4D mesh.
#include "mesh/adjacency.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <numeric>
#include <vector>

#include "mesh/errors.h"
#include "tests/mesh/product_mesh.h"

namespace morphmap {
namespace {

using test_mesh::icosphere;
using test_mesh::octahedron;
using test_mesh::product_mesh;
using test_mesh::with_component;

TEST(Adjacency, StarsListEveryIncidentTetOnceInOrder) {
  const TetMesh4 mesh = product_mesh(octahedron(), 2, 1.0);
  const VertexTets adj = build_vertex_tets(mesh.T, mesh.vertex_count());
  std::int64_t total = 0;
  for (Eigen::Index v = 0; v < mesh.vertex_count(); ++v) {
    for (std::int64_t j = adj.first(int(v)); j < adj.last(int(v)); ++j) {
      const int t = adj.tet(j);
      EXPECT_TRUE((mesh.T.row(t).array() == int(v)).any());
      if (j > adj.first(int(v))) {
        EXPECT_LT(adj.tet(j - 1), t);
      }
    }
    total += adj.last(int(v)) - adj.first(int(v));
  }
  EXPECT_EQ(total, 4 * mesh.tet_count());
}

TEST(Adjacency, CensusTellsBornAndVanishingComponentsApart) {
  const TetMesh4 main = product_mesh(icosphere(1), 4, 1.0);
  const ComponentCensus alone = component_census(main);
  EXPECT_EQ(alone.through, 1);
  EXPECT_EQ(alone.born + alone.vanishing + alone.floating, 0);

  // An octahedron that exists for t in [0.5, 1] only touches B; one for t in [0, 0.5] only touches A.
  const TetMesh4 born = with_component(main, product_mesh(octahedron(), 2, 0.5), 0.5, VertexSide::B);
  const ComponentCensus b = component_census(born);
  EXPECT_EQ(b.through, 1);
  EXPECT_EQ(b.born, 1);
  EXPECT_EQ(b.born_vertices, 18);  // 6 vertices x 3 layers
  EXPECT_EQ(b.vanishing, 0);
  const TetMesh4 both = with_component(born, product_mesh(octahedron(), 2, 0.5), 0.0, VertexSide::A);
  const ComponentCensus c = component_census(both);
  EXPECT_EQ(c.born, 1);
  EXPECT_EQ(c.vanishing, 1);
  EXPECT_EQ(c.vanishing_vertices, 18);
  EXPECT_EQ(c.floating, 0);

  // From labels computed before (the Laplace stage's): the same census, and labels of another size are refused.
  const std::vector<int> labels = component_labels(both.T, both.vertex_count());
  const ComponentCensus given = component_census(both, &labels);
  EXPECT_EQ(given.born, c.born);
  EXPECT_EQ(given.vanishing, c.vanishing);
  EXPECT_EQ(given.through, c.through);
  EXPECT_EQ(given.vanishing_vertices, c.vanishing_vertices);
  EXPECT_EQ(given.born_vertices, c.born_vertices);
  // Every vertex its own component: as many "floating" components as interior vertices.
  std::vector<int> apart(labels.size());
  std::iota(apart.begin(), apart.end(), 0);
  EXPECT_GT(component_census(both, &apart).floating, 0);
  const std::vector<int> short_labels(labels.begin(), labels.end() - 1);
  EXPECT_THROW(component_census(both, &short_labels), InvalidInput);
}

// The concurrent labels against a serial union-find, with some tets left out (so that components split), on one
// thread and on all: every vertex labelled with the smallest vertex of its component.
TEST(Adjacency, ComponentLabelsAreEachComponentsSmallestVertexOnAnyThreadCount) {
  TetMesh4 mesh =
      with_component(product_mesh(icosphere(2), 6, 1.0), product_mesh(octahedron(), 2, 0.5), 0.5, VertexSide::B);
  // Reverse the tet order so that unions do not arrive in vertex order.
  mesh.T = mesh.T.colwise().reverse().eval();
  std::vector<std::uint8_t> keep(static_cast<std::size_t>(mesh.tet_count()), 1);
  for (Eigen::Index t = 0; t < mesh.tet_count(); t += 3) keep[std::size_t(t)] = 0;
  const std::vector<std::uint8_t>* const masks[] = {nullptr, &keep};
  for (const std::vector<std::uint8_t>* mask : masks) {
    DisjointSets serial(mesh.vertex_count());
    for (Eigen::Index t = 0; t < mesh.tet_count(); ++t) {
      if (mask != nullptr && !(*mask)[std::size_t(t)]) continue;
      for (int k = 1; k < 4; ++k) serial.unite(mesh.T(t, 0), mesh.T(t, k));
    }
    std::vector<int> expected(static_cast<std::size_t>(mesh.vertex_count()));
    for (Eigen::Index v = 0; v < mesh.vertex_count(); ++v) expected[std::size_t(v)] = int(serial.find(v));
    const std::vector<int> all_threads = component_labels(mesh.T, mesh.vertex_count(), mask);
    std::vector<int> one_thread;
    {
      tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
      one_thread = component_labels(mesh.T, mesh.vertex_count(), mask);
    }
    EXPECT_EQ(all_threads, expected);
    EXPECT_EQ(one_thread, expected);
    // More than one component, so the test would see labels merged across them.
    std::vector<int> roots = expected;
    std::sort(roots.begin(), roots.end());
    EXPECT_GT(std::unique(roots.begin(), roots.end()) - roots.begin(), mask != nullptr ? 2 : 1);
  }
}

// Every face's neighbour against a search of all tets for the face's three vertices: on a mesh with a boundary (the
// product's ends) and two components, with one tet doubled (its faces then held by three tets: kManyTets), on one
// thread and on all; a tet that repeats a vertex leaves nothing known.
// Checks face_neighbours(T) on all threads and on one against a search of every tet for each face's holders;
// returns the number of faces held by one tet and by more than two.
std::pair<int, int> expect_face_neighbours_found(const TetIndices& T, Eigen::Index vertices) {
  const VertexTets stars = build_vertex_tets(T, vertices);
  const FaceNeighbours all = face_neighbours(T, stars);
  FaceNeighbours one;
  {
    tbb::global_control single(tbb::global_control::max_allowed_parallelism, 1);
    one = face_neighbours(T, stars);
  }
  EXPECT_TRUE(all.known());
  EXPECT_TRUE(one.known());
  if (!all.known() || !one.known()) return {0, 0};
  int boundary = 0, many = 0;
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) {
      std::vector<int> holders;
      for (Eigen::Index u = 0; u < T.rows(); ++u) {
        int shared = 0;
        for (int i = 0; i < 4; ++i)
          if (i != k) shared += (T.row(u).array() == T(t, i)).any() ? 1 : 0;
        if (shared == 3) holders.push_back(int(u));
      }
      int expected = FaceNeighbours::kManyTets;
      if (holders.size() == 1) expected = FaceNeighbours::kNoTet;
      if (holders.size() == 2) expected = holders[0] == t ? holders[1] : holders[0];
      boundary += expected == FaceNeighbours::kNoTet ? 1 : 0;
      many += expected == FaceNeighbours::kManyTets ? 1 : 0;
      EXPECT_EQ(all.across[std::size_t(t) * 4 + std::size_t(k)], expected) << "tet " << t << " face " << k;
      EXPECT_EQ(one.across[std::size_t(t) * 4 + std::size_t(k)], expected) << "tet " << t << " face " << k;
    }
  return {boundary, many};
}

TEST(Adjacency, FaceNeighboursAreWhatASearchOfEveryTetFinds) {
  TetMesh4 mesh =
      with_component(product_mesh(icosphere(1), 3, 1.0), product_mesh(octahedron(), 2, 0.5), 0.5, VertexSide::B);
  const Eigen::Index doubled = 7;
  mesh.T.conservativeResize(mesh.T.rows() + 1, 4);
  mesh.T.row(mesh.T.rows() - 1) = mesh.T.row(doubled).reverse();
  const auto [boundary, many] = expect_face_neighbours_found(mesh.T, mesh.vertex_count());
  EXPECT_GT(boundary, 0);
  // The doubled tet's faces inside the mesh are held by three tets (it, its copy and the one across), each seeing
  // kManyTets.
  EXPECT_EQ(many, 3 * 4);

  mesh.T(0, 1) = mesh.T(0, 0);
  EXPECT_FALSE(face_neighbours(mesh.T, build_vertex_tets(mesh.T, mesh.vertex_count())).known());
}

// A vertex whose faces reach more other vertices than the pair table holds (a cone of 100 tets from vertex 0 over a
// fan around vertex 1): its faces are grouped by the sort instead, with the same result; one tet is doubled so that
// some of those faces have three holders.
TEST(Adjacency, FaceNeighboursOfAVertexWithAHundredNeighbours) {
  const int ring = 100;
  TetIndices T(ring + 1, 4);
  for (int i = 0; i < ring; ++i) T.row(i) << 0, 1, 2 + i, 2 + (i + 1) % ring;
  T.row(ring) = T.row(5).reverse();
  const auto [boundary, many] = expect_face_neighbours_found(T, ring + 2);
  EXPECT_EQ(boundary, 2 * (ring - 1));  // each tet's faces without vertex 0 or without vertex 1, but the doubled one's
  EXPECT_EQ(many, 2 * 3);  // the doubled tet's faces through 0 and 1, each held by it, its copy and a neighbour
}

TEST(Adjacency, IndexRangeIsTheSmallestAndLargestIndex) {
  TetIndices T(200000, 4);
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) T(t, k) = int((t * 7919 + k * 104729) % 1000003) + 5;
  T(123456, 2) = 3;
  T(7, 0) = 2000000;
  const std::pair<int, int> range = index_range(T);
  EXPECT_EQ(range.first, T.minCoeff());
  EXPECT_EQ(range.second, T.maxCoeff());
  EXPECT_EQ(range.first, 3);
  EXPECT_EQ(range.second, 2000000);
  EXPECT_EQ(index_range(TetIndices(0, 4)), std::make_pair(0, -1));
}

// Enough tets for the parallel build to split them (a chunk a thread, each of at least 2^16 tets): every list in tet
// order, as a serial counting sort gives it, on one thread and on all.
TEST(Adjacency, StarsBuiltInChunksAreTheSerialBuild) {
  const Eigen::Index vertices = 5000;
  TetIndices T(700000, 4);
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) T(t, k) = int((t * 7919 + k * 104729 + (t / 1000) * 31) % vertices);
  std::vector<std::vector<int>> expected(static_cast<std::size_t>(vertices));
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    for (int k = 0; k < 4; ++k) expected[std::size_t(T(t, k))].push_back(int(t));
  const VertexTets all = build_vertex_tets(T, vertices);
  VertexTets one;
  {
    tbb::global_control single(tbb::global_control::max_allowed_parallelism, 1);
    one = build_vertex_tets(T, vertices);
  }
  const VertexTets* const builds[] = {&all, &one};
  for (const VertexTets* adj : builds) {
    ASSERT_EQ(adj->offset.size(), std::size_t(vertices) + 1);
    for (Eigen::Index v = 0; v < vertices; ++v) {
      const std::vector<int> star(adj->tets.begin() + adj->first(int(v)), adj->tets.begin() + adj->last(int(v)));
      ASSERT_EQ(star, expected[std::size_t(v)]) << "vertex " << v;
    }
  }
}

}  // namespace
}  // namespace morphmap
