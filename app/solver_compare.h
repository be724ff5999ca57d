// Extra solves of the harmonic field's Dirichlet system for comparison (paper §6.1 solves it both by
// Gauss-Seidel diffusion and by implicit integration, and Table II reports both). The map always uses the
// pipeline's own backend; these solves only measure the others on the identical system.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/tet_mesh4.h"
#include "solver/laplace.h"

namespace morphmap {

struct SolverComparison {
  std::string backend;         ///< the backend that produced the solution (auto: the one it chose)
  int iterations = 0;          ///< CG iterations, Gauss-Seidel sweeps or back-substitutions
  double residual = 0.0;       ///< final relative residual |b - Ax| / |b|
  double change = 0.0;         ///< gauss-seidel: mean |change| per unknown in the last sweep (Table II's "conv.")
  double setup_seconds = 0.0;  ///< factorisation or preconditioner set-up
  double solve_seconds = 0.0;
  std::int64_t memory_bytes = 0;  ///< the solver's own storage (see SolveReport)
  double max_difference = 0.0;    ///< max |s - s_reference| over the unknowns: how far from the map's solution
};

struct SolverComparisonResult {
  std::vector<SolverComparison> solves;  ///< one per requested backend, in request order
  double assemble_seconds = 0.0;         ///< the system, assembled once for all of them
  double seconds = 0.0;                  ///< whole comparison
};

/// Assembles the Dirichlet system of `mesh` once and solves it with every backend in `backends` (same tolerance,
/// iteration limit and warm start as `options`). `reference` (#V) is the pipeline's harmonic field.
/// Throws InvalidInput for an unknown backend and SolverError if a backend fails.
SolverComparisonResult compare_solvers(const TetMesh4& mesh, const Eigen::VectorXd& reference,
                                       const std::vector<std::string>& backends, const LaplaceOptions& options);

}  // namespace morphmap
