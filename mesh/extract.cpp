// Marching pentatopes over the space-time lattice (paper §5.2). Each hypercube is split into the 24
// Kuhn (Freudenthal) simplices, a triangulation that is conforming across cells; a linear field cuts a
// pentatope in a tetrahedron (1|4 sign split) or a triangular prism (2|3). Prisms are split into three
// tets by the rule of Dompierre et al. ("How to subdivide pyramids, prisms and hexahedra into
// tetrahedra", 1999): every quad face takes the diagonal from its vertex with the smallest global id,
// so neighbouring pentatopes agree and the mesh is watertight. Written by hand: no library extracts
// iso-hypersurfaces in 4D.
//
// Two passes over the cells that can change sign, both TBB-parallel. The first counts, per cell, the
// tets it emits and the crossing edges it owns (the edges leaving its lower corner); prefix sums then
// give every cell its slice of the output arrays and every crossing edge its vertex id, so the second
// pass writes vertices, oriented tets and provenance in place. No sort, no hash table, no per-thread
// buffers: output order and ids are fixed by the lattice alone, whatever the thread count.
#include "mesh/extract.h"

#ifdef __linux__
#include <sys/mman.h>
#endif
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <tuple>

#include "mesh/errors.h"

namespace morphmap {
namespace {

// The facet code of a tet face inside its pentatope's prism (PentatopeCase, LatticeFaces::code).
constexpr int kInsidePrism = 7;

// Kuhn simplex s of the unit hypercube walks from corner 0000 to 1111, adding one axis per step in the
// order of permutation s. Corner bits: 1 = x, 2 = y, 4 = z, 8 = t.
struct KuhnTable {
  std::array<std::array<int, 5>, 24> corner{};  // corner bitmask of simplex vertex 0..4
  std::array<std::array<int, 4>, 24> axis{};    // axis added between vertex m and m + 1
  std::array<unsigned, 24> corner_set{};        // bit c set when corner c is a vertex of the simplex
  std::array<int, 256> of_axes{};               // simplex of the axis order a0 a1 a2 a3 (index a0 a1 a2 a3 base 4)
  // The simplex across facet q (opposite vertex q) of simplex s, in the same cube for q = 1..3 (two steps of the
  // walk swapped), in the cube one step along axis[s][0] for q = 0 and one step back along axis[s][3] for q = 4
  // (the walk rotated): the Kuhn triangulation is conforming, so a facet is shared by exactly these two.
  int across(int s, int q) const {
    std::array<int, 4> a = axis[std::size_t(s)];
    if (q == 0) std::rotate(a.begin(), a.begin() + 1, a.end());
    if (q == 4) std::rotate(a.begin(), a.begin() + 3, a.end());
    if (q >= 1 && q <= 3) std::swap(a[std::size_t(q) - 1], a[std::size_t(q)]);
    return of_axes[std::size_t(a[0] * 64 + a[1] * 16 + a[2] * 4 + a[3])];
  }
  KuhnTable() {
    std::array<int, 4> perm{0, 1, 2, 3};
    int s = 0;
    do {
      int mask = 0;
      corner[std::size_t(s)][0] = 0;
      corner_set[std::size_t(s)] = 1u;
      for (int m = 0; m < 4; ++m) {
        axis[std::size_t(s)][std::size_t(m)] = perm[std::size_t(m)];
        mask |= 1 << perm[std::size_t(m)];
        corner[std::size_t(s)][std::size_t(m) + 1] = mask;
        corner_set[std::size_t(s)] |= 1u << mask;
      }
      of_axes[std::size_t(perm[0] * 64 + perm[1] * 16 + perm[2] * 4 + perm[3])] = s;
      ++s;
    } while (std::next_permutation(perm.begin(), perm.end()));
  }
};
const KuhnTable kKuhn;

// Prism vertex relabelings that move vertex v to position 0 (bottom 0,1,2; top 3,4,5; i above i+3).
constexpr int kPrismRotation[6][6] = {{0, 1, 2, 3, 4, 5}, {1, 2, 0, 4, 5, 3}, {2, 0, 1, 5, 3, 4},
                                      {3, 5, 4, 0, 2, 1}, {4, 3, 5, 1, 0, 2}, {5, 4, 3, 2, 1, 0}};

// The two ways to split a prism rotated so that its smallest-id vertex is 0: tets as prism vertices
// before rotation is applied.
constexpr int kPrismSplit[2][3][4] = {{{0, 1, 2, 5}, {0, 1, 5, 4}, {0, 4, 5, 3}},
                                      {{0, 1, 2, 4}, {0, 4, 2, 5}, {0, 4, 5, 3}}};

// Split of a prism into three tets with diagonals chosen by global vertex id: returns 2 * rotation + choice.
inline int prism_split(const int id[6]) {
  const int vmin = int(std::min_element(id, id + 6) - id);
  const int* r = kPrismRotation[vmin];
  return 2 * vmin + (std::min(id[r[1]], id[r[5]]) < std::min(id[r[2]], id[r[4]]) ? 0 : 1);
}

// Marching-pentatope cases of one Kuhn simplex s and one sign pattern of its five vertices (bit q set
// when simplex vertex q is positive). The tets are listed as indices into the case's crossing edges and
// already oriented. Orientation is a combinatorial invariant: the cut of a non-degenerate pentatope by
// the zero set of a linear field with a given sign pattern never degenerates as the crossings slide
// along their edges, and positive axis scalings keep the sign of cross4 . grad d. So it is decided once
// on the unit hypercube with crossings at edge midpoints, instead of with a cross product per output
// tet (which also misjudged tiny tets near a lattice corner in floating point).
struct PentatopeCase {
  int edges = 0;             // 0 (no crossing), 4 (1|4 split) or 6 (2|3 split)
  int a[6] = {}, b[6] = {};  // crossing edges as hypercube corner pairs, a < b
  int lone[4] = {};          // 1|4 split: the tet
  int prism[12][3][4] = {};  // 2|3 split: the three tets of split 2 * rotation + choice (see prism_split)
  // Per output tet, 3 bits a face (face k, opposite tet vertex k, at bit 5 + 3 k): the facet of the simplex it lies on
  // (the simplex vertex none of its crossing edges touch), or kInsidePrism. LatticeFaces::code without the simplex.
  std::uint32_t lone_facets = 0;
  std::uint32_t prism_facets[12][3] = {};
};

struct CaseTable {
  PentatopeCase cases[24][32];
  CaseTable() {
    for (int s = 0; s < 24; ++s)
      for (int mask = 1; mask < 31; ++mask) build(s, mask, cases[s][mask]);
  }

  static void build(int s, int mask, PentatopeCase& c) {
    const auto& cm = kKuhn.corner[std::size_t(s)];
    int P[5], N[5], np = 0, nn = 0;
    for (int q = 0; q < 5; ++q) (mask & (1 << q) ? P[np++] : N[nn++]) = cm[std::size_t(q)];
    auto set_edge = [&](int e, int u, int v) {
      c.a[e] = std::min(u, v);
      c.b[e] = std::max(u, v);
    };
    if (np == 1 || nn == 1) {
      const int lone = np == 1 ? P[0] : N[0];
      const int* others = np == 1 ? N : P;
      c.edges = 4;
      for (int q = 0; q < 4; ++q) set_edge(q, lone, others[q]);
      const int tet[4] = {0, 1, 2, 3};
      orient(mask, s, c, tet, c.lone);
      c.lone_facets = facets(s, c, c.lone);
    } else {
      const int* pair = np == 2 ? P : N;
      const int* triple = np == 2 ? N : P;
      c.edges = 6;
      for (int q = 0; q < 3; ++q) {
        set_edge(q, pair[0], triple[q]);
        set_edge(q + 3, pair[1], triple[q]);
      }
      for (int split = 0; split < 12; ++split)
        for (int t = 0; t < 3; ++t) {
          int tet[4];
          for (int q = 0; q < 4; ++q) tet[q] = kPrismRotation[split / 2][kPrismSplit[split % 2][t][q]];
          orient(mask, s, c, tet, c.prism[split][t]);
          c.prism_facets[split][t] = facets(s, c, c.prism[split][t]);
        }
    }
  }

  // PentatopeCase::lone_facets and prism_facets of the output tet `tet` (edge indices).
  static std::uint32_t facets(int s, const PentatopeCase& c, const int tet[4]) {
    const auto& cm = kKuhn.corner[std::size_t(s)];
    std::uint32_t code = 0;
    for (int k = 0; k < 4; ++k) {
      unsigned touched = 0;
      for (int j = 0; j < 4; ++j)
        if (j != k) touched |= (1u << c.a[tet[j]]) | (1u << c.b[tet[j]]);
      std::uint32_t facet = std::uint32_t(kInsidePrism);
      for (int q = 0; q < 5; ++q)
        if (!(touched & (1u << cm[std::size_t(q)]))) facet = std::uint32_t(q);
      code |= facet << (5 + 3 * k);
    }
    return code;
  }

  // Writes tet (edge indices) to out, swapping two vertices when cross4 would point where d decreases.
  static void orient(int mask, int s, const PentatopeCase& c, const int tet[4], int out[4]) {
    auto corner = [](int bits) {
      return Eigen::Vector4d(bits & 1 ? 1.0 : 0.0, bits & 2 ? 1.0 : 0.0, bits & 4 ? 1.0 : 0.0, bits & 8 ? 1.0 : 0.0);
    };
    Eigen::Vector4d p[4];
    for (int q = 0; q < 4; ++q) p[q] = 0.5 * (corner(c.a[tet[q]]) + corner(c.b[tet[q]]));
    // Field +1 at positive vertices, -1 at negative ones: its gradient along the Kuhn walk.
    Eigen::Vector4d g;
    for (int q = 0; q < 4; ++q) {
      const double f0 = mask & (1 << q) ? 1.0 : -1.0, f1 = mask & (1 << (q + 1)) ? 1.0 : -1.0;
      g(kKuhn.axis[std::size_t(s)][std::size_t(q)]) = f1 - f0;
    }
    const bool swap = cross4(p[1] - p[0], p[2] - p[0], p[3] - p[0]).dot(g) < 0.0;
    out[0] = tet[0], out[1] = tet[1], out[2] = swap ? tet[3] : tet[2], out[3] = swap ? tet[2] : tet[3];
  }
};
const CaseTable kCases;

struct Lattice {
  const MorphField& field;
  int K;
  double h, dt;  // spatial spacing and tau spacing (c / K)
  double snap;
  std::int64_t n3, sx, sy, sz;  // points per time level; strides of x, y, z
  std::int64_t cx, cy, cz;      // cubes per axis

  // The one place a lattice value is computed, so every cell sharing a lattice point sees the same float.
  float value(std::int64_t idx3, int level) const {
    const double t = double(level) / K;
    double d =
        field.levels.empty() ? field.linear_value(idx3, t) : double(field.levels[std::size_t(level * n3 + idx3)]);
    if (std::abs(d) < snap) d = d < 0.0 ? -snap : snap;
    return float(d);
  }
  std::int64_t corner_index(std::int64_t base3, int b) const {
    return base3 + ((b & 1) ? sx : 0) + ((b & 2) ? sy : 0) + ((b & 4) ? sz : 0);
  }
  // Crossing on the lattice edge from lower point (i, j, k, level) along corner mask m; the same
  // arguments give the same bits in every cell that computes it.
  Eigen::Vector4d crossing(std::int64_t i, std::int64_t j, std::int64_t k, int level, int m, float f0, float f1) const {
    const double w = double(f0) / (double(f0) - double(f1));
    Eigen::Vector4d q(field.origin.x() + h * double(i), field.origin.y() + h * double(j),
                      field.origin.z() + h * double(k), dt * level);
    if (m & 1) q(0) += w * h;
    if (m & 2) q(1) += w * h;
    if (m & 4) q(2) += w * h;
    if (m & 8) q(3) += w * dt;
    return q;
  }
};

// The 16 corner values of the 4D cell (cube, level), corner bit 8 = upper time level.
struct Cell {
  std::int64_t cube = 0, i = 0, j = 0, k = 0, base3 = 0;
  int level = 0;
  float f[16];
  unsigned positive = 0;  // bit c set when f[c] > 0
};

// Crossing edges owned by a cell: bit m (1..15) for the edge from corner 0 to corner m; in the top
// time slab also bit 15 + m (m = 1..7) for the spatial edge from corner 8 to corner 8 | m, so that the
// t = 1 vertices have an owner too.
unsigned owned_edges(const Cell& c, int K) {
  unsigned bits = 0;
  const bool p0 = c.positive & 1u;
  for (int m = 1; m < 16; ++m)
    if (bool(c.positive & (1u << m)) != p0) bits |= 1u << m;
  if (c.level == K - 1) {
    const bool p8 = c.positive & (1u << 8);
    for (int m = 1; m < 8; ++m)
      if (bool(c.positive & (1u << (8 | m))) != p8) bits |= 1u << (15 + m);
  }
  return bits;
}

constexpr std::int64_t kChunkCubes = 64;

// The output arrays are first touched by pass 2, one 4 KiB page fault at a time; asking for transparent
// huge pages (the kernel default is madvise-only) cuts that cost. A hint: failure is harmless.
void advise_huge_pages(void* data, std::size_t bytes) {
#ifdef __linux__
  constexpr std::uintptr_t kHuge = std::uintptr_t(2) << 20;
  const std::uintptr_t begin = (reinterpret_cast<std::uintptr_t>(data) + kHuge - 1) & ~(kHuge - 1);
  const std::uintptr_t end = (reinterpret_cast<std::uintptr_t>(data) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#else
  (void)data, (void)bytes;
#endif
}

// Bit count without the libgcc call that std::bitset::count becomes on baseline x86-64 (measured 2%).
inline int bit_count(std::uint32_t x) {
  x = x - ((x >> 1) & 0x55555555u);
  x = (x & 0x33333333u) + ((x >> 2) & 0x33333333u);
  return int((((x + (x >> 4)) & 0x0F0F0F0Fu) * 0x01010101u) >> 24);
}

}  // namespace

// Written by hand (no library knows the Kuhn triangulation's facets). Every entry is written by one tet, so the
// result does not depend on the thread count. (face_neighbours settles the same faces from the vertex stars: on
// cow -> horse a little slower, on sphere -> bunny at 19.7 M tets 1.5 s against 0.2 s.)
void lattice_face_neighbours(const LatticeFaces& f, const TetIndices& T, int* across, std::size_t stride) {
  if (!f.known() || f.code.size() != std::size_t(T.rows()) || stride < 4)
    throw InvalidInput("lattice_face_neighbours: " + std::to_string(f.code.size()) + " tets recorded for " +
                       std::to_string(T.rows()) + ", stride " + std::to_string(stride));
  const std::vector<std::uint32_t>& code = f.code;
  const std::vector<std::uint64_t>& layout = f.layout;
  const std::vector<std::int64_t>& tet_offset = f.tet_offset;
  const std::vector<std::int64_t>& candidates = f.candidates;
  const std::vector<std::int32_t>& cube_ordinal = f.cube_ordinal;
  const int K = f.time_steps;
  // Faces no second tet holds (the ends of the morph) keep this.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, std::size_t(T.rows())), [&](const auto& r) {
    for (std::size_t t = r.begin(); t != r.end(); ++t) std::fill_n(across + t * stride, 4, int(FaceNeighbours::kNoTet));
  });
  const std::int64_t slots = std::int64_t(candidates.size()) * K;
  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, slots, 256), [&](const tbb::blocked_range<std::int64_t>& r) {
    for (std::int64_t slot = r.begin(); slot != r.end(); ++slot) {
      if (tet_offset[std::size_t(slot)] == tet_offset[std::size_t(slot) + 1]) continue;
      const std::int64_t ordinal = slot / K;
      const int level = int(slot - ordinal * K);
      const std::int64_t cube = candidates[std::size_t(ordinal)];
      const std::int64_t at[3] = {cube % f.cx, (cube / f.cx) % f.cy, cube / (f.cx * f.cy)};
      const std::int64_t extent[3] = {f.cx, f.cy, f.cz}, cube_stride[3] = {1, f.cx, f.cx * f.cy};
      // The cell one step up along axis, as its slot; -1 outside the lattice or where d does not change sign over
      // the cube.
      auto next_cell = [&](int axis) -> std::int64_t {
        if (axis == 3) return level + 1 >= K ? -1 : slot + 1;
        if (at[axis] + 1 >= extent[axis]) return -1;
        const std::int32_t next = cube_ordinal[std::size_t(cube + cube_stride[axis])];
        return next < 0 ? -1 : std::int64_t(next) * K + level;
      };
      for (std::int64_t t = tet_offset[std::size_t(slot)]; t < tet_offset[std::size_t(slot) + 1]; ++t) {
        const std::uint32_t c = code[std::size_t(t)];
        const int s = int(c & 31u);
        for (int k = 0; k < 4; ++k) {
          // Each shared face is settled by one of its two tets, which writes both entries: the one in the lower
          // simplex of the cell, the lower tet of a prism, the one in the lower cell along the facet's axis.
          const int q = int((c >> (5 + 3 * k)) & 7u);
          if (q == 4) continue;
          std::int64_t where = slot;
          int simplex = s;
          if (q < 5) {
            simplex = kKuhn.across(s, q);
            if (q != 0 && simplex < s) continue;
            if (q == 0) where = next_cell(kKuhn.axis[std::size_t(s)][0]);
          }
          if (where < 0) continue;
          int face[3], m = 0;
          for (int j = 0; j < 4; ++j)
            if (j != k) face[m++] = T(t, j);
          // A cell's tets are in simplex order, one for each simplex cut in a tet and three for a prism.
          const std::uint64_t cut = layout[std::size_t(where)];
          if (!(cut & (std::uint64_t(1) << simplex))) continue;
          const std::uint32_t below = (1u << simplex) - 1u;
          const std::int64_t first = tet_offset[std::size_t(where)] + bit_count(std::uint32_t(cut) & below) +
                                     2 * bit_count(std::uint32_t(cut >> 32) & below);
          const std::int64_t last = first + ((cut >> (32 + simplex)) & 1u ? 3 : 1);
          for (std::int64_t u = q == kInsidePrism ? t + 1 : first; u < last; ++u) {
            int shared = 0, other = 0;
            for (int j = 0; j < 4; ++j) {
              const int v = T(u, j);
              if (v == face[0] || v == face[1] || v == face[2])
                ++shared;
              else
                other = j;
            }
            if (shared == 3) {
              across[std::size_t(t) * stride + std::size_t(k)] = int(u);
              across[std::size_t(u) * stride + std::size_t(other)] = int(t);
              break;
            }
          }
        }
      }
    }
  });
}

FaceNeighbours lattice_face_neighbours(const LatticeFaces& faces, const TetIndices& T) {
  FaceNeighbours result;
  if (!faces.known()) return result;
  result.across.reset(new int[std::size_t(T.rows()) * 4]);
  lattice_face_neighbours(faces, T, result.across.get(), 4);
  return result;
}

ExtractResult extract_hypersurface(const MorphField& field, const ExtractOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (options.time_steps < 1)
    throw InvalidInput("extract_hypersurface: time_steps must be at least 1 (got " +
                       std::to_string(options.time_steps) + ")");
  const Eigen::Vector3i& dims = field.dims;
  if ((dims.array() < 2).any())
    throw InvalidInput("extract_hypersurface: lattice has fewer than 2 points along an axis");
  const std::int64_t n3 = std::int64_t(dims.x()) * dims.y() * dims.z();
  if (field.dA.size() != std::size_t(n3) || field.dB.size() != std::size_t(n3))
    throw InvalidInput("extract_hypersurface: field arrays do not match the lattice dimensions");
  if (!field.levels.empty() && (field.time_levels != options.time_steps + 1 ||
                                field.levels.size() != std::size_t(n3) * std::size_t(field.time_levels)))
    throw InvalidInput("extract_hypersurface: the morph was sampled at " + std::to_string(field.time_levels) +
                       " time levels, extraction with " + std::to_string(options.time_steps) + " time steps needs " +
                       std::to_string(options.time_steps + 1));

  ExtractResult result;
  TetMesh4& mesh = result.mesh;
  const int K = options.time_steps;
  mesh.time_steps = K;
  mesh.voxel_size = field.voxel_size;
  mesh.time_scale = options.time_scale > 0.0 ? options.time_scale
                    : field.extent > 0.0     ? 2.0 * field.extent
                                             : K * field.voxel_size;
  const Lattice lat{field,
                    K,
                    field.voxel_size,
                    mesh.time_scale / K,
                    options.zero_snap * field.voxel_size,
                    n3,
                    1,
                    dims.x(),
                    std::int64_t(dims.x()) * dims.y(),
                    dims.x() - 1,
                    dims.y() - 1,
                    dims.z() - 1};
  if (field.levels.empty()) {
    for (std::size_t q = 0; q < field.dA.size(); ++q)
      result.snapped_values += (std::abs(field.dA[q]) < lat.snap) + (std::abs(field.dB[q]) < lat.snap);
  } else {
    for (const float v : field.levels) result.snapped_values += std::abs(v) < lat.snap;
  }

  // Candidate cubes: d can change sign over a cube only if neither both fields are >= 0 at all its
  // corners nor both < 0 (d is a convex combination of dA and dB); a morph sampled per level is tested at every
  // level. Chunks are concatenated in order.
  const std::int64_t cube_count = lat.cx * lat.cy * lat.cz;
  std::vector<std::int32_t> cube_ordinal(std::size_t(cube_count), -1);
  std::vector<std::int64_t> candidates;
  {
    const std::int64_t slab = lat.cx * lat.cy;
    std::vector<std::vector<std::int64_t>> per_z(std::size_t(lat.cz));
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, lat.cz), [&](const tbb::blocked_range<std::int64_t>& r) {
      for (std::int64_t k = r.begin(); k != r.end(); ++k)
        for (std::int64_t j = 0; j < lat.cy; ++j)
          for (std::int64_t i = 0; i < lat.cx; ++i) {
            const std::int64_t base3 = i + lat.sy * j + lat.sz * k;
            bool nonneg = false, neg = false;
            for (int b = 0; b < 8; ++b) {
              const std::size_t q = std::size_t(lat.corner_index(base3, b));
              if (field.levels.empty()) {
                nonneg |= field.dA[q] >= 0.0f || field.dB[q] >= 0.0f;
                neg |= field.dA[q] < 0.0f || field.dB[q] < 0.0f;
              } else {
                for (int l = 0; l < field.time_levels; ++l) {
                  const float v = field.levels[std::size_t(l) * std::size_t(n3) + q];
                  nonneg |= v >= 0.0f;
                  neg |= v < 0.0f;
                }
              }
            }
            if (nonneg && neg) per_z[std::size_t(k)].push_back(i + lat.cx * j + slab * k);
          }
    });
    for (const auto& z : per_z) candidates.insert(candidates.end(), z.begin(), z.end());
  }
  if (candidates.size() >= std::size_t(std::numeric_limits<std::int32_t>::max()))
    throw InvalidInput("extract_hypersurface: too many candidate cubes (" + std::to_string(candidates.size()) + ")");
  for (std::size_t c = 0; c < candidates.size(); ++c) cube_ordinal[std::size_t(candidates[c])] = std::int32_t(c);
  result.candidate_cubes = std::int64_t(candidates.size());

  auto load = [&](std::int64_t ordinal, int level, Cell& cell, bool first_level, const float* below) {
    cell.cube = candidates[std::size_t(ordinal)];
    cell.i = cell.cube % lat.cx;
    cell.j = (cell.cube / lat.cx) % lat.cy;
    cell.k = cell.cube / (lat.cx * lat.cy);
    cell.base3 = cell.i + lat.sy * cell.j + lat.sz * cell.k;
    cell.level = level;
    for (int b = 0; b < 8; ++b) {
      const std::int64_t q = lat.corner_index(cell.base3, b);
      cell.f[b] = first_level ? lat.value(q, level) : below[b];
      cell.f[b + 8] = lat.value(q, level + 1);
    }
    cell.positive = 0;
    for (int b = 0; b < 16; ++b)
      if (cell.f[b] > 0.0f) cell.positive |= 1u << b;
  };

  // Visits every cell with a sign change, chunk by chunk (chunk = kChunkCubes candidate cubes, all
  // their time slabs), calling visit(chunk, slot, cell); chunks run in parallel.
  const std::int64_t chunks = (std::int64_t(candidates.size()) + kChunkCubes - 1) / kChunkCubes;
  auto for_each_active_cell = [&](auto&& visit) {
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, chunks), [&](const tbb::blocked_range<std::int64_t>& r) {
      Cell cell;
      for (std::int64_t c = r.begin(); c != r.end(); ++c) {
        const std::int64_t end = std::min<std::int64_t>(std::int64_t(candidates.size()), (c + 1) * kChunkCubes);
        for (std::int64_t o = c * kChunkCubes; o < end; ++o)
          for (int l = 0; l < K; ++l) {
            load(o, l, cell, l == 0, cell.f + 8);
            if (cell.positive != 0 && cell.positive != 0xFFFFu) visit(c, std::size_t(o * K + l), cell);
          }
      }
    });
  };

  // Pass 1: tets and owned crossing edges per cell (slot = ordinal * K + level).
  const std::int64_t slots = std::int64_t(candidates.size()) * K;
  std::vector<std::uint32_t> cell_bits(std::size_t(slots), 0);
  std::vector<std::uint8_t> cell_tets(std::size_t(slots), 0);
  // For face_neighbours: the simplices of each cell with tets (bits 0-23) and those cut in a prism (bits 32-55).
  std::vector<std::uint64_t> cell_layout(options.face_neighbours ? std::size_t(slots) : 0, 0);
  std::vector<std::int64_t> chunk_prisms(std::size_t(chunks), 0), chunk_active(std::size_t(chunks), 0);
  for_each_active_cell([&](std::int64_t c, std::size_t slot, const Cell& cell) {
    ++chunk_active[std::size_t(c)];
    cell_bits[slot] = owned_edges(cell, K);
    int tets = 0;
    std::uint64_t layout = 0;
    for (int s = 0; s < 24; ++s) {
      const int np = bit_count(cell.positive & kKuhn.corner_set[std::size_t(s)]);
      if (np == 0 || np == 5) continue;
      const bool prism = np == 2 || np == 3;
      tets += prism ? 3 : 1;
      chunk_prisms[std::size_t(c)] += prism;
      layout |= (std::uint64_t(1) << s) | (std::uint64_t(prism) << (32 + s));
    }
    if (!cell_layout.empty()) cell_layout[slot] = layout;
    cell_tets[slot] = std::uint8_t(tets);
  });
  for (std::int64_t c = 0; c < chunks; ++c) {
    result.prisms += chunk_prisms[std::size_t(c)];
    result.active_cells += chunk_active[std::size_t(c)];
  }

  // Prefix sums: first tet and first vertex id of every cell.
  std::vector<std::int64_t> tet_offset(std::size_t(slots) + 1, 0), vertex_base(std::size_t(slots) + 1, 0);
  for (std::int64_t q = 0; q < slots; ++q) {
    tet_offset[std::size_t(q) + 1] = tet_offset[std::size_t(q)] + cell_tets[std::size_t(q)];
    vertex_base[std::size_t(q) + 1] = vertex_base[std::size_t(q)] + bit_count(cell_bits[std::size_t(q)]);
  }
  const std::int64_t tet_count = tet_offset.back(), vertex_count = vertex_base.back();
  if (tet_count == 0) throw TopologyError("extract_hypersurface: the morph field has no zero crossing in the lattice");
  if (vertex_count >= std::numeric_limits<int>::max())
    throw InvalidInput("extract_hypersurface: " + std::to_string(vertex_count) + " vertices exceed 32-bit indices");
  std::vector<std::uint8_t>().swap(cell_tets);
  result.scratch_bytes = std::int64_t(cube_ordinal.size() * 4 + candidates.size() * 8) +
                         slots * (4 + 8 + 8 + (options.face_neighbours ? 8 : 0));
  if (options.before_allocate) options.before_allocate(tet_count, vertex_count);

  mesh.V.resize(vertex_count, 4);
  mesh.T.resize(tet_count, 4);
  mesh.side.assign(std::size_t(vertex_count), VertexSide::Interior);
  advise_huge_pages(mesh.V.data(), std::size_t(mesh.V.size()) * sizeof(double));
  advise_huge_pages(mesh.T.data(), std::size_t(mesh.T.size()) * sizeof(int));
  // Per tet, for face_neighbours: its Kuhn simplex (bits 0-4) and, 3 bits a face (face k at bit 5 + 3 k), the facet
  // of the simplex it lies on, or kInsidePrism.
  std::vector<std::uint32_t> face_code(options.face_neighbours ? std::size_t(tet_count) : 0);
  if (options.record_source_cells) {
    mesh.source_cell.resize(std::size_t(tet_count));
    advise_huge_pages(mesh.source_cell.data(), mesh.source_cell.size() * sizeof(std::int64_t));
  }

  // Vertex id of the crossing on edge (a, b) of the current cell, a subset of b: the edge belongs to the
  // cell whose lower corner is corner a (the top-slab cell for spatial edges at t = 1).
  auto vertex_id = [&](const Cell& cell, int a, int b) {
    const std::int64_t owner =
        cube_ordinal[std::size_t(cell.cube + (a & 1) + lat.cx * ((a >> 1) & 1) + lat.cx * lat.cy * ((a >> 2) & 1))];
    const int level = cell.level + (a >> 3);
    const int m = a ^ b;
    const std::size_t slot = std::size_t(owner * K + std::min(level, K - 1));
    const int bit = level == K ? 15 + m : m;
    return int(vertex_base[slot] + bit_count(cell_bits[slot] & ((1u << bit) - 1u)));
  };

  // Pass 2: owned vertices, then tets (oriented by the case table).
  // Per-thread cache of one cell's crossing ids, valid where stamp == the cell's serial.
  struct EdgeCache {
    std::uint32_t serial = 0;
    std::uint32_t stamp[16][16] = {};
    int id[16][16];
  };
  tbb::enumerable_thread_specific<std::unique_ptr<EdgeCache>> caches([] { return std::make_unique<EdgeCache>(); });
  for_each_active_cell([&](std::int64_t, std::size_t slot, const Cell& cell) {
    EdgeCache* cache = caches.local().get();
    const std::uint32_t serial = ++cache->serial;
    const int l = cell.level;
    const unsigned bits = cell_bits[slot];
    std::int64_t id = vertex_base[slot];
    for (int bit = 1; bit < 23; ++bit) {
      if (!(bits & (1u << bit))) continue;
      const bool top = bit > 15;
      const int a = top ? 8 : 0, m = top ? bit - 15 : bit;
      mesh.V.row(id) = lat.crossing(cell.i, cell.j, cell.k, l + (a >> 3), m, cell.f[a], cell.f[a | m]).transpose();
      mesh.side[std::size_t(id)] = top ? VertexSide::B : (l == 0 && m < 8 ? VertexSide::A : VertexSide::Interior);
      ++id;
    }
    auto edge_id = [&](int a, int b) {
      if (cache->stamp[a][b] != serial) {
        cache->stamp[a][b] = serial;
        cache->id[a][b] = vertex_id(cell, a, b);
      }
      return cache->id[a][b];
    };
    std::int64_t row = tet_offset[slot];
    const std::int64_t source_base = (cell.base3 + lat.n3 * l) * 24;
    for (int s = 0; s < 24; ++s) {
      const auto& cm = kKuhn.corner[std::size_t(s)];
      int mask = 0;
      for (int q = 0; q < 5; ++q) mask |= int((cell.positive >> cm[std::size_t(q)]) & 1u) << q;
      const PentatopeCase& pc = kCases.cases[s][mask];
      if (pc.edges == 0) continue;
      int ids[6];
      for (int e = 0; e < pc.edges; ++e) ids[e] = edge_id(pc.a[e], pc.b[e]);
      auto emit = [&](const int tet[4], std::uint32_t facets) {
        mesh.T.row(row) << ids[tet[0]], ids[tet[1]], ids[tet[2]], ids[tet[3]];
        if (options.record_source_cells) mesh.source_cell[std::size_t(row)] = source_base + s;
        if (options.face_neighbours) face_code[std::size_t(row)] = std::uint32_t(s) | facets;
        ++row;
      };
      if (pc.edges == 4) {
        emit(pc.lone, pc.lone_facets);
      } else {
        const int split = prism_split(ids);
        for (int t = 0; t < 3; ++t) emit(pc.prism[split][t], pc.prism_facets[split][t]);
      }
    }
  });

  if (options.face_neighbours) {
    LatticeFaces& f = result.faces;
    f.code = std::move(face_code);
    f.layout = std::move(cell_layout);
    f.tet_offset = std::move(tet_offset);
    f.candidates = std::move(candidates);
    f.cube_ordinal = std::move(cube_ordinal);
    f.cx = lat.cx, f.cy = lat.cy, f.cz = lat.cz;
    f.time_steps = K;
  }

  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace morphmap
