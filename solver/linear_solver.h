// Sparse symmetric positive definite solvers behind one interface (paper §6.1 solves the same
// system by Gauss-Seidel diffusion or by implicit integration with conjugate gradients).
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <string>
#include <vector>

namespace morphmap {

using SparseMatrixD = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

struct SolveOptions {
  double tolerance = 1e-10;     ///< iterative backends stop at relative residual |b - Ax| / |b| below this
  int max_iterations = 20000;   ///< iterative backends give up (SolverError) after this many iterations
};

/// Diagnostics of one factorisation plus one solve.
struct SolveReport {
  std::string backend;          ///< "cholmod", "cg"
  int iterations = 0;           ///< CG iterations; for direct solvers, back-substitutions (1 + refinement steps)
  double residual = 0.0;        ///< final relative residual |b - Ax| / |b| (computed, not estimated)
  double setup_seconds = 0.0;   ///< analysis + factorisation, or preconditioner set-up
  double solve_seconds = 0.0;
};

/// Stateful solver: `compute` once (factorisation reused), `solve` for any number of right-hand sides.
class LinearSolver {
 public:
  virtual ~LinearSolver() = default;
  virtual std::string name() const = 0;
  /// A must be symmetric positive definite (both triangles stored). Throws SolverError.
  virtual void compute(const SparseMatrixD& A) = 0;
  /// Solves A x = b. `x` on entry is the initial guess for iterative backends (resized if empty).
  virtual SolveReport solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) = 0;
};

/// Names accepted by make_solver, in the order `--help` lists them.
std::vector<std::string> solver_names();

/// "cholmod" (supernodal Cholesky) or "cg" (Jacobi-preconditioned conjugate gradients).
/// Throws InvalidInput for an unknown name.
std::unique_ptr<LinearSolver> make_solver(const std::string& name, const SolveOptions& options = {});

}  // namespace morphmap
