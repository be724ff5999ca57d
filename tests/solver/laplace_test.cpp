// Tests of the cotangent Laplace-Beltrami operator and the harmonic field s (paper §6.1).
#include "solver/laplace.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/errors.h"
#include "tests/solver/test_meshes.h"

namespace morphmap {
namespace {

/// A slab bent out of its 3-plane and turned by a random rotation: every tet has its own hull.
TetMesh4 curved_slab(int n, int nz, unsigned seed) {
  TetMesh4 mesh = test::make_slab_mesh(n, nz);
  test::perturb_interior(mesh, 0.3 / n, seed);
  test::transform_embedding(mesh, test::random_rotation(seed + 1), Eigen::Vector4d(0.5, -2.0, 1.0, 3.0));
  return mesh;
}

Eigen::VectorXd expected_linear(const TetMesh4& flat) { return flat.V.col(3) / flat.time_scale; }

TEST(LaplaceStiffness, SymmetricWithZeroRowSums) {
  const TetMesh4 mesh = curved_slab(4, 5, 11);
  const SparseMatrixD K = cotangent_stiffness(mesh.V, mesh.T);
  ASSERT_EQ(K.rows(), mesh.V.rows());
  const Eigen::MatrixXd D = Eigen::MatrixXd(K);
  const double scale = D.cwiseAbs().maxCoeff();
  EXPECT_LE((D - D.transpose()).cwiseAbs().maxCoeff(), 1e-15 * scale);
  EXPECT_LE((K * Eigen::VectorXd::Ones(K.cols())).cwiseAbs().maxCoeff(), 1e-13 * scale);
  EXPECT_GT(D.diagonal().minCoeff(), 0.0);
  // Positive semidefinite with the constants as the only null direction (the mesh is connected).
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(D);
  EXPECT_GT(eigen.eigenvalues()(0), -1e-12 * scale);
  EXPECT_GT(eigen.eigenvalues()(1), 1e-6 * scale);
}

// What lets solve_harmonic tell its solver to skip the symmetry check (SolveOptions::symmetric_by_construction):
// the Dirichlet system's A is symmetric to the bit.
TEST(LaplaceStiffness, DirichletSystemIsExactlySymmetric) {
  TetMesh4 mesh = curved_slab(5, 4, 21);
  const DirichletSystem system = dirichlet_system(mesh);
  ASSERT_GT(system.A.rows(), 10);
  const SparseMatrixD transposed = system.A.transpose();
  ASSERT_EQ(system.A.nonZeros(), transposed.nonZeros());
  for (Eigen::Index j = 0; j < system.A.outerSize(); ++j) {
    SparseMatrixD::InnerIterator a(system.A, j), t(transposed, j);
    for (; a && t; ++a, ++t) {
      ASSERT_EQ(a.index(), t.index());
      ASSERT_EQ(a.value(), t.value()) << "(" << a.index() << ", " << j << ")";
    }
    ASSERT_FALSE(a || t);
  }
}

TEST(LaplaceStiffness, EqualsDenseSumOverTets) {
  const TetMesh4 mesh = curved_slab(3, 2, 5);
  Eigen::MatrixXd G;
  Eigen::VectorXd vol;
  barycentric_gradients(mesh.V, mesh.T, G, vol);
  ASSERT_EQ(G.rows(), 4 * mesh.T.rows());
  ASSERT_EQ(G.cols(), 4);
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(mesh.V.rows(), mesh.V.rows());
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    const Eigen::Matrix4d Gt = G.middleRows<4>(4 * t);  // row i: gradient of hat i
    const Eigen::Matrix4d Ke = vol(t) * Gt * Gt.transpose();
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) dense(mesh.T(t, i), mesh.T(t, j)) += Ke(i, j);
    }
  }
  const Eigen::MatrixXd K = Eigen::MatrixXd(cotangent_stiffness(mesh.V, mesh.T));
  EXPECT_LE((K - dense).cwiseAbs().maxCoeff(), 1e-13 * dense.cwiseAbs().maxCoeff());
}

TEST(LaplaceStiffness, BarycentricGradientsAreHatGradients) {
  const TetMesh4 mesh = curved_slab(2, 2, 7);
  Eigen::MatrixXd G;
  Eigen::VectorXd vol;
  barycentric_gradients(mesh.V, mesh.T, G, vol);
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    Eigen::Matrix<double, 4, 3> E;
    const Eigen::Vector4d v0 = mesh.V.row(mesh.T(t, 0)).transpose();
    for (int k = 0; k < 3; ++k) E.col(k) = mesh.V.row(mesh.T(t, k + 1)).transpose() - v0;
    // Volume independently: |cross4| is the 3-volume of the parallelepiped.
    EXPECT_NEAR(vol(t), cross4(E.col(0), E.col(1), E.col(2)).norm() / 6.0, 1e-14);
    const Eigen::Matrix<double, 4, 3> Q =
        Eigen::HouseholderQR<Eigen::Matrix<double, 4, 3>>(E).householderQ() * Eigen::Matrix<double, 4, 3>::Identity();
    for (int i = 0; i < 4; ++i) {
      const Eigen::Vector4d g = G.row(4 * t + i).transpose();
      EXPECT_LE((g - Q * (Q.transpose() * g)).norm(), 1e-10 * g.norm());  // lies in the hull
      for (int j = 1; j < 4; ++j) {
        // hat_i(v_j) - hat_i(v_0) = delta_ij - delta_i0
        const double expected = (i == j ? 1.0 : 0.0) - (i == 0 ? 1.0 : 0.0);
        EXPECT_NEAR(g.dot(E.col(j - 1)), expected, 1e-11);
      }
    }
  }
}

TEST(LaplaceStiffness, OffDiagonalIsCotangentWeight) {
  std::mt19937 rng(2024);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::MatrixXd V(4, 4);
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) V(r, c) = normal(rng);
    }
    TetIndices T(1, 4);
    T << 0, 1, 2, 3;
    const Eigen::MatrixXd K = Eigen::MatrixXd(cotangent_stiffness(V, T));

    // Independent route: orthonormal 3D coordinates of the hull, outward face normals by cross products.
    Eigen::Matrix<double, 4, 3> E;
    for (int k = 0; k < 3; ++k) E.col(k) = (V.row(k + 1) - V.row(0)).transpose();
    const Eigen::Matrix<double, 4, 3> Q =
        Eigen::HouseholderQR<Eigen::Matrix<double, 4, 3>>(E).householderQ() * Eigen::Matrix<double, 4, 3>::Identity();
    std::vector<Eigen::Vector3d> p(4);
    for (int m = 0; m < 4; ++m) p[static_cast<std::size_t>(m)] = Q.transpose() * (V.row(m) - V.row(0)).transpose();
    for (int i = 0; i < 4; ++i) {
      for (int j = i + 1; j < 4; ++j) {
        int kl[2], c = 0;
        for (int m = 0; m < 4; ++m) {
          if (m != i && m != j) kl[c++] = m;
        }
        const Eigen::Vector3d& pk = p[static_cast<std::size_t>(kl[0])];
        const Eigen::Vector3d& pl = p[static_cast<std::size_t>(kl[1])];
        const Eigen::Vector3d& pi = p[static_cast<std::size_t>(i)];
        const Eigen::Vector3d& pj = p[static_cast<std::size_t>(j)];
        Eigen::Vector3d n_i = (pl - pk).cross(pi - pk);  // face (k, l, i), outward = away from j
        if (n_i.dot(pj - pk) > 0.0) n_i = -n_i;
        Eigen::Vector3d n_j = (pl - pk).cross(pj - pk);  // face (k, l, j), outward = away from i
        if (n_j.dot(pi - pk) > 0.0) n_j = -n_j;
        const double theta = std::acos(-1.0) - std::acos(n_i.normalized().dot(n_j.normalized()));
        const double expected = -(pl - pk).norm() / (6.0 * std::tan(theta));
        EXPECT_NEAR(K(i, j), expected, 1e-10 * (1.0 + std::abs(expected))) << "trial " << trial << " edge " << i << j;
        EXPECT_EQ(K(i, j), K(j, i));
      }
    }
  }
}

TEST(LaplaceStiffness, DegenerateTetContributesNothing) {
  // Tet 0 is fine; tet 1 is flat (four coplanar points); tet 2 has a repeated vertex.
  Eigen::MatrixXd V(7, 4);
  V << 0, 0, 0, 0,  //
      1, 0, 0, 0,   //
      0, 1, 0, 0,   //
      0, 0, 0, 1,   //
      2, 2, 0, 0,   //
      3, 2, 0, 0,   //
      2, 3, 0, 0;
  TetIndices T(3, 4);
  T << 0, 1, 2, 3,  //
      4, 5, 6, 1,   // z = 0 and tau = 0 for all four: a flat quad
      0, 1, 1, 3;
  Eigen::MatrixXd G;
  Eigen::VectorXd vol;
  barycentric_gradients(V, T, G, vol);
  EXPECT_GT(vol(0), 0.0);
  EXPECT_EQ(vol(1), 0.0);
  EXPECT_EQ(vol(2), 0.0);
  EXPECT_TRUE(G.allFinite());
  EXPECT_EQ(G.bottomRows(8).cwiseAbs().maxCoeff(), 0.0);
  const SparseMatrixD K = cotangent_stiffness(V, T);
  const SparseMatrixD K_good = cotangent_stiffness(V, T.topRows(1));
  EXPECT_EQ(Eigen::MatrixXd(K), Eigen::MatrixXd(K_good));
}

TEST(LaplaceStiffness, RejectsBadIndices) {
  Eigen::MatrixXd V = Eigen::MatrixXd::Zero(3, 4);
  TetIndices T(1, 4);
  T << 0, 1, 2, 3;
  EXPECT_THROW(cotangent_stiffness(V, T), InvalidInput);
  // A V with other than 4 columns no longer compiles: Points4 fixes the column count.
}

class LaplaceHarmonic : public ::testing::TestWithParam<std::string> {
 protected:
  LaplaceOptions options() const {
    LaplaceOptions o;
    o.solver = GetParam();
    o.solve.tolerance = 1e-12;
    // Gauss-Seidel has no residual test: converge it to rounding level instead.
    o.solve.change_threshold = 1e-16;
    o.solve.max_iterations = 100000;
    return o;
  }
};

TEST_P(LaplaceHarmonic, SlabIsLinearInTau) {
  const TetMesh4 flat = test::make_slab_mesh(5, 6, 2.5);
  const Eigen::VectorXd expected = expected_linear(flat);
  TetMesh4 rotated = flat;  // same labels and expected values, new hulls
  test::transform_embedding(rotated, test::random_rotation(3), Eigen::Vector4d(1.0, 2.0, 3.0, 4.0));
  for (const TetMesh4* mesh : {&flat, static_cast<const TetMesh4*>(&rotated)}) {
    LaplaceOptions o = options();
    o.warm_start = false;  // else CG would start from the answer on the flat slab
    const LaplaceResult result = solve_harmonic(*mesh, o);
    ASSERT_EQ(result.s.size(), mesh->V.rows());
    EXPECT_LT((result.s - expected).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_EQ(result.unknowns, 6 * 6 * 5);
    EXPECT_EQ(result.floating_components, 0);
    EXPECT_EQ(result.floating_vertices, 0);
    EXPECT_EQ(result.degenerate_tets, 0);
    if (GetParam() == "auto") {
      EXPECT_TRUE(result.report.backend == "cholmod" || result.report.backend == "cg" ||
                  result.report.backend == "cg-ic" || result.report.backend == "cg-amg")
          << result.report.backend;
    } else {
      EXPECT_EQ(result.report.backend, GetParam());
    }
    EXPECT_LE(result.report.residual, 1e-12);
    EXPECT_GE(result.seconds, result.assemble_seconds);
  }
}

// The slab [0,1]^2 x [0,1] and, far from it, a box spanning t in [0.3, 0.6] with no A or B vertex.
TetMesh4 floating_box() {
  test::BoxSpec spec;
  spec.nx = spec.ny = 2;
  spec.nz = 3;
  spec.height = 0.3;
  spec.origin = Eigen::Vector4d(5.0, 0.0, 0.0, 0.3);
  spec.flag_ends = false;
  return test::make_box_mesh(spec);
}

TEST_P(LaplaceHarmonic, FloatingComponentIsDetected) {
  const TetMesh4 slab = test::make_slab_mesh(3, 4);
  const TetMesh4 box = floating_box();
  const TetMesh4 mesh = test::merge_meshes(slab, box);
  const LaplaceResult result = solve_harmonic(mesh, options());
  EXPECT_EQ(result.floating_components, 1);
  EXPECT_EQ(result.floating_vertices, box.V.rows());
  EXPECT_EQ(result.unknowns, 4 * 4 * 3);
  const Eigen::Index vs = slab.V.rows();
  EXPECT_LT((result.s.head(vs) - expected_linear(slab)).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((result.s.tail(box.V.rows()).array() - 0.45).abs().maxCoeff(), 1e-12);
}

TEST_P(LaplaceHarmonic, OneSidedComponentIsConstant) {
  // A component that touches only A (it vanishes mid-morph) gets s = 0 throughout.
  const TetMesh4 slab = test::make_slab_mesh(3, 3);
  test::BoxSpec spec;
  spec.nz = 2;
  spec.height = 0.4;
  spec.origin = Eigen::Vector4d(-4.0, 0.0, 0.0, 0.0);
  spec.flag_ends = false;
  TetMesh4 box = test::make_box_mesh(spec);
  for (Eigen::Index i = 0; i < box.V.rows(); ++i) {
    if (box.V(i, 3) == 0.0) box.side[static_cast<std::size_t>(i)] = VertexSide::A;
  }
  const TetMesh4 mesh = test::merge_meshes(slab, box);
  const LaplaceResult result = solve_harmonic(mesh, options());
  EXPECT_EQ(result.floating_components, 0);
  EXPECT_LT(result.s.tail(box.V.rows()).cwiseAbs().maxCoeff(), 1e-10);
  EXPECT_LT((result.s.head(slab.V.rows()) - expected_linear(slab)).cwiseAbs().maxCoeff(), 1e-9);
}

TEST_P(LaplaceHarmonic, DegenerateTetIsSkipped) {
  TetMesh4 mesh = test::make_slab_mesh(3, 3);
  const Eigen::VectorXd expected = expected_linear(mesh);
  // Four coplanar interior vertices of the layer k = 1 (ids (k * 4 + j) * 4 + i).
  mesh.T.conservativeResize(mesh.T.rows() + 1, 4);
  mesh.T.bottomRows(1) << 16, 17, 20, 21;
  mesh.source_cell.push_back(0);
  const LaplaceResult result = solve_harmonic(mesh, options());
  EXPECT_EQ(result.degenerate_tets, 1);
  EXPECT_LT((result.s - expected).cwiseAbs().maxCoeff(), 1e-9);
}

// The components the stage found are the census's when no tet was left out: with a floating box, its labels are
// component_labels' over every tet; with a degenerate tet (whose vertices then may split off) they are those of the
// tets with stiffness.
TEST(LaplaceComponents, RootsAreTheComponentLabelsOfTheTetsWithStiffness) {
  const TetMesh4 slab = test::make_slab_mesh(3, 4);
  const TetMesh4 mesh = test::merge_meshes(slab, floating_box());
  const LaplaceResult result = solve_harmonic(mesh, LaplaceOptions{});
  ASSERT_EQ(result.degenerate_tets, 0);
  EXPECT_EQ(result.component_root, component_labels(mesh.T, mesh.vertex_count()));
  EXPECT_EQ(result.component_root[std::size_t(slab.V.rows())], slab.V.rows());  // the box's smallest vertex

  TetMesh4 flat = test::make_slab_mesh(3, 3);
  flat.V.conservativeResize(flat.V.rows() + 1, 4);
  flat.V.bottomRows(1) = flat.V.row(16);  // a vertex on a flat tet only
  flat.side.push_back(VertexSide::Interior);
  flat.T.conservativeResize(flat.T.rows() + 1, 4);
  flat.T.bottomRows(1) << 16, 17, 20, int(flat.V.rows() - 1);
  flat.source_cell.push_back(0);
  const LaplaceResult degenerate = solve_harmonic(flat, LaplaceOptions{});
  ASSERT_EQ(degenerate.degenerate_tets, 1);
  std::vector<std::uint8_t> keep(std::size_t(flat.T.rows()), 1);
  keep.back() = 0;
  EXPECT_EQ(degenerate.component_root, component_labels(flat.T, flat.vertex_count(), &keep));
  EXPECT_NE(degenerate.component_root, component_labels(flat.T, flat.vertex_count()));
}

INSTANTIATE_TEST_SUITE_P(LaplaceBackends, LaplaceHarmonic, ::testing::ValuesIn(solver_names()),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

TEST(LaplaceHarmonicCompare, EveryBackendAgreesWithCholmod) {
  const TetMesh4 mesh = curved_slab(7, 7, 21);
  LaplaceOptions options;
  options.solver = "cholmod";
  const LaplaceResult direct = solve_harmonic(mesh, options);
  ASSERT_EQ(direct.unknowns, 8 * 8 * 6);
  const double scale = direct.s.cwiseAbs().maxCoeff();
  for (const std::string& backend : solver_names()) {
    options.solver = backend;
    options.solve.tolerance = 1e-12;
    options.solve.change_threshold = 1e-16;
    options.solve.max_iterations = 100000;
    const LaplaceResult result = solve_harmonic(mesh, options);
    EXPECT_LE((result.s - direct.s).cwiseAbs().maxCoeff(), 1e-8 * scale) << backend;
    EXPECT_GT(result.report.memory_bytes, 0) << backend;
    if (backend == "gauss-seidel") {
      EXPECT_LT(result.report.change, 1e-16);
      EXPECT_LE(result.report.residual, 1e-11);
    } else {
      EXPECT_LE(result.report.residual, 1e-12) << backend;
    }
  }
}

TEST(LaplaceHarmonicCompare, GaussSeidelDiffusionFromTime) {
  // The paper's diffusion: sweeps from s = t. On the bent slab s = t is not harmonic, so sweeps change it, by
  // less and less; at Table II's threshold it is close to the harmonic field but not at rounding level.
  const TetMesh4 mesh = curved_slab(7, 7, 21);
  LaplaceOptions options;
  options.solver = "cholmod";
  const LaplaceResult direct = solve_harmonic(mesh, options);
  options.solver = "gauss-seidel";
  std::vector<double> change;
  for (int sweeps : {1, 10}) {
    options.solve.max_iterations = sweeps;
    const LaplaceResult result = solve_harmonic(mesh, options);
    EXPECT_EQ(result.report.iterations, sweeps);
    change.push_back(result.report.change);
  }
  EXPECT_GT(change[0], change[1]);
  options.solve.max_iterations = 100000;
  const LaplaceResult converged = solve_harmonic(mesh, options);  // default threshold 1e-5
  EXPECT_LT(converged.report.change, 1e-5);
  EXPECT_GT(converged.report.iterations, 10);
  EXPECT_LT((converged.s - direct.s).cwiseAbs().maxCoeff(), 1e-2);
  EXPECT_GT(converged.report.residual, 1e-12);
}

TEST(LaplaceHarmonicCompare, GaussSeidelWarmStartsFromTime) {
  // On the flat slab s = t exactly: from it the first sweep changes nothing measurable and stops.
  const TetMesh4 mesh = test::make_slab_mesh(4, 4);
  LaplaceOptions options;
  options.solver = "gauss-seidel";
  const LaplaceResult warm = solve_harmonic(mesh, options);
  EXPECT_EQ(warm.report.iterations, 1);
  EXPECT_LT(warm.report.change, 1e-15 * double(warm.unknowns));  // the total change: rounding in every unknown
  options.warm_start = false;
  EXPECT_GT(solve_harmonic(mesh, options).report.iterations, 10);
}

TEST(LaplaceDirichletSystem, MatchesSolveHarmonic) {
  const TetMesh4 mesh = curved_slab(5, 4, 8);
  const DirichletSystem system = dirichlet_system(mesh);
  LaplaceOptions options;
  options.solver = "cholmod";
  const LaplaceResult result = solve_harmonic(mesh, options);
  ASSERT_EQ(system.A.rows(), result.unknowns);
  ASSERT_EQ(system.A.cols(), result.unknowns);
  ASSERT_EQ(system.b.size(), result.unknowns);
  ASSERT_EQ(static_cast<Eigen::Index>(system.unknown.size()), mesh.V.rows());
  Eigen::VectorXd x(result.unknowns);
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    const int u = system.unknown[static_cast<std::size_t>(i)];
    EXPECT_EQ(u >= 0, mesh.side[static_cast<std::size_t>(i)] == VertexSide::Interior);
    if (u < 0) {
      EXPECT_EQ(system.s(i), result.s(i));
      continue;
    }
    x(u) = result.s(i);
    EXPECT_EQ(system.x0(u), mesh.time_of(i));
  }
  EXPECT_LE((system.A * x - system.b).norm(), 1e-12 * system.b.norm());
  EXPECT_EQ(system.degenerate_tets, result.degenerate_tets);
  EXPECT_EQ(system.floating_components, 0);
}

TEST(LaplaceHarmonicCompare, CholmodAndCgAgreeOnCurvedMesh) {
  const TetMesh4 mesh = curved_slab(8, 8, 99);
  LaplaceOptions options;
  options.solver = "cholmod";
  const LaplaceResult direct = solve_harmonic(mesh, options);
  options.solver = "cg";
  options.solve.tolerance = 1e-12;
  const LaplaceResult iterative = solve_harmonic(mesh, options);
  EXPECT_EQ(direct.unknowns, 9 * 9 * 7);
  EXPECT_LT((direct.s - iterative.s).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_GT(iterative.report.iterations, 1);
  // Bent, the solution is no longer t: the test would pass trivially otherwise.
  Eigen::VectorXd t(mesh.V.rows());
  for (Eigen::Index i = 0; i < t.size(); ++i) t(i) = static_cast<double>(i / 81) / 8.0;
  EXPECT_GT((direct.s - t).cwiseAbs().maxCoeff(), 1e-4);
}

TEST(LaplaceHarmonicCompare, CgIndependentOfThreadCount) {
  const TetMesh4 mesh = curved_slab(24, 24, 4);
  LaplaceOptions options;
  options.solver = "cg";
  std::vector<Eigen::VectorXd> s;
  for (int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    s.push_back(solve_harmonic(mesh, options).s);
  }
  EXPECT_EQ(std::memcmp(s[0].data(), s[1].data(), sizeof(double) * static_cast<std::size_t>(s[0].size())), 0);
}

TEST(LaplaceHarmonicCompare, WarmStartFromExactTime) {
  // On the flat slab s = t exactly, so a warm start is already converged.
  const TetMesh4 mesh = test::make_slab_mesh(4, 4);
  LaplaceOptions options;
  options.solver = "cg";
  EXPECT_EQ(solve_harmonic(mesh, options).report.iterations, 0);
  options.warm_start = false;
  // From zero too: s = t is piecewise linear in t between the time levels, so the deflation's coarse solve alone
  // finds it. Without deflation CG has to iterate.
  const LaplaceResult cold = solve_harmonic(mesh, options);
  EXPECT_EQ(cold.report.iterations, 0);
  EXPECT_LT((cold.s - expected_linear(mesh)).cwiseAbs().maxCoeff(), 1e-12);
  options.deflation_cell_voxels = 0.0;
  EXPECT_GT(solve_harmonic(mesh, options).report.iterations, 0);
}

/// A slab bent out of its hyperplane whose cells are `stretch` times longer in tau than wide, as the pipeline's
/// (c = 2 * box makes them about 13 times longer).
TetMesh4 stretched_slab(int n, int nz, double stretch, unsigned seed) {
  test::BoxSpec spec;
  spec.nx = spec.ny = n;
  spec.nz = nz;
  spec.height = stretch * nz / n;
  TetMesh4 mesh = test::make_box_mesh(spec);
  test::perturb_interior(mesh, 0.3 / n, seed);
  return mesh;
}

TEST(LaplaceDeflation, SpaceTimeCellsAreIndependentHatsInTime) {
  const TetMesh4 mesh = stretched_slab(24, 6, 12.0, 3);
  const DirichletSystem system = dirichlet_system(mesh);
  const int unknowns = int(system.A.rows());
  const DeflationSpace space = space_time_cells(mesh, system.unknown, unknowns, 6.0);
  // 4 x 4 cells of 6 voxels (the 25th vertex column starts a fifth) and hats at the 7 time levels, minus those
  // with no unknown in their support (the end levels' cells hold unknowns only on one side of them).
  ASSERT_GT(space.columns, 16 * 5);
  ASSERT_EQ(space.column.rows(), unknowns);
  Eigen::MatrixXd Z = Eigen::MatrixXd::Zero(unknowns, space.columns);
  for (int i = 0; i < unknowns; ++i) {
    double sum = 0.0;
    for (int e = 0; e < 2; ++e) {
      if (space.column(i, e) < 0) continue;
      EXPECT_GT(space.weight(i, e), 0.0);
      Z(i, space.column(i, e)) += space.weight(i, e);
      sum += space.weight(i, e);
    }
    // Hats in time sum to one, less the weight of a hat left out.
    EXPECT_GT(sum, 0.0) << i;
    EXPECT_LE(sum, 1.0 + 1e-12) << i;
  }
  // Independent columns: Z^T Z is positive definite.
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(Z.transpose() * Z);
  EXPECT_GT(eigen.eigenvalues()(0), 0.5);
  // Off: no columns.
  EXPECT_EQ(space_time_cells(mesh, system.unknown, unknowns, 0.0).columns, 0);
  // Capped: cells grow by 1.5 until the space fits (6 voxels: 4 x 4 cells, more than 60 columns; 9 voxels: 3 x 3).
  const DeflationSpace capped = space_time_cells(mesh, system.unknown, unknowns, 6.0, 60);
  EXPECT_LE(capped.columns, 60);
  EXPECT_EQ(capped.columns, space_time_cells(mesh, system.unknown, unknowns, 9.0).columns);
  EXPECT_LT(capped.columns, space.columns);
}

TEST(LaplaceDeflation, CellsSplitIntoTheirConnectedParts) {
  // Two parallel slabs half a voxel apart share every cell; with the couplings each cell gets one set of hats per
  // slab, every column's support within one slab, and a connected slab's space is the same with or without them.
  const TetMesh4 a = test::make_slab_mesh(12, 4);
  TetMesh4 b = a;
  b.V.col(2).array() += 0.5 * a.voxel_size;
  const TetMesh4 sheets = test::merge_meshes(a, b);
  const DirichletSystem one = dirichlet_system(a), two = dirichlet_system(sheets);
  const int n1 = int(one.A.rows()), n2 = int(two.A.rows());
  const DeflationSpace single = space_time_cells(a, one.unknown, n1, 6.0);
  const DeflationSpace single_split = space_time_cells(a, one.unknown, n1, 6.0, kMaxDeflationColumns, &one.A);
  ASSERT_GT(single.columns, 0);
  EXPECT_EQ(single_split.columns, single.columns);
  EXPECT_EQ(single_split.column, single.column);
  EXPECT_EQ(single_split.weight, single.weight);
  const DeflationSpace merged = space_time_cells(sheets, two.unknown, n2, 6.0);
  const DeflationSpace split = space_time_cells(sheets, two.unknown, n2, 6.0, kMaxDeflationColumns, &two.A);
  EXPECT_EQ(merged.columns, single.columns);
  EXPECT_EQ(split.columns, 2 * single.columns);
  // The slab each column's unknowns come from: b's vertices follow a's.
  std::vector<int> slab_of_column(std::size_t(split.columns), -1);
  for (Eigen::Index v = 0; v < sheets.V.rows(); ++v) {
    const int u = two.unknown[std::size_t(v)];
    if (u < 0) continue;
    const int slab = v < a.V.rows() ? 0 : 1;
    for (int e = 0; e < 2; ++e) {
      const int c = split.column(u, e);
      if (c < 0) continue;
      if (slab_of_column[std::size_t(c)] < 0) slab_of_column[std::size_t(c)] = slab;
      EXPECT_EQ(slab_of_column[std::size_t(c)], slab) << "column " << c << " spans both slabs";
    }
  }
  EXPECT_THROW(space_time_cells(sheets, two.unknown, n2, 6.0, kMaxDeflationColumns, &one.A), InvalidInput);
}

TEST(LaplaceDeflation, CellWithFewUnknownsKeepsIndependentHats) {
  // One cell, three unknowns at t = 0.3, 0.3 and 0.35 of a 1-interval morph: the hats of levels 0 and 1 both
  // reach them. Kept by Schoenberg-Whitney: hat 0 takes t = 0.3, hat 1 needs a later t, 0.35 (0.3 again would make
  // the two columns dependent on the first two rows alone, but the third separates them). With the unknowns at
  // 0.3 only, the two columns would be proportional, so one hat is dropped.
  TetMesh4 mesh;
  mesh.V = Points4::Zero(3, 4);
  mesh.V(0, 3) = 0.3;
  mesh.V(1, 3) = 0.3;
  mesh.V(2, 3) = 0.35;
  mesh.time_scale = 1.0;
  mesh.voxel_size = 1.0;
  mesh.time_steps = 1;
  DeflationSpace space = space_time_cells(mesh, {0, 1, 2}, 3, 4.0);
  EXPECT_EQ(space.columns, 2);
  mesh.V(2, 3) = 0.3;
  space = space_time_cells(mesh, {0, 1, 2}, 3, 4.0);
  EXPECT_EQ(space.columns, 1);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(space.column(i, 0), 0);
    EXPECT_DOUBLE_EQ(space.weight(i, 0), 0.7);  // hat 0 at t = 0.3; hat 1 was dropped
    EXPECT_EQ(space.column(i, 1), -1);
  }
}

TEST(LaplaceDeflation, KeepsTheSolutionAndCutsIterations) {
  const TetMesh4 mesh = stretched_slab(24, 6, 12.0, 3);
  LaplaceOptions options;
  options.solver = "cholmod";
  const LaplaceResult direct = solve_harmonic(mesh, options);
  for (const std::string backend : {"cg", "cg-amg"}) {
    options.solver = backend;
    options.deflation_cell_voxels = 0.0;
    const LaplaceResult plain = solve_harmonic(mesh, options);
    options.deflation_cell_voxels = 6.0;
    const LaplaceResult deflated = solve_harmonic(mesh, options);
    EXPECT_EQ(plain.report.deflation_columns, 0) << backend;
    EXPECT_GT(deflated.report.deflation_columns, 0) << backend;
    EXPECT_NE(deflated.report.detail.find("deflated by "), std::string::npos) << deflated.report.detail;
    EXPECT_LE(deflated.report.residual, 1e-8) << backend;
    EXPECT_LT((deflated.s - direct.s).cwiseAbs().maxCoeff(), 1e-6) << backend;
    // Measured: cg 79 -> 30, cg-amg 22 -> 16 iterations.
    EXPECT_LT((backend == std::string("cg") ? 2 : 1) * deflated.report.iterations, plain.report.iterations)
        << backend << ": " << deflated.report.iterations << " against " << plain.report.iterations;
  }
}

TEST(LaplaceHarmonicCompare, RejectsBadInput) {
  TetMesh4 mesh = test::make_slab_mesh(2, 2);
  LaplaceOptions options;
  options.solver = "lu";
  try {
    solve_harmonic(mesh, options);
    FAIL() << "expected InvalidInput";
  } catch (const InvalidInput& e) {
    EXPECT_STREQ(e.what(), "unknown solver 'lu' (choose cholmod, cg, cg-ic, cg-amg, gauss-seidel, ldlt, auto)");
  }
  options.solver = "cholmod";
  mesh.side.pop_back();
  EXPECT_THROW(solve_harmonic(mesh, options), InvalidInput);
}

}  // namespace
}  // namespace morphmap
