// A surface's topology kept on the lattice (mesh/thin_features.h): the zero set's Euler characteristic and
// components, segment crossings, signs by winding number, and thin parts put back where they fall between points.
#include "mesh/thin_features.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>

#include "mesh/errors.h"

namespace morphmap {
namespace {

// An axis-aligned box as a closed mesh with outward normals, and its exact signed distance.
Surface box_mesh(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  Surface s;
  s.name = "box";
  s.V.resize(8, 3);
  for (int b = 0; b < 8; ++b)
    s.V.row(b) << ((b & 1) ? hi.x() : lo.x()), ((b & 2) ? hi.y() : lo.y()), ((b & 4) ? hi.z() : lo.z());
  s.F.resize(12, 3);
  s.F << 0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4, 2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5;
  return s;
}

double box_distance(const Eigen::Vector3d& p, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  const Eigen::Vector3d q = (p - 0.5 * (lo + hi)).cwiseAbs() - 0.5 * (hi - lo);
  return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}

// A unit lattice of n^3 points at the origin, its values from `distance`.
template <class Distance>
MorphField unit_lattice(int n, Distance&& distance) {
  MorphField f;
  f.voxel_size = 1.0;
  f.dims = Eigen::Vector3i(n, n, n);
  f.dA.resize(std::size_t(f.dims.prod()));
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) f.dA[std::size_t(f.index(i, j, k))] = float(distance(f.point(i, j, k)));
  return f;
}

TEST(LatticeTopology, CountsSpheresToriShellsAndParts) {
  const auto sphere = [](const Eigen::Vector3d& p) { return (p - Eigen::Vector3d::Constant(8.3)).norm() - 5.1; };
  const auto torus = [](const Eigen::Vector3d& p) {
    const Eigen::Vector3d q = p - Eigen::Vector3d::Constant(8.3);
    return std::hypot(std::hypot(q.x(), q.y()) - 4.6, q.z()) - 1.9;
  };
  const auto two = [](const Eigen::Vector3d& p) {
    return std::min((p - Eigen::Vector3d(4.4, 8.2, 8.1)).norm() - 2.7,
                    (p - Eigen::Vector3d(12.1, 8.2, 8.1)).norm() - 2.7);
  };
  const auto shell = [](const Eigen::Vector3d& p) {
    const double r = (p - Eigen::Vector3d::Constant(8.3)).norm();
    return std::max(r - 6.1, 2.9 - r);  // a hollow ball: two boundary spheres
  };
  struct Case {
    const char* name;
    LatticeTopology expected;
    MorphField field;
  };
  const Case cases[] = {{"sphere", {2, 1}, unit_lattice(18, sphere)},
                        {"torus", {0, 1}, unit_lattice(18, torus)},
                        {"two spheres", {4, 2}, unit_lattice(18, two)},
                        {"shell", {4, 2}, unit_lattice(18, shell)},
                        {"nothing", {0, 0}, unit_lattice(6, [](const Eigen::Vector3d&) { return 1.0; })}};
  for (const Case& c : cases) {
    const LatticeTopology t = lattice_topology(c.field, c.field.dA);
    EXPECT_EQ(t.euler, c.expected.euler) << c.name;
    EXPECT_EQ(t.components, c.expected.components) << c.name;
  }
}

TEST(SurfaceCrossings, CountsEntriesAndExitsOnceEach) {
  const Surface box = box_mesh(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 1, 1));
  const SurfaceLocator locator(box);
  std::vector<int> directions;
  const std::vector<double> at =
      locator.crossings(Eigen::Vector3d(-1, 0.3, 0.6), Eigen::Vector3d(3, 0.3, 0.6), 10, 1e-4, &directions);
  ASSERT_EQ(at.size(), 2u);
  EXPECT_NEAR(at[0], 0.25, 1e-6);
  EXPECT_NEAR(at[1], 0.5, 1e-6);
  EXPECT_EQ(directions, (std::vector<int>{-1, 1}));
  EXPECT_EQ(locator.crossings(Eigen::Vector3d(-1, 0.3, 0.6), Eigen::Vector3d(3, 0.3, 0.6), 1).size(), 1u);
  EXPECT_TRUE(locator.crossings(Eigen::Vector3d(-1, 2, 0.6), Eigen::Vector3d(3, 2, 0.6), 10).empty());
  // Through the diagonal both triangles of the bottom and the top faces share: one crossing each.
  EXPECT_EQ(locator.crossings(Eigen::Vector3d(0.4, 0.4, -1), Eigen::Vector3d(0.4, 0.4, 2), 10).size(), 2u);
}

TEST(KeepThinFeatures, PutsAPlateBetweenLatticePlanesBackOnTheLattice) {
  // 0.4 voxels thick, between the planes z = 5 and z = 6: no lattice point is inside it.
  const Eigen::Vector3d lo(2.5, 2.5, 5.3), hi(8.5, 8.5, 5.7);
  const Surface plate = box_mesh(lo, hi);
  MorphField f = unit_lattice(12, [&](const Eigen::Vector3d& p) { return box_distance(p, lo, hi); });
  const LatticeTopology sampled = lattice_topology(f, f.dA);
  EXPECT_EQ(sampled.components, 0);  // the plate is lost
  const SurfaceLocator locator(plate);
  std::vector<float> off = f.dA;
  ThinFeatureOptions disabled;
  disabled.enabled = false;
  keep_thin_features(locator, f, off, {2, 1}, disabled);
  EXPECT_EQ(off, f.dA);

  const ThinFeatureResult r = keep_thin_features(locator, f, f.dA, {2, 1});
  EXPECT_EQ(r.sampled_components, 0);
  EXPECT_EQ(r.sign_disagreements, 0);
  EXPECT_GT(r.thin_edges, 0);
  EXPECT_GT(r.moved_inside, 0);
  EXPECT_EQ(r.moved_outside, 0);
  EXPECT_EQ(r.groups_kept, 1);
  const LatticeTopology kept = lattice_topology(f, f.dA);
  EXPECT_EQ(kept.euler, 2);
  EXPECT_EQ(kept.components, 1);
  EXPECT_EQ(r.kept_euler, kept.euler);
  EXPECT_EQ(r.kept_components, kept.components);
  // Only points next to the plate moved, to just inside: within a voxel of it, and keeping their distance.
  for (int k = 0; k < 12; ++k)
    for (int j = 0; j < 12; ++j)
      for (int i = 0; i < 12; ++i) {
        const float v = f.dA[std::size_t(f.index(i, j, k))];
        if (v < 0.0f) {
          EXPECT_LT(box_distance(f.point(i, j, k), lo, hi), 1.0);
          EXPECT_NEAR(-v, box_distance(f.point(i, j, k), lo, hi), 1e-5);
        }
      }
}

TEST(KeepThinFeatures, WindingNumberCorrectsWrongSignsThatChangeTopology) {
  const Eigen::Vector3d lo(2.5, 2.5, 2.5), hi(9.5, 9.5, 9.5);
  const Surface box = box_mesh(lo, hi);
  MorphField f = unit_lattice(13, [&](const Eigen::Vector3d& p) { return box_distance(p, lo, hi); });
  const std::vector<float> right = f.dA;
  // A wrong sign deep inside makes a cavity (a second boundary surface); one outside, a separate speck.
  f.dA[std::size_t(f.index(6, 6, 6))] *= -1.0f;
  f.dA[std::size_t(f.index(0, 6, 6))] = -0.5f;
  f.dA[std::size_t(f.index(11, 11, 11))] = -0.5f;  // 1.5 voxels out along each axis
  EXPECT_EQ(lattice_topology(f, f.dA).components, 4);
  const SurfaceLocator locator(box);
  const ThinFeatureResult r = keep_thin_features(locator, f, f.dA, {2, 1});
  EXPECT_EQ(r.sign_disagreements, 3);
  EXPECT_EQ(r.sign_flips, 3);
  EXPECT_EQ(r.grazing_lines, 0);
  for (std::size_t q = 0; q < right.size(); ++q) EXPECT_EQ(f.dA[q] < 0.0f, right[q] < 0.0f) << q;
  EXPECT_EQ(r.kept_euler, 2);
  EXPECT_EQ(r.kept_components, 1);
}

TEST(KeepThinFeatures, KeepsOnlyGroupsThatBringTheTopologyNearerAndIgnoresTheThreadCount) {
  // A rod thinner than a voxel along x: the points nearest it lie on both sides, in separate groups.
  const Eigen::Vector3d rod_lo(1.5, 5.3, 5.2), rod_hi(10.5, 5.6, 5.6);
  const Surface rod = box_mesh(rod_lo, rod_hi);
  const auto sample = [&] {
    return unit_lattice(13, [&](const Eigen::Vector3d& p) { return box_distance(p, rod_lo, rod_hi); });
  };
  const SurfaceLocator locator(rod);
  const LatticeTopology target{2, 1};
  MorphField one = sample(), two = sample();
  const LatticeTopology before = lattice_topology(one, one.dA);
  ThinFeatureResult r1, r2;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    r1 = keep_thin_features(locator, one, one.dA, target);
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    r2 = keep_thin_features(locator, two, two.dA, target);
  }
  EXPECT_EQ(one.dA, two.dA);
  EXPECT_EQ(r1.groups_kept, r2.groups_kept);
  const LatticeTopology after = lattice_topology(one, one.dA);
  EXPECT_EQ(before.components, 0);  // the rod is lost between the lattice lines
  // Its candidates fall in two groups: the first puts the rod back, the second would add a second piece.
  EXPECT_EQ(r1.groups, 2);
  EXPECT_EQ(r1.groups_kept, 1);
  EXPECT_EQ(after.euler, target.euler);
  EXPECT_EQ(after.components, target.components);
  EXPECT_EQ(after.euler, r1.kept_euler);
  EXPECT_EQ(after.components, r1.kept_components);
  EXPECT_GT(r1.thin_edges, 0);
}

TEST(KeepThinFeatures, RejectsValuesOfTheWrongSize) {
  const Surface box = box_mesh(Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(2, 2, 2));
  MorphField f = unit_lattice(4, [](const Eigen::Vector3d&) { return 1.0; });
  std::vector<float> values(5, 1.0f);
  const SurfaceLocator locator(box);
  EXPECT_THROW(keep_thin_features(locator, f, values, {2, 1}), InvalidInput);
  EXPECT_THROW(lattice_topology(f, values), InvalidInput);
}

}  // namespace
}  // namespace morphmap
