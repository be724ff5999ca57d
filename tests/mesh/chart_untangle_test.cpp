// The fold-free layout of a disk with a fixed boundary, on grids whose inside is scrambled or collapsed by hand.
#include "mesh/chart_untangle.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <vector>

namespace morphmap {
namespace {

// An n by n grid of unit squares, each cut into two counter-clockwise triangles, minus the squares with i >= cut and
// j >= cut (an L-shaped disk when cut < n, a square when cut >= n). The boundary vertices are fixed.
struct Grid {
  Eigen::MatrixX2d x;
  Eigen::MatrixX3i F;
  std::vector<char> fixed;
  std::vector<Eigen::Matrix2d> inverse;
  std::vector<double> area;
};

Grid grid(int n, int cut) {
  Grid g;
  const auto id = [n](int i, int j) { return j * (n + 1) + i; };
  g.x.resize((n + 1) * (n + 1), 2);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) g.x.row(id(i, j)) << i, j;
  std::vector<Eigen::Vector3i> faces;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      if (i >= cut && j >= cut) continue;
      faces.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
      faces.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
    }
  g.F.resize(Eigen::Index(faces.size()), 3);
  for (std::size_t f = 0; f < faces.size(); ++f) g.F.row(Eigen::Index(f)) = faces[f].transpose();
  // Boundary: vertices on an edge used by one triangle only.
  std::vector<int> uses(std::size_t(g.x.rows()) * std::size_t(g.x.rows()), 0);
  for (const auto& f : faces)
    for (int k = 0; k < 3; ++k) {
      const int a = std::min(f(k), f((k + 1) % 3)), b = std::max(f(k), f((k + 1) % 3));
      ++uses[std::size_t(a) * std::size_t(g.x.rows()) + std::size_t(b)];
    }
  g.fixed.assign(std::size_t(g.x.rows()), 0);
  for (const auto& f : faces)
    for (int k = 0; k < 3; ++k) {
      const int a = std::min(f(k), f((k + 1) % 3)), b = std::max(f(k), f((k + 1) % 3));
      if (uses[std::size_t(a) * std::size_t(g.x.rows()) + std::size_t(b)] == 1)
        g.fixed[std::size_t(a)] = 1, g.fixed[std::size_t(b)] = 1;
    }
  for (Eigen::Index f = 0; f < g.F.rows(); ++f) {
    Eigen::Matrix2d E;
    E.col(0) = (g.x.row(g.F(f, 1)) - g.x.row(g.F(f, 0))).transpose();
    E.col(1) = (g.x.row(g.F(f, 2)) - g.x.row(g.F(f, 0))).transpose();
    g.inverse.push_back(E.inverse());
    g.area.push_back(0.5 * E.determinant());
  }
  return g;
}

int folded(const Grid& g) {
  int count = 0;
  for (Eigen::Index f = 0; f < g.F.rows(); ++f) {
    const Eigen::Vector2d a = (g.x.row(g.F(f, 1)) - g.x.row(g.F(f, 0))).transpose();
    const Eigen::Vector2d b = (g.x.row(g.F(f, 2)) - g.x.row(g.F(f, 0))).transpose();
    count += !(a.x() * b.y() - a.y() * b.x() > 0.0);
  }
  return count;
}

TEST(ChartUntangle, ScrambledSquareComesOutFoldFree) {
  Grid g = grid(10, 10);
  // Every free vertex reflected through the centre: most triangles turn over.
  for (Eigen::Index v = 0; v < g.x.rows(); ++v)
    if (!g.fixed[std::size_t(v)])
      g.x.row(v) = Eigen::RowVector2d(10.0, 10.0) - g.x.row(v) +
                   Eigen::RowVector2d(0.3 * std::sin(double(v)), 0.2 * std::cos(3.0 * double(v)));
  ASSERT_GT(folded(g), 20);
  const Eigen::MatrixX2d before = g.x;
  const ChartUntangleResult r = untangle_chart(g.x, g.fixed, g.F, g.inverse, g.area);
  EXPECT_TRUE(r.untangled);
  EXPECT_LT(r.smallest_det_before, 0.0);
  EXPECT_GT(r.smallest_det_after, 0.0);
  EXPECT_EQ(folded(g), 0);
  for (Eigen::Index v = 0; v < g.x.rows(); ++v)
    if (g.fixed[std::size_t(v)]) {
      EXPECT_EQ(g.x.row(v), before.row(v)) << "boundary vertex " << v << " moved";
    }
}

TEST(ChartUntangle, CollapsedInsideOfAnLShapeIsSpreadAgain) {
  // The inside of a non-convex disk merged into one point (every inner triangle flat or inverted): a Tutte layout of
  // such a boundary can fold next to the reflex corner; the untangling leaves no triangle non-positive.
  Grid g = grid(12, 6);
  for (Eigen::Index v = 0; v < g.x.rows(); ++v)
    if (!g.fixed[std::size_t(v)]) g.x.row(v) << 2.0, 2.0;
  ASSERT_GT(folded(g), 50);
  const ChartUntangleResult r = untangle_chart(g.x, g.fixed, g.F, g.inverse, g.area);
  EXPECT_TRUE(r.untangled) << r.smallest_det_after;
  EXPECT_EQ(folded(g), 0);
  // Nothing left inside the removed square (all vertices in the L).
  for (Eigen::Index v = 0; v < g.x.rows(); ++v)
    if (!g.fixed[std::size_t(v)]) {
      EXPECT_FALSE(g.x(v, 0) > 6.0 + 1e-9 && g.x(v, 1) > 6.0 + 1e-9) << v;
    }
}

TEST(ChartUntangle, FoldFreeStartStaysNearItsReference) {
  // The grid as it is: nothing to do, and the vertices barely move (the energy's minimum is the reference shape).
  Grid g = grid(6, 6);
  const Eigen::MatrixX2d before = g.x;
  const ChartUntangleResult r = untangle_chart(g.x, g.fixed, g.F, g.inverse, g.area);
  EXPECT_TRUE(r.untangled);
  EXPECT_LT((g.x - before).cwiseAbs().maxCoeff(), 1e-6);
}

}  // namespace
}  // namespace morphmap
