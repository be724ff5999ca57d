#include "mesh/morph_topology.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "mesh/errors.h"
#include "mesh/thin_features.h"

namespace morphmap {
namespace {

int neighbour(int dx, int dy, int dz) {
  const auto& offsets = kuhn_neighbour_offsets();
  for (std::size_t b = 0; b < offsets.size(); ++b)
    if (offsets[b][0] == dx && offsets[b][1] == dy && offsets[b][2] == dz) return int(b);
  return -1;
}

TEST(MorphTopology, SimplePointsOfTheKuhnLink) {
  ASSERT_EQ(kuhn_neighbour_offsets().size(), 14u);
  EXPECT_FALSE(simple_lattice_point(0));               // a new component
  EXPECT_FALSE(simple_lattice_point((1u << 14) - 1));  // fills a cavity
  for (int b = 0; b < 14; ++b) {
    EXPECT_TRUE(simple_lattice_point(1u << b)) << b;                        // grows a part by one point
    EXPECT_TRUE(simple_lattice_point(((1u << 14) - 1) & ~(1u << b))) << b;  // all but one: fills a dent
  }
  // Two opposite neighbours are not joined in the link: the point would join two parts (or close a loop).
  EXPECT_FALSE(simple_lattice_point((1u << neighbour(1, 0, 0)) | (1u << neighbour(-1, 0, 0))));
  // Two neighbours joined by a Kuhn edge are one part.
  EXPECT_TRUE(simple_lattice_point((1u << neighbour(1, 0, 0)) | (1u << neighbour(1, 1, 0))));
  // A ring of the six neighbours around the (1,1,1) axis: adding the point would fill a loop's hole.
  const unsigned ring = (1u << neighbour(1, 0, 0)) | (1u << neighbour(1, 1, 0)) | (1u << neighbour(0, 1, 0)) |
                        (1u << neighbour(0, 1, 1)) | (1u << neighbour(0, 0, 1)) | (1u << neighbour(1, 0, 1));
  EXPECT_FALSE(simple_lattice_point(ring));
}

// A small ball grows into a dumbbell whose end balls, far from the ball but thick, cross zero before the thin rod
// reaches them: the linear interpolation has them as separate components for a while.
MorphField dumbbell_morph() {
  const SignedDistance ball = [](const Eigen::Vector3d& p) { return p.norm() - 0.3; };
  const SignedDistance dumbbell = [](const Eigen::Vector3d& p) {
    const double left = (p - Eigen::Vector3d(-1.5, 0, 0)).norm() - 0.5;
    const double right = (p - Eigen::Vector3d(1.5, 0, 0)).norm() - 0.5;
    const double along = std::clamp(p.x(), -1.5, 1.5);
    const double rod = (p - Eigen::Vector3d(along, 0, 0)).norm() - 0.12;
    return std::min({left, right, rod});
  };
  return sample_morph(ball, dumbbell, 2.4, 49);
}

std::vector<LatticeTopology> level_topologies(const MorphField& field, int K) {
  std::vector<LatticeTopology> result;
  const std::size_t n3 = std::size_t(field.point_count());
  std::vector<float> level(n3);
  for (int l = 0; l <= K; ++l) {
    const double t = double(l) / K;
    for (std::size_t q = 0; q < n3; ++q)
      level[q] = field.levels.empty() ? float((1.0 - t) * field.dA[q] + t * field.dB[q]) : field.levels[l * n3 + q];
    result.push_back(lattice_topology(field, level));
  }
  return result;
}

TEST(MorphTopology, GrowingDumbbellKeepsOneComponentAtEveryLevel) {
  const int K = 20;
  MorphField free = dumbbell_morph();
  const auto before = level_topologies(free, K);
  ASSERT_EQ(before.front().components, 1);
  ASSERT_EQ(before.back().components, 1);
  ASSERT_EQ(before.front().euler, before.back().euler);
  // The linear interpolation splits off the end balls at some level.
  EXPECT_TRUE(std::any_of(before.begin(), before.end(), [](const LatticeTopology& t) { return t.components > 1; }));

  MorphField kept = free;
  const MorphTopologyResult result = keep_morph_topology(kept, K, {"auto"});
  EXPECT_TRUE(result.applied);
  EXPECT_GT(result.delayed_points, 0);
  EXPECT_EQ(result.forced_flips, 0);
  EXPECT_GT(result.levels_changed_free, 0);
  EXPECT_EQ(result.levels_changed_kept, 0);
  ASSERT_EQ(kept.time_levels, K + 1);
  for (const LatticeTopology& t : level_topologies(kept, K)) {
    EXPECT_EQ(t.components, 1);
    EXPECT_EQ(t.euler, before.front().euler);
  }
  // The ends are the two distance fields bit for bit, and a point that never waited keeps the linear interpolation.
  const std::size_t n3 = std::size_t(kept.point_count());
  for (std::size_t q = 0; q < n3; ++q) {
    ASSERT_EQ(kept.levels[q], kept.dA[q]);
    ASSERT_EQ(kept.levels[std::size_t(K) * n3 + q], kept.dB[q]);
  }
  std::size_t same = 0;
  for (std::size_t q = 0; q < n3; ++q) same += kept.levels[5 * n3 + q] == float(0.75 * kept.dA[q] + 0.25 * kept.dB[q]);
  EXPECT_GT(same, n3 - std::size_t(result.delayed_points) - 1);
}

TEST(MorphTopology, FreeAndDifferentEndsLeaveTheMorphAlone) {
  MorphField field = dumbbell_morph();
  EXPECT_FALSE(keep_morph_topology(field, 8, {"free"}).applied);
  EXPECT_TRUE(field.levels.empty());
  // A ball into two balls: the ends differ, so auto keeps the linear interpolation and preserve forces the split.
  const SignedDistance ball = [](const Eigen::Vector3d& p) { return p.norm() - 0.6; };
  const SignedDistance two = [](const Eigen::Vector3d& p) {
    return std::min((p - Eigen::Vector3d(-1, 0, 0)).norm(), (p - Eigen::Vector3d(1, 0, 0)).norm()) - 0.4;
  };
  MorphField split = sample_morph(ball, two, 2.0, 41);
  EXPECT_FALSE(keep_morph_topology(split, 8, {"auto"}).applied);
  EXPECT_TRUE(split.levels.empty());
  const MorphTopologyResult forced = keep_morph_topology(split, 8, {"preserve"});
  EXPECT_TRUE(forced.applied);
  EXPECT_GT(forced.forced_flips, 0);
  EXPECT_THROW(keep_morph_topology(split, 8, {"preserve"}), InvalidInput);  // already sampled per level
  MorphField other = dumbbell_morph();
  EXPECT_THROW(keep_morph_topology(other, 8, {"sometimes"}), InvalidInput);
  EXPECT_THROW(keep_morph_topology(other, 0, {"auto"}), InvalidInput);
}

}  // namespace
}  // namespace morphmap
