// A morph without the topology changes its ends do not need (see morph_topology.h). Written by hand: OpenVDB's level
// set tools advect and filter fronts but have no simple-point test, and the order here must be the extraction's own
// triangulation (the Kuhn one, 14 neighbours), not the 6/26 adjacencies of digital-topology libraries.
#include "mesh/morph_topology.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <queue>
#include <set>
#include <utility>

#include "mesh/errors.h"
#include "mesh/stopwatch.h"

namespace morphmap {
namespace {

constexpr int kNeighbours = 14;

// The link of a lattice point: the triangles opposite it in the 24 Kuhn tets around it, as neighbour indices. A tet
// of the cube at corner c is c + S0, c + S1, c + S2, c + S3 for a chain of corner masks 0 < S1 < S2 < 7 (bits x, y,
// z); the point is in it when it is one of those corners.
struct Link {
  std::vector<std::array<int, 3>> triangles;
  std::vector<std::array<int, 2>> edges;
  std::vector<std::uint8_t> simple;  ///< 2^14 entries: simple_lattice_point's answer for each neighbour mask

  Link() {
    const auto& offsets = kuhn_neighbour_offsets();
    const auto neighbour = [&](const std::array<int, 3>& d) {
      for (int b = 0; b < kNeighbours; ++b)
        if (offsets[std::size_t(b)] == d) return b;
      throw Error("kuhn link: offset not a neighbour");  // unreachable: every tet edge is a Kuhn edge
    };
    const auto corner = [](int mask) { return std::array<int, 3>{{mask & 1, (mask >> 1) & 1, (mask >> 2) & 1}}; };
    for (int f = 0; f < 8; ++f)        // the point is corner f of the cube at -f
      for (int a = 0; a < 3; ++a)      // first axis of the chain
        for (int b = 0; b < 3; ++b) {  // second axis
          if (b == a) continue;
          const int chain[4] = {0, 1 << a, (1 << a) | (1 << b), 7};
          if (std::find(chain, chain + 4, f) == chain + 4) continue;
          std::array<int, 3> triangle{};
          int m = 0;
          for (const int S : chain) {
            if (S == f) continue;
            const auto cs = corner(S), cf = corner(f);
            triangle[std::size_t(m++)] = neighbour({{cs[0] - cf[0], cs[1] - cf[1], cs[2] - cf[2]}});
          }
          std::sort(triangle.begin(), triangle.end());
          triangles.push_back(triangle);
        }
    for (const auto& t : triangles)
      for (int i = 0; i < 3; ++i)
        for (int j = i + 1; j < 3; ++j) edges.push_back({{t[std::size_t(i)], t[std::size_t(j)]}});
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());

    simple.assign(std::size_t(1) << kNeighbours, 0);
    for (std::uint32_t mask = 1; mask + 1 < (1u << kNeighbours); ++mask) {
      // The full subcomplex of the link sphere on the inside neighbours is contractible iff it is connected with
      // Euler characteristic 1 (a proper subcomplex of a 2-sphere has no H2, and its H1 is free).
      std::array<int, kNeighbours> root{};
      for (int v = 0; v < kNeighbours; ++v) root[std::size_t(v)] = v;
      const auto find = [&](int v) {
        while (root[std::size_t(v)] != v) v = root[std::size_t(v)];
        return v;
      };
      const auto in = [&](int v) { return (mask >> v) & 1u; };
      int chi = 0, parts = 0;
      for (int v = 0; v < kNeighbours; ++v) chi += int(in(v));
      for (const auto& e : edges)
        if (in(e[0]) && in(e[1])) {
          --chi;
          const int r0 = find(e[0]), r1 = find(e[1]);
          if (r0 != r1) root[std::size_t(std::max(r0, r1))] = std::min(r0, r1);
        }
      for (const auto& t : triangles) chi += int(in(t[0]) && in(t[1]) && in(t[2]));
      for (int v = 0; v < kNeighbours; ++v) parts += int(in(v) && find(v) == v);
      simple[mask] = chi == 1 && parts == 1;
    }
  }
};

const Link& link() {
  static const Link instance;
  return instance;
}

}  // namespace

const std::vector<std::array<int, 3>>& kuhn_neighbour_offsets() {
  static const std::vector<std::array<int, 3>> offsets = [] {
    const std::array<std::array<int, 3>, 7> positive{
        {{{1, 0, 0}}, {{0, 1, 0}}, {{0, 0, 1}}, {{1, 1, 0}}, {{1, 0, 1}}, {{0, 1, 1}}, {{1, 1, 1}}}};
    std::vector<std::array<int, 3>> all;
    for (const auto& d : positive) {
      all.push_back(d);
      all.push_back({{-d[0], -d[1], -d[2]}});
    }
    return all;
  }();
  return offsets;
}

bool simple_lattice_point(std::uint32_t inside_neighbours) {
  return link().simple[inside_neighbours & ((1u << kNeighbours) - 1)] != 0;
}

MorphTopologyResult keep_morph_topology(MorphField& field, int time_steps, const MorphTopologyOptions& options) {
  const auto start = Clock::now();
  if (options.mode != "auto" && options.mode != "preserve" && options.mode != "free")
    throw InvalidInput("keep_morph_topology: unknown mode '" + options.mode + "' (auto, preserve or free)");
  if (time_steps < 1) throw InvalidInput("keep_morph_topology: time_steps must be at least 1");
  if (!field.levels.empty()) throw InvalidInput("keep_morph_topology: the morph is already sampled per time level");
  const std::int64_t n3 = field.point_count();
  if (field.dA.size() != std::size_t(n3) || field.dB.size() != std::size_t(n3))
    throw InvalidInput("keep_morph_topology: dA and dB must have point_count() entries");

  MorphTopologyResult result;
  if (options.mode == "free") return result;  // nothing counted: the default costs nothing
  result.source = lattice_topology(field, field.dA);
  result.target = lattice_topology(field, field.dB);
  const bool same = result.source.euler == result.target.euler && result.source.components == result.target.components;
  if (options.mode == "auto" && !same) {
    result.seconds = seconds_since(start);
    return result;
  }
  result.applied = true;

  const Eigen::Vector3i& n = field.dims;
  std::array<std::int64_t, kNeighbours> step{};
  for (int b = 0; b < kNeighbours; ++b) {
    const auto& d = kuhn_neighbour_offsets()[std::size_t(b)];
    step[std::size_t(b)] = d[0] + std::int64_t(n.x()) * (d[1] + std::int64_t(n.y()) * d[2]);
  }
  const auto interior = [&](std::int64_t q) {
    const std::int64_t i = q % n.x(), j = (q / n.x()) % n.y(), k = q / (std::int64_t(n.x()) * n.y());
    return i > 0 && j > 0 && k > 0 && i + 1 < n.x() && j + 1 < n.y() && k + 1 < n.z();
  };

  // Each point's side now; the changing points' crossing times t* and the times t' they changed.
  std::vector<std::uint8_t> inside(std::size_t(n3), 0);
  std::vector<std::int64_t> changing;
  for (std::int64_t q = 0; q < n3; ++q) {
    const bool a = field.dA[std::size_t(q)] < 0.0f, b = field.dB[std::size_t(q)] < 0.0f;
    inside[std::size_t(q)] = a;
    if (a != b) changing.push_back(q);
  }
  result.changing_points = std::int64_t(changing.size());
  // A value of 0 is outside (as in the extraction); here it counts as a tiny positive one, so that t* lies in [0, 1)
  // and the resampled values keep their sides.
  const double tiny = 1e-6 * field.voxel_size;
  const auto end_values = [&](std::int64_t q) {
    const double a = field.dA[std::size_t(q)], b = field.dB[std::size_t(q)];
    return std::pair<double, double>(a == 0.0 ? tiny : a, b == 0.0 ? tiny : b);
  };
  const auto crossing_time = [&](std::int64_t q) {
    const auto [a, b] = end_values(q);
    return a / (a - b);
  };
  std::vector<double> changed(changing.size(), 0.0);
  enum : std::uint8_t { kQueued, kBlocked, kDone };
  std::vector<std::uint8_t> state(changing.size(), kQueued);
  // Slot of a changing point among `changing` (sorted by index), for its neighbours' lookups.
  const auto slot = [&](std::int64_t q) -> std::int64_t {
    const auto it = std::lower_bound(changing.begin(), changing.end(), q);
    return it != changing.end() && *it == q ? std::int64_t(it - changing.begin()) : -1;
  };
  using Event = std::pair<double, std::int64_t>;  // (time, slot): earliest first, then lowest index
  std::priority_queue<Event, std::vector<Event>, std::greater<Event>> queue;
  std::set<std::pair<double, std::int64_t>> blocked;  // (t*, slot) of points waiting for a neighbour
  for (std::size_t s = 0; s < changing.size(); ++s) queue.push({crossing_time(changing[s]), std::int64_t(s)});

  double now = 0.0;
  const auto flip = [&](std::int64_t s) {
    const std::int64_t q = changing[std::size_t(s)];
    inside[std::size_t(q)] ^= 1u;
    state[std::size_t(s)] = kDone;
    changed[std::size_t(s)] = now;
    for (int b = 0; b < kNeighbours; ++b) {
      const std::int64_t o = slot(q + step[std::size_t(b)]);
      if (o < 0 || state[std::size_t(o)] != kBlocked) continue;
      blocked.erase({crossing_time(changing[std::size_t(o)]), o});
      state[std::size_t(o)] = kQueued;
      queue.push({now, o});
    }
  };
  const auto is_simple = [&](std::int64_t q) {
    if (!interior(q)) return false;
    std::uint32_t mask = 0;
    for (int b = 0; b < kNeighbours; ++b) mask |= std::uint32_t(inside[std::size_t(q + step[std::size_t(b)])]) << b;
    return simple_lattice_point(mask);
  };
  for (;;) {
    while (!queue.empty()) {
      const auto [time, s] = queue.top();
      queue.pop();
      now = std::max(now, time);
      if (is_simple(changing[std::size_t(s)])) {
        flip(s);
      } else {
        state[std::size_t(s)] = kBlocked;
        blocked.insert({crossing_time(changing[std::size_t(s)]), s});
      }
    }
    if (blocked.empty()) break;
    // Nothing can change simply: the ends' topologies differ (or the lattice cannot go between them one simple point
    // at a time), so the longest-waiting point changes anyway.
    const std::int64_t s = blocked.begin()->second;
    blocked.erase(blocked.begin());
    ++result.forced_flips;
    flip(s);
  }

  // The levels: the linear interpolation where a point changed at its own time (bit for bit what the extraction
  // computes from dA and dB), otherwise d(t) = dA (1 - t / t') before t' and dB (t - t') / (1 - t') after it, with
  // the two levels around t' on one line so that the vertical lattice edge crosses zero at t' itself.
  const int K = time_steps;
  field.time_levels = K + 1;
  field.levels.resize(std::size_t(field.time_levels) * std::size_t(n3));
  for (std::int64_t q = 0; q < n3; ++q)
    for (int l = 0; l <= K; ++l) {
      const double t = double(l) / K;
      field.levels[std::size_t(l) * std::size_t(n3) + std::size_t(q)] = float(field.linear_value(q, t));
    }
  for (std::size_t s = 0; s < changing.size(); ++s) {
    const std::int64_t q = changing[s];
    const auto [a, b] = end_values(q);
    const double tc = crossing_time(q), tq = changed[s];
    if (!(tq > tc)) continue;
    ++result.delayed_points;
    result.max_delay = std::max(result.max_delay, tq - tc);
    std::vector<double> d(std::size_t(K) + 1);
    for (int l = 0; l <= K; ++l) {
      const double t = double(l) / K;
      d[std::size_t(l)] = t < tq ? a * (1.0 - t / tq) : b * (t - tq) / (1.0 - tq);
    }
    const int l = std::min(K - 1, int(std::floor(tq * K)));  // the slab [l, l + 1] / K holding t'
    const double t0 = double(l) / K, t1 = double(l + 1) / K;
    if (t0 < tq && tq < t1) {
      if (l + 1 < K)
        d[std::size_t(l) + 1] = -d[std::size_t(l)] * (t1 - tq) / (tq - t0);
      else if (l > 0)
        d[std::size_t(l)] = -d[std::size_t(l) + 1] * (tq - t0) / (t1 - tq);
    }
    for (int m = 1; m < K; ++m)
      field.levels[std::size_t(m) * std::size_t(n3) + std::size_t(q)] = float(d[std::size_t(m)]);
  }

  // Diagnostics: levels whose zero set differs from the source's, before and after.
  std::vector<float> level(static_cast<std::size_t>(n3));
  for (int l = 1; l < K; ++l) {
    const double t = double(l) / K;
    for (std::int64_t q = 0; q < n3; ++q) level[std::size_t(q)] = float(field.linear_value(q, t));
    const LatticeTopology free = lattice_topology(field, level);
    std::copy_n(field.levels.begin() + std::ptrdiff_t(std::size_t(l) * std::size_t(n3)), n3, level.begin());
    const LatticeTopology kept = lattice_topology(field, level);
    result.levels_changed_free += free.euler != result.source.euler || free.components != result.source.components;
    result.levels_changed_kept += kept.euler != result.source.euler || kept.components != result.source.components;
  }
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace morphmap
