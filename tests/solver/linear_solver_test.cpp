// Tests of the SPD solver backends used for the Laplace system (paper §6.1).
#include "solver/linear_solver.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "mesh/errors.h"
#include "solver/laplace.h"
#include "tests/solver/test_meshes.h"

namespace morphmap {
namespace {

SparseMatrixD from_triplets(int n, const std::vector<Eigen::Triplet<double, int>>& triplets) {
  SparseMatrixD A(n, n);
  A.setFromTriplets(triplets.begin(), triplets.end());
  return A;
}

/// 1D Dirichlet Laplacian plus a shift: SPD with a known condition.
SparseMatrixD path_laplacian(int n, double shift) {
  std::vector<Eigen::Triplet<double, int>> triplets;
  for (int i = 0; i < n; ++i) {
    triplets.emplace_back(i, i, 2.0 + shift);
    if (i + 1 < n) {
      triplets.emplace_back(i, i + 1, -1.0);
      triplets.emplace_back(i + 1, i, -1.0);
    }
  }
  return from_triplets(n, triplets);
}

/// Interior block of the slab's stiffness: a real 3D-mesh system of a few thousand unknowns.
SparseMatrixD slab_system(int n, int nz) {
  const TetMesh4 mesh = test::make_slab_mesh(n, nz);
  const SparseMatrixD K = cotangent_stiffness(mesh.V, mesh.T);
  std::vector<int> index(static_cast<std::size_t>(mesh.V.rows()), -1);
  int unknowns = 0;
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    if (mesh.side[static_cast<std::size_t>(i)] == VertexSide::Interior) index[static_cast<std::size_t>(i)] = unknowns++;
  }
  std::vector<Eigen::Triplet<double, int>> triplets;
  for (Eigen::Index j = 0; j < K.outerSize(); ++j) {
    for (SparseMatrixD::InnerIterator it(K, j); it; ++it) {
      const int r = index[static_cast<std::size_t>(it.row())];
      const int c = index[static_cast<std::size_t>(j)];
      if (r >= 0 && c >= 0) triplets.emplace_back(r, c, it.value());
    }
  }
  return from_triplets(unknowns, triplets);
}

std::string error_of(const std::string& backend, const SparseMatrixD& A) {
  auto solver = make_solver(backend);
  try {
    solver->compute(A);
  } catch (const SolverError& e) {
    return e.what();
  }
  return "";
}

class LinearSolverBackend : public ::testing::TestWithParam<std::string> {};

TEST_P(LinearSolverBackend, SolvesSmallSystem) {
  const SparseMatrixD A = path_laplacian(50, 0.1);
  Eigen::VectorXd expected(50);
  for (int i = 0; i < 50; ++i) expected(i) = std::sin(0.3 * i) + 0.01 * i;
  const Eigen::VectorXd b = A * expected;
  auto solver = make_solver(GetParam());
  EXPECT_EQ(solver->name(), GetParam());
  solver->compute(A);
  Eigen::VectorXd x;
  const SolveReport report = solver->solve(b, x);
  EXPECT_EQ(report.backend, GetParam());
  EXPECT_LT((x - expected).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LE(report.residual, 1e-10);
  EXPECT_NEAR(report.residual, (b - A * x).norm() / b.norm(), 1e-15);
  EXPECT_GE(report.iterations, 1);

  // The factorisation (or preconditioner) is reused for a second right-hand side.
  const Eigen::VectorXd b2 = A * Eigen::VectorXd::Ones(50);
  solver->solve(b2, x);
  EXPECT_LT((x - Eigen::VectorXd::Ones(50)).cwiseAbs().maxCoeff(), 1e-8);
}

TEST_P(LinearSolverBackend, SolvesMeshSystem) {
  const SparseMatrixD A = slab_system(8, 8);
  Eigen::VectorXd expected = Eigen::VectorXd::LinSpaced(A.rows(), -1.0, 2.0);
  const Eigen::VectorXd b = A * expected;
  auto solver = make_solver(GetParam(), SolveOptions{1e-12, 20000});
  solver->compute(A);
  Eigen::VectorXd x;
  const SolveReport report = solver->solve(b, x);
  EXPECT_LE(report.residual, 1e-12);
  EXPECT_LT((x - expected).cwiseAbs().maxCoeff(), 1e-9);
}

TEST_P(LinearSolverBackend, ZeroRightHandSideGivesZero) {
  auto solver = make_solver(GetParam());
  solver->compute(path_laplacian(10, 0.0));
  Eigen::VectorXd x = Eigen::VectorXd::Constant(10, 3.0);
  const SolveReport report = solver->solve(Eigen::VectorXd::Zero(10), x);
  EXPECT_EQ(x.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(report.residual, 0.0);
}

TEST_P(LinearSolverBackend, RejectsBadInput) {
  const std::string backend = GetParam();
  const std::string prefix = backend + ": ";

  SparseMatrixD rectangular(3, 4);
  EXPECT_EQ(error_of(backend, rectangular).rfind(prefix + "matrix is not square", 0), 0u);

  SparseMatrixD asymmetric = path_laplacian(5, 0.0);
  asymmetric.coeffRef(1, 2) = -0.5;
  EXPECT_EQ(error_of(backend, asymmetric), prefix + "matrix is not symmetric (column 1, tolerance 2e-12)");

  SparseMatrixD infinite = path_laplacian(5, 0.0);
  infinite.coeffRef(3, 3) = std::numeric_limits<double>::infinity();
  EXPECT_EQ(error_of(backend, infinite), prefix + "matrix has a non-finite entry at (3, 3)");

  SparseMatrixD negative_diagonal = path_laplacian(5, 0.0);
  negative_diagonal.coeffRef(4, 4) = -1.0;
  EXPECT_EQ(error_of(backend, negative_diagonal), prefix + "matrix has a non-positive diagonal entry (column 4)");

  SparseMatrixD missing_diagonal = from_triplets(2, {{0, 0, 1.0}, {0, 1, 0.5}, {1, 0, 0.5}});
  EXPECT_EQ(error_of(backend, missing_diagonal), prefix + "matrix has a non-positive diagonal entry (column 1)");

  auto solver = make_solver(backend);
  Eigen::VectorXd x;
  EXPECT_THROW(solver->solve(Eigen::VectorXd::Ones(3), x), SolverError);  // before compute
  solver->compute(path_laplacian(4, 0.0));
  EXPECT_THROW(solver->solve(Eigen::VectorXd::Ones(3), x), SolverError);  // wrong size
}

TEST_P(LinearSolverBackend, EmptySystem) {
  auto solver = make_solver(GetParam());
  solver->compute(SparseMatrixD(0, 0));
  Eigen::VectorXd x;
  solver->solve(Eigen::VectorXd(), x);
  EXPECT_EQ(x.size(), 0);
}

INSTANTIATE_TEST_SUITE_P(LinearSolverBackends, LinearSolverBackend, ::testing::Values("cholmod", "cg"),
                         [](const ::testing::TestParamInfo<std::string>& info) { return info.param; });

TEST(LinearSolver, NamesAndUnknownName) {
  EXPECT_EQ(solver_names(), (std::vector<std::string>{"cholmod", "cg"}));
  for (const auto& name : solver_names()) EXPECT_EQ(make_solver(name)->name(), name);
  try {
    make_solver("x");
    FAIL() << "expected InvalidInput";
  } catch (const InvalidInput& e) {
    EXPECT_STREQ(e.what(), "unknown solver 'x' (choose cholmod, cg)");
  }
}

TEST(LinearSolver, CholmodReportsIndefiniteColumn) {
  // Positive diagonal, symmetric, but eigenvalues 3 and -1: the second pivot is 1 - 4 < 0.
  const SparseMatrixD A = from_triplets(3, {{0, 0, 4.0}, {1, 1, 1.0}, {2, 2, 1.0}, {0, 1, 4.0}, {1, 0, 4.0}});
  // The failing pivot is 0 or 1 depending on CHOLMOD's ordering; column 2 is fine in any order.
  const std::string message = error_of("cholmod", A);
  EXPECT_TRUE(message == "cholmod: matrix is not positive definite (column 0)" ||
              message == "cholmod: matrix is not positive definite (column 1)")
      << message;
}

TEST(LinearSolver, CgDetectsIndefiniteMatrix) {
  const SparseMatrixD A = from_triplets(2, {{0, 0, 1.0}, {1, 1, 1.0}, {0, 1, 2.0}, {1, 0, 2.0}});
  auto solver = make_solver("cg");
  solver->compute(A);
  Eigen::VectorXd x;
  EXPECT_THROW(solver->solve(Eigen::Vector2d(1.0, -1.0), x), SolverError);
}

TEST(LinearSolver, CgThrowsWithoutConvergence) {
  const SparseMatrixD A = path_laplacian(400, 0.0);
  auto solver = make_solver("cg", SolveOptions{1e-10, 5});
  solver->compute(A);
  Eigen::VectorXd x;
  try {
    solver->solve(Eigen::VectorXd::Ones(400), x);
    FAIL() << "expected SolverError";
  } catch (const SolverError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("cg: no convergence after 5 iterations", 0), 0u) << e.what();
  }
}

TEST(LinearSolver, CgWarmStartFromSolutionTakesNoIteration) {
  const SparseMatrixD A = path_laplacian(30, 0.5);
  const Eigen::VectorXd expected = Eigen::VectorXd::LinSpaced(30, 0.0, 1.0);
  auto solver = make_solver("cg");
  solver->compute(A);
  Eigen::VectorXd x = expected;
  const SolveReport report = solver->solve(A * expected, x);
  EXPECT_EQ(report.iterations, 0);
  EXPECT_EQ(x, expected);

  // A nearby start converges in fewer iterations than a cold one.
  Eigen::VectorXd cold;
  const int cold_iterations = solver->solve(A * expected, cold).iterations;
  Eigen::VectorXd warm = expected + 1e-6 * Eigen::VectorXd::Ones(30);
  EXPECT_LT(solver->solve(A * expected, warm).iterations, cold_iterations);
}

TEST(LinearSolver, CgBitwiseIndependentOfThreadCount) {
  // Big enough for several row blocks, so a thread-count-dependent reduction would show.
  const SparseMatrixD A = slab_system(22, 22);
  ASSERT_GT(A.rows(), 2 * 4096);
  Eigen::VectorXd b(A.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i) b(i) = std::cos(0.37 * static_cast<double>(i));
  std::vector<Eigen::VectorXd> solutions;
  std::vector<int> iterations;
  for (int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    auto solver = make_solver("cg");
    solver->compute(A);
    Eigen::VectorXd x;
    iterations.push_back(solver->solve(b, x).iterations);
    solutions.push_back(x);
  }
  EXPECT_EQ(iterations[0], iterations[1]);
  ASSERT_EQ(solutions[0].size(), solutions[1].size());
  EXPECT_EQ(std::memcmp(solutions[0].data(), solutions[1].data(), sizeof(double) * solutions[0].size()), 0);
}

}  // namespace
}  // namespace morphmap
