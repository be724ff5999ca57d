// Vertex -> incident tets (see adjacency.h).
#include "mesh/adjacency.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <memory>
#include <string>

#include "mesh/errors.h"

namespace morphmap {

VertexTets build_vertex_tets(const TetIndices& T, Eigen::Index vertex_count) {
  // A counting sort in chunks of tets, one a thread: each chunk counts its own uses of every vertex, so that chunk
  // c's tets go to vertex v's list after those of chunks 0 .. c-1, in tet order within the chunk. Every list is in
  // increasing tet order however many chunks there are, so the thread count changes nothing but the work split.
  // (Serial, the build was the longest pass left on one core in a cow -> horse run, 14-16 ms.)
  const Eigen::Index tets = T.rows();
  const Eigen::Index chunks = std::max<Eigen::Index>(
      1, std::min<Eigen::Index>(tbb::this_task_arena::max_concurrency(), tets / (Eigen::Index(1) << 16)));
  const Eigen::Index chunk_tets = (tets + chunks - 1) / chunks;
  const std::size_t n = static_cast<std::size_t>(vertex_count);
  // cursor[c * n + v]: chunk c's count of vertex v, then where chunk c writes v's next tet. Zeroed by its chunk.
  const std::unique_ptr<std::int64_t[]> cursor(new std::int64_t[std::size_t(chunks) * n]);
  tbb::parallel_for(Eigen::Index(0), chunks, [&](Eigen::Index c) {
    std::int64_t* count = cursor.get() + std::size_t(c) * n;
    std::fill(count, count + n, std::int64_t(0));
    const Eigen::Index end = std::min(tets, (c + 1) * chunk_tets);
    for (Eigen::Index t = c * chunk_tets; t < end; ++t)
      for (int k = 0; k < 4; ++k) ++count[static_cast<std::size_t>(T(t, k))];
  });
  VertexTets adj;
  adj.offset.assign(n + 1, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t v = r.begin(); v != r.end(); ++v) {
      std::int64_t total = 0;
      for (Eigen::Index c = 0; c < chunks; ++c) total += cursor[std::size_t(c) * n + v];
      adj.offset[v + 1] = total;
    }
  });
  for (std::size_t i = 1; i < adj.offset.size(); ++i) adj.offset[i] += adj.offset[i - 1];
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t v = r.begin(); v != r.end(); ++v) {
      std::int64_t at = adj.offset[v];
      for (Eigen::Index c = 0; c < chunks; ++c) {
        std::int64_t& slot = cursor[std::size_t(c) * n + v];
        const std::int64_t count = slot;
        slot = at;
        at += count;
      }
    }
  });
  // Not zeroed (UninitialisedVector): the fill below writes every entry, in parallel, so it is also the first touch.
  adj.tets.resize(static_cast<std::size_t>(adj.offset.back()));
  tbb::parallel_for(Eigen::Index(0), chunks, [&](Eigen::Index c) {
    std::int64_t* fill = cursor.get() + std::size_t(c) * n;
    const Eigen::Index end = std::min(tets, (c + 1) * chunk_tets);
    for (Eigen::Index t = c * chunk_tets; t < end; ++t)
      for (int k = 0; k < 4; ++k)
        adj.tets[static_cast<std::size_t>(fill[static_cast<std::size_t>(T(t, k))]++)] = int(t);
  });
  return adj;
}

std::pair<int, int> index_range(const TetIndices& T) {
  if (T.size() == 0) return {0, -1};
  using Range = std::pair<int, int>;
  return tbb::parallel_reduce(
      tbb::blocked_range<Eigen::Index>(0, T.rows(), 1 << 16), Range(T(0, 0), T(0, 0)),
      [&](const tbb::blocked_range<Eigen::Index>& r, Range range) {
        for (Eigen::Index t = r.begin(); t != r.end(); ++t)
          for (int k = 0; k < 4; ++k) {
            range.first = std::min(range.first, T(t, k));
            range.second = std::max(range.second, T(t, k));
          }
        return range;
      },
      [](const Range& a, const Range& b) { return Range(std::min(a.first, b.first), std::max(a.second, b.second)); });
}

SharedStars stars_or_build(const SharedStars& given, const TetIndices& T, Eigen::Index vertex_count) {
  if (given) return given;
  return std::make_shared<const VertexTets>(build_vertex_tets(T, vertex_count));
}

namespace {

// Union-find on atomic parents. A root is linked only under a smaller root, and only while it is still a root (the
// compare-and-swap expects it to point to itself), so every set ends with its smallest member as its root whatever
// order the unions ran in. Path halving writes a grandparent over a parent, an ancestor either way, so a racing
// find can only see a shorter path to the same root.
class ConcurrentSets {
 public:
  explicit ConcurrentSets(Eigen::Index n) : parent_(new std::atomic<int>[std::size_t(n)]) {
    tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, n), [&](const tbb::blocked_range<Eigen::Index>& r) {
      for (Eigen::Index i = r.begin(); i != r.end(); ++i)
        parent_[std::size_t(i)].store(int(i), std::memory_order_relaxed);
    });
  }
  int find(int a) const {
    for (;;) {
      int p = parent_[std::size_t(a)].load(std::memory_order_relaxed);
      if (p == a) return a;
      const int grand = parent_[std::size_t(p)].load(std::memory_order_relaxed);
      if (grand != p) parent_[std::size_t(a)].compare_exchange_weak(p, grand, std::memory_order_relaxed);
      a = grand;
    }
  }
  void unite(int a, int b) {
    for (;;) {
      a = find(a);
      b = find(b);
      if (a == b) return;
      if (a < b) std::swap(a, b);
      int expected = a;
      if (parent_[std::size_t(a)].compare_exchange_strong(expected, b, std::memory_order_acq_rel)) return;
    }
  }

 private:
  std::unique_ptr<std::atomic<int>[]> parent_;
};

}  // namespace

std::vector<int> component_labels(const TetIndices& T, Eigen::Index vertex_count,
                                  const std::vector<std::uint8_t>* keep) {
  ConcurrentSets sets(vertex_count);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, T.rows(), 4096),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      for (Eigen::Index t = r.begin(); t != r.end(); ++t) {
                        if (keep != nullptr && !(*keep)[std::size_t(t)]) continue;
                        for (int k = 1; k < 4; ++k) sets.unite(T(t, 0), T(t, k));
                      }
                    });
  std::vector<int> label(static_cast<std::size_t>(vertex_count));
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, vertex_count), [&](const tbb::blocked_range<Eigen::Index>& r) {
    for (Eigen::Index v = r.begin(); v != r.end(); ++v) label[std::size_t(v)] = sets.find(int(v));
  });
  return label;
}

FaceNeighbours face_neighbours(const TetIndices& T, const VertexTets& stars) {
  FaceNeighbours result;
  const Eigen::Index tets = T.rows();
  const bool repeats = tbb::parallel_reduce(
      tbb::blocked_range<Eigen::Index>(0, tets), false,
      [&](const tbb::blocked_range<Eigen::Index>& r, bool found) {
        for (Eigen::Index t = r.begin(); t != r.end() && !found; ++t)
          for (int i = 0; i < 4; ++i)
            for (int j = i + 1; j < 4; ++j) found = found || T(t, i) == T(t, j);
        return found;
      },
      [](bool a, bool b) { return a || b; });
  if (repeats) return result;
  // Not zeroed: every entry is written below (each face of a tet with four distinct vertices has a smallest one).
  result.across.reset(new int[std::size_t(tets) * 4]);
  struct FaceUse {
    std::uint64_t face;  // the face's vertices other than v, b < c, as (b << 32) | c: equal faces meet in a sort
    int tet;
    int slot;  // the position in the tet's row of its vertex opposite the face
  };
  // Equal faces are found by a table over pairs of v's link vertices (each numbered in order of first appearance),
  // which costs a lookup a use where sorting the uses (22 a vertex on cow -> horse) was a fifth of the pass; a vertex
  // with more than kLink link vertices above it takes the sort. Within a face the order of its holders does not
  // matter (two tets see each other, more all see kManyTets), so both give the same entries.
  constexpr int kLink = 64;
  struct Scratch {
    std::vector<int> local;                  // #V: a link vertex's number, -1 when it has none
    std::vector<int> numbered;               // the link vertices numbered, to reset `local`
    std::vector<int> cell;                   // kLink x kLink: the group of a pair of link numbers, -1 when none
    std::vector<int> touched;                // cells set, to reset them
    std::vector<std::array<int, 3>> groups;  // per face: its first use, its second (or -1) and its use count
    std::vector<int> group_of;               // per use
    std::vector<FaceUse> uses;
  };
  const Eigen::Index vertices = Eigen::Index(stars.offset.size()) - 1;
  tbb::enumerable_thread_specific<Scratch> scratch([&] {
    Scratch w;
    w.local.assign(std::size_t(vertices), -1);
    w.cell.assign(std::size_t(kLink) * kLink, -1);
    return w;
  });
  auto write = [&](const FaceUse& use, int holders, const FaceUse* other) {
    int value = FaceNeighbours::kManyTets;
    if (holders == 1) value = FaceNeighbours::kNoTet;
    if (holders == 2) value = other->tet;
    result.across[std::size_t(use.tet) * 4 + std::size_t(use.slot)] = value;
  };
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, vertices, 512), [&](const tbb::blocked_range<Eigen::Index>& r) {
    Scratch& w = scratch.local();
    std::vector<FaceUse>& uses = w.uses;
    for (Eigen::Index v = r.begin(); v != r.end(); ++v) {
      uses.clear();
      for (std::int64_t j = stars.first(int(v)); j < stars.last(int(v)); ++j) {
        const int t = stars.tet(j);
        const int row[4] = {T(t, 0), T(t, 1), T(t, 2), T(t, 3)};
        for (int k = 0; k < 4; ++k) {
          if (row[k] == v) continue;  // the face opposite v does not hold it
          int other[2] = {-1, -1}, m = 0;
          bool smallest = true;
          for (int i = 0; i < 4; ++i) {
            if (i == k || row[i] == v) continue;
            smallest = smallest && row[i] > v;
            other[m++] = row[i];
          }
          if (!smallest) continue;
          const std::uint64_t b = std::uint64_t(std::min(other[0], other[1]));
          const std::uint64_t c = std::uint64_t(std::max(other[0], other[1]));
          uses.push_back({(b << 32) | c, t, k});
        }
      }
      auto number = [&](int u) {
        int& n = w.local[std::size_t(u)];
        if (n < 0) {
          n = int(w.numbered.size());
          w.numbered.push_back(u);
        }
        return n;
      };
      bool fits = true;
      w.group_of.resize(uses.size());
      for (std::size_t u = 0; u < uses.size() && fits; ++u) {
        const int lb = number(int(uses[u].face >> 32)), lc = number(int(uses[u].face & 0xffffffffu));
        fits = lb < kLink && lc < kLink;
        if (!fits) break;
        int& g = w.cell[std::size_t(lb * kLink + lc)];
        if (g < 0) {
          g = int(w.groups.size());
          w.groups.push_back({int(u), -1, 0});
          w.touched.push_back(lb * kLink + lc);
        } else if (w.groups[std::size_t(g)][1] < 0) {
          w.groups[std::size_t(g)][1] = int(u);
        }
        ++w.groups[std::size_t(g)][2];
        w.group_of[u] = g;
      }
      if (fits) {
        for (std::size_t u = 0; u < uses.size(); ++u) {
          const std::array<int, 3>& g = w.groups[std::size_t(w.group_of[u])];
          write(uses[u], g[2], &uses[std::size_t(g[0]) == u ? std::size_t(g[1]) : std::size_t(g[0])]);
        }
      } else {
        std::sort(uses.begin(), uses.end(), [](const FaceUse& x, const FaceUse& y) { return x.face < y.face; });
        for (std::size_t a = 0; a < uses.size();) {
          std::size_t e = a + 1;
          while (e < uses.size() && uses[e].face == uses[a].face) ++e;
          for (std::size_t i = a; i < e; ++i) write(uses[i], int(e - a), &uses[i == a ? a + 1 : a]);
          a = e;
        }
      }
      for (const int c : w.touched) w.cell[std::size_t(c)] = -1;
      for (const int u : w.numbered) w.local[std::size_t(u)] = -1;
      w.touched.clear();
      w.numbered.clear();
      w.groups.clear();
    }
  });
  return result;
}

ComponentCensus component_census(const TetMesh4& mesh, const std::vector<int>* labels) {
  const Eigen::Index n = mesh.vertex_count();
  if (labels != nullptr && Eigen::Index(labels->size()) != n)
    throw InvalidInput("component_census: " + std::to_string(labels->size()) + " component labels for " +
                       std::to_string(n) + " vertices");
  std::vector<int> computed;
  if (labels == nullptr) computed = component_labels(mesh.T, n);
  const std::vector<int>& root = labels != nullptr ? *labels : computed;
  std::vector<std::uint8_t> touches(static_cast<std::size_t>(n), 0);  // per root: bit 1 A, bit 2 B
  std::vector<Eigen::Index> size(static_cast<std::size_t>(n), 0);
  for (Eigen::Index v = 0; v < n; ++v) {
    const auto r = static_cast<std::size_t>(root[std::size_t(v)]);
    ++size[r];
    if (mesh.side[std::size_t(v)] == VertexSide::A) touches[r] |= 1;
    if (mesh.side[std::size_t(v)] == VertexSide::B) touches[r] |= 2;
  }
  ComponentCensus c;
  for (Eigen::Index v = 0; v < n; ++v) {
    if (root[std::size_t(v)] != v) continue;
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
