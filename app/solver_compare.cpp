// Comparison solves on the pipeline's Dirichlet system (paper §6.1, Table II), through the public solver API.
#include "app/solver_compare.h"

#include <algorithm>
#include <cmath>
#include <memory>

#include "mesh/stopwatch.h"

namespace morphmap {

SolverComparisonResult compare_solvers(const TetMesh4& mesh, const Eigen::VectorXd& reference,
                                       const std::vector<std::string>& backends, const LaplaceOptions& options) {
  const auto start = Clock::now();
  SolverComparisonResult result;
  if (backends.empty()) return result;
  for (const std::string& name : backends) (void)make_solver(name, options.solve);  // reject before assembling
  const DirichletSystem system = dirichlet_system(mesh);
  result.assemble_seconds = system.assemble_seconds;
  // The CG backends get solve_harmonic's deflation too (the others ignore it).
  const DeflationSpace deflation = space_time_cells(mesh, system.unknown, int(system.A.rows()),
                                                    options.deflation_cell_voxels, kMaxDeflationColumns, &system.A);
  for (const std::string& name : backends) {
    const std::unique_ptr<LinearSolver> solver = make_solver(name, options.solve);
    // The same start as solve_harmonic's, so iteration counts compare like for like.
    Eigen::VectorXd x = options.warm_start ? system.x0 : Eigen::VectorXd::Zero(system.b.size());
    solver->set_deflation(deflation);
    solver->compute(system.A);
    const SolveReport report = solver->solve(system.b, x);
    SolverComparison c;
    c.backend = report.backend.empty() ? name : report.backend;
    c.iterations = report.iterations;
    c.residual = report.residual;
    c.change = report.change;
    c.setup_seconds = report.setup_seconds;
    c.solve_seconds = report.solve_seconds;
    c.memory_bytes = report.memory_bytes;
    for (std::size_t v = 0; v < system.unknown.size(); ++v) {
      const int u = system.unknown[v];
      if (u >= 0 && Eigen::Index(v) < reference.size())
        c.max_difference = std::max(c.max_difference, std::abs(x[u] - reference[Eigen::Index(v)]));
    }
    result.solves.push_back(std::move(c));
  }
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace morphmap
