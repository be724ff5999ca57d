// Sparse symmetric positive definite solvers behind one interface (paper §6.1 solves the same system by
// Gauss-Seidel diffusion or by implicit integration with conjugate gradients; Table II compares them).
// Every backend reports the same diagnostics, so they can be compared side by side (bench/bench_solve.cpp).
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace morphmap {

using SparseMatrixD = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;

/// How Gauss-Seidel measures "the total change in the scalar values" of one sweep (paper §6.1).
enum class ChangeMeasure {
  Total,  ///< sum over the unknowns of |s_i(new) - s_i(old)|: the paper's words, and what its threshold stops
  Mean,   ///< that sum divided by the number of unknowns (independent of the mesh size)
};

struct SolveOptions {
  double tolerance = 1e-8;         ///< cg, cg-ic, cg-amg: stop at relative residual |b - Ax| / |b| below this;
                                   ///< auto estimates each candidate's time to reach it. 1e-8 against 1e-10 on
                                   ///< sphere -> bunny (0.4M tets): 60 instead of 77 cg-amg iterations, labels
                                   ///< moved by at most 1e-4 (median 8e-8) of the bounding-box diagonal
  int max_iterations = 20000;      ///< cg, cg-ic give up (SolverError) after this many iterations; gauss-seidel
                                   ///< stops (without error) after this many sweeps
  double amg_strength = 0.15;      ///< cg-amg: j joins i's aggregate only if |a_ij| >= amg_strength sqrt(a_ii a_jj)
                                   ///< (halved on each coarser level). Larger values mean fewer iterations but
                                   ///< denser levels. With cubic lattice cells (c = K h; cow -> horse 1.7M tets)
                                   ///< 0.05, 0.08, 0.12, 0.2 took 44, 43, 41, 36 iterations and the same time within
                                   ///< noise; with the map's default c = 2 box, whose cells are 13x longer in time
                                   ///< than wide (strongly anisotropic), 0.08, 0.12, 0.15, 0.2 took 133, 123, 109,
                                   ///< 111 iterations and 1.12, 1.03, 1.00, 1.07 s on cow -> horse (1.66M tets), 98,
                                   ///< 86, 81, 80 and 1.18, 1.18, 1.14, 1.20 s on sphere -> bunny (2.4M tets; medians
                                   ///< of 3, interleaved)
  int amg_coarsest = 400;          ///< cg-amg: levels are added until one has at most this many unknowns, which a
                                   ///< dense Cholesky factor solves exactly
  double change_threshold = 1e-5;  ///< gauss-seidel stops once the change of s in one sweep (change_measure) is
                                   ///< below this (1e-5 is Table II's value)
  /// Total (the paper's "total change in the scalar values"): on the 0.2M-tet bench systems 1e-5 takes 1400-2700
  /// sweeps and leaves a relative residual of ~4e-9, as accurate as the other backends at 1e-8. Mean stops at
  /// 1e-5 after 380-600 sweeps, near Table II's sweep counts (469, 535), at a residual of ~1e-4.
  ChangeMeasure change_measure = ChangeMeasure::Total;
  /// cg, cg-ic, cg-amg: the caller vouches that A is exactly symmetric (the Laplace stage, whose assembly sums
  /// (i, j) and (j, i) from the same doubles in the same order), so the input check skips its symmetry test, a
  /// binary search per entry that took 21 ms of cow -> horse's 1.85 s; finiteness and the diagonal are still checked.
  /// Not a command-line option.
  bool symmetric_by_construction = false;
};

/// Diagnostics of one set-up (factorisation or preconditioner) plus one solve.
struct SolveReport {
  std::string backend;         ///< the backend that produced x; for "auto", the one it chose
  int iterations = 0;          ///< CG iterations (auto: its probe's included) or Gauss-Seidel sweeps; for
                               ///< direct solvers, back-substitutions (1 + refinement steps)
  double residual = 0.0;       ///< final relative residual |b - Ax| / |b| (computed, not estimated)
  double change = 0.0;         ///< gauss-seidel: change of s in the last sweep (SolveOptions::change_measure); 0 for
                               ///< the others
  double setup_seconds = 0.0;  ///< analysis + factorisation, or preconditioner set-up (auto: plus its probes)
  double solve_seconds = 0.0;
  /// The solver's own storage in bytes, computed from sizes: factor or preconditioner, work vectors, and for
  /// cholmod the peak of CHOLMOD's allocations (cholmod_common::memory_usage). It excludes the caller's b and x
  /// and the copy of A that every backend keeps (nnz * 12 + (n + 1) * 4 bytes), which is the same for all.
  std::int64_t memory_bytes = 0;
  std::string detail;         ///< free text; auto: the estimate of every candidate and the choice
  int deflation_columns = 0;  ///< CG backends: columns of the deflation space used (0: none given, or dropped)
};

/// A coarse space Z (#unknowns by `columns`) for deflated CG: CG runs in the A-orthogonal complement of span(Z), and
/// the component in span(Z) is solved exactly with the Galerkin matrix Z^T A Z (Nicolaides 1987; "DEF1" in Tang,
/// Nabben, Vuik and Erlangga 2009). It removes the slow modes a preconditioner leaves: on the morph systems those
/// are smooth in space-time (on cow -> horse, 98% of cg-amg's error after 62 iterations is a function of t alone),
/// which the Laplace stage's space-time cells (solver/laplace.h) span. Each row has at most two entries, which keeps
/// the work per CG iteration to a few passes over #unknowns numbers. Columns must be linearly independent.
struct DeflationSpace {
  int columns = 0;                                                   ///< m; 0 = no deflation
  Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> column;     ///< #unknowns by 2: columns, -1 = no entry
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> weight;  ///< #unknowns by 2: the entries
};

/// Stateful solver: `compute` once (factorisation reused), `solve` for any number of right-hand sides.
class LinearSolver {
 public:
  virtual ~LinearSolver() = default;
  virtual std::string name() const = 0;
  /// The coarse space the CG backends (cg, cg-ic, cg-amg and auto's CG candidates) deflate; the direct backends and
  /// gauss-seidel ignore it. Set before compute(); an empty space (the default) turns deflation off. Checked by
  /// compute (InvalidInput for a row count other than A's or a column out of range).
  void set_deflation(DeflationSpace space) { deflation_space_ = std::move(space); }
  /// A must be symmetric positive definite (both triangles stored). Throws SolverError. The solver keeps a copy.
  void compute(const SparseMatrixD& A) {
    SparseMatrixD copy = A;
    compute_taking(copy);
  }
  /// compute() for a matrix the caller no longer needs: the solver takes A's storage (A is left empty) instead of
  /// copying it (on cow -> horse, 1.66 M tets, the copy was 45 MB at the run's peak).
  void compute(SparseMatrixD&& A) { compute_taking(A); }
  /// Solves A x = b. `x` on entry is the initial guess for iterative backends (resized if empty).
  virtual SolveReport solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) = 0;

 protected:
  /// compute() on a matrix the backend may take by swapping (Eigen 3.4's SparseMatrix has no move constructor).
  virtual void compute_taking(SparseMatrixD& A) = 0;
  DeflationSpace deflation_space_;
};

/// Names accepted by make_solver, in the order `--help` lists them.
std::vector<std::string> solver_names();

/// "total" / "mean"; parse_change_measure throws InvalidInput for anything else.
std::string change_measure_name(ChangeMeasure measure);
ChangeMeasure parse_change_measure(const std::string& name);

/// Backends:
///  - "cholmod": supernodal sparse Cholesky (CHOLMOD), factorisation kept for further right-hand sides.
///  - "cg": conjugate gradients with a Jacobi preconditioner, TBB-parallel, bitwise independent of threads.
///  - "cg-ic": conjugate gradients with an incomplete Cholesky preconditioner (Eigen::IncompleteCholesky).
///  - "cg-amg": conjugate gradients preconditioned by one V-cycle of aggregation algebraic multigrid (l1-Jacobi
///    smoothing, Galerkin coarse levels, dense Cholesky on the coarsest), TBB-parallel, bitwise independent of
///    threads. 6-8x fewer iterations than cg on our morph systems.
///  - "gauss-seidel": the paper's diffusion, sequential sweeps from the initial guess until the change of a sweep
///    (SolveOptions::change_measure: total or per unknown) falls below SolveOptions::change_threshold (or
///    max_iterations sweeps).
///  - "ldlt": Eigen::SimplicialLDLT, what libigl's min_quad_with_fixed uses; a reference.
///  - "auto": measures cholmod, cg and cg-ic on the actual system (see AutoSolver in the .cpp) and runs the one
///    estimated fastest. Its choice depends on timings, so it is the one backend whose output can vary from run
///    to run; name a backend for bitwise reproducible results.
/// The CG backends (cg, cg-ic, cg-amg) deflate the coarse space given by set_deflation, if any.
/// Throws InvalidInput for an unknown name.
std::unique_ptr<LinearSolver> make_solver(const std::string& name, const SolveOptions& options = {});

/// y = A x for a symmetric A stored in full (both triangles), read as CSR: row i is column i of the CSC storage.
/// TBB-parallel over fixed blocks of rows; each row is summed by one thread in storage order, so y is bitwise
/// the same for any thread count. The kernel every iterative backend uses. y is resized.
void symmetric_multiply(const SparseMatrixD& A, const Eigen::VectorXd& x, Eigen::VectorXd& y);

/// Bytes symmetric_multiply must move at least: values and row indices (nnz * (8 + 4)), column starts
/// ((n + 1) * 4, Eigen's int offsets), x read once and y written once (2 * n * 8). Gathers of x that miss the
/// cache and the write-allocate read of y come on top, so bytes / seconds is a lower bound of the bandwidth used.
std::int64_t symmetric_multiply_bytes(const SparseMatrixD& A);

}  // namespace morphmap
