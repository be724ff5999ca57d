// Marching pentatopes over the space-time lattice (paper §5.2). Each hypercube is split into the 24
// Kuhn simplices (the Freudenthal triangulation is conforming across cells); a linear field cuts a
// pentatope in a tetrahedron (1|4 sign split) or a triangular prism (2|3). Prisms are split into
// three tets by the rule of Dompierre et al. ("How to subdivide pyramids, prisms and hexahedra into
// tetrahedra", 1999): every quad face takes the diagonal from its vertex with the smallest global
// key, so neighbouring pentatopes agree and the mesh is watertight. Written by hand because no
// library extracts iso-hypersurfaces in 4D.
#include "mesh/extract.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>

#include "mesh/errors.h"

namespace morphmap {
namespace {

// Kuhn simplex m of the unit hypercube walks from corner 0000 to 1111, adding one axis per step in
// the order of permutation m. Corner bits: 1 = x, 2 = y, 4 = z, 8 = t.
struct KuhnTable {
  std::array<std::array<int, 5>, 24> corner{};  // corner bitmask of simplex vertex 0..4
  std::array<std::array<int, 4>, 24> axis{};    // axis added between vertex m and m + 1
  KuhnTable() {
    std::array<int, 4> perm{0, 1, 2, 3};
    int s = 0;
    do {
      int mask = 0;
      corner[s][0] = 0;
      for (int m = 0; m < 4; ++m) {
        axis[s][m] = perm[m];
        mask |= 1 << perm[m];
        corner[s][m + 1] = mask;
      }
      ++s;
    } while (std::next_permutation(perm.begin(), perm.end()));
  }
};
const KuhnTable kKuhn;

// A crossing vertex is identified by its lattice edge: the lower lattice point's global id and the
// 0/1 offset to the upper one (edges of Kuhn simplices are monotone), packed in 64 bits.
using EdgeKey = std::uint64_t;
inline EdgeKey edge_key(std::int64_t lower_id, int offset_mask) { return (std::uint64_t(lower_id) << 4) | unsigned(offset_mask); }

// Prism vertex relabelings that move vertex v to position 0 (bottom 0,1,2; top 3,4,5; i above i+3).
constexpr int kPrismRotation[6][6] = {{0, 1, 2, 3, 4, 5}, {1, 2, 0, 4, 5, 3}, {2, 0, 1, 5, 3, 4},
                                      {3, 5, 4, 0, 2, 1}, {4, 3, 5, 1, 0, 2}, {5, 4, 3, 2, 1, 0}};

struct LocalTet {
  std::array<EdgeKey, 4> key;
  std::int64_t source;
};

struct ChunkOutput {
  std::vector<LocalTet> tets;
  std::int64_t active_cells = 0;
  std::int64_t prisms = 0;
};

struct Lattice {
  const MorphField& field;
  int K;
  double h, dt_len;  // spatial spacing and tau spacing (c / K)
  double snap;
  std::int64_t n3;   // lattice points per time level

  float value(std::int64_t idx3, int level) const {
    const double t = double(level) / K;
    double d = (1.0 - t) * field.dA[std::size_t(idx3)] + t * field.dB[std::size_t(idx3)];
    if (std::abs(d) < snap) d = d < 0.0 ? -snap : snap;
    return float(d);
  }
};

void split_prism(const std::array<EdgeKey, 6>& key, std::vector<std::array<int, 4>>& out) {
  int vmin = int(std::min_element(key.begin(), key.end()) - key.begin());
  const int* r = kPrismRotation[vmin];
  auto k = [&](int i) { return key[std::size_t(r[i])]; };
  if (std::min(k(1), k(5)) < std::min(k(2), k(4))) {
    out.push_back({r[0], r[1], r[2], r[5]});
    out.push_back({r[0], r[1], r[5], r[4]});
  } else {
    out.push_back({r[0], r[1], r[2], r[4]});
    out.push_back({r[0], r[4], r[2], r[5]});
  }
  out.push_back({r[0], r[4], r[5], r[3]});
}

}  // namespace

ExtractResult extract_hypersurface(const MorphField& field, const ExtractOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (options.time_steps < 1)
    throw InvalidInput("extract_hypersurface: time_steps must be at least 1 (got " + std::to_string(options.time_steps) + ")");
  const Eigen::Vector3i& dims = field.dims;
  if ((dims.array() < 2).any()) throw InvalidInput("extract_hypersurface: lattice has fewer than 2 points along an axis");

  ExtractResult result;
  TetMesh4& mesh = result.mesh;
  mesh.time_steps = options.time_steps;
  mesh.voxel_size = field.voxel_size;
  mesh.time_scale = options.time_scale > 0.0 ? options.time_scale : options.time_steps * field.voxel_size;

  const Lattice lat{field, options.time_steps, field.voxel_size, mesh.time_scale / options.time_steps,
                    options.zero_snap * field.voxel_size, std::int64_t(dims.x()) * dims.y() * dims.z()};
  const std::int64_t stride[4] = {1, dims.x(), std::int64_t(dims.x()) * dims.y(), lat.n3};
  const double spacing[4] = {lat.h, lat.h, lat.h, lat.dt_len};

  for (std::size_t q = 0; q < field.dA.size(); ++q)
    result.snapped_values += (std::abs(field.dA[q]) < lat.snap) + (std::abs(field.dB[q]) < lat.snap);
  // Spatial cubes where d can change sign at some t: neither both fields positive at all corners
  // nor both negative at all corners (d is a convex combination of dA and dB).
  const int cx = dims.x() - 1, cy = dims.y() - 1, cz = dims.z() - 1;
  const std::int64_t cube_count = std::int64_t(cx) * cy * cz;

  // Fixed chunking (independent of the thread count) so concatenating chunk outputs in chunk order
  // gives the same tet order on every run.
  const std::int64_t chunk = 4096;
  const std::int64_t chunks = (cube_count + chunk - 1) / chunk;
  std::vector<ChunkOutput> outputs(static_cast<std::size_t>(chunks));

  tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, chunks), [&](const tbb::blocked_range<std::int64_t>& range) {
    std::vector<std::array<int, 4>> prism_tets;
    for (std::int64_t c = range.begin(); c != range.end(); ++c) {
      ChunkOutput& out = outputs[std::size_t(c)];
      const std::int64_t end = std::min(cube_count, (c + 1) * chunk);
      for (std::int64_t cube = c * chunk; cube < end; ++cube) {
        const int i = int(cube % cx), j = int((cube / cx) % cy), k = int(cube / (std::int64_t(cx) * cy));
        const std::int64_t base3 = field.index(i, j, k);
        std::int64_t corner3[8];
        bool any_nonneg = false, any_nonpos = false;
        for (int b = 0; b < 8; ++b) {
          corner3[b] = base3 + ((b & 1) ? stride[0] : 0) + ((b & 2) ? stride[1] : 0) + ((b & 4) ? stride[2] : 0);
          const float a = field.dA[std::size_t(corner3[b])], bb = field.dB[std::size_t(corner3[b])];
          any_nonneg |= a >= 0.0f || bb >= 0.0f;
          any_nonpos |= a < 0.0f || bb < 0.0f;
        }
        if (!(any_nonneg && any_nonpos)) continue;
        float prev[8];
        for (int b = 0; b < 8; ++b) prev[b] = lat.value(corner3[b], 0);
        for (int l = 0; l < options.time_steps; ++l) {
          float f[16];
          bool pos = false, neg = false;
          for (int b = 0; b < 8; ++b) {
            f[b] = prev[b];
            f[b + 8] = lat.value(corner3[b], l + 1);
            prev[b] = f[b + 8];
          }
          for (float v : f) (v > 0.0f ? pos : neg) = true;
          if (!(pos && neg)) continue;
          ++out.active_cells;
          const std::int64_t base = base3 + lat.n3 * l;
          for (int s = 0; s < 24; ++s) {
            const auto& cm = kKuhn.corner[std::size_t(s)];
            int P[5], N[5], np = 0, nn = 0;
            for (int m = 0; m < 5; ++m) (f[cm[std::size_t(m)]] > 0.0f ? P[np++] : N[nn++]) = m;
            if (np == 0 || nn == 0) continue;
            // Edge key of simplex vertices (m1, m2), m1 < m2 along the walk so corner m1 <= corner m2.
            auto key = [&](int m1, int m2) {
              if (m1 > m2) std::swap(m1, m2);
              const int lo = cm[std::size_t(m1)], hi = cm[std::size_t(m2)];
              std::int64_t id = base;
              for (int a = 0; a < 4; ++a)
                if (lo & (1 << a)) id += stride[a];
              return edge_key(id, hi & ~lo);
            };
            const std::int64_t source = (base)*24 + s;
            if (np == 1 || nn == 1) {
              const bool lone_pos = np == 1;
              const int lone = lone_pos ? P[0] : N[0];
              const int* others = lone_pos ? N : P;
              out.tets.push_back({{key(lone, others[0]), key(lone, others[1]), key(lone, others[2]), key(lone, others[3])}, source});
            } else {
              const bool pair_pos = np == 2;
              const int* pair = pair_pos ? P : N;
              const int* triple = pair_pos ? N : P;
              std::array<EdgeKey, 6> pk;
              for (int q = 0; q < 3; ++q) {
                pk[std::size_t(q)] = key(pair[0], triple[q]);
                pk[std::size_t(q + 3)] = key(pair[1], triple[q]);
              }
              prism_tets.clear();
              split_prism(pk, prism_tets);
              for (const auto& t : prism_tets)
                out.tets.push_back({{pk[std::size_t(t[0])], pk[std::size_t(t[1])], pk[std::size_t(t[2])], pk[std::size_t(t[3])]}, source});
              ++out.prisms;
            }
          }
        }
      }
    }
  });

  std::size_t tet_count = 0;
  for (const auto& o : outputs) {
    tet_count += o.tets.size();
    result.active_cells += o.active_cells;
    result.prisms += o.prisms;
  }
  if (tet_count == 0) throw TopologyError("extract_hypersurface: the morph field has no zero crossing in the lattice");

  // Vertex ids are the ranks of the distinct edge keys: a deterministic numbering.
  std::vector<EdgeKey> keys;
  keys.reserve(tet_count * 4);
  for (const auto& o : outputs)
    for (const auto& t : o.tets) keys.insert(keys.end(), t.key.begin(), t.key.end());
  tbb::parallel_sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());

  mesh.T.resize(Eigen::Index(tet_count), 4);
  mesh.source_cell.resize(tet_count);
  {
    std::size_t row = 0;
    for (auto& o : outputs) {
      for (const auto& t : o.tets) {
        for (int q = 0; q < 4; ++q)
          mesh.T(Eigen::Index(row), q) =
              int(std::lower_bound(keys.begin(), keys.end(), t.key[std::size_t(q)]) - keys.begin());
        mesh.source_cell[row++] = t.source;
      }
      std::vector<LocalTet>().swap(o.tets);
    }
  }

  // Crossing positions: linear interpolation of the (snapped) lattice values along each edge.
  const Eigen::Index nv = Eigen::Index(keys.size());
  mesh.V.resize(nv, 4);
  mesh.side.assign(keys.size(), VertexSide::Interior);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, nv), [&](const tbb::blocked_range<Eigen::Index>& range) {
    for (Eigen::Index v = range.begin(); v != range.end(); ++v) {
      const std::int64_t lo = std::int64_t(keys[std::size_t(v)] >> 4);
      const int mask = int(keys[std::size_t(v)] & 15u);
      const std::int64_t idx3 = lo % lat.n3;
      const int level = int(lo / lat.n3);
      const int i = int(idx3 % dims.x()), j = int((idx3 / dims.x()) % dims.y()), k = int(idx3 / (std::int64_t(dims.x()) * dims.y()));
      std::int64_t hi3 = idx3;
      for (int a = 0; a < 3; ++a)
        if (mask & (1 << a)) hi3 += stride[a];
      const int hi_level = level + ((mask & 8) ? 1 : 0);
      const double f0 = lat.value(idx3, level), f1 = lat.value(hi3, hi_level);
      const double w = f0 / (f0 - f1);
      const Eigen::Vector3d p0 = field.point(i, j, k);
      Eigen::Vector4d q;
      q.head<3>() = p0;
      q(3) = level * lat.dt_len;
      for (int a = 0; a < 4; ++a)
        if (mask & (1 << a)) q(a) += w * spacing[a];
      mesh.V.row(v) = q.transpose();
      if (level == 0 && hi_level == 0) mesh.side[std::size_t(v)] = VertexSide::A;
      if (level == lat.K) mesh.side[std::size_t(v)] = VertexSide::B;
    }
  });

  // Orientation: cross4 of each tet must point where d increases. Inside one Kuhn simplex the
  // linear interpolant's gradient has component (f[m+1] - f[m]) / spacing along the axis added at step m.
  std::vector<double> volumes(tet_count);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tet_count), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t t = range.begin(); t != range.end(); ++t) {
      const std::int64_t base = mesh.source_cell[t] / 24;
      const int s = int(mesh.source_cell[t] % 24);
      const std::int64_t idx3 = base % lat.n3;
      const int level = int(base / lat.n3);
      Eigen::Vector4d g;
      double fprev = lat.value(idx3, level);
      std::int64_t cur3 = idx3;
      int cur_level = level;
      for (int m = 0; m < 4; ++m) {
        const int a = kKuhn.axis[std::size_t(s)][std::size_t(m)];
        if (a == 3) ++cur_level; else cur3 += stride[a];
        const double fnext = lat.value(cur3, cur_level);
        g(a) = (fnext - fprev) / spacing[a];
        fprev = fnext;
      }
      auto row = mesh.T.row(Eigen::Index(t));
      const Eigen::Vector4d v0 = mesh.V.row(row(0)).transpose();
      const Eigen::Vector4d n = cross4(mesh.V.row(row(1)).transpose() - v0, mesh.V.row(row(2)).transpose() - v0,
                                       mesh.V.row(row(3)).transpose() - v0);
      if (n.dot(g) < 0.0) std::swap(row(2), row(3));
      volumes[t] = n.norm() / 6.0;
    }
  });

  double mean_volume = 0.0, min_volume = std::numeric_limits<double>::infinity();
  for (double v : volumes) {
    mean_volume += v;
    min_volume = std::min(min_volume, v);
  }
  mean_volume /= double(tet_count);
  for (double v : volumes)
    if (v <= 1e-12 * mean_volume) ++result.degenerate_tets;
  result.min_volume_ratio = mean_volume > 0.0 ? min_volume / mean_volume : 0.0;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace morphmap
