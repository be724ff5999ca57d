// Critical points of s on the 4D mesh (see critical_points.h). Written by hand: no library classifies the vertices
// of a tetrahedral 3-manifold embedded in R^4 (CGAL's and VTK's topology tools work on 2D or 3D ambient meshes).
#include "solver/critical_points.h"

#include <tbb/blocked_range.h>
#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <string>
#include <utility>

#include "mesh/errors.h"
#include "mesh/stopwatch.h"

namespace morphmap {
namespace {

// Parts of the link below and above its centre: one union-find over the link's edges whose ends lie on one side.
std::pair<int, int> link_parts(const std::vector<std::array<int, 3>>& triangles, const std::vector<char>& below,
                               std::vector<int>& root) {
  const std::size_t n = below.size();
  root.resize(n);
  for (std::size_t i = 0; i < n; ++i) root[i] = int(i);
  const auto find = [&](int a) {
    while (root[std::size_t(a)] != a) a = root[std::size_t(a)] = root[std::size_t(root[std::size_t(a)])];
    return a;
  };
  for (const auto& t : triangles)
    for (int e = 0; e < 3; ++e) {
      const int a = t[std::size_t(e)], b = t[std::size_t((e + 1) % 3)];
      if (below[std::size_t(a)] != below[std::size_t(b)]) continue;
      const int ra = find(a), rb = find(b);
      if (ra != rb) root[std::size_t(std::max(ra, rb))] = std::min(ra, rb);
    }
  std::pair<int, int> parts{0, 0};
  for (std::size_t i = 0; i < n; ++i)
    if (find(int(i)) == int(i)) ++(below[i] ? parts.first : parts.second);
  return parts;
}

}  // namespace

CriticalPointResult critical_points(const TetMesh4& mesh, const VertexTets& stars, const Eigen::VectorXd& s,
                                    const CriticalPointOptions& options) {
  const auto start = Clock::now();
  const Eigen::Index nv = mesh.vertex_count();
  if (s.size() != nv)
    throw InvalidInput("critical_points: s has " + std::to_string(s.size()) + " values for " + std::to_string(nv) +
                       " vertices");
  const auto lower = [&](int a, int b) { return s(a) < s(b) || (s(a) == s(b) && a < b); };

  struct Local {
    std::int64_t interior = 0, minima = 0, maxima = 0, saddles = 0, multiplicity = 0;
    std::vector<int> index;  ///< #V: a link vertex's local number while its star is classified, else -1
  };
  tbb::combinable<Local> locals;
  // Blocks of a fixed size, merged in block order below, so the list does not depend on the threads.
  constexpr Eigen::Index kBlock = 4096;
  const Eigen::Index blocks = (nv + kBlock - 1) / kBlock;
  std::vector<std::vector<int>> block_listed(std::size_t(std::max<Eigen::Index>(blocks, 0)));
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, blocks), [&](const tbb::blocked_range<Eigen::Index>& range) {
    Local& local = locals.local();
    if (local.index.empty()) local.index.assign(std::size_t(nv), -1);
    std::vector<int> vertices, root;
    std::vector<std::array<int, 3>> triangles;
    std::vector<char> below;
    for (Eigen::Index block = range.begin(); block != range.end(); ++block)
      for (Eigen::Index v = block * kBlock; v < std::min(nv, (block + 1) * kBlock); ++v) {
        if (!mesh.side.empty() && mesh.side[std::size_t(v)] != VertexSide::Interior) continue;
        ++local.interior;
        // The link's vertices in first-seen order (a per-thread index over all vertices, reset after each star),
        // and each star tet's opposite triangle in that local numbering.
        vertices.clear();
        triangles.clear();
        for (std::int64_t j = stars.first(int(v)); j < stars.last(int(v)); ++j) {
          std::array<int, 3> tri{};
          int m = 0;
          for (int c = 0; c < 4; ++c) {
            const int u = mesh.T(stars.tet(j), c);
            if (u == v) continue;
            int& slot = local.index[std::size_t(u)];
            if (slot < 0) {
              slot = int(vertices.size());
              vertices.push_back(u);
            }
            tri[std::size_t(m++)] = slot;
          }
          triangles.push_back(tri);
        }
        for (const int u : vertices) local.index[std::size_t(u)] = -1;
        below.resize(vertices.size());
        for (std::size_t i = 0; i < vertices.size(); ++i) below[i] = lower(vertices[i], int(v));
        const auto [down, up] = link_parts(triangles, below, root);
        if (down == 1 && up == 1) continue;
        if (down == 0) ++local.minima;
        if (up == 0) ++local.maxima;
        if (down >= 2 || up >= 2) {
          ++local.saddles;
          local.multiplicity += std::max(down - 1, 0) + std::max(up - 1, 0);
        }
        block_listed[std::size_t(block)].push_back(int(v));
      }
  });
  CriticalPointResult result;
  locals.combine_each([&](const Local& l) {
    result.interior_vertices += l.interior;
    result.minima += l.minima;
    result.maxima += l.maxima;
    result.saddles += l.saddles;
    result.saddle_multiplicity += l.multiplicity;
  });
  for (const auto& listed : block_listed) result.listed.insert(result.listed.end(), listed.begin(), listed.end());
  std::sort(result.listed.begin(), result.listed.end(), [&](int a, int b) { return lower(a, b); });
  if (result.listed.size() > std::size_t(std::max(options.keep, 0))) result.listed.resize(std::size_t(options.keep));
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace morphmap
