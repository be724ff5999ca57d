// Variational implicit morph: sampling, the interpolant's end shapes and extraction from per-level values.
#include "mesh/vim.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>

#include "mesh/errors.h"
#include "mesh/extract.h"
#include "mesh/shapes.h"

namespace morphmap {
namespace {

Surface sphere(double radius) { return make_shape(parse_shape_spec("sphere:size=" + std::to_string(radius)), {}); }

TEST(FarthestPointSamples, SpreadsOverALineAndStopsAtDuplicates) {
  Eigen::MatrixXd V = Eigen::MatrixXd::Zero(11, 3);
  for (int i = 0; i < 11; ++i) V(i, 0) = i;
  EXPECT_EQ(farthest_point_samples(V, 3), (std::vector<int>{0, 10, 5}));
  EXPECT_EQ(farthest_point_samples(V, 20).size(), 11u);
  Eigen::MatrixXd twice(4, 3);
  twice << 0, 0, 0, 1, 0, 0, 0, 0, 0, 1, 0, 0;
  EXPECT_EQ(farthest_point_samples(twice, 3), (std::vector<int>{0, 1}));
}

struct VimCase {
  Surface A = sphere(0.5), B = sphere(0.8);
  MorphOptions lattice;
  VimOptions vim;
  VimCase() {
    lattice.voxels = 16;
    vim.samples = 150;
  }
};

TEST(VimMorph, EndLevelsHaveTheShapesAsZeroSets) {
  const VimCase c;
  const int steps = 4;
  const MorphResult r = build_vim_morph(c.A, c.B, c.lattice, c.vim, steps);
  const MorphField& f = r.field;
  EXPECT_EQ(r.method, "vim");
  EXPECT_EQ(f.time_levels, steps + 1);
  const std::int64_t n3 = std::int64_t(f.dims.prod());
  ASSERT_EQ(f.levels.size(), std::size_t(n3) * (steps + 1));
  EXPECT_LT(r.fit_residual, 1e-6);
  // Away from the surface (more than a voxel), the sign of G at t = 0 and t = 1 is the shape's inside/outside, and
  // near it |G| approximates the distance.
  int checked = 0;
  for (int k = 0; k < f.dims.z(); ++k)
    for (int j = 0; j < f.dims.y(); ++j)
      for (int i = 0; i < f.dims.x(); ++i) {
        const double radius = f.point(i, j, k).norm();
        const std::size_t q = std::size_t(f.index(i, j, k));
        for (const auto& [level, shape_radius] : {std::pair<int, double>{0, 0.5}, {steps, 0.8}}) {
          const double g = f.levels[std::size_t(level) * std::size_t(n3) + q];
          const double d = radius - shape_radius;
          if (std::abs(d) > f.voxel_size) {
            EXPECT_EQ(g < 0.0, d < 0.0) << "level " << level << " radius " << radius;
            ++checked;
          }
          if (std::abs(d) < 0.5 * f.voxel_size) {
            EXPECT_NEAR(g, d, 0.3 * f.voxel_size);
          }
        }
      }
  EXPECT_GT(checked, 1000);
  for (std::int64_t q = 0; q < n3; ++q) {
    EXPECT_EQ(f.dA[std::size_t(q)], f.levels[std::size_t(q)]);
    EXPECT_EQ(f.dB[std::size_t(q)], f.levels[std::size_t(steps * n3 + q)]);
  }
}

TEST(VimMorph, ExtractionUsesTheLevelsAndTheirCount) {
  const VimCase c;
  const MorphResult r = build_vim_morph(c.A, c.B, c.lattice, c.vim, 4);
  ExtractOptions options;
  options.time_steps = 4;
  const ExtractResult e = extract_hypersurface(r.field, options);
  const TetMesh4& mesh = e.mesh;
  ASSERT_GT(mesh.tet_count(), 0);
  // Vertices on the t = 0 and t = 1 boundaries lie on the two spheres, to the lattice's resolution and the sag of
  // the sphere meshes' faces.
  int ends = 0;
  for (Eigen::Index v = 0; v < mesh.V.rows(); ++v) {
    const double t = mesh.time_of(int(v));
    if (t != 0.0 && t != 1.0) continue;
    EXPECT_NEAR(mesh.V.row(v).head<3>().norm(), t == 0.0 ? 0.5 : 0.8, 0.25 * r.field.voxel_size);
    ++ends;
  }
  EXPECT_GT(ends, 100);
  options.time_steps = 5;
  EXPECT_THROW(extract_hypersurface(r.field, options), InvalidInput);
}

TEST(VimMorph, SameFieldForAnyThreadCount) {
  const VimCase c;
  MorphResult one, two;
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 1);
    one = build_vim_morph(c.A, c.B, c.lattice, c.vim, 3);
  }
  {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, 2);
    two = build_vim_morph(c.A, c.B, c.lattice, c.vim, 3);
  }
  EXPECT_EQ(one.field.levels, two.field.levels);
}

TEST(VimMorph, RejectsBadOptions) {
  VimCase c;
  c.vim.samples = 2;
  EXPECT_THROW(build_vim_morph(c.A, c.B, c.lattice, c.vim, 4), InvalidInput);
  c.vim.samples = 100;
  c.vim.separation = 0.0;
  EXPECT_THROW(build_vim_morph(c.A, c.B, c.lattice, c.vim, 4), InvalidInput);
  c.vim.separation = 1.0;
  EXPECT_THROW(build_vim_morph(c.A, c.B, c.lattice, c.vim, 0), InvalidInput);
}

}  // namespace
}  // namespace morphmap
