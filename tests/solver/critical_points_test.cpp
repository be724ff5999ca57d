#include "solver/critical_points.h"

#include <gtest/gtest.h>

#include <array>
#include <functional>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/errors.h"

namespace morphmap {
namespace {

constexpr int kN = 9;  // lattice points a side; the centre (4, 4, 4) is a vertex

int point(int i, int j, int k) { return i + kN * (j + kN * k); }

// The Kuhn triangulation of a cube of kN^3 points (tau = 0), its boundary points marked as A.
TetMesh4 kuhn_block() {
  TetMesh4 mesh;
  mesh.V.resize(kN * kN * kN, 4);
  mesh.side.assign(std::size_t(kN * kN * kN), VertexSide::Interior);
  for (int k = 0; k < kN; ++k)
    for (int j = 0; j < kN; ++j)
      for (int i = 0; i < kN; ++i) {
        mesh.V.row(point(i, j, k)) << i - kN / 2, j - kN / 2, k - kN / 2, 0.0;
        if (i == 0 || j == 0 || k == 0 || i == kN - 1 || j == kN - 1 || k == kN - 1)
          mesh.side[std::size_t(point(i, j, k))] = VertexSide::A;
      }
  std::vector<std::array<int, 4>> tets;
  const int axes[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k + 1 < kN; ++k)
    for (int j = 0; j + 1 < kN; ++j)
      for (int i = 0; i + 1 < kN; ++i)
        for (const auto& order : axes) {
          std::array<int, 3> c{{i, j, k}};
          std::array<int, 4> t{};
          t[0] = point(c[0], c[1], c[2]);
          for (int m = 0; m < 3; ++m) {
            ++c[std::size_t(order[m])];
            t[std::size_t(m) + 1] = point(c[0], c[1], c[2]);
          }
          tets.push_back(t);
        }
  mesh.T.resize(Eigen::Index(tets.size()), 4);
  for (std::size_t t = 0; t < tets.size(); ++t)
    for (int c = 0; c < 4; ++c) mesh.T(Eigen::Index(t), c) = tets[t][std::size_t(c)];
  return mesh;
}

CriticalPointResult classify(const std::function<double(double, double, double)>& f) {
  const TetMesh4 mesh = kuhn_block();
  const VertexTets stars = build_vertex_tets(mesh.T, mesh.vertex_count());
  Eigen::VectorXd s(mesh.vertex_count());
  for (Eigen::Index v = 0; v < s.size(); ++v) s(v) = f(mesh.V(v, 0), mesh.V(v, 1), mesh.V(v, 2));
  return critical_points(mesh, stars, s);
}

TEST(CriticalPoints, LinearFieldHasNone) {
  const CriticalPointResult r = classify([](double x, double y, double z) { return z + 0.3 * x + 0.1 * y; });
  EXPECT_EQ(r.interior_vertices, (kN - 2) * (kN - 2) * (kN - 2));
  EXPECT_EQ(r.minima + r.maxima + r.saddles, 0);
  EXPECT_TRUE(r.listed.empty());
}

TEST(CriticalPoints, BowlHasOneMinimumAndCapOneMaximum) {
  const CriticalPointResult bowl =
      classify([](double x, double y, double z) { return x * x + 1.1 * y * y + 1.3 * z * z; });
  EXPECT_EQ(bowl.minima, 1);
  EXPECT_EQ(bowl.maxima + bowl.saddles, 0);
  ASSERT_EQ(bowl.listed.size(), 1u);
  EXPECT_EQ(bowl.listed[0], point(kN / 2, kN / 2, kN / 2));
  const CriticalPointResult cap =
      classify([](double x, double y, double z) { return -(x * x + 1.1 * y * y + 1.3 * z * z); });
  EXPECT_EQ(cap.maxima, 1);
  EXPECT_EQ(cap.minima + cap.saddles, 0);
}

TEST(CriticalPoints, SaddleIsFoundAtTheCentre) {
  // Lower set near the centre: the double cone |z| > r, so the lower link has two parts.
  const CriticalPointResult r =
      classify([](double x, double y, double z) { return x * x + 1.1 * y * y - 1.3 * z * z; });
  EXPECT_EQ(r.saddles, 1);
  EXPECT_EQ(r.saddle_multiplicity, 1);
  EXPECT_EQ(r.minima + r.maxima, 0);
  ASSERT_EQ(r.listed.size(), 1u);
  EXPECT_EQ(r.listed[0], point(kN / 2, kN / 2, kN / 2));
}

TEST(CriticalPoints, WrongSizeIsRefused) {
  const TetMesh4 mesh = kuhn_block();
  const VertexTets stars = build_vertex_tets(mesh.T, mesh.vertex_count());
  EXPECT_THROW(critical_points(mesh, stars, Eigen::VectorXd::Zero(3)), InvalidInput);
}

}  // namespace
}  // namespace morphmap
