// A surface's topology kept on the lattice (see thin_features.h). Written by hand: OpenVDB's sampling has no notion of
// features between lattice points, and no library corrects samples against the mesh they came from.
#include "mesh/thin_features.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <string>
#include <utility>

#include "mesh/adjacency.h"
#include "mesh/errors.h"

namespace morphmap {
namespace {

// The Kuhn triangulation's edges from a lattice point: (i, j, k) + d for the 7 nonzero d in {0, 1}^3.
constexpr std::array<std::array<int, 3>, 7> kEdges{
    {{{1, 0, 0}}, {{0, 1, 0}}, {{0, 0, 1}}, {{1, 1, 0}}, {{1, 0, 1}}, {{0, 1, 1}}, {{1, 1, 1}}}};

// Calls visit(i, j, k, q) for every lattice point, slabs of k in parallel: visit may write only its own point's
// entries and per-k sums.
template <class Visit>
void for_each_point(const MorphField& field, Visit&& visit) {
  const Eigen::Vector3i& n = field.dims;
  tbb::parallel_for(tbb::blocked_range<int>(0, n.z()), [&](const tbb::blocked_range<int>& range) {
    for (int k = range.begin(); k != range.end(); ++k)
      for (int j = 0; j < n.y(); ++j)
        for (int i = 0; i < n.x(); ++i) visit(i, j, k, field.index(i, j, k));
  });
}

float other_sign(float v, double h) {
  const float tiny = float(1e-6 * h);
  return v < 0.0f ? std::max(-v, tiny) : std::min(-v, -tiny);
}

// The Kuhn simplices with lowest vertex q: chains of nonempty subsets S1 < S2 < ... of {x, y, z} (bit masks), each
// vertex q + S; every simplex of the triangulation has one such form, inside the cube at q. 7 edges, 12 triangles and
// 6 tets, so a point whose cube has one sign throughout adds 1 - 7 + 12 - 6 = 0 to chi: only cubes the zero set
// crosses need counting.
struct KuhnStar {
  struct Simplex {
    std::array<std::int64_t, 3> offset{};  ///< the other vertices, from q
    int size = 0;                          ///< how many: the simplex's dimension
  };
  std::vector<Simplex> simplices;
  std::array<std::int64_t, 8> corner{};  ///< offset of cube corner `mask` from q
  std::array<std::int64_t, 7> edge{};    ///< offsets of the 7 Kuhn edges' other ends (kEdges)
  explicit KuhnStar(const Eigen::Vector3i& n) {
    for (int mask = 0; mask < 8; ++mask)
      corner[std::size_t(mask)] =
          std::int64_t(mask & 1) + std::int64_t(n.x()) * (((mask >> 1) & 1) + std::int64_t(n.y()) * ((mask >> 2) & 1));
    for (std::size_t e = 0; e < kEdges.size(); ++e)
      edge[e] = kEdges[e][0] + std::int64_t(n.x()) * (kEdges[e][1] + std::int64_t(n.y()) * kEdges[e][2]);
    for (int a = 1; a < 8; ++a) {
      simplices.push_back({{{corner[std::size_t(a)], 0, 0}}, 1});
      for (int b = 1; b < 8; ++b) {
        if ((a & b) != a || a == b) continue;
        simplices.push_back({{{corner[std::size_t(a)], corner[std::size_t(b)], 0}}, 2});
        for (int c = 1; c < 8; ++c)
          if ((b & c) == b && b != c)
            simplices.push_back({{{corner[std::size_t(a)], corner[std::size_t(b)], corner[std::size_t(c)]}}, 3});
      }
    }
  }
};

// Calls visit(q) for every point whose cube lies in the lattice and has corners of both signs or a marked corner
// (`marked` may be empty), in index order; per k slab in parallel, so `visit` must only accumulate per slab.
template <class Visit>
void for_each_crossed_cube(const MorphField& field, const std::vector<float>& values,
                           const std::vector<std::uint8_t>& marked, const KuhnStar& star, Visit&& visit) {
  const Eigen::Vector3i& n = field.dims;
  tbb::parallel_for(tbb::blocked_range<int>(0, std::max(n.z() - 1, 0)), [&](const tbb::blocked_range<int>& range) {
    for (int k = range.begin(); k != range.end(); ++k)
      for (int j = 0; j + 1 < n.y(); ++j)
        for (int i = 0; i + 1 < n.x(); ++i) {
          const std::int64_t q = field.index(i, j, k);
          bool in = false, out = false, mark = false;
          for (const std::int64_t c : star.corner) {
            (values[std::size_t(q + c)] < 0.0f ? in : out) = true;
            mark = mark || (!marked.empty() && marked[std::size_t(q + c)]);
          }
          if ((in && out) || mark) visit(k, q);
        }
  });
}

// Regions of one sign joined by Kuhn edges, over the points not `excluded` (may be empty). Slabs of k are joined in
// parallel (every index a slab's unions and finds touch lies in the slab), then the edges between slabs in order;
// the partition does not depend on that order, and each region's root is its smallest index either way.
DisjointSets sign_regions(const MorphField& field, const std::vector<float>& values,
                          const std::vector<std::uint8_t>& excluded, const KuhnStar& star) {
  const Eigen::Vector3i& n = field.dims;
  DisjointSets parts(values.size());
  const auto join_edges = [&](int i, int j, int k, bool within, int k_end) {
    const std::int64_t q = field.index(i, j, k);
    if (!excluded.empty() && excluded[std::size_t(q)]) return;
    const bool in = values[std::size_t(q)] < 0.0f;
    for (std::size_t e = 0; e < kEdges.size(); ++e) {
      const int ok = k + kEdges[e][2];
      if (i + kEdges[e][0] >= n.x() || j + kEdges[e][1] >= n.y() || ok >= n.z()) continue;
      if ((ok < k_end) != within) continue;
      const std::int64_t o = q + star.edge[e];
      if ((excluded.empty() || !excluded[std::size_t(o)]) && (values[std::size_t(o)] < 0.0f) == in) parts.unite(q, o);
    }
  };
  constexpr int kSlabs = 16;
  const int depth = std::max(1, (n.z() + kSlabs - 1) / kSlabs);
  tbb::parallel_for(0, kSlabs, [&](int slab) {
    const int k_end = std::min(n.z(), (slab + 1) * depth);
    for (int k = slab * depth; k < k_end; ++k)
      for (int j = 0; j < n.y(); ++j)
        for (int i = 0; i < n.x(); ++i) join_edges(i, j, k, true, k_end);
  });
  for (int slab = 0; slab < kSlabs; ++slab) {
    const int k_end = std::min(n.z(), (slab + 1) * depth);
    if (k_end <= slab * depth) continue;
    for (int j = 0; j < n.y(); ++j)
      for (int i = 0; i < n.x(); ++i) join_edges(i, j, k_end - 1, false, k_end);
  }
  return parts;
}

}  // namespace

LatticeTopology lattice_topology(const MorphField& field, const std::vector<float>& values) {
  const Eigen::Vector3i& n = field.dims;
  if (values.size() != std::size_t(field.point_count()))
    throw InvalidInput("lattice_topology: values must have point_count() = " + std::to_string(field.point_count()) +
                       " entries");
  const KuhnStar star(n);
  std::vector<std::int64_t> chi(std::size_t(std::max(n.z(), 1)), 0);
  for_each_crossed_cube(field, values, {}, star, [&](int k, std::int64_t q) {
    if (!(values[std::size_t(q)] < 0.0f)) return;
    std::int64_t sum = 1;
    for (const auto& simplex : star.simplices) {
      bool all = true;
      for (int m = 0; m < simplex.size && all; ++m)
        all = values[std::size_t(q + simplex.offset[std::size_t(m)])] < 0.0f;
      if (all) sum += simplex.size % 2 == 0 ? 1 : -1;
    }
    chi[std::size_t(k)] += sum;
  });
  DisjointSets parts = sign_regions(field, values, {}, star);
  std::int64_t regions = 0;
  for (std::size_t q = 0; q < values.size(); ++q) regions += parts.find(std::int64_t(q)) == std::int64_t(q);
  LatticeTopology topology;
  for (const std::int64_t c : chi) topology.euler += 2 * c;
  topology.components = regions - 1;
  return topology;
}

namespace {

// The zero set's topology as a function of the signs at a few candidate points, the rest fixed: what does not touch
// a candidate (the other simplices' part of chi, the regions of the other points) is counted once, so that trying a
// group costs O(candidates), not a pass over the lattice. Candidates must not lie on the lattice's boundary.
class CandidateTopology {
 public:
  CandidateTopology(const MorphField& field, const std::vector<float>& values, const std::vector<std::int64_t>& points)
      : values_(values) {
    const Eigen::Vector3i& n = field.dims;
    const KuhnStar star(n);
    std::vector<std::uint8_t> candidate(values.size(), 0);
    for (const std::int64_t q : points) candidate[std::size_t(q)] = 1;
    std::vector<std::int64_t> chi(std::size_t(std::max(n.z(), 1)), 0);
    std::vector<std::vector<std::array<std::int64_t, 4>>> touching(chi.size());
    for_each_crossed_cube(field, values, candidate, star, [&](int k, std::int64_t q) {
      const bool in = values[std::size_t(q)] < 0.0f;
      if (candidate[std::size_t(q)])
        touching[std::size_t(k)].push_back({{q, -1, -1, -1}});
      else
        chi[std::size_t(k)] += in;
      for (const auto& simplex : star.simplices) {
        std::array<std::int64_t, 4> ids{{q, -1, -1, -1}};
        bool touches = candidate[std::size_t(q)] != 0, all = in;
        for (int m = 0; m < simplex.size; ++m) {
          const std::int64_t v = q + simplex.offset[std::size_t(m)];
          ids[std::size_t(m + 1)] = v;
          touches = touches || candidate[std::size_t(v)];
          all = all && values[std::size_t(v)] < 0.0f;
        }
        if (touches)
          touching[std::size_t(k)].push_back(ids);
        else if (all)
          fixed_chi_delta(chi[std::size_t(k)], simplex.size);
      }
    });
    for (std::size_t k = 0; k < chi.size(); ++k) {
      fixed_chi_ += chi[k];
      simplices_.insert(simplices_.end(), touching[k].begin(), touching[k].end());
    }
    DisjointSets parts = sign_regions(field, values, candidate, star);
    std::vector<std::int64_t> id(values.size(), -1);
    for (std::size_t q = 0; q < values.size(); ++q)
      if (!candidate[q] && parts.find(std::int64_t(q)) == std::int64_t(q)) id[q] = fixed_regions_++;
    for (std::size_t c = 0; c < points.size(); ++c) {
      const std::int64_t q = points[c];
      const int i = int(q % n.x()), j = int((q / n.x()) % n.y()), k = int(q / (std::int64_t(n.x()) * n.y()));
      for (std::size_t e = 0; e < kEdges.size(); ++e)
        for (const int s : {1, -1}) {
          const int oi = i + s * kEdges[e][0], oj = j + s * kEdges[e][1], ok = k + s * kEdges[e][2];
          if (oi < 0 || oj < 0 || ok < 0 || oi >= n.x() || oj >= n.y() || ok >= n.z()) continue;
          const std::int64_t o = field.index(oi, oj, ok);
          const std::int64_t other =
              candidate[std::size_t(o)]
                  ? fixed_regions_ + std::int64_t(std::lower_bound(points.begin(), points.end(), o) - points.begin())
                  : id[std::size_t(parts.find(o))];
          links_.push_back({q, o, fixed_regions_ + std::int64_t(c), other});
        }
    }
    candidates_ = std::int64_t(points.size());
  }

  LatticeTopology evaluate() const {
    std::int64_t chi = fixed_chi_;
    for (const auto& simplex : simplices_) {
      bool all = true;
      int size = -1;
      for (const std::int64_t v : simplex) {
        if (v < 0) break;
        ++size;
        all = all && values_[std::size_t(v)] < 0.0f;
      }
      if (all) fixed_chi_delta(chi, size);
    }
    DisjointSets regions(std::size_t(fixed_regions_ + candidates_));
    for (const auto& link : links_)
      if ((values_[std::size_t(link[0])] < 0.0f) == (values_[std::size_t(link[1])] < 0.0f))
        regions.unite(link[2], link[3]);
    std::int64_t count = 0;
    for (std::int64_t r = 0; r < fixed_regions_ + candidates_; ++r) count += regions.find(r) == r;
    return {2 * chi, count - 1};
  }

 private:
  // A simplex of dimension `size` counts (-1)^size in chi (a vertex +1, an edge -1, a triangle +1, a tet -1).
  static void fixed_chi_delta(std::int64_t& chi, int size) { chi += size % 2 == 0 ? 1 : -1; }

  const std::vector<float>& values_;
  std::int64_t fixed_chi_ = 0;
  std::int64_t fixed_regions_ = 0;
  std::int64_t candidates_ = 0;
  std::vector<std::array<std::int64_t, 4>> simplices_;  ///< simplices with a candidate vertex (unused ids -1)
  std::vector<std::array<std::int64_t, 4>> links_;      ///< Kuhn edges from a candidate: ends, then their region nodes
};

std::int64_t distance_from(const LatticeTopology& a, const LatticeTopology& b) {
  return std::abs(a.euler - b.euler) + std::abs(a.components - b.components);
}

struct GroupOutcome {
  std::int64_t groups = 0, kept = 0, moved_inside = 0, moved_outside = 0;
  LatticeTopology initial;   ///< the zero set's, before any group
  LatticeTopology topology;  ///< the zero set's, after the kept groups
};

// Splits `points` (ascending) into groups joined by Kuhn edges and tries each, in order of its lowest point, with its
// points' signs flipped on the values so far: kept when the zero set's topology comes nearer `target` (with
// `keep_ties`, also when it stays as near), undone otherwise. Handles and components are not local properties, so
// each trial counts them over the lattice (in O(points), CandidateTopology).
GroupOutcome flip_groups(const MorphField& field, std::vector<float>& values, const std::vector<std::int64_t>& points,
                         const LatticeTopology& target, bool keep_ties) {
  GroupOutcome outcome;
  const Eigen::Vector3i& n = field.dims;
  std::vector<std::uint8_t> candidate(values.size(), 0);
  for (const std::int64_t q : points) candidate[std::size_t(q)] = 1;
  DisjointSets groups(values.size());
  for (const std::int64_t q : points) {
    const int i = int(q % n.x()), j = int((q / n.x()) % n.y()), k = int(q / (std::int64_t(n.x()) * n.y()));
    for (const auto& d : kEdges) {
      if (i + d[0] >= n.x() || j + d[1] >= n.y() || k + d[2] >= n.z()) continue;
      const std::int64_t o = field.index(i + d[0], j + d[1], k + d[2]);
      if (candidate[std::size_t(o)]) groups.unite(q, o);
    }
  }
  std::vector<std::vector<std::int64_t>> members;
  std::vector<std::int64_t> slot(values.size(), -1);
  for (const std::int64_t q : points) {
    const std::int64_t root = groups.find(q);
    if (slot[std::size_t(root)] < 0) {
      slot[std::size_t(root)] = std::int64_t(members.size());
      members.emplace_back();
    }
    members[std::size_t(slot[std::size_t(root)])].push_back(q);
  }
  outcome.groups = std::int64_t(members.size());
  const CandidateTopology topology(field, values, points);
  outcome.initial = outcome.topology = topology.evaluate();
  std::vector<float> before;
  for (const auto& group : members) {
    before.clear();
    for (const std::int64_t q : group) {
      before.push_back(values[std::size_t(q)]);
      values[std::size_t(q)] = other_sign(values[std::size_t(q)], field.voxel_size);
    }
    const LatticeTopology trial = topology.evaluate();
    const std::int64_t now = distance_from(trial, target), was = distance_from(outcome.topology, target);
    if (now < was || (keep_ties && now == was)) {
      outcome.topology = trial;
      ++outcome.kept;
      for (const float v : before) ++(v < 0.0f ? outcome.moved_outside : outcome.moved_inside);
    } else {
      for (std::size_t m = 0; m < group.size(); ++m) values[std::size_t(group[m])] = before[m];
    }
  }
  return outcome;
}

}  // namespace

WindingVotes winding_votes(const SurfaceLocator& locator, const MorphField& field) {
  WindingVotes result;
  std::vector<std::uint8_t>& inside = result.inside;
  std::vector<std::uint8_t>& votes = result.votes;
  inside.assign(std::size_t(field.point_count()), 0);
  votes.assign(std::size_t(field.point_count()), 0);
  const Eigen::Vector3i& n = field.dims;
  const double h = field.voxel_size;
  std::int64_t grazing = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, w = (axis + 2) % 3;
    const int length = n(axis);
    std::vector<std::uint8_t> bad(std::size_t(n(u)) * std::size_t(n(w)), 0);
    tbb::parallel_for(tbb::blocked_range<int>(0, n(w)), [&](const tbb::blocked_range<int>& range) {
      std::vector<double> at;
      std::vector<int> direction;
      for (int b = range.begin(); b != range.end(); ++b)
        for (int a = 0; a < n(u); ++a) {
          Eigen::Vector3i first = Eigen::Vector3i::Zero();
          first(u) = a;
          first(w) = b;
          Eigen::Vector3i last = first;
          last(axis) = length - 1;
          // From a voxel before the first point to a voxel past the last, both outside every surface (padding).
          const Eigen::Vector3d step = h * Eigen::Vector3d::Unit(axis);
          const Eigen::Vector3d from = field.point(first.x(), first.y(), first.z()) - step;
          const Eigen::Vector3d to = field.point(last.x(), last.y(), last.z()) + step;
          const double span = double(length + 1);  // the segment's length in voxels
          at = locator.crossings(from, to, 1 << 20, 1e-3 / span, &direction);
          int total = 0;
          for (const int d : direction) total += d;
          if (total != 0) {
            bad[std::size_t(a) + std::size_t(n(u)) * std::size_t(b)] = 1;
            continue;
          }
          std::size_t passed = 0;
          int winding = 0;
          for (int m = 0; m < length; ++m) {
            const double t = double(m + 1) / span;
            while (passed < at.size() && at[passed] < t) winding += direction[passed++];
            Eigen::Vector3i p = first;
            p(axis) = m;
            const std::size_t q = std::size_t(field.index(p.x(), p.y(), p.z()));
            inside[q] = std::uint8_t(inside[q] + (winding != 0));
            ++votes[q];
          }
        }
    });
    for (const std::uint8_t o : bad) grazing += o;
  }
  result.grazing_lines = grazing;
  return result;
}

ThinFeatureResult keep_thin_features(const SurfaceLocator& locator, const MorphField& field, std::vector<float>& values,
                                     const LatticeTopology& target, const ThinFeatureOptions& options,
                                     const WindingVotes* winding) {
  ThinFeatureResult result;
  const Eigen::Vector3i& n = field.dims;
  if (values.size() != std::size_t(field.point_count()))
    throw InvalidInput("keep_thin_features: values must have point_count() = " + std::to_string(field.point_count()) +
                       " entries (got " + std::to_string(values.size()) + ")");
  if (!options.enabled || n.minCoeff() < 2) return result;
  const double h = field.voxel_size;

  WindingVotes own;
  if (winding == nullptr) {
    own = winding_votes(locator, field);
    winding = &own;
  }
  const std::vector<std::uint8_t>&inside = winding->inside, &votes = winding->votes;
  result.grazing_lines = winding->grazing_lines;
  std::vector<std::int64_t> wrong;
  for (std::size_t q = 0; q < values.size(); ++q) {
    if (2 * inside[q] == votes[q]) continue;  // a tie (or no vote): the sampled sign stands
    const bool in = 2 * inside[q] > votes[q];
    if (in != (values[q] < 0.0f)) wrong.push_back(std::int64_t(q));
  }
  result.sign_disagreements = std::int64_t(wrong.size());
  // A right sign can still open a handle (points inside a part thinner than a voxel that no Kuhn edge joins), so
  // these too go in groups, kept unless they take the topology further from the surface's.
  const GroupOutcome signs = flip_groups(field, values, wrong, target, true);
  result.sampled_euler = signs.initial.euler;
  result.sampled_components = signs.initial.components;
  result.sign_flips = signs.moved_inside + signs.moved_outside;
  if (distance_from(signs.topology, target) == 0) {  // no group of thin parts could be kept
    result.kept_euler = signs.topology.euler;
    result.kept_components = signs.topology.components;
    return result;
  }

  // Thin edges, found per k slab (each point casts its forward edges) and gathered in slab order: of each, the end
  // nearer the surface is a candidate. A point farther than the longest edge from the surface has none.
  const double reach = h * std::sqrt(3.0);
  std::vector<std::vector<std::int64_t>> nearer(std::size_t(n.z()));
  std::vector<std::int64_t> tested(std::size_t(n.z()), 0);
  for_each_point(field, [&](int i, int j, int k, std::int64_t a) {
    const float va = values[std::size_t(a)];
    if (!(double(std::abs(va)) < reach)) return;
    for (std::size_t e = 0; e < kEdges.size(); ++e) {
      const int bi = i + kEdges[e][0], bj = j + kEdges[e][1], bk = k + kEdges[e][2];
      if (bi >= n.x() || bj >= n.y() || bk >= n.z()) continue;
      const std::int64_t b = field.index(bi, bj, bk);
      const float vb = values[std::size_t(b)];
      if ((va < 0.0f) != (vb < 0.0f)) continue;
      // Two crossings at s1 < s2 along an edge of length l put its ends within s1 and l - s2 of the surface.
      const double length = h * std::sqrt(double(kEdges[e][0] + kEdges[e][1] + kEdges[e][2]));
      if (double(std::abs(va)) + double(std::abs(vb)) >= length) continue;
      ++tested[std::size_t(k)];
      if (locator.crossings(field.point(i, j, k), field.point(bi, bj, bk), 2).size() < 2) continue;
      nearer[std::size_t(k)].push_back(std::abs(va) <= std::abs(vb) ? a : b);  // a < b: the lower index on a tie
    }
  });
  std::vector<std::int64_t> points;
  for (int k = 0; k < n.z(); ++k) {
    result.edges_tested += tested[std::size_t(k)];
    result.thin_edges += std::int64_t(nearer[std::size_t(k)].size());
    points.insert(points.end(), nearer[std::size_t(k)].begin(), nearer[std::size_t(k)].end());
  }
  std::sort(points.begin(), points.end());
  points.erase(std::unique(points.begin(), points.end()), points.end());
  const GroupOutcome thin_parts = flip_groups(field, values, points, target, false);
  result.groups = thin_parts.groups;
  result.groups_kept = thin_parts.kept;
  result.moved_inside = thin_parts.moved_inside;
  result.moved_outside = thin_parts.moved_outside;
  const LatticeTopology& current = thin_parts.topology;
  result.kept_euler = current.euler;
  result.kept_components = current.components;
  return result;
}

}  // namespace morphmap
