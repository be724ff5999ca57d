// Tests of the SPD solver backends used for the Laplace system (paper §6.1, Tables I and II).
#include "solver/linear_solver.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
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

/// Options under which `backend` solves to `tolerance`: Gauss-Seidel has no residual test, so it gets a change
/// threshold at rounding level and enough sweeps to reach it on these small systems.
SolveOptions options_for(const std::string& backend, double tolerance = 1e-10) {
  SolveOptions options;
  options.tolerance = tolerance;
  if (backend == "gauss-seidel") {
    options.change_threshold = 1e-16;
    options.max_iterations = 100000;
  }
  return options;
}

bool is_auto_choice(const std::string& backend) {
  return backend == "cholmod" || backend == "cg" || backend == "cg-ic" || backend == "cg-amg";
}

/// What a report should name: the backend itself, or for auto one of its candidates.
void expect_backend(const SolveReport& report, const std::string& backend) {
  if (backend == "auto") {
    EXPECT_TRUE(is_auto_choice(report.backend)) << report.backend;
    EXPECT_EQ(report.detail.rfind("auto: ", 0), 0u) << report.detail;
  } else {
    EXPECT_EQ(report.backend, backend);
  }
}

class LinearSolverBackend : public ::testing::TestWithParam<std::string> {};

TEST_P(LinearSolverBackend, SolvesSmallSystem) {
  const SparseMatrixD A = path_laplacian(50, 0.1);
  Eigen::VectorXd expected(50);
  for (int i = 0; i < 50; ++i) expected(i) = std::sin(0.3 * i) + 0.01 * i;
  const Eigen::VectorXd b = A * expected;
  auto solver = make_solver(GetParam(), options_for(GetParam()));
  EXPECT_EQ(solver->name(), GetParam());
  solver->compute(A);
  Eigen::VectorXd x;
  const SolveReport report = solver->solve(b, x);
  expect_backend(report, GetParam());
  EXPECT_LT((x - expected).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LE(report.residual, 1e-10);
  EXPECT_NEAR(report.residual, (b - A * x).norm() / b.norm(), 1e-15);
  EXPECT_GE(report.iterations, 1);
  EXPECT_GT(report.memory_bytes, 0);
  EXPECT_GE(report.setup_seconds, 0.0);
  EXPECT_GE(report.solve_seconds, 0.0);

  // The factorisation (or preconditioner) is reused for a second right-hand side.
  const Eigen::VectorXd b2 = A * Eigen::VectorXd::Ones(50);
  solver->solve(b2, x);
  EXPECT_LT((x - Eigen::VectorXd::Ones(50)).cwiseAbs().maxCoeff(), 1e-8);
}

TEST_P(LinearSolverBackend, SolvesMeshSystem) {
  const SparseMatrixD A = slab_system(8, 8);
  Eigen::VectorXd expected = Eigen::VectorXd::LinSpaced(A.rows(), -1.0, 2.0);
  const Eigen::VectorXd b = A * expected;
  auto solver = make_solver(GetParam(), options_for(GetParam(), 1e-12));
  solver->compute(A);
  Eigen::VectorXd x;
  const SolveReport report = solver->solve(b, x);
  EXPECT_LE(report.residual, 1e-12);
  EXPECT_LT((x - expected).cwiseAbs().maxCoeff(), 1e-9);
}

// compute(SparseMatrixD&&) takes the matrix's storage (the caller's A is left empty) and solves exactly as compute
// on a copy does.
TEST_P(LinearSolverBackend, TakesAMovedMatrix) {
  const SparseMatrixD A = slab_system(6, 6);
  const Eigen::VectorXd b = A * Eigen::VectorXd::LinSpaced(A.rows(), -1.0, 2.0);
  auto copied = make_solver(GetParam(), options_for(GetParam()));
  copied->compute(A);
  Eigen::VectorXd x_copied;
  copied->solve(b, x_copied);

  SparseMatrixD handed = A;
  auto taking = make_solver(GetParam(), options_for(GetParam()));
  taking->compute(std::move(handed));
  EXPECT_EQ(handed.nonZeros(), 0);
  Eigen::VectorXd x_taken;
  const SolveReport report = taking->solve(b, x_taken);
  EXPECT_NEAR(report.residual, (b - A * x_taken).norm() / b.norm(), 1e-15);
  if (GetParam() != "auto") {  // auto's choice depends on timings
    EXPECT_EQ(x_taken, x_copied);
  }
  EXPECT_LT((x_taken - x_copied).cwiseAbs().maxCoeff(), 1e-6);
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

// SolveOptions::symmetric_by_construction takes the symmetry on trust (cg, cg-ic, cg-amg) and keeps the other checks.
TEST(LinearSolverTrust, SymmetricByConstructionSkipsTheSymmetryTestOnly) {
  SolveOptions trusted;
  trusted.symmetric_by_construction = true;
  for (const std::string backend : {"cg", "cg-ic", "cg-amg"}) {
    auto error = [&](const SparseMatrixD& A) {
      auto solver = make_solver(backend, trusted);
      try {
        solver->compute(A);
      } catch (const SolverError& e) {
        return std::string(e.what());
      }
      return std::string();
    };
    SparseMatrixD asymmetric = path_laplacian(5, 0.0);
    asymmetric.coeffRef(1, 2) = -0.5;
    EXPECT_EQ(error(asymmetric), "") << backend;
    EXPECT_NE(error_of(backend, asymmetric), "") << backend;
    SparseMatrixD infinite = path_laplacian(5, 0.0);
    infinite.coeffRef(3, 3) = std::numeric_limits<double>::infinity();
    EXPECT_EQ(error(infinite), backend + ": matrix has a non-finite entry at (3, 3)");
    SparseMatrixD negative_diagonal = path_laplacian(5, 0.0);
    negative_diagonal.coeffRef(4, 4) = -1.0;
    EXPECT_EQ(error(negative_diagonal), backend + ": matrix has a non-positive diagonal entry (column 4)");
    // The same solution as with the check.
    const SparseMatrixD A = path_laplacian(30, 0.1);
    const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(30, -1.0, 2.0);
    auto checked = make_solver(backend);
    auto taken = make_solver(backend, trusted);
    checked->compute(A);
    taken->compute(A);
    Eigen::VectorXd x_checked, x_taken;
    checked->solve(b, x_checked);
    taken->solve(b, x_taken);
    EXPECT_EQ(x_checked, x_taken) << backend;
  }
}

TEST_P(LinearSolverBackend, EmptySystem) {
  auto solver = make_solver(GetParam());
  solver->compute(SparseMatrixD(0, 0));
  Eigen::VectorXd x;
  solver->solve(Eigen::VectorXd(), x);
  EXPECT_EQ(x.size(), 0);
}

INSTANTIATE_TEST_SUITE_P(LinearSolverBackends, LinearSolverBackend, ::testing::ValuesIn(solver_names()),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

TEST(LinearSolver, NamesAndUnknownName) {
  EXPECT_EQ(solver_names(),
            (std::vector<std::string>{"cholmod", "cg", "cg-ic", "cg-amg", "gauss-seidel", "ldlt", "auto"}));
  for (const auto& name : solver_names()) EXPECT_EQ(make_solver(name)->name(), name);
  for (const std::string bad : {"x", "", "CG", "cg ", "gauss_seidel"}) {
    try {
      make_solver(bad);
      FAIL() << "expected InvalidInput for '" << bad << "'";
    } catch (const InvalidInput& e) {
      EXPECT_EQ(std::string(e.what()),
                "unknown solver '" + bad + "' (choose cholmod, cg, cg-ic, cg-amg, gauss-seidel, ldlt, auto)");
    }
  }
}

TEST(LinearSolver, LdltAgreesWithCholmod) {
  const SparseMatrixD A = slab_system(7, 9);
  Eigen::VectorXd b(A.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i) b(i) = std::sin(0.7 * static_cast<double>(i)) + 0.2;
  Eigen::VectorXd direct, reference;
  auto cholmod = make_solver("cholmod");
  cholmod->compute(A);
  cholmod->solve(b, direct);
  auto ldlt = make_solver("ldlt");
  ldlt->compute(A);
  const SolveReport report = ldlt->solve(b, reference);
  EXPECT_EQ(report.iterations, 1);
  EXPECT_LE(report.residual, 1e-12);
  EXPECT_LE((direct - reference).cwiseAbs().maxCoeff(), 1e-10 * direct.cwiseAbs().maxCoeff());
}

TEST(LinearSolver, LdltRejectsIndefiniteMatrix) {
  const SparseMatrixD A = from_triplets(3, {{0, 0, 4.0}, {1, 1, 1.0}, {2, 2, 1.0}, {0, 1, 4.0}, {1, 0, 4.0}});
  EXPECT_EQ(error_of("ldlt", A), "ldlt: matrix is not positive definite");
}

/// One Gauss-Seidel sweep written out with dense rows, the paper's update s_i = (b_i - sum_j A_ij s_j) / A_ii.
double reference_sweep(const Eigen::MatrixXd& A, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
  double total = 0.0;
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    const double next = (b(i) - A.row(i).dot(x) + A(i, i) * x(i)) / A(i, i);
    total += std::abs(next - x(i));
    x(i) = next;
  }
  return total;  // the paper's "total change in the scalar values"
}

TEST(LinearSolver, GaussSeidelSweepAndChangeMeasure) {
  const SparseMatrixD A = slab_system(4, 5);
  const Eigen::MatrixXd dense = Eigen::MatrixXd(A);
  const Eigen::VectorXd b =
      A * Eigen::VectorXd::LinSpaced(A.rows(), 0.0, 1.0) + Eigen::VectorXd::Constant(A.rows(), 0.1);
  const Eigen::VectorXd start = Eigen::VectorXd::Constant(A.rows(), 0.5);
  Eigen::VectorXd expected = start;
  std::vector<double> expected_change;
  for (int sweep = 0; sweep < 3; ++sweep) expected_change.push_back(reference_sweep(dense, b, expected));

  for (const ChangeMeasure measure : {ChangeMeasure::Total, ChangeMeasure::Mean}) {
    SolveOptions options;
    options.max_iterations = 3;
    options.change_threshold = 0.0;  // only the sweep limit stops it
    options.change_measure = measure;
    auto solver = make_solver("gauss-seidel", options);
    solver->compute(A);
    Eigen::VectorXd x = start;
    SolveReport report;
    ASSERT_NO_THROW(report = solver->solve(b, x));  // stopping at max_iterations is not an error
    EXPECT_EQ(report.iterations, 3);
    EXPECT_LE((x - expected).cwiseAbs().maxCoeff(), 1e-14);
    const double change =
        measure == ChangeMeasure::Total ? expected_change.back() : expected_change.back() / double(A.rows());
    EXPECT_NEAR(report.change, change, 1e-14 * change) << change_measure_name(measure);
    EXPECT_NEAR(report.residual, (b - A * x).norm() / b.norm(), 1e-15);
    EXPECT_GT(report.residual, 1e-6);  // far from converged: the limit, not the residual, stopped it
  }
  EXPECT_EQ(SolveOptions{}.change_measure, ChangeMeasure::Total);  // the paper's measure by default
  EXPECT_EQ(parse_change_measure("mean"), ChangeMeasure::Mean);
  EXPECT_EQ(parse_change_measure(change_measure_name(ChangeMeasure::Total)), ChangeMeasure::Total);
  EXPECT_THROW(parse_change_measure("max"), InvalidInput);
}

TEST(LinearSolver, GaussSeidelChangeShrinksWithSweeps) {
  // Table I's rows: 1, 10 and 100 sweeps from the same start.
  const SparseMatrixD A = slab_system(10, 10);
  Eigen::VectorXd b(A.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i) b(i) = 1e-3 * std::cos(0.1 * static_cast<double>(i));
  std::vector<double> change;
  std::vector<int> sweeps;
  for (int limit : {1, 10, 100}) {
    SolveOptions options;
    options.max_iterations = limit;
    options.change_threshold = 0.0;  // only the sweep limit stops it
    auto solver = make_solver("gauss-seidel", options);
    solver->compute(A);
    Eigen::VectorXd x = Eigen::VectorXd::Zero(A.rows());
    const SolveReport report = solver->solve(b, x);
    change.push_back(report.change);
    sweeps.push_back(report.iterations);
  }
  EXPECT_EQ(sweeps, (std::vector<int>{1, 10, 100}));
  EXPECT_GT(change[0], change[1]);
  EXPECT_GT(change[1], change[2]);
  EXPECT_GT(change[2], 0.0);
}

TEST(LinearSolver, GaussSeidelStopsAtChangeThreshold) {
  const SparseMatrixD A = slab_system(6, 6);
  const Eigen::VectorXd b = A * Eigen::VectorXd::LinSpaced(A.rows(), 0.0, 1.0);
  for (double threshold : {1e-5, 1e-9}) {
    SolveOptions options;
    options.change_threshold = threshold;
    auto solver = make_solver("gauss-seidel", options);
    solver->compute(A);
    Eigen::VectorXd x;
    const SolveReport report = solver->solve(b, x);
    EXPECT_LT(report.change, threshold);
    EXPECT_GT(report.iterations, 1);
    EXPECT_LT(report.iterations, options.max_iterations);
    // One sweep fewer would not have met the threshold.
    SolveOptions fewer = options;
    fewer.max_iterations = report.iterations - 1;
    auto again = make_solver("gauss-seidel", fewer);
    again->compute(A);
    Eigen::VectorXd y;
    EXPECT_GE(again->solve(b, y).change, threshold);
  }
}

TEST(LinearSolver, CgIcBeatsJacobiOnBadlyScaledMatrix) {
  // A thin slab (strong coupling along tau, weak across) with rows and columns scaled over six decades: Jacobi
  // undoes the scaling but not the anisotropy, an incomplete factorisation handles both.
  const TetMesh4 mesh = test::make_slab_mesh(10, 10, 0.05);
  const SparseMatrixD K = cotangent_stiffness(mesh.V, mesh.T);
  std::vector<int> index(static_cast<std::size_t>(mesh.V.rows()), -1);
  int unknowns = 0;
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    if (mesh.side[static_cast<std::size_t>(i)] == VertexSide::Interior) index[static_cast<std::size_t>(i)] = unknowns++;
  }
  std::vector<Eigen::Triplet<double, int>> triplets;
  Eigen::VectorXd scale(unknowns);
  for (int i = 0; i < unknowns; ++i) scale(i) = std::pow(10.0, 3.0 * std::sin(1.3 * i));
  for (Eigen::Index j = 0; j < K.outerSize(); ++j) {
    for (SparseMatrixD::InnerIterator it(K, j); it; ++it) {
      const int r = index[static_cast<std::size_t>(it.row())];
      const int c = index[static_cast<std::size_t>(j)];
      if (r >= 0 && c >= 0) triplets.emplace_back(r, c, scale(r) * it.value() * scale(c));
    }
  }
  const SparseMatrixD A = from_triplets(unknowns, triplets);
  Eigen::VectorXd b(unknowns);
  for (int i = 0; i < unknowns; ++i) b(i) = std::cos(0.37 * i);
  std::map<std::string, SolveReport> reports;
  std::map<std::string, Eigen::VectorXd> solutions;
  for (const std::string backend : {"cg", "cg-ic"}) {
    auto solver = make_solver(backend, SolveOptions{1e-10, 100000});
    solver->compute(A);
    reports[backend] = solver->solve(b, solutions[backend]);
    EXPECT_LE(reports[backend].residual, 1e-10) << backend;
  }
  EXPECT_LT(2 * reports["cg-ic"].iterations, reports["cg"].iterations)
      << "cg-ic " << reports["cg-ic"].iterations << ", cg " << reports["cg"].iterations;
}

/// Dirichlet Laplacian of an m^3 grid of unknowns (7-point stencil): a 3D system whose Jacobi-CG iteration count
/// grows like m, so a broken multigrid hierarchy (wrong Galerkin product, transfers or smoother) shows as an
/// iteration count near Jacobi-CG's.
SparseMatrixD grid_laplacian(int m) {
  std::vector<Eigen::Triplet<double, int>> triplets;
  auto id = [m](int i, int j, int k) { return (k * m + j) * m + i; };
  for (int k = 0; k < m; ++k)
    for (int j = 0; j < m; ++j)
      for (int i = 0; i < m; ++i) {
        const int v = id(i, j, k);
        triplets.emplace_back(v, v, 6.0);
        if (i + 1 < m) triplets.emplace_back(v, id(i + 1, j, k), -1.0), triplets.emplace_back(id(i + 1, j, k), v, -1.0);
        if (j + 1 < m) triplets.emplace_back(v, id(i, j + 1, k), -1.0), triplets.emplace_back(id(i, j + 1, k), v, -1.0);
        if (k + 1 < m) triplets.emplace_back(v, id(i, j, k + 1), -1.0), triplets.emplace_back(id(i, j, k + 1), v, -1.0);
      }
  return from_triplets(m * m * m, triplets);
}

/// Solves A x = b, b_i = 1 + sin(0.01 i), with cg and cg-amg to 1e-10, each report and solution under its backend's
/// name.
void solve_to_1e10(const SparseMatrixD& A, std::map<std::string, SolveReport>& reports,
                   std::map<std::string, Eigen::VectorXd>& solutions) {
  Eigen::VectorXd b(A.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i) b(i) = 1.0 + std::sin(0.01 * double(i));
  for (const std::string backend : {"cg", "cg-amg"}) {
    auto solver = make_solver(backend, SolveOptions{1e-10, 100000});
    solver->compute(A);
    reports[backend] = solver->solve(b, solutions[backend]);
    EXPECT_LE(reports[backend].residual, 1e-10) << backend;
  }
}

TEST(LinearSolver, MultigridCutsIterations) {
  // 40^3 = 64000 unknowns, four levels. To 1e-10 Jacobi-CG took 157 iterations here, the V-cycle 47; without a
  // working coarse correction the l1-Jacobi-smoothed cycle alone is no better than Jacobi.
  const SparseMatrixD A = grid_laplacian(40);
  std::map<std::string, SolveReport> reports;
  std::map<std::string, Eigen::VectorXd> solutions;
  solve_to_1e10(A, reports, solutions);
  EXPECT_LT(reports["cg-amg"].iterations, 60);
  EXPECT_LT(reports["cg-amg"].iterations * 3, reports["cg"].iterations)
      << "cg-amg " << reports["cg-amg"].iterations << ", cg " << reports["cg"].iterations;
  EXPECT_LT((solutions["cg-amg"] - solutions["cg"]).norm(), 1e-8 * solutions["cg"].norm());
  // The report names the levels, finest first.
  EXPECT_EQ(reports["cg-amg"].detail.rfind("cg-amg levels: 64000 (", 0), 0u) << reports["cg-amg"].detail;
  EXPECT_NE(reports["cg-amg"].detail.find(", "), std::string::npos) << reports["cg-amg"].detail;
}

// Levels whose columns lie within 32767 rows of every row read them as 16-bit offsets; a level with a longer
// coupling keeps the 32-bit columns. Two 40^3 grids joined at every 7th node, 64000 rows apart, take that path at the
// finest level (a broken fallback, reading those couplings at wrong columns, makes the cycle useless) and still
// converge like one grid, to cg's solution.
TEST(LinearSolver, MultigridWithLongCouplings) {
  const SparseMatrixD G = grid_laplacian(40);
  const int n = int(G.rows());
  std::vector<Eigen::Triplet<double, int>> triplets;
  for (int j = 0; j < n; ++j)
    for (SparseMatrixD::InnerIterator it(G, j); it; ++it) {
      triplets.emplace_back(int(it.row()), j, it.value());
      triplets.emplace_back(int(it.row()) + n, j + n, it.value());
    }
  for (int i = 0; i < n; i += 7) {  // weak couplings between the grids, the diagonal raised to keep A an M-matrix
    triplets.emplace_back(i, i + n, -0.5);
    triplets.emplace_back(i + n, i, -0.5);
    triplets.emplace_back(i, i, 0.5);
    triplets.emplace_back(i + n, i + n, 0.5);
  }
  const SparseMatrixD A = from_triplets(2 * n, triplets);
  std::map<std::string, SolveReport> reports;
  std::map<std::string, Eigen::VectorXd> solutions;
  solve_to_1e10(A, reports, solutions);
  EXPECT_LT(reports["cg-amg"].iterations, 60);
  EXPECT_LT((solutions["cg-amg"] - solutions["cg"]).norm(), 1e-8 * solutions["cg"].norm());
}

TEST(LinearSolver, MultigridOnMeshSystemAndSingleLevel) {
  // A morph-like mesh system beats Jacobi-CG too; a system at most amg_coarsest unknowns is one level, solved
  // directly (one iteration).
  const SparseMatrixD A = slab_system(24, 24);
  Eigen::VectorXd b(A.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i) b(i) = 1.0 + std::sin(0.01 * double(i));
  std::map<std::string, SolveReport> reports;
  for (const std::string backend : {"cg", "cg-amg"}) {
    auto solver = make_solver(backend, SolveOptions{1e-10, 100000});
    solver->compute(A);
    Eigen::VectorXd x;
    reports[backend] = solver->solve(b, x);
    EXPECT_LE(reports[backend].residual, 1e-10) << backend;
  }
  EXPECT_LT(reports["cg-amg"].iterations * 2, reports["cg"].iterations)
      << "cg-amg " << reports["cg-amg"].iterations << ", cg " << reports["cg"].iterations;

  const SparseMatrixD small = slab_system(6, 7);
  ASSERT_LE(small.rows(), SolveOptions().amg_coarsest);
  auto solver = make_solver("cg-amg", SolveOptions{1e-10, 100});
  solver->compute(small);
  Eigen::VectorXd x;
  const SolveReport report = solver->solve(small * Eigen::VectorXd::LinSpaced(small.rows(), 0.0, 1.0), x);
  EXPECT_LE(report.iterations, 2);
  EXPECT_LE(report.residual, 1e-10);
  EXPECT_EQ(report.detail,
            "cg-amg levels: " + std::to_string(small.rows()) + " (" + std::to_string(small.nonZeros()) + ")");
}

/// b_i = cos(0.37 i): a right-hand side with every frequency in it.
Eigen::VectorXd cosine_rhs(Eigen::Index n) {
  Eigen::VectorXd b(n);
  for (Eigen::Index i = 0; i < n; ++i) b(i) = std::cos(0.37 * static_cast<double>(i));
  return b;
}

/// A fresh `backend` set up on A and solved from x = 0 into x.
SolveReport solve_fresh(const std::string& backend, const SolveOptions& options, const SparseMatrixD& A,
                        const Eigen::VectorXd& b, Eigen::VectorXd& x) {
  auto solver = make_solver(backend, options);
  solver->compute(A);
  x.resize(0);
  return solver->solve(b, x);
}

TEST(LinearSolver, AutoMeasuresAndNamesItsChoice) {
  // Big enough that cg-amg does not converge within auto's probe at this tolerance; whether the other candidates
  // are worth measuring depends on timings, so the detail names each either with its estimate or as not measured.
  const SparseMatrixD A = grid_laplacian(32);
  const Eigen::VectorXd b = cosine_rhs(A.rows());
  auto solver = make_solver("auto", SolveOptions{1e-13, 20000});
  solver->compute(A);
  Eigen::VectorXd x;
  const SolveReport report = solver->solve(b, x);
  EXPECT_TRUE(is_auto_choice(report.backend)) << report.backend;
  EXPECT_NE(report.detail.find("chose " + report.backend + " "), std::string::npos) << report.detail;
  EXPECT_EQ(report.detail.rfind("auto: cg-amg: setup ", 0), 0u) << report.detail;
  EXPECT_EQ(report.detail.find("converged in the probe"), std::string::npos) << report.detail;
  const bool skipped = report.detail.find("; cg, cg-ic, cholmod: not measured (") != std::string::npos;
  for (const char* candidate : {"; cg: ", "; cg-ic: ", "; cholmod ("}) {
    EXPECT_NE(skipped, report.detail.find(candidate) != std::string::npos) << candidate << " in " << report.detail;
  }
  EXPECT_LE(report.residual, 1e-13);
  EXPECT_GT(report.memory_bytes, 0);

  Eigen::VectorXd reference;
  solve_fresh("cholmod", SolveOptions(), A, b, reference);
  EXPECT_LE((x - reference).cwiseAbs().maxCoeff(), 1e-8 * reference.cwiseAbs().maxCoeff());

  // A second right-hand side reuses the choice and its set-up.
  Eigen::VectorXd x2;
  const SolveReport second = solver->solve(2.0 * b, x2);
  EXPECT_EQ(second.backend, report.backend);
  EXPECT_LE((x2 - 2.0 * reference).cwiseAbs().maxCoeff(), 2e-8 * reference.cwiseAbs().maxCoeff());
}

TEST(LinearSolver, AutoStopsAtTheDefaultWhenItsProbeConverges) {
  // cg-amg solves this system within auto's probe: nothing else is measured and x is bitwise cg-amg's own.
  const SparseMatrixD A = slab_system(16, 16);
  const Eigen::VectorXd b = cosine_rhs(A.rows());
  Eigen::VectorXd x, y;
  const SolveReport report = solve_fresh("auto", SolveOptions{1e-8, 20000}, A, b, x);
  EXPECT_EQ(report.backend, "cg-amg");
  EXPECT_NE(report.detail.find("converged in the probe"), std::string::npos) << report.detail;
  EXPECT_EQ(report.detail.find("cg-ic"), std::string::npos) << report.detail;
  EXPECT_EQ(solve_fresh("cg-amg", SolveOptions{1e-8, 20000}, A, b, y).iterations, report.iterations);
  ASSERT_EQ(x.size(), y.size());
  EXPECT_EQ(std::memcmp(x.data(), y.data(), sizeof(double) * static_cast<std::size_t>(x.size())), 0);
}

TEST(LinearSolver, SymmetricMultiplyMatchesEigen) {
  const SparseMatrixD A = slab_system(22, 22);  // several row blocks
  Eigen::VectorXd x(A.cols());
  for (Eigen::Index i = 0; i < x.size(); ++i) x(i) = std::sin(0.01 * static_cast<double>(i));
  std::vector<Eigen::VectorXd> y(2);
  for (int threads : {1, 2}) {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    symmetric_multiply(A, x, y[static_cast<std::size_t>(threads - 1)]);
  }
  const Eigen::VectorXd expected = A * x;
  EXPECT_LE((y[0] - expected).cwiseAbs().maxCoeff(), 1e-12 * expected.cwiseAbs().maxCoeff());
  EXPECT_EQ(std::memcmp(y[0].data(), y[1].data(), sizeof(double) * static_cast<std::size_t>(y[0].size())), 0);
  EXPECT_EQ(symmetric_multiply_bytes(A), A.nonZeros() * 12 + (A.rows() + 1) * 4 + 2 * A.rows() * 8);
  Eigen::VectorXd wrong(3), out;
  EXPECT_THROW(symmetric_multiply(A, wrong, out), InvalidInput);
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

TEST(LinearSolver, MultigridRejectsIndefiniteMatrix) {
  // Small enough to be the coarsest level itself, so its Cholesky factorisation meets the negative pivot.
  const SparseMatrixD A = from_triplets(3, {{0, 0, 4.0}, {1, 1, 1.0}, {2, 2, 1.0}, {0, 1, 4.0}, {1, 0, 4.0}});
  EXPECT_EQ(error_of("cg-amg", A),
            "cg-amg: Cholesky factorisation of the coarsest level (3 unknowns) failed: its Galerkin operator is not "
            "numerically positive definite");
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

/// Piecewise-constant columns over consecutive runs of `run` unknowns: a deflation space with one entry a row.
DeflationSpace run_space(Eigen::Index n, int run) {
  DeflationSpace space;
  space.columns = int((n + run - 1) / run);
  space.column.setConstant(n, 2, -1);
  space.weight.setZero(n, 2);
  for (Eigen::Index i = 0; i < n; ++i) {
    space.column(i, 0) = int(i / run);
    space.weight(i, 0) = 1.0;
  }
  return space;
}

// Deflating a 1D Laplacian by piecewise constants removes its smoothest modes, which are what makes Jacobi-CG slow:
// every CG backend (and auto's choice) keeps its solution and the report counts the columns; cg needs far fewer
// iterations.
TEST(LinearSolver, DeflationKeepsTheSolutionAndCutsIterations) {
  const SparseMatrixD A = path_laplacian(2000, 1e-4);
  const Eigen::VectorXd b = cosine_rhs(A.rows());
  for (const std::string backend : {"cg", "cg-ic", "cg-amg", "auto"}) {
    const SolveOptions options{1e-10, 100000};
    SolveReport plain_report, deflated_report;
    Eigen::VectorXd plain, deflated;
    {
      auto solver = make_solver(backend, options);
      solver->compute(A);
      plain_report = solver->solve(b, plain);
    }
    {
      auto solver = make_solver(backend, options);
      solver->set_deflation(run_space(A.rows(), 50));
      solver->compute(A);
      deflated_report = solver->solve(b, deflated);
    }
    EXPECT_EQ(plain_report.deflation_columns, 0) << backend;
    if (deflated_report.backend != "cholmod") {
      EXPECT_EQ(deflated_report.deflation_columns, 40) << backend << " ran " << deflated_report.backend;
    }
    EXPECT_LE(deflated_report.residual, 1e-10) << backend;
    EXPECT_LT((deflated - plain).norm(), 1e-7 * plain.norm()) << backend;
    if (backend == std::string("cg")) {
      EXPECT_LT(3 * deflated_report.iterations, plain_report.iterations)
          << deflated_report.iterations << " against " << plain_report.iterations;
    }
  }
}

TEST(LinearSolver, DeflationWithDependentColumnsIsDropped) {
  const SparseMatrixD A = path_laplacian(300, 0.01);
  const Eigen::VectorXd b = cosine_rhs(A.rows());
  DeflationSpace space = run_space(A.rows(), 30);
  space.columns += 1;  // the last column repeats the first one's rows: Z^T A Z is singular
  for (Eigen::Index i = 0; i < 30; ++i) {
    space.column(i, 1) = space.columns - 1;
    space.weight(i, 1) = 2.0;
  }
  auto solver = make_solver("cg", SolveOptions{1e-10, 100000});
  solver->set_deflation(space);
  solver->compute(A);
  Eigen::VectorXd x;
  const SolveReport report = solver->solve(b, x);
  EXPECT_EQ(report.deflation_columns, 0);
  EXPECT_NE(report.detail.find("deflation off"), std::string::npos) << report.detail;
  EXPECT_LE(report.residual, 1e-10);
}

TEST(LinearSolver, RejectsMalformedDeflation) {
  const SparseMatrixD A = path_laplacian(100, 0.01);
  DeflationSpace columns = run_space(100, 10);
  columns.column(5, 0) = 10;
  const std::vector<std::pair<DeflationSpace, std::string>> cases = {
      {run_space(99, 10), ": deflation space has 99 rows for 100 unknowns"},
      {columns, ": deflation space has a column index outside [-1, 10)"}};
  for (const std::string backend : {"cg", "cg-amg"})
    for (const auto& [space, message] : cases) {
      auto solver = make_solver(backend);
      solver->set_deflation(space);
      try {
        solver->compute(A);
        ADD_FAILURE() << "expected InvalidInput: " << message;
      } catch (const InvalidInput& e) {
        EXPECT_EQ(std::string(e.what()), backend + message);
      }
    }
}

TEST(LinearSolver, IterativeBackendsBitwiseIndependentOfThreadCount) {
  // Big enough for several row blocks, so a thread-count-dependent reduction would show.
  const SparseMatrixD A = slab_system(22, 22);
  ASSERT_GT(A.rows(), 2 * 4096);
  Eigen::VectorXd b(A.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i) b(i) = std::cos(0.37 * static_cast<double>(i));
  for (const std::string backend : {"cg", "cg-ic", "cg-amg", "gauss-seidel", "deflated cg-amg"}) {
    std::vector<Eigen::VectorXd> solutions;
    std::vector<int> iterations;
    for (int threads : {1, 2}) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
      const bool deflated = backend.rfind("deflated ", 0) == 0;
      auto solver = make_solver(deflated ? backend.substr(9) : backend);
      if (deflated) solver->set_deflation(run_space(A.rows(), 97));  // spans crossing the row blocks' edges
      solver->compute(A);
      Eigen::VectorXd x;
      iterations.push_back(solver->solve(b, x).iterations);
      solutions.push_back(x);
    }
    EXPECT_EQ(iterations[0], iterations[1]) << backend;
    ASSERT_EQ(solutions[0].size(), solutions[1].size());
    EXPECT_EQ(std::memcmp(solutions[0].data(), solutions[1].data(), sizeof(double) * solutions[0].size()), 0)
        << backend;
  }
}

}  // namespace
}  // namespace morphmap
