// Sparse SPD solvers for the Laplace system of paper §6.1 and Table II. The paper iterates Gauss-Seidel
// diffusion ("until the total change in the scalar values is below a desired threshold") or runs conjugate
// gradients on the implicit step. We offer both, plus a supernodal Cholesky factorisation (CHOLMOD), an
// incomplete-Cholesky PCG, Eigen's SimplicialLDLT as the reference libigl users get, and "auto", which
// measures the fast candidates on the actual matrix and runs the one it estimates fastest.
#include "solver/linear_solver.h"

#include <cholmod.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <Eigen/Cholesky>
#include <Eigen/IterativeLinearSolvers>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <numeric>
#include <sstream>

#include "mesh/errors.h"
#include "mesh/stopwatch.h"

namespace morphmap {
namespace {

// Relative tolerance of the symmetry check: assembly sums the same products for (i, j) and (j, i), so
// a real system is symmetric to rounding; anything larger is a caller's bug, not noise.
constexpr double kSymmetryTolerance = 1e-12;

// Rows per block of the parallel kernels. Fixed (not derived from the thread count) so that the partial sums
// of every dot product, and hence every iterate, are bitwise identical for any number of threads.
constexpr Eigen::Index kBlockRows = 4096;

constexpr std::int64_t kDoubleBytes = sizeof(double);
constexpr std::int64_t kIndexBytes = sizeof(int);

Eigen::Index block_count(Eigen::Index n) { return (n + kBlockRows - 1) / kBlockRows; }

/// Runs f(i) for every row, in parallel over the fixed row blocks.
template <typename F>
void for_blocks(Eigen::Index n, const F& f) {
  tbb::parallel_for(Eigen::Index(0), block_count(n), [&](Eigen::Index block) {
    const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
    for (Eigen::Index i = block * kBlockRows; i < end; ++i) f(i);
  });
}

/// Sum of row_term(i) over all rows as per-block partial sums added in block order: the same bits for any
/// thread count. `partial` is scratch of block_count(n) entries.
template <typename F>
double block_sum(Eigen::Index n, std::vector<double>& partial, const F& row_term) {
  const Eigen::Index blocks = block_count(n);
  partial.resize(static_cast<std::size_t>(blocks));
  tbb::parallel_for(Eigen::Index(0), blocks, [&](Eigen::Index block) {
    const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
    double sum = 0.0;
    for (Eigen::Index i = block * kBlockRows; i < end; ++i) sum += row_term(i);
    partial[static_cast<std::size_t>(block)] = sum;
  });
  double total = 0.0;
  for (Eigen::Index block = 0; block < blocks; ++block) total += partial[static_cast<std::size_t>(block)];
  return total;
}

/// Row i of A times v. A is symmetric, so row i is column i of the CSC storage: a contiguous read. Two
/// interleaved partial sums hide the latency of the dependent additions (a row has ~15 entries); the order is
/// fixed, so the result does not depend on threads.
inline double row_times(const SparseMatrixD& A, Eigen::Index i, const Eigen::VectorXd& v) {
  const int* inner = A.innerIndexPtr();
  const double* values = A.valuePtr();
  const double* x = v.data();
  const int end = A.outerIndexPtr()[i + 1];
  int k = A.outerIndexPtr()[i];
  double even = 0.0, odd = 0.0;
  for (; k + 1 < end; k += 2) {
    even += values[k] * x[inner[k]];
    odd += values[k + 1] * x[inner[k + 1]];
  }
  if (k < end) even += values[k] * x[inner[k]];
  return even + odd;
}

/// row_times with row i's columns read as 16-bit offsets from i (`offset`, in A's storage order, as cg-amg's finest
/// level keeps them): the same products summed in the same order, 10 bytes an entry read instead of 12.
inline double row_times(const SparseMatrixD& A, const std::int16_t* offset, Eigen::Index i, const Eigen::VectorXd& v) {
  if (offset == nullptr) return row_times(A, i, v);
  const double* values = A.valuePtr();
  const double* x = v.data() + i;
  const int end = A.outerIndexPtr()[i + 1];
  int k = A.outerIndexPtr()[i];
  double even = 0.0, odd = 0.0;
  for (; k + 1 < end; k += 2) {
    even += values[k] * x[offset[k]];
    odd += values[k + 1] * x[offset[k + 1]];
  }
  if (k < end) even += values[k] * x[offset[k]];
  return even + odd;
}

/// Storage of a compressed sparse matrix: values, inner indices and outer starts.
std::int64_t sparse_bytes(std::int64_t nnz, std::int64_t cols) {
  return nnz * (kDoubleBytes + kIndexBytes) + (cols + 1) * kIndexBytes;
}

/// The first column j with bad_column(j), or -1: columns in parallel over fixed blocks, each block stopping at its
/// first, and the earliest block's wins, so the answer is a sequential scan's.
template <typename F>
Eigen::Index first_bad_column(const SparseMatrixD& A, const F& bad_column) {
  const Eigen::Index n = A.cols();
  std::vector<Eigen::Index> first(static_cast<std::size_t>(block_count(n)), -1);
  tbb::parallel_for(Eigen::Index(0), block_count(n), [&](Eigen::Index block) {
    const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
    for (Eigen::Index j = block * kBlockRows; j < end; ++j) {
      if (bad_column(j)) {
        first[static_cast<std::size_t>(block)] = j;
        return;
      }
    }
  });
  for (Eigen::Index j : first)
    if (j >= 0) return j;
  return -1;
}

/// Rejects what a Cholesky or CG solve cannot handle, naming the backend in the message; without check_symmetry
/// (SolveOptions::symmetric_by_construction) A's symmetry is taken on trust.
/// Returns the diagonal (every entry positive).
Eigen::VectorXd check_spd_input(const SparseMatrixD& A, const std::string& backend, bool check_symmetry = true) {
  if (A.rows() != A.cols()) {
    std::ostringstream msg;
    msg << backend << ": matrix is not square (" << A.rows() << " by " << A.cols() << ")";
    throw SolverError(msg.str());
  }
  const Eigen::Index n = A.cols();
  const int* outer = A.outerIndexPtr();
  const int* nonzeros = A.innerNonZeroPtr();  // null when compressed
  const int* inner = A.innerIndexPtr();
  const double* values = A.valuePtr();
  auto column_end = [&](Eigen::Index j) { return nonzeros ? outer[j] + nonzeros[j] : outer[j + 1]; };

  const Eigen::Index non_finite = first_bad_column(A, [&](Eigen::Index j) {
    for (int k = outer[j]; k < column_end(j); ++k)
      if (!std::isfinite(values[k])) return true;
    return false;
  });
  if (non_finite >= 0) {
    for (SparseMatrixD::InnerIterator it(A, non_finite); it; ++it) {
      if (std::isfinite(it.value())) continue;
      std::ostringstream msg;
      msg << backend << ": matrix has a non-finite entry at (" << it.row() << ", " << non_finite << ")";
      throw SolverError(msg.str());
    }
  }
  Eigen::VectorXd diagonal = Eigen::VectorXd::Zero(n);
  Eigen::Index asymmetric = n;
  double tolerance = 0.0;
  if (!check_symmetry) {
    for_blocks(n, [&](Eigen::Index j) {
      for (int k = outer[j]; k < column_end(j); ++k)
        if (inner[k] == j) diagonal(j) += values[k];
    });
  } else {
    double max_abs = 0.0;
    {
      std::vector<double> block_max(static_cast<std::size_t>(block_count(n)), 0.0);
      tbb::parallel_for(Eigen::Index(0), block_count(n), [&](Eigen::Index block) {
        const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
        double m = 0.0;
        for (Eigen::Index j = block * kBlockRows; j < end; ++j)
          for (int k = outer[j]; k < column_end(j); ++k) m = std::max(m, std::abs(values[k]));
        block_max[static_cast<std::size_t>(block)] = m;
      });
      for (double m : block_max) max_abs = std::max(max_abs, m);
    }
    tolerance = kSymmetryTolerance * max_abs;

    // Symmetry: each strictly upper entry (i, j), i < j, is compared with its mirror (j, i), found by binary search in
    // column i; a mismatch flags column i, the smaller of the two (what a scan of both triangles would report first).
    // Mirrors found are counted: if fewer than the strictly lower entries, some lower entry has no upper partner,
    // and a scan of both triangles (each entry against coeff()) finds the first offending column. Checking one
    // triangle with a counted match takes half the searches: the check was most of cg's set-up.
    const Eigen::Index blocks = block_count(n);
    std::vector<Eigen::Index> block_first_asymmetric(static_cast<std::size_t>(blocks), n);
    std::vector<std::int64_t> block_matched(static_cast<std::size_t>(blocks), 0);
    std::vector<std::int64_t> block_lower(static_cast<std::size_t>(blocks), 0);
    tbb::parallel_for(Eigen::Index(0), blocks, [&](Eigen::Index block) {
      const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
      std::int64_t matched = 0, lower = 0;
      Eigen::Index first_asymmetric = n;
      for (Eigen::Index j = block * kBlockRows; j < end; ++j) {
        for (int k = outer[j]; k < column_end(j); ++k) {
          const int i = inner[k];
          if (i == j) {
            diagonal(j) += values[k];
          } else if (i > j) {
            ++lower;
          } else {
            const int* first = inner + outer[i];
            const int* last = inner + column_end(i);
            const int* at = std::lower_bound(first, last, int(j));
            double mirror = 0.0;
            if (at != last && *at == j) {
              mirror = values[at - inner];
              ++matched;
            }
            if (std::abs(values[k] - mirror) > tolerance)
              first_asymmetric = std::min<Eigen::Index>(first_asymmetric, i);
          }
        }
      }
      block_first_asymmetric[static_cast<std::size_t>(block)] = first_asymmetric;
      block_matched[static_cast<std::size_t>(block)] = matched;
      block_lower[static_cast<std::size_t>(block)] = lower;
    });
    for (Eigen::Index first : block_first_asymmetric) asymmetric = std::min(asymmetric, first);
    if (std::accumulate(block_matched.begin(), block_matched.end(), std::int64_t(0)) !=
        std::accumulate(block_lower.begin(), block_lower.end(), std::int64_t(0))) {
      const Eigen::Index full = first_bad_column(A, [&](Eigen::Index j) {
        for (SparseMatrixD::InnerIterator it(A, j); it; ++it)
          if (it.row() != j && std::abs(it.value() - A.coeff(j, it.row())) > tolerance) return true;
        return false;
      });
      if (full >= 0) asymmetric = std::min(asymmetric, full);
    }
  }
  const Eigen::Index non_positive = first_bad_column(A, [&](Eigen::Index j) { return !(diagonal(j) > 0.0); });
  if (asymmetric < n && (non_positive < 0 || asymmetric <= non_positive)) {
    std::ostringstream msg;
    msg << backend << ": matrix is not symmetric (column " << asymmetric << ", tolerance " << tolerance << ")";
    throw SolverError(msg.str());
  }
  if (non_positive >= 0) {
    std::ostringstream msg;
    msg << backend << ": matrix has a non-positive diagonal entry (column " << non_positive << ")";
    throw SolverError(msg.str());
  }
  return diagonal;
}

void check_rhs(const SparseMatrixD& A, const Eigen::VectorXd& b, bool ready, const std::string& backend) {
  if (!ready) throw SolverError(backend + ": solve called before compute");
  if (b.size() != A.rows()) {
    std::ostringstream msg;
    msg << backend << ": right-hand side has " << b.size() << " entries, matrix has " << A.rows() << " rows";
    throw SolverError(msg.str());
  }
  if (!b.allFinite()) throw SolverError(backend + ": right-hand side is not finite");
}

/// |b - A x| / |b|, or |b - A x| when b = 0 (then x = 0 is the answer and any other x is off by |A x|).
/// A is symmetric and compressed (every backend's A_ is), so rows are read as columns, in parallel over the fixed
/// blocks: Eigen's b - A x was a serial pass over the matrix after every solve.
double relative_residual(const SparseMatrixD& A, const Eigen::VectorXd& b, const Eigen::VectorXd& x) {
  std::vector<double> partial;
  const double b_norm = std::sqrt(block_sum(b.size(), partial, [&](Eigen::Index i) { return b(i) * b(i); }));
  const double r_norm = std::sqrt(block_sum(b.size(), partial, [&](Eigen::Index i) {
    const double r = b(i) - row_times(A, i, x);
    return r * r;
  }));
  return b_norm > 0.0 ? r_norm / b_norm : r_norm;
}

/// Moves A's storage into `own` (A is left empty), compressed.
void take_storage(SparseMatrixD& A, SparseMatrixD& own) {
  own = SparseMatrixD();
  own.swap(A);
  own.makeCompressed();
}

/// Takes A's storage (A is left empty), compressed, and checks it; the one entry point of every backend's compute.
Eigen::VectorXd take_matrix(SparseMatrixD& A, SparseMatrixD& own, const std::string& backend,
                            bool check_symmetry = true) {
  take_storage(A, own);
  return check_spd_input(own, backend, check_symmetry);
}

std::string format_number(double value, int digits = 3) {
  std::ostringstream s;
  s << std::setprecision(digits) << value;
  return s.str();
}

// ---------------------------------------------------------------------------------------------------------------
// CHOLMOD

class CholmodSolver final : public LinearSolver {
 public:
  /// amd_only: order with AMD alone, a cheap analysis whose flop count bounds the default one's from above
  /// (auto uses it to rule cholmod out without paying for METIS).
  explicit CholmodSolver(bool amd_only = false) {
    cholmod_l_start(&common_);
    common_.supernodal = CHOLMOD_SUPERNODAL;
    // nmethods = 0: CHOLMOD orders with AMD and also tries METIS (keeping the sparser factor) whenever
    // AMD's fill looks poor, which is the case for the 3D-mesh Laplacians we solve.
    common_.nmethods = 0;
    if (amd_only) {
      common_.nmethods = 1;
      common_.method[0].ordering = CHOLMOD_AMD;
      common_.postorder = 1;
    }
    // Failures surface as SolverError with our own message; CHOLMOD's printing would only duplicate them.
    common_.print = 0;
  }
  ~CholmodSolver() override {
    free_factor();
    free_lower();
    cholmod_l_finish(&common_);
  }
  CholmodSolver(const CholmodSolver&) = delete;
  CholmodSolver& operator=(const CholmodSolver&) = delete;

  std::string name() const override { return "cholmod"; }

  void compute_taking(SparseMatrixD& A) override {
    const auto start = Clock::now();
    ready_ = false;
    check_spd_input(A, name());
    analyze_taking(A);
    factorize_analyzed();
    setup_seconds_ = seconds_since(start);
  }

  /// Symbolic analysis only (ordering, supernodes, flop count), for a matrix the caller has checked; auto
  /// uses flops() and factor_entries() to estimate the factorisation before paying for it.
  void analyze_checked(const SparseMatrixD& A) {
    SparseMatrixD copy = A;
    analyze_taking(copy);
  }

  /// analyze_checked on A's storage, which it takes (A is left empty).
  void analyze_taking(SparseMatrixD& A) {
    const auto start = Clock::now();
    ready_ = false;
    free_factor();
    free_lower();
    take_storage(A, A_);
    if (A_.cols() > 0) analyze_lower();
    analyze_seconds_ = seconds_since(start);
  }

  /// Numeric factorisation after analyze_checked; the symbolic factor is reused.
  void factorize_analyzed() {
    const auto start = Clock::now();
    if (A_.cols() > 0) factorize_lower();
    factorize_seconds_ = seconds_since(start);
    setup_seconds_ = analyze_seconds_ + factorize_seconds_;
    ready_ = true;
  }

  double flops() const { return common_.fl; }
  /// Entries the numeric factor will hold (supernodal storage, padding included) once factorised.
  double factor_entries() const {
    if (factor_ != nullptr && factor_->is_super && factor_->xsize > 0) return static_cast<double>(factor_->xsize);
    return common_.lnz;
  }
  double analyze_seconds() const { return analyze_seconds_; }
  double factorize_seconds() const { return factorize_seconds_; }
  /// Peak of CHOLMOD's own allocations so far: matrix copy, symbolic and numeric factor, workspace.
  std::int64_t peak_bytes() const { return static_cast<std::int64_t>(common_.memory_usage); }

  SolveReport solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    check_rhs(A_, b, ready_, name());
    const auto start = Clock::now();
    const Eigen::Index n = A_.rows();
    x.resize(n);
    int solves = 0;
    if (n > 0) {
      x = back_substitute(b);
      ++solves;
      // Iterative refinement with the same factor: the slivers of iso-surfacing make the Laplacian
      // ill-conditioned, and one or two corrections take the error in s from ~1e-11 to roundoff.
      double residual = relative_residual(A_, b, x);
      for (int step = 0; step < kRefinementSteps && residual > 0.0; ++step) {
        const Eigen::VectorXd correction = back_substitute(b - A_ * x);
        ++solves;
        const Eigen::VectorXd refined = x + correction;
        const double refined_residual = relative_residual(A_, b, refined);
        if (!(refined_residual < residual)) break;
        x = refined;
        residual = refined_residual;
      }
    }
    SolveReport report;
    report.backend = name();
    report.iterations = solves;
    report.setup_seconds = setup_seconds_;
    report.residual = relative_residual(A_, b, x);
    report.solve_seconds = seconds_since(start);
    // CHOLMOD's peak covers its copy of A, the factor and the dense right-hand sides; the refinement adds the
    // residual, correction and refined vectors.
    report.memory_bytes = peak_bytes() + 3 * static_cast<std::int64_t>(n) * kDoubleBytes;
    return report;
  }

  /// One forward and backward substitution with the factor (no refinement).
  Eigen::VectorXd back_substitute(const Eigen::VectorXd& rhs) {
    const Eigen::Index n = rhs.size();
    cholmod_dense* B =
        cholmod_l_allocate_dense(static_cast<std::size_t>(n), 1, static_cast<std::size_t>(n), CHOLMOD_REAL, &common_);
    if (B == nullptr) throw SolverError("cholmod: out of memory allocating the right-hand side");
    std::copy(rhs.data(), rhs.data() + n, static_cast<double*>(B->x));
    cholmod_dense* X = cholmod_l_solve(CHOLMOD_A, factor_, B, &common_);
    cholmod_l_free_dense(&B, &common_);
    if (X == nullptr || common_.status < CHOLMOD_OK) {
      if (X != nullptr) cholmod_l_free_dense(&X, &common_);
      throw SolverError("cholmod: solve failed (status " + std::to_string(common_.status) + ")");
    }
    Eigen::VectorXd out(n);
    const double* xs = static_cast<const double*>(X->x);
    std::copy(xs, xs + n, out.data());
    cholmod_l_free_dense(&X, &common_);
    return out;
  }

 private:
  static constexpr int kRefinementSteps = 2;

  /// Hands CHOLMOD the lower triangle (stype = -1): it reads only one triangle of a symmetric matrix.
  void analyze_lower() {
    const Eigen::Index n = A_.cols();
    std::size_t lower_nnz = 0;
    for (Eigen::Index j = 0; j < n; ++j) {
      for (SparseMatrixD::InnerIterator it(A_, j); it; ++it) {
        if (it.row() >= j) ++lower_nnz;
      }
    }
    lower_ = cholmod_l_allocate_sparse(static_cast<std::size_t>(n), static_cast<std::size_t>(n), lower_nnz, 1, 1, -1,
                                       CHOLMOD_REAL, &common_);
    if (lower_ == nullptr) throw SolverError("cholmod: out of memory allocating the matrix");
    auto* p = static_cast<SuiteSparse_long*>(lower_->p);
    auto* i = static_cast<SuiteSparse_long*>(lower_->i);
    auto* v = static_cast<double*>(lower_->x);
    SuiteSparse_long k = 0;
    for (Eigen::Index j = 0; j < n; ++j) {
      p[j] = k;
      for (SparseMatrixD::InnerIterator it(A_, j); it; ++it) {
        if (it.row() < j) continue;
        i[k] = it.row();
        v[k] = it.value();
        ++k;
      }
    }
    p[n] = k;

    factor_ = cholmod_l_analyze(lower_, &common_);
    if (factor_ == nullptr) {
      free_lower();
      throw SolverError("cholmod: symbolic analysis failed (status " + std::to_string(common_.status) + ")");
    }
  }

  void factorize_lower() {
    const Eigen::Index n = A_.cols();
    if (factor_ == nullptr || lower_ == nullptr) throw SolverError("cholmod: factorisation called before analysis");
    cholmod_l_factorize(lower_, factor_, &common_);
    free_lower();
    if (common_.status == CHOLMOD_NOT_POSDEF) {
      // minor counts pivots in CHOLMOD's fill-reducing order; report the caller's column.
      long column = static_cast<long>(factor_->minor);
      if (factor_->Perm != nullptr && column >= 0 && column < static_cast<long>(n)) {
        column = static_cast<long>(static_cast<const SuiteSparse_long*>(factor_->Perm)[column]);
      }
      free_factor();
      throw SolverError("cholmod: matrix is not positive definite (column " + std::to_string(column) + ")");
    }
    if (common_.status < CHOLMOD_OK) {
      const int status = common_.status;
      free_factor();
      throw SolverError("cholmod: factorisation failed (status " + std::to_string(status) + ")");
    }
  }

  void free_factor() {
    if (factor_ != nullptr) cholmod_l_free_factor(&factor_, &common_);
  }
  void free_lower() {
    if (lower_ != nullptr) cholmod_l_free_sparse(&lower_, &common_);
  }

  cholmod_common common_{};
  cholmod_factor* factor_ = nullptr;
  cholmod_sparse* lower_ = nullptr;  // held between analysis and factorisation only
  SparseMatrixD A_;                  // kept for the true residual of every solve
  double analyze_seconds_ = 0.0;
  double factorize_seconds_ = 0.0;
  double setup_seconds_ = 0.0;
  bool ready_ = false;
};

// ---------------------------------------------------------------------------------------------------------------
// Preconditioned conjugate gradients: "cg" (Jacobi), "cg-ic" (incomplete Cholesky), "cg-amg" (aggregation AMG)

// ---------------------------------------------------------------------------------------------------------------
// Aggregation algebraic multigrid (cg-amg's preconditioner)
//
// Written here because no well-kept library serves on this machine: Debian's hypre 2.26 BoomerAMG is serial (no
// OpenMP build), needs MPI_Init (0.3 s, pulls OpenMPI) and took 0.35 s set-up + 0.34 s solve on a 287k-unknown
// 7-point Poisson system, no faster than Jacobi-CG on our morph systems; Trilinos ML and PETSc GAMG come with MPI
// too. The hierarchy is plain (unsmoothed) aggregation, whose Galerkin products are sums of entries and cost
// little to set up: smoothed aggregation cut the iterations by a third on a 28k-unknown morph system but made the
// coarse operators 2.7x denser and the set-up 3x longer.

/// Compressed rows of a sparse matrix. For a symmetric level operator rows and columns coincide, so Eigen's CSC
/// storage of A reads as this.
template <typename T>
struct Csr {
  int rows = 0;
  std::vector<int> start = {0};  ///< rows + 1 offsets
  std::vector<int> col;
  std::vector<T> val;
};

/// Non-owning view of compressed rows (Eigen's arrays for the finest level, a Csr for the others).
struct CsrView {
  int rows = 0;
  const int* start = nullptr;
  const int* col = nullptr;
  const double* val = nullptr;
};

CsrView view(const Csr<double>& M) { return {M.rows, M.start.data(), M.col.data(), M.val.data()}; }
CsrView view(const SparseMatrixD& A) { return {int(A.rows()), A.outerIndexPtr(), A.innerIndexPtr(), A.valuePtr()}; }

/// Runs f(begin, end) over the fixed row blocks of an n-row operand: in parallel when there are several, inline
/// when there is one (coarse levels, where a task would cost more than the work).
template <typename F>
void for_row_blocks(int n, const F& f) {
  const int blocks = int(block_count(n));
  if (blocks <= 1) {
    if (n > 0) f(0, n);
    return;
  }
  tbb::parallel_for(0, blocks,
                    [&](int block) { f(block * int(kBlockRows), std::min(n, (block + 1) * int(kBlockRows))); });
}

/// Strength-of-connection aggregation (Vanek, Mandel and Brezina 1996), within each fixed block of kBlockRows rows:
/// j is a strong neighbour of i when it lies in i's block and |a_ij| >= theta sqrt(a_ii a_jj). Phase 1: a node whose
/// strong neighbours are all free founds an aggregate with them. Phase 2: a free node joins the phase-1 aggregate of
/// its strongest strong neighbour. Phase 3: what is left founds aggregates with its free strong neighbours. Blocks
/// run in parallel, each in node order, and are numbered in block order, so the result does not depend on the
/// thread count. Confining aggregates to blocks costs little (a block's boundary rows are a small part of it) and
/// keeps each aggregate's rows close in memory, which makes the Galerkin product and the transfers cache friendly.
std::vector<int> aggregate_strong(const CsrView& A, const std::vector<double>& diag, double theta, int& count,
                                  std::vector<int>& offset) {
  const int n = A.rows;
  std::vector<double> scale(static_cast<std::size_t>(n));
  for_row_blocks(n, [&](int begin, int end) {
    for (int i = begin; i < end; ++i) scale[std::size_t(i)] = 1.0 / std::sqrt(diag[std::size_t(i)]);
  });
  std::vector<char> strong(std::size_t(A.start[n]), 0);
  std::vector<int> agg(std::size_t(n), -1);
  std::vector<int> block_aggregates(static_cast<std::size_t>(std::max<Eigen::Index>(1, block_count(n))), 0);
  for_row_blocks(n, [&](int begin, int end) {
    for (int i = begin; i < end; ++i) {
      const double threshold = theta / scale[std::size_t(i)];
      for (int k = A.start[i]; k < A.start[i + 1]; ++k) {
        const int j = A.col[k];
        strong[std::size_t(k)] =
            j != i && j >= begin && j < end && std::abs(A.val[k]) * scale[std::size_t(j)] >= threshold;
      }
    }
    int local = 0;
    for (int i = begin; i < end; ++i) {
      if (agg[std::size_t(i)] >= 0) continue;
      bool free = true, any = false;
      for (int k = A.start[i]; k < A.start[i + 1] && free; ++k) {
        if (!strong[std::size_t(k)]) continue;
        any = true;
        free = agg[std::size_t(A.col[k])] < 0;
      }
      if (!free || !any) continue;
      for (int k = A.start[i]; k < A.start[i + 1]; ++k)
        if (strong[std::size_t(k)]) agg[std::size_t(A.col[k])] = local;
      agg[std::size_t(i)] = local++;
    }
    const std::vector<int> first(agg.begin() + begin, agg.begin() + end);
    for (int i = begin; i < end; ++i) {
      if (agg[std::size_t(i)] >= 0) continue;
      double best = 0.0;
      for (int k = A.start[i]; k < A.start[i + 1]; ++k) {
        const int j = A.col[k];
        if (!strong[std::size_t(k)] || first[std::size_t(j - begin)] < 0) continue;
        const double w = std::abs(A.val[k]) * scale[std::size_t(j)];
        if (w > best) {
          best = w;
          agg[std::size_t(i)] = first[std::size_t(j - begin)];
        }
      }
    }
    for (int i = begin; i < end; ++i) {
      if (agg[std::size_t(i)] >= 0) continue;
      for (int k = A.start[i]; k < A.start[i + 1]; ++k)
        if (strong[std::size_t(k)] && agg[std::size_t(A.col[k])] < 0) agg[std::size_t(A.col[k])] = local;
      agg[std::size_t(i)] = local++;
    }
    block_aggregates[std::size_t(begin / int(kBlockRows))] = local;
  });
  // Local numbers to global ones, block by block.
  offset.assign(block_aggregates.size() + 1, 0);
  for (std::size_t block = 0; block < block_aggregates.size(); ++block)
    offset[block + 1] = offset[block] + block_aggregates[block];
  count = offset.back();
  for_row_blocks(n, [&](int begin, int end) {
    const int shift = offset[std::size_t(begin / int(kBlockRows))];
    for (int i = begin; i < end; ++i) agg[std::size_t(i)] += shift;
  });
  return agg;
}

/// One level of the hierarchy. Its smoother is l1-Jacobi, x <- x + D^-1 (b - A x) with
/// D_i = (sum_j |a_ij|) / kJacobiWeight, which converges for any SPD A (D - A/2 is positive definite) and whose
/// sweeps are plain row products with no dependency between rows. (With a K-cycle, a symmetric hybrid Gauss-Seidel
/// by row blocks took 30 iterations where l1-Jacobi took 33 on the 1.6M-tet sphere -> bunny system, but each of its
/// sweeps cost about two SpMVs: a chain of dependent rows and several short spans per row.) The cycle reads the
/// operator only as S = A D^-1, in single precision (it only preconditions, so float values cut the bytes of each sweep
/// by a third at no cost in CG iterations): with u = D x, A x = S u, so each of a cycle's two sweeps is one pass over
/// S.
struct AmgLevel {
  int n = 0;
  Csr<double> op;              // the operator below the finest level: pattern kept (it is S's), values until set up
  const int* start = nullptr;  // S's pattern: A's own arrays on the finest level, op's below
  const int* col = nullptr;
  std::vector<float> val;                    // S = A D^-1
  std::vector<std::int16_t> offset;          // col[k] - i for row i's entries k, when every one fits (else empty)
  std::vector<double> scale, inverse_scale;  // D, D^-1 (a multiply per row instead of a division)
  std::vector<int> agg;                      // row -> row of the next coarser level
  std::vector<int> member_start, members;    // row of the next coarser level -> its rows here, in order (set-up)
  std::vector<int> block_offset;             // row block k's aggregates are block_offset[k] .. block_offset[k + 1] - 1
  Eigen::VectorXd b, x, u;                   // right-hand side and solution (below the finest level), D (x + P e)
};

/// Sum of val[k] * x[index[k]] over k in [begin, last), with two interleaved partial sums (a row has ~15 entries).
template <class Index>
inline double sparse_row_dot(const float* val, const Index* index, int begin, int last, const double* x) {
  double even = 0.0, odd = 0.0;
  int k = begin;
  for (; k + 1 < last; k += 2) {
    even += double(val[k]) * x[index[k]];
    odd += double(val[k + 1]) * x[index[k + 1]];
  }
  if (k < last) even += double(val[k]) * x[index[k]];
  return even + odd;
}

/// Row i of S times v. Columns are read as 16-bit offsets from the row where they fit (AmgLevel::offset): each pass
/// over S then moves 6 bytes an entry instead of 8, the same products in the same order.
inline double level_row(const AmgLevel& L, int i, const double* v) {
  if (!L.offset.empty()) return sparse_row_dot(L.val.data(), L.offset.data(), L.start[i], L.start[i + 1], v + i);
  return sparse_row_dot(L.val.data(), L.col, L.start[i], L.start[i + 1], v);
}

/// Galerkin operator P^T A P of the piecewise-constant prolongation of L.agg: coarse row c sums the rows of its
/// members, entry by entry, into the aggregates of their columns. Coarse rows in parallel over fixed blocks, each
/// summed in member and storage order and sorted by column, so the result does not depend on the thread count.
Csr<double> galerkin_rows(const CsrView& A, const AmgLevel& L, int count) {
  const int blocks = int(block_count(count));
  std::vector<std::vector<std::pair<int, double>>> parts(std::size_t(std::max(blocks, 1)));
  std::vector<int> length(static_cast<std::size_t>(count), 0);
  tbb::enumerable_thread_specific<std::vector<int>> markers([&] { return std::vector<int>(std::size_t(count), -1); });
  for_row_blocks(count, [&](int begin, int end) {
    std::vector<int>& slot = markers.local();
    auto& out = parts[std::size_t(begin / int(kBlockRows))];
    for (int c = begin; c < end; ++c) {
      const std::size_t row_begin = out.size();
      for (int m = L.member_start[std::size_t(c)]; m < L.member_start[std::size_t(c) + 1]; ++m) {
        const int i = L.members[std::size_t(m)];
        for (int k = A.start[i]; k < A.start[i + 1]; ++k) {
          const int d = L.agg[std::size_t(A.col[k])];
          int& q = slot[std::size_t(d)];
          if (q < 0) {
            q = int(out.size() - row_begin);
            out.emplace_back(d, A.val[k]);
          } else {
            out[row_begin + std::size_t(q)].second += A.val[k];
          }
        }
      }
      for (std::size_t e = row_begin; e < out.size(); ++e) slot[std::size_t(out[e].first)] = -1;
      std::sort(out.begin() + std::ptrdiff_t(row_begin), out.end(),
                [](const auto& x, const auto& y) { return x.first < y.first; });
      length[std::size_t(c)] = int(out.size() - row_begin);
    }
  });
  Csr<double> C;
  C.rows = count;
  C.start.resize(std::size_t(count) + 1);
  C.start[0] = 0;
  for (int c = 0; c < count; ++c) C.start[std::size_t(c) + 1] = C.start[std::size_t(c)] + length[std::size_t(c)];
  C.col.reserve(std::size_t(C.start.back()));
  C.val.reserve(std::size_t(C.start.back()));
  for (const auto& part : parts) {
    for (const auto& e : part) {
      C.col.push_back(e.first);
      C.val.push_back(e.second);
    }
  }
  return C;
}

/// The preconditioner of cg-amg: one V-cycle of aggregation multigrid, l1-Jacobi pre- and post-smoothing (the
/// same symmetric smoother, so the cycle is a symmetric positive definite operator and plain CG applies), down to
/// a coarsest level solved by Cholesky. (Notay's K-cycle, two flexible-CG steps on every coarse level, took 33
/// instead of 40 iterations on the 1.6M-tet sphere -> bunny system but no less time; over-correcting the coarse
/// correction by 1.3-1.8 took more iterations.) Every kernel runs over fixed row blocks and sums in a fixed order, so z
/// is bitwise the same for any thread count.
class AggregationMultigrid {
 public:
  /// Builds the hierarchy of A (checked by the caller): aggregation and Galerkin products until a level has at
  /// most options.amg_coarsest unknowns, or aggregation stops reducing.
  void compute(const SparseMatrixD& A, const SolveOptions& options) {
    levels_.clear();
    levels_.reserve(kMaxLevels);
    Csr<double> next;
    for (int depth = 0;; ++depth) {
      levels_.emplace_back();
      AmgLevel& L = levels_.back();
      if (depth > 0) L.op = std::move(next);
      const CsrView Av = depth == 0 ? view(A) : view(L.op);
      L.n = Av.rows;
      const std::vector<double> diagonal = prepare_smoother(L, Av);
      // The finest level's right-hand side is CG's residual and its solution z: it needs only u.
      if (depth > 0) {
        L.b.resize(L.n);
        L.x.resize(L.n);
      }
      L.u.resize(L.n);
      if (L.n <= options.amg_coarsest || depth + 1 == int(kMaxLevels)) break;
      int count = 0;
      L.agg = aggregate_strong(Av, diagonal, options.amg_strength * std::pow(0.5, depth), count, L.block_offset);
      if (count == 0 || count * 10 > L.n * 9) break;  // too little progress to be worth a level
      members_of(L, count);
      next = galerkin_rows(Av, L, count);
      L.member_start = std::vector<int>();
      L.members = std::vector<int>();
    }
    // The coarsest operator is factorised exactly: densely when it is as small as amg_coarsest asks (a dense solve
    // has no permutation or temporaries to pay for at every cycle), else sparse (aggregation stalled, e.g. on a
    // diagonal matrix).
    AmgLevel& C = levels_.back();
    const CsrView last = levels_.size() == 1 ? view(A) : view(C.op);
    if (C.n <= kDenseCoarsest) {
      Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(C.n, C.n);
      for (int i = 0; i < C.n; ++i)
        for (int k = last.start[i]; k < last.start[i + 1]; ++k) dense(last.col[k], i) = last.val[k];
      dense_factor_.compute(dense);
      if (dense_factor_.info() != Eigen::Success) throw coarsest_failed(C.n);
    } else {
      SparseMatrixD coarse(C.n, C.n);
      coarse.resizeNonZeros(last.start[C.n]);
      std::copy(last.start, last.start + C.n + 1, coarse.outerIndexPtr());
      std::copy(last.col, last.col + last.start[C.n], coarse.innerIndexPtr());
      std::copy(last.val, last.val + last.start[C.n], coarse.valuePtr());
      sparse_factor_.compute(coarse);
      if (sparse_factor_.info() != Eigen::Success) throw coarsest_failed(C.n);
    }
    for (AmgLevel& L : levels_) L.op.val = std::vector<double>();
  }

  /// z = M^-1 r by one V-cycle; returns r . z, summed over fixed blocks in the last pass.
  double apply(const Eigen::VectorXd& r, Eigen::VectorXd& z) {
    z.resize(r.size());
    if (levels_.size() == 1) {
      z = r;
      solve_coarsest(z);
      return z.dot(r);
    }
    const AmgLevel& L = levels_[0];
    descend(0, r);
    partial_.assign(static_cast<std::size_t>(block_count(L.n)), 0.0);
    for_row_blocks(L.n, [&](int begin, int end) {
      double rz = 0.0;
      for (int i = begin; i < end; ++i) {
        z(i) = post_smooth(L, r, i);
        rz += r(i) * z(i);
      }
      partial_[std::size_t(begin / int(kBlockRows))] = rz;
    });
    return std::accumulate(partial_.begin(), partial_.end(), 0.0);
  }

  /// The finest level's columns as 16-bit offsets from their row, in the storage order of the matrix given to
  /// compute() (whose arrays that level shares), or null when some column is too far from its row.
  const std::int16_t* fine_offsets() const {
    return levels_.empty() || levels_[0].offset.empty() ? nullptr : levels_[0].offset.data();
  }

  /// Unknowns and stored entries of every level, finest first: "249554 (3592586), 48303 (742099), ...".
  std::string describe() const {
    std::ostringstream s;
    for (const AmgLevel& L : levels_) s << (&L == &levels_[0] ? "" : ", ") << L.n << " (" << L.val.size() << ")";
    return s.str();
  }

  std::int64_t memory_bytes() const {
    std::int64_t bytes = 0;
    for (const AmgLevel& L : levels_) {
      bytes +=
          std::int64_t(L.val.size()) * std::int64_t(sizeof(float)) +
          std::int64_t(L.offset.size()) * std::int64_t(sizeof(std::int16_t)) +
          std::int64_t(L.op.start.size() + L.op.col.size() + L.agg.size() + L.members.size() + L.member_start.size()) *
              kIndexBytes +
          std::int64_t(L.scale.size() + L.inverse_scale.size() + L.b.size() + L.x.size() + L.u.size()) * kDoubleBytes;
    }
    const Eigen::Index coarsest = levels_.empty() ? 0 : levels_.back().n;
    if (coarsest <= kDenseCoarsest) return bytes + std::int64_t(coarsest) * coarsest * kDoubleBytes;
    return bytes + sparse_bytes(sparse_factor_.matrixL().nestedExpression().nonZeros(), coarsest);
  }

 private:
  // Measured on the 1.6M-tet sphere -> bunny system with a K-cycle (PCG iterations to 1e-8): weight 1.0 (plain
  // l1-Jacobi): 39, 1.4: 34, 1.6: 33, 1.8: 33. Below 2 the smoother stays convergent.
  static constexpr double kJacobiWeight = 1.6;
  static constexpr int kDenseCoarsest = 2000;
  static constexpr std::size_t kMaxLevels = 16;

  static SolverError coarsest_failed(int n) {
    return SolverError("cg-amg: Cholesky factorisation of the coarsest level (" + std::to_string(n) +
                       " unknowns) failed: its Galerkin operator is not numerically positive definite");
  }

  /// S = A D^-1 in single precision and D; returns the diagonal of A.
  static std::vector<double> prepare_smoother(AmgLevel& L, const CsrView& A) {
    const int n = L.n;
    std::vector<double> diagonal(static_cast<std::size_t>(n), 0.0);
    L.scale.resize(std::size_t(n));
    L.inverse_scale.resize(std::size_t(n));
    for_row_blocks(n, [&](int begin, int end) {
      for (int i = begin; i < end; ++i) {
        double l1 = 0.0;
        for (int k = A.start[i]; k < A.start[i + 1]; ++k) {
          if (A.col[k] == i) diagonal[std::size_t(i)] += A.val[k];
          l1 += std::abs(A.val[k]);
        }
        L.scale[std::size_t(i)] = l1 / kJacobiWeight;
        L.inverse_scale[std::size_t(i)] = kJacobiWeight / l1;
      }
    });
    L.start = A.start;
    L.col = A.col;
    // The extraction numbers vertices cell by cell, so a row's columns lie within a few slabs of it: on cow -> horse
    // (260 k unknowns) every offset is below 18700.
    L.offset.resize(std::size_t(A.start[n]));
    std::atomic<bool> short_offsets{true};
    for_row_blocks(n, [&](int begin, int end) {
      for (int i = begin; i < end; ++i)
        for (int k = A.start[i]; k < A.start[i + 1]; ++k) {
          const int offset = A.col[k] - i;
          if (std::abs(offset) > std::numeric_limits<std::int16_t>::max()) short_offsets = false;
          L.offset[std::size_t(k)] = std::int16_t(offset);
        }
    });
    if (!short_offsets) L.offset = std::vector<std::int16_t>();
    L.val.resize(std::size_t(A.start[n]));
    for_row_blocks(n, [&](int begin, int end) {
      for (int i = begin; i < end; ++i)
        for (int k = A.start[i]; k < A.start[i + 1]; ++k)
          L.val[std::size_t(k)] = float(A.val[k] * L.inverse_scale[std::size_t(A.col[k])]);
    });
    return diagonal;
  }

  /// The rows of each aggregate in increasing order (a counting sort of agg).
  static void members_of(AmgLevel& L, int count) {
    L.member_start.assign(std::size_t(count) + 1, 0);
    for (int a : L.agg) ++L.member_start[std::size_t(a) + 1];
    for (int c = 0; c < count; ++c) L.member_start[std::size_t(c) + 1] += L.member_start[std::size_t(c)];
    L.members.resize(L.agg.size());
    std::vector<int> cursor(L.member_start.begin(), L.member_start.end() - 1);
    for (int i = 0; i < L.n; ++i) L.members[std::size_t(cursor[std::size_t(L.agg[std::size_t(i)])]++)] = i;
  }

  void solve_coarsest(Eigen::VectorXd& x) const {
    if (levels_.back().n <= kDenseCoarsest) {
      dense_factor_.solveInPlace(x);
    } else {
      x = sparse_factor_.solve(x);
    }
  }

  /// Post-smoothing of row i once descend(l, b) has set u = D (x + P e): x_i + D_i^-1 (b - A (x + P e))_i, which is
  /// (u_i + b_i - (S u)_i) / D_i.
  static double post_smooth(const AmgLevel& L, const Eigen::VectorXd& b, int i) {
    return (L.u(i) + b(i) - level_row(L, i, L.u.data())) * L.inverse_scale[std::size_t(i)];
  }

  /// The V-cycle on level l down to the coarse correction. Pre-smoothing from x = 0 gives x = D^-1 b, whose
  /// residual b - A D^-1 b = b - S b takes one pass; it is restricted (a gather over each aggregate's members, in
  /// cache: computing the rows in member order instead would read A out of order) and corrected on the coarser
  /// level; then u = D (x + P e) = b + D P e, ready for the post-smoothing pass, which the caller runs (apply fuses
  /// CG's r . z into it).
  void descend(std::size_t l, const Eigen::VectorXd& b) {
    AmgLevel& L = levels_[l];
    AmgLevel& C = levels_[l + 1];
    // A row block's aggregates hold rows of that block only, so the block restricts its own residual rows as it
    // computes them, in row order (the order of a sum over each aggregate's members), with no residual vector.
    for_row_blocks(L.n, [&](int begin, int end) {
      const std::size_t block = std::size_t(begin / int(kBlockRows));
      for (int c = L.block_offset[block]; c < L.block_offset[block + 1]; ++c) C.b(c) = 0.0;
      for (int i = begin; i < end; ++i) C.b(L.agg[std::size_t(i)]) += b(i) - level_row(L, i, b.data());
    });
    if (l + 2 == levels_.size()) {
      C.x = C.b;
      solve_coarsest(C.x);
    } else {
      descend(l + 1, C.b);
      for_row_blocks(C.n, [&](int begin, int end) {
        for (int i = begin; i < end; ++i) C.x(i) = post_smooth(C, C.b, i);
      });
    }
    for_row_blocks(L.n, [&](int begin, int end) {
      for (int i = begin; i < end; ++i) L.u(i) = b(i) + L.scale[std::size_t(i)] * C.x(L.agg[std::size_t(i)]);
    });
  }

  std::vector<AmgLevel> levels_;
  std::vector<double> partial_;
  Eigen::LLT<Eigen::MatrixXd> dense_factor_;
  Eigen::SimplicialLLT<SparseMatrixD, Eigen::Lower, Eigen::AMDOrdering<int>> sparse_factor_;
};

/// The coarse part of deflated CG (DeflationSpace): A Z by rows, the Cholesky factor of E = Z^T A Z and the two
/// transfers. Written by hand: Eigen's sparse product is sequential and general, where a row of Z has at most two
/// entries and a row of A Z a handful (the Z columns of the row's neighbours). Every sum has one order whatever the
/// thread count: A Z's rows are built block by block in row order, E's entries are summed in row order, and the
/// restriction Z^T v sums each row block into its own span of columns and adds the spans in block order.
class Deflation {
 public:
  bool active() const { return columns_ > 0; }
  int columns() const { return columns_; }

  /// Builds A Z and factorises E. An empty space (0 columns) leaves deflation off. Throws InvalidInput for a
  /// malformed space; false when E is not numerically positive definite (dependent columns), deflation then off.
  bool compute(const SparseMatrixD& A, const DeflationSpace& space, const std::string& backend) {
    columns_ = 0;
    az_start_.clear();
    az_col_.clear();
    az_val_.clear();
    if (space.columns <= 0) return true;
    const Eigen::Index n = A.rows();
    if (space.column.rows() != n || space.weight.rows() != n) {
      std::ostringstream msg;
      msg << backend << ": deflation space has " << space.column.rows() << " rows for " << n << " unknowns";
      throw InvalidInput(msg.str());
    }
    if (n > 0 && (space.column.maxCoeff() >= space.columns || space.column.minCoeff() < -1)) {
      std::ostringstream msg;
      msg << backend << ": deflation space has a column index outside [-1, " << space.columns << ")";
      throw InvalidInput(msg.str());
    }
    z_col_ = space.column;
    z_val_ = space.weight;
    // Rows of A Z, block by block (each block's rows in order), then concatenated in block order.
    const Eigen::Index blocks = block_count(n);
    std::vector<std::vector<int>> block_col(static_cast<std::size_t>(blocks));
    std::vector<std::vector<double>> block_val(static_cast<std::size_t>(blocks));
    std::vector<int> row_length(static_cast<std::size_t>(n));
    tbb::parallel_for(Eigen::Index(0), blocks, [&](Eigen::Index block) {
      std::vector<int>& cols = block_col[static_cast<std::size_t>(block)];
      std::vector<double>& vals = block_val[static_cast<std::size_t>(block)];
      const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
      for (Eigen::Index i = block * kBlockRows; i < end; ++i) {
        const std::size_t first = cols.size();
        for (SparseMatrixD::InnerIterator it(A, i); it; ++it) {
          for (int e = 0; e < 2; ++e) {
            const int c = z_col_(it.index(), e);
            if (c < 0) continue;
            const double value = it.value() * z_val_(it.index(), e);
            std::size_t at = first;
            while (at < cols.size() && cols[at] != c) ++at;
            if (at == cols.size()) {
              cols.push_back(c);
              vals.push_back(value);
            } else {
              vals[at] += value;
            }
          }
        }
        row_length[static_cast<std::size_t>(i)] = int(cols.size() - first);
      }
    });
    az_start_.assign(static_cast<std::size_t>(n) + 1, 0);
    for (Eigen::Index i = 0; i < n; ++i)
      az_start_[static_cast<std::size_t>(i) + 1] = az_start_[static_cast<std::size_t>(i)] + row_length[std::size_t(i)];
    az_col_.reserve(std::size_t(az_start_.back()));
    az_val_.reserve(std::size_t(az_start_.back()));
    for (Eigen::Index block = 0; block < blocks; ++block) {
      az_col_.insert(az_col_.end(), block_col[std::size_t(block)].begin(), block_col[std::size_t(block)].end());
      az_val_.insert(az_val_.end(), block_val[std::size_t(block)].begin(), block_val[std::size_t(block)].end());
      std::vector<int>().swap(block_col[std::size_t(block)]);
      std::vector<double>().swap(block_val[std::size_t(block)]);
    }
    // E = Z^T (A Z), lower triangle (what the factorisation reads). Each entry E(a, c) sums z(i, a) (A Z)(i, c) over
    // the rows i of column a in increasing order, the order in which a triplet list in row order would have summed
    // it, so E is the same to the bit; but the sums are kept per column a in a scratch row instead of as one triplet
    // per product, which on cow -> horse was a 29 MB list (1.8 M triplets for E's 50 k entries) at the set-up's
    // peak of memory.
    std::vector<int> z_start(std::size_t(space.columns) + 1, 0);
    for (Eigen::Index i = 0; i < n; ++i)
      for (int e = 0; e < 2; ++e)
        if (z_col_(i, e) >= 0) ++z_start[std::size_t(z_col_(i, e)) + 1];
    for (int a = 0; a < space.columns; ++a) z_start[std::size_t(a) + 1] += z_start[std::size_t(a)];
    std::vector<std::pair<int, double>> z_rows(std::size_t(z_start.back()));  // (row, weight) by column, rows rising
    {
      std::vector<int> fill(z_start.begin(), z_start.end() - 1);
      for (Eigen::Index i = 0; i < n; ++i)
        for (int e = 0; e < 2; ++e)
          if (z_col_(i, e) >= 0) z_rows[std::size_t(fill[std::size_t(z_col_(i, e))]++)] = {int(i), z_val_(i, e)};
    }
    std::vector<Eigen::Triplet<double>> entries;
    std::vector<double> row_sum(std::size_t(space.columns), 0.0);
    std::vector<char> used(std::size_t(space.columns), 0);
    std::vector<int> touched;
    for (int a = 0; a < space.columns; ++a) {
      touched.clear();
      for (int j = z_start[std::size_t(a)]; j < z_start[std::size_t(a) + 1]; ++j) {
        const auto [i, weight] = z_rows[std::size_t(j)];
        for (int k = az_start_[std::size_t(i)]; k < az_start_[std::size_t(i) + 1]; ++k) {
          const int c = az_col_[std::size_t(k)];
          if (c > a) continue;
          const double value = weight * az_val_[std::size_t(k)];
          if (!used[std::size_t(c)]) {
            used[std::size_t(c)] = 1;
            touched.push_back(c);
            row_sum[std::size_t(c)] = value;
          } else {
            row_sum[std::size_t(c)] += value;
          }
        }
      }
      for (const int c : touched) {
        entries.emplace_back(a, c, row_sum[std::size_t(c)]);
        used[std::size_t(c)] = 0;
      }
    }
    SparseMatrixD E(space.columns, space.columns);
    E.setFromTriplets(entries.begin(), entries.end());
    factor_.compute(E);
    if (factor_.info() != Eigen::Success) {
      az_start_.clear();
      az_col_.clear();
      az_val_.clear();
      return false;
    }
    // The column span of each row block, for restrict_to_coarse.
    span_lo_.assign(static_cast<std::size_t>(blocks), 0);
    span_start_.assign(static_cast<std::size_t>(blocks) + 1, 0);
    for (Eigen::Index block = 0; block < blocks; ++block) {
      int lo = std::numeric_limits<int>::max(), hi = -1;
      for (Eigen::Index i = block * kBlockRows; i < std::min(n, (block + 1) * kBlockRows); ++i)
        for (int e = 0; e < 2; ++e)
          if (z_col_(i, e) >= 0) {
            lo = std::min(lo, z_col_(i, e));
            hi = std::max(hi, z_col_(i, e));
          }
      span_lo_[std::size_t(block)] = hi < 0 ? 0 : lo;
      span_start_[std::size_t(block) + 1] = span_start_[std::size_t(block)] + (hi < 0 ? 0 : hi - lo + 1);
    }
    partial_.resize(static_cast<std::size_t>(span_start_.back()));
    columns_ = space.columns;
    coarse_.resize(columns_);
    return true;
  }

  /// coarse = Z^T v: each row block sums its rows in order into its own span of columns (the Laplace stage numbers
  /// columns in order of first use, so a block's span is short), and the spans are added in block order.
  void restrict_to_coarse(const Eigen::VectorXd& v, Eigen::VectorXd& coarse) {
    const Eigen::Index n = v.size();
    tbb::parallel_for(Eigen::Index(0), block_count(n), [&](Eigen::Index block) {
      const std::size_t b = static_cast<std::size_t>(block);
      double* sum = partial_.data() + span_start_[b];
      std::fill(sum, sum + (span_start_[b + 1] - span_start_[b]), 0.0);
      const int lo = span_lo_[b];
      const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
      for (Eigen::Index i = block * kBlockRows; i < end; ++i)
        for (int e = 0; e < 2; ++e)
          if (z_col_(i, e) >= 0) sum[z_col_(i, e) - lo] += z_val_(i, e) * v(i);
    });
    coarse.setZero(columns_);
    for (std::size_t b = 0; b + 1 < span_start_.size(); ++b) {
      const double* sum = partial_.data() + span_start_[b];
      for (std::int64_t k = 0; k < span_start_[b + 1] - span_start_[b]; ++k) coarse(span_lo_[b] + k) += sum[k];
    }
  }

  /// y = E^-1 Z^T v, kept for az_row.
  void solve_coarse(const Eigen::VectorXd& v) {
    restrict_to_coarse(v, coarse_);
    y_ = factor_.solve(coarse_);
  }
  /// (Z^T v) . y after solve_coarse(v): v . A Z E^-1 Z^T v.
  double coarse_energy() const { return coarse_.dot(y_); }

  /// Row i of A Z y, y from the last solve_coarse.
  double az_row(Eigen::Index i) const {
    double sum = 0.0;
    for (int k = az_start_[std::size_t(i)]; k < az_start_[std::size_t(i) + 1]; ++k)
      sum += az_val_[std::size_t(k)] * y_(az_col_[std::size_t(k)]);
    return sum;
  }

  /// x <- x + Z E^-1 (Z^T b - (A Z)^T x): from the deflated iterate to the solution of A x = b.
  void complete(const Eigen::VectorXd& b, Eigen::VectorXd& x) {
    restrict_to_coarse(b, coarse_);
    for (Eigen::Index i = 0; i < x.size(); ++i)
      for (int k = az_start_[std::size_t(i)]; k < az_start_[std::size_t(i) + 1]; ++k)
        coarse_(az_col_[std::size_t(k)]) -= az_val_[std::size_t(k)] * x(i);
    y_ = factor_.solve(coarse_);
    for_blocks(x.size(), [&](Eigen::Index i) {
      for (int e = 0; e < 2; ++e)
        if (z_col_(i, e) >= 0) x(i) += z_val_(i, e) * y_(z_col_(i, e));
    });
  }

  std::int64_t memory_bytes() const {
    if (!active()) return 0;
    const std::int64_t n = z_col_.rows();
    const std::int64_t factor = factor_.matrixL().nestedExpression().nonZeros();
    return n * 2 * (kIndexBytes + kDoubleBytes) + std::int64_t(az_col_.size()) * (kIndexBytes + kDoubleBytes) +
           (n + 1) * kIndexBytes + factor * (kIndexBytes + kDoubleBytes) + 3 * std::int64_t(columns_) * kDoubleBytes;
  }

 private:
  int columns_ = 0;
  Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor> z_col_;
  Eigen::Matrix<double, Eigen::Dynamic, 2, Eigen::RowMajor> z_val_;
  std::vector<int> az_start_, az_col_;
  std::vector<double> az_val_;
  Eigen::SimplicialLLT<SparseMatrixD, Eigen::Lower, Eigen::AMDOrdering<int>> factor_;
  Eigen::VectorXd coarse_, y_;
  std::vector<int> span_lo_;              // per row block: its first column
  std::vector<std::int64_t> span_start_;  // per row block: where its span starts in partial_
  std::vector<double> partial_;
};

enum class Preconditioner { Jacobi, IncompleteCholesky, Multigrid };

class PcgSolver final : public LinearSolver {
 public:
  PcgSolver(const SolveOptions& options, Preconditioner preconditioner)
      : options_(options), preconditioner_(preconditioner) {}

  std::string name() const override {
    return preconditioner_ == Preconditioner::Jacobi      ? "cg"
           : preconditioner_ == Preconditioner::Multigrid ? "cg-amg"
                                                          : "cg-ic";
  }

  void compute_taking(SparseMatrixD& A) override {
    const auto start = Clock::now();
    ready_ = false;
    const Eigen::VectorXd diagonal = take_matrix(A, A_, name(), !options_.symmetric_by_construction);
    setup(diagonal);
    setup_seconds_ = seconds_since(start);
  }

  /// compute() for a matrix (and its diagonal) the caller has already checked.
  void compute_checked(const SparseMatrixD& A, const Eigen::VectorXd& diagonal) {
    const auto start = Clock::now();
    ready_ = false;
    A_ = A;
    A_.makeCompressed();
    setup(diagonal);
    setup_seconds_ = seconds_since(start);
  }

  double setup_seconds() const { return setup_seconds_; }

  SolveReport solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    check_rhs(A_, b, ready_, name());
    const auto start_time = Clock::now();
    start(b, x);
    return finish(b, x, start_time);
  }

  /// Runs CG begun by start() to convergence (or SolverError at max_iterations) and reports, iterations counted
  /// from start(). start() + advance() + finish() computes exactly what solve() does: the same iterates, bit for bit.
  SolveReport finish(const Eigen::VectorXd& b, Eigen::VectorXd& x, Clock::time_point start_time) {
    advance(b, x, options_.max_iterations, true, nullptr);
    SolveReport report;
    report.backend = name();
    report.setup_seconds = setup_seconds_;
    report.iterations = iterations_;
    report.residual = relative_residual(A_, b, x);
    report.solve_seconds = seconds_since(start_time);
    report.memory_bytes = memory_bytes();
    if (preconditioner_ == Preconditioner::Multigrid) report.detail = "cg-amg levels: " + amg_.describe();
    report.deflation_columns = deflation_.columns();
    if (deflation_.active()) {
      report.detail += std::string(report.detail.empty() ? "" : "; ") + "deflated by " +
                       std::to_string(deflation_.columns()) + " coarse columns";
    } else if (deflation_failed_) {
      report.detail += std::string(report.detail.empty() ? "" : "; ") +
                       "deflation off: Z^T A Z is not numerically positive definite (dependent columns)";
    }
    return report;
  }

  /// Storage held: the preconditioner, the CG vectors r, z, p, q (and the work vector of cg-ic) and the
  /// per-block partial sums.
  std::int64_t memory_bytes() const {
    const auto n = static_cast<std::int64_t>(A_.rows());
    const std::int64_t partials = 2 * static_cast<std::int64_t>(block_count(A_.rows())) * kDoubleBytes;
    const std::int64_t deflation = deflation_.memory_bytes();
    if (preconditioner_ == Preconditioner::Jacobi) return 5 * n * kDoubleBytes + partials + deflation;
    if (preconditioner_ == Preconditioner::Multigrid)
      return 5 * n * kDoubleBytes + partials + amg_.memory_bytes() + deflation;
    // L, the scaling S, and the vectors r, z, p, q, w.
    const std::int64_t factor = n > 0 ? sparse_bytes(ic_.matrixL().nonZeros(), n) : 0;
    return factor + n * kDoubleBytes + 5 * n * kDoubleBytes + partials + deflation;
  }

  /// Begins CG on A x = b from x (zero if it is empty or not finite). A zero b gives x = 0, converged at once.
  void start(const Eigen::VectorXd& b, Eigen::VectorXd& x) {
    const Eigen::Index n = A_.rows();
    iterations_ = 0;
    converged_ = false;
    complete_ = false;
    if (x.size() != n || !x.allFinite()) x = Eigen::VectorXd::Zero(n);
    b_norm_ = std::sqrt(dot(b, b));
    if (b_norm_ == 0.0) {
      // The unique solution; CG would divide by |b| = 0.
      x.setZero();
      converged_ = true;
      return;
    }
    target_ = options_.tolerance * b_norm_;
    r_.resize(n);
    z_.resize(n);
    p_.resize(n);
    q_.resize(n);
    rr_ = residual(b, x, r_);
    if (deflation_.active()) rr_ = deflate(r_);
    complete_ = deflation_.active();
    rz_ = precondition(r_, z_);
    p_ = z_;
  }

  /// Continues CG (same b and x as start()) until converged or `limit` iterations since start(); past the limit
  /// throws SolverError when `throw_on_limit`. Appends |r_k| / |b| (the recurrence residual) after every
  /// iteration k reached to `history` when given. Returns whether it converged.
  bool advance(const Eigen::VectorXd& b, Eigen::VectorXd& x, int limit, bool throw_on_limit,
               std::vector<double>* history) {
    const Eigen::Index n = A_.rows();
    while (!converged_) {
      if (std::sqrt(rr_) <= target_) {
        // The recurrence for r drifts from b - A x; accept only the true residual, else restart from it.
        rr_ = residual(b, x, r_);
        if (deflation_.active()) rr_ = deflate(r_);
        if (std::sqrt(rr_) <= target_) {
          converged_ = true;
          break;
        }
        rz_ = precondition(r_, z_);
        p_ = z_;
      }
      if (history != nullptr) history->push_back(std::sqrt(rr_) / b_norm_);
      if (iterations_ >= limit) {
        if (!throw_on_limit) break;
        std::ostringstream msg;
        msg << name() << ": no convergence after " << iterations_ << " iterations (relative residual "
            << std::sqrt(rr_) / b_norm_ << ", tolerance " << options_.tolerance << ")";
        throw SolverError(msg.str());
      }
      double pq = multiply_dot(p_, q_);
      if (deflation_.active()) {
        // The deflated operator P A, P = I - A Z E^-1 Z^T: (P A p)_i = q_i - (A Z y)_i with y = E^-1 Z^T q, and
        // p . P A p = p . q - (Z^T q) . y (A is symmetric). The update passes subtract A Z y from q on the fly.
        deflation_.solve_coarse(q_);
        pq -= deflation_.coarse_energy();
      }
      if (!(pq > 0.0) || !std::isfinite(pq)) {
        throw SolverError(name() + ": matrix is not positive definite (p^T A p = " + std::to_string(pq) + ")");
      }
      const double alpha = rz_ / pq;
      double rz_next = 0.0;
      if (preconditioner_ == Preconditioner::Jacobi) {
        rz_next = update_jacobi(alpha, x, rr_);
      } else {
        rr_ = update(alpha, x);
        rz_next = precondition(r_, z_);
      }
      const double beta = rz_next / rz_;
      rz_ = rz_next;
      for_blocks(n, [&](Eigen::Index i) { p_(i) = z_(i) + beta * p_(i); });
      ++iterations_;
    }
    if (converged_ && complete_) {
      // CG ran on P A x = P b; x + Z E^-1 Z^T (b - A x) solves A x = b, with the residual P (b - A x) just checked.
      deflation_.complete(b, x);
      complete_ = false;
    }
    return converged_;
  }

  int iterations() const { return iterations_; }

 private:
  void setup(const Eigen::VectorXd& diagonal) {
    // The deflation's set-up has sequential parts (Z^T A Z's entries, its factorisation): it runs beside the
    // preconditioner's, whose passes are parallel. Both are deterministic, so the result does not depend on the
    // schedule; wait() rethrows an exception of either.
    tbb::task_group group;
    bool deflated = true;
    group.run([&] { deflated = deflation_.compute(A_, deflation_space_, name()); });
    group.run([&] { setup_preconditioner(diagonal); });
    group.wait();
    deflation_failed_ = !deflated;
    ready_ = true;
  }

  void setup_preconditioner(const Eigen::VectorXd& diagonal) {
    if (preconditioner_ == Preconditioner::Jacobi) {
      inverse_diagonal_ = diagonal.cwiseInverse();
    } else if (preconditioner_ == Preconditioner::Multigrid) {
      amg_.compute(A_, options_);
      offsets_ = amg_.fine_offsets();
    } else if (A_.rows() > 0) {
      // Lin-More incomplete Cholesky: the pattern of A's lower triangle, with a diagonal shift retried until the
      // factorisation exists. Natural ordering: our unknowns come in the extraction's spatially coherent order,
      // which keeps the triangular solves cache friendly. With AMD an iteration took twice as long on a
      // 124k-unknown morph system for 10% fewer iterations, and an anisotropic system took 10x more iterations
      // (minimum degree orders are known to be poor for incomplete factorisations). Sequential, so the same for
      // any thread count.
      ic_.compute(A_);
      if (ic_.info() != Eigen::Success) throw SolverError("cg-ic: incomplete Cholesky factorisation failed");
      w_.resize(A_.rows());
    }
  }

  double dot(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
    return block_sum(a.size(), partial_a_, [&](Eigen::Index i) { return a(i) * b(i); });
  }

  /// r = b - A x; returns |r|^2.
  double residual(const Eigen::VectorXd& b, const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    return block_sum(b.size(), partial_a_, [&](Eigen::Index i) {
      r(i) = b(i) - row_times(A_, offsets_, i, x);
      return r(i) * r(i);
    });
  }

  /// r <- P r = r - A Z E^-1 Z^T r; returns |r|^2.
  double deflate(Eigen::VectorXd& r) {
    deflation_.solve_coarse(r);
    return block_sum(r.size(), partial_a_, [&](Eigen::Index i) {
      r(i) -= deflation_.az_row(i);
      return r(i) * r(i);
    });
  }

  /// z = M^-1 r; returns r.z.
  double precondition(const Eigen::VectorXd& r, Eigen::VectorXd& z) {
    if (preconditioner_ == Preconditioner::Jacobi) {
      return block_sum(r.size(), partial_a_, [&](Eigen::Index i) {
        z(i) = inverse_diagonal_(i) * r(i);
        return r(i) * z(i);
      });
    }
    if (preconditioner_ == Preconditioner::Multigrid) return amg_.apply(r, z);
    // z = S L^-T L^-1 S r (Eigen's IncompleteCholesky::solve without its temporaries; no permutation with the
    // natural ordering). The two triangular solves are sequential: they are the part of cg-ic that does not scale
    // with threads, and they read about as many bytes as the SpMV, so an IC iteration costs two to three Jacobi
    // iterations.
    w_ = r.cwiseProduct(ic_.scalingS());
    ic_.matrixL().triangularView<Eigen::Lower>().solveInPlace(w_);
    ic_.matrixL().adjoint().triangularView<Eigen::Upper>().solveInPlace(w_);
    z = w_.cwiseProduct(ic_.scalingS());
    return dot(r, z);
  }

  /// q = A p; returns p.q.
  double multiply_dot(const Eigen::VectorXd& p, Eigen::VectorXd& q) {
    return block_sum(p.size(), partial_a_, [&](Eigen::Index i) {
      q(i) = row_times(A_, offsets_, i, p);
      return p(i) * q(i);
    });
  }

  /// x += alpha p, r -= alpha P q (P q = q - A Z y when deflated); returns r.r.
  double update(double alpha, Eigen::VectorXd& x) {
    const bool deflated = deflation_.active();
    return block_sum(x.size(), partial_a_, [&](Eigen::Index i) {
      x(i) += alpha * p_(i);
      r_(i) -= alpha * projected_q(i, deflated);
      return r_(i) * r_(i);
    });
  }

  /// (P A p)_i: q_i, less (A Z y)_i when deflated (y from the iteration's solve_coarse(q)).
  double projected_q(Eigen::Index i, bool deflated) const { return deflated ? q_(i) - deflation_.az_row(i) : q_(i); }

  /// x += alpha p, r -= alpha q, z = D^-1 r in one pass; returns r.z and sets rr = r.r.
  double update_jacobi(double alpha, Eigen::VectorXd& x, double& rr) {
    const Eigen::Index n = x.size();
    const Eigen::Index blocks = block_count(n);
    partial_a_.resize(static_cast<std::size_t>(blocks));
    partial_b_.resize(static_cast<std::size_t>(blocks));
    const bool deflated = deflation_.active();
    tbb::parallel_for(Eigen::Index(0), blocks, [&](Eigen::Index block) {
      const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
      double rz_sum = 0.0, rr_sum = 0.0;
      for (Eigen::Index i = block * kBlockRows; i < end; ++i) {
        x(i) += alpha * p_(i);
        r_(i) -= alpha * projected_q(i, deflated);
        z_(i) = inverse_diagonal_(i) * r_(i);
        rz_sum += r_(i) * z_(i);
        rr_sum += r_(i) * r_(i);
      }
      partial_a_[static_cast<std::size_t>(block)] = rz_sum;
      partial_b_[static_cast<std::size_t>(block)] = rr_sum;
    });
    double rz = 0.0;
    rr = 0.0;
    for (Eigen::Index block = 0; block < blocks; ++block) {
      rz += partial_a_[static_cast<std::size_t>(block)];
      rr += partial_b_[static_cast<std::size_t>(block)];
    }
    return rz;
  }

  SolveOptions options_;
  Preconditioner preconditioner_;
  SparseMatrixD A_;
  Eigen::VectorXd inverse_diagonal_;
  Eigen::IncompleteCholesky<double, Eigen::Lower, Eigen::NaturalOrdering<int>> ic_;
  AggregationMultigrid amg_;
  const std::int16_t* offsets_ = nullptr;  // A_'s columns as offsets (the multigrid's, for cg-amg), or null
  Deflation deflation_;
  bool deflation_failed_ = false;  // a space was given but Z^T A Z could not be factorised
  bool complete_ = false;          // x is the deflated iterate until advance() completes it at convergence
  Eigen::VectorXd r_, z_, p_, q_, w_;
  std::vector<double> partial_a_, partial_b_;
  // CG state between start() and the end of advance(): |r|^2, r.z, |b|, the absolute target, the count.
  double rr_ = 0.0, rz_ = 0.0, b_norm_ = 0.0, target_ = 0.0;
  int iterations_ = 0;
  bool converged_ = false;
  double setup_seconds_ = 0.0;
  bool ready_ = false;
};

// ---------------------------------------------------------------------------------------------------------------
// Gauss-Seidel diffusion (the paper's iteration)

class GaussSeidelSolver final : public LinearSolver {
 public:
  explicit GaussSeidelSolver(const SolveOptions& options) : options_(options) {}

  std::string name() const override { return "gauss-seidel"; }

  void compute_taking(SparseMatrixD& A) override {
    const auto start = Clock::now();
    ready_ = false;
    inverse_diagonal_ = take_matrix(A, A_, name()).cwiseInverse();
    setup_seconds_ = seconds_since(start);
    ready_ = true;
  }

  /// Sweeps x_i = (b_i - sum_{j != i} A_ij x_j) / A_ii over i = 0..n-1 in order, each update using the values
  /// already updated in this sweep. The paper stops "when the total change in the scalar values is below a
  /// desired threshold": by default the change is that total, sum |x_i(new) - x_i(old)|; ChangeMeasure::Mean
  /// divides it by n, so that a threshold does not depend on the mesh size (the paper's Table I lists 0.0109,
  /// 0.00119 and 0.000204 after 1, 10 and 100 sweeps, Table II stops at 1e-5). Reaching max_iterations sweeps is
  /// not an error: the paper's Table I rows are fixed sweep counts. The sweep is inherently sequential, hence
  /// deterministic.
  SolveReport solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    check_rhs(A_, b, ready_, name());
    const auto start = Clock::now();
    const Eigen::Index n = A_.rows();
    if (x.size() != n || !x.allFinite()) x = Eigen::VectorXd::Zero(n);
    SolveReport report;
    report.backend = name();
    report.setup_seconds = setup_seconds_;
    report.memory_bytes = static_cast<std::int64_t>(n) * kDoubleBytes;  // the inverse diagonal
    if (b.squaredNorm() == 0.0) {
      // The unique solution, as the other backends return it; sweeping would only approach it.
      x.setZero();
      report.solve_seconds = seconds_since(start);
      return report;
    }
    const int* outer = A_.outerIndexPtr();
    const int* inner = A_.innerIndexPtr();
    const double* values = A_.valuePtr();
    double* xs = x.data();
    int sweeps = 0;
    double change = 0.0;
    while (sweeps < options_.max_iterations) {
      double total = 0.0;
      for (Eigen::Index i = 0; i < n; ++i) {
        double sum = 0.0;
        for (int k = outer[i]; k < outer[i + 1]; ++k) {
          if (inner[k] != i) sum += values[k] * xs[inner[k]];
        }
        const double next = (b(i) - sum) * inverse_diagonal_(i);
        total += std::abs(next - xs[i]);
        xs[i] = next;
      }
      ++sweeps;
      const bool mean = options_.change_measure == ChangeMeasure::Mean;
      change = mean && n > 0 ? total / static_cast<double>(n) : total;
      if (!std::isfinite(change)) {
        throw SolverError("gauss-seidel: diverged after " + std::to_string(sweeps) + " sweeps");
      }
      if (change < options_.change_threshold || change == 0.0) break;
    }
    report.iterations = sweeps;
    report.change = change;
    report.residual = relative_residual(A_, b, x);
    report.solve_seconds = seconds_since(start);
    return report;
  }

 private:
  SolveOptions options_;
  SparseMatrixD A_;
  Eigen::VectorXd inverse_diagonal_;
  double setup_seconds_ = 0.0;
  bool ready_ = false;
};

// ---------------------------------------------------------------------------------------------------------------
// Eigen's SimplicialLDLT (the reference)

class LdltSolver final : public LinearSolver {
 public:
  std::string name() const override { return "ldlt"; }

  void compute_taking(SparseMatrixD& A) override {
    const auto start = Clock::now();
    ready_ = false;
    take_matrix(A, A_, name());
    if (A_.rows() > 0) {
      ldlt_.compute(A_);
      // LDL^T exists for some indefinite matrices too; positive definite means every pivot in D is positive.
      if (ldlt_.info() != Eigen::Success || !(ldlt_.vectorD().minCoeff() > 0.0)) {
        throw SolverError("ldlt: matrix is not positive definite");
      }
    }
    setup_seconds_ = seconds_since(start);
    ready_ = true;
  }

  SolveReport solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    check_rhs(A_, b, ready_, name());
    const auto start = Clock::now();
    const Eigen::Index n = A_.rows();
    if (n > 0) {
      x = ldlt_.solve(b);
    } else {
      x.resize(0);
    }
    SolveReport report;
    report.backend = name();
    report.iterations = 1;
    report.setup_seconds = setup_seconds_;
    report.residual = relative_residual(A_, b, x);
    report.solve_seconds = seconds_since(start);
    const auto nn = static_cast<std::int64_t>(n);
    // L, D, the permutation and its inverse, the elimination tree and column counts, and the solve's temporary.
    const std::int64_t factor = n > 0 ? sparse_bytes(ldlt_.matrixL().nestedExpression().nonZeros(), nn) : 0;
    report.memory_bytes = factor + nn * kDoubleBytes + 4 * nn * kIndexBytes + nn * kDoubleBytes;
    return report;
  }

 private:
  SparseMatrixD A_;
  Eigen::SimplicialLDLT<SparseMatrixD, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt_;
  double setup_seconds_ = 0.0;
  bool ready_ = false;
};

// ---------------------------------------------------------------------------------------------------------------
// auto: pick by measurement

/// CHOLMOD's speed on this machine, measured once per process, as a two-term model of the supernodal numeric
/// factorisation: seconds = flops * seconds_per_flop + entries * seconds_per_entry. The first term is the dense
/// BLAS work (rate measured on a dense matrix: one supernode); the second the sparse bookkeeping (assembly and
/// scatter of update matrices), measured as what a 3D grid Laplacian takes beyond its flops. On our systems
/// the model came within a factor 2 of the measured factorisation from 1e8 to 4e11 flops, where one flop rate
/// alone was off by up to 4x.
struct CholmodRate {
  double seconds_per_flop = 0.0;     ///< dense factorisation
  double seconds_per_entry = 0.0;    ///< per entry of the supernodal factor, beyond the flops
  double solve_per_entry = 0.0;      ///< one forward + backward substitution, per entry of the factor
  double calibration_seconds = 0.0;  ///< what measuring took

  double factorize_seconds(double flops, double entries) const {
    return flops * seconds_per_flop + entries * seconds_per_entry;
  }
};

/// Best of two factorisations (the first also pays for starting the BLAS threads): seconds, flops, entries,
/// and the seconds of one substitution.
struct CholmodTiming {
  double seconds = std::numeric_limits<double>::infinity();
  double flops = 0.0;
  double entries = 0.0;
  double solve_seconds = std::numeric_limits<double>::infinity();
};

CholmodTiming time_cholmod(const SparseMatrixD& A) {
  CholmodTiming timing;
  for (int run = 0; run < 2; ++run) {
    CholmodSolver solver;
    solver.analyze_checked(A);
    timing.flops = solver.flops();
    timing.entries = solver.factor_entries();
    solver.factorize_analyzed();
    timing.seconds = std::min(timing.seconds, solver.factorize_seconds());
    const auto start = Clock::now();
    solver.back_substitute(Eigen::VectorXd::Ones(A.rows()));
    timing.solve_seconds = std::min(timing.solve_seconds, seconds_since(start));
  }
  return timing;
}

/// The dense term alone (about 0.1 s to measure): enough for auto's lower bound, which most systems stop at.
const CholmodRate& cholmod_dense_rate() {
  static const CholmodRate rate = [] {
    const auto start = Clock::now();
    // 1200 unknowns, 5.8e8 flops in one supernode.
    constexpr int n = 1200;
    Eigen::MatrixXd dense = Eigen::MatrixXd::Constant(n, n, 1.0);
    dense.diagonal().array() += n;
    const CholmodTiming timing = time_cholmod(dense.sparseView());
    CholmodRate measured;
    measured.seconds_per_flop = timing.seconds / timing.flops;
    measured.calibration_seconds = seconds_since(start);
    return measured;
  }();
  return rate;
}

/// Both terms and the substitution speed (another ~0.2 s to measure).
const CholmodRate& cholmod_rate() {
  static const CholmodRate rate = [] {
    const auto start = Clock::now();
    CholmodRate measured = cholmod_dense_rate();
    // 3D grid Laplacian: 20^3 = 8000 unknowns, ~3e8 flops in many small supernodes.
    constexpr int k = 20;
    const int n = k * k * k;
    std::vector<Eigen::Triplet<double, int>> triplets;
    triplets.reserve(static_cast<std::size_t>(7 * n));
    auto id = [&](int i, int j, int l) { return (l * k + j) * k + i; };
    auto link = [&](int a, int b) {
      triplets.emplace_back(a, b, -1.0);
      triplets.emplace_back(b, a, -1.0);
    };
    for (int l = 0; l < k; ++l) {
      for (int j = 0; j < k; ++j) {
        for (int i = 0; i < k; ++i) {
          const int v = id(i, j, l);
          triplets.emplace_back(v, v, 6.0);
          if (i + 1 < k) link(v, id(i + 1, j, l));
          if (j + 1 < k) link(v, id(i, j + 1, l));
          if (l + 1 < k) link(v, id(i, j, l + 1));
        }
      }
    }
    SparseMatrixD grid(n, n);
    grid.setFromTriplets(triplets.begin(), triplets.end());
    const CholmodTiming timing = time_cholmod(grid);
    const double beyond_flops = std::max(0.0, timing.seconds - timing.flops * measured.seconds_per_flop);
    measured.seconds_per_entry = beyond_flops / timing.entries;
    measured.solve_per_entry = timing.solve_seconds / timing.entries;
    measured.calibration_seconds += seconds_since(start);
    return measured;
  }();
  return rate;
}

/// "auto": on the first solve, estimates for cg-amg, cg, cg-ic and cholmod the time to the tolerance on this very
/// system, then runs the fastest.
///  - cg-amg (the default) first: set up, then kProbeIterations iterations from the caller's initial guess; seconds
///    per iteration and the residual reduction per iteration over the second half of the probe (the first
///    iterations of CG barely reduce the residual of a smooth warm start, then it converges geometrically)
///    extrapolate to the tolerance. On our morph systems it converges within or just past its probe.
///  - The others only if they could win: a candidate's measurement costs at least kProbeFloorMultiplies sparse
///    products (cg and cg-ic: their probe iterations; cholmod: its AMD analysis, measured at ~150 products), timed
///    here with one product; when that floor exceeds cg-amg's estimated time to go, no candidate can save more than
///    its measurement costs, so none is measured. Otherwise cg and cg-ic are probed like cg-amg, and cholmod is
///    estimated by probe_cholmod (symbolic analysis for the flop count, converted with a rate measured once per
///    process).
///  The probes are resumable, so the chosen CG variant continues where its probe stopped: x is bitwise what the named
///  backend alone computes, and only the losers' probes are overhead. Gauss-Seidel and ldlt are references, not
///  candidates. The report names the backend that ran; `detail` lists every estimate or why it was skipped.
///  setup_seconds covers all probes (including the iterations of the chosen CG variant's probe, which `iterations`
///  also counts) and the chosen backend's set-up.
class AutoSolver final : public LinearSolver {
 public:
  explicit AutoSolver(const SolveOptions& options) : options_(options) {}

  std::string name() const override { return "auto"; }

  void compute_taking(SparseMatrixD& A) override {
    ready_ = false;
    chosen_.reset();
    diagonal_ = take_matrix(A, A_, name());
    ready_ = true;
  }

  /// The first solve measures and chooses (the residual reduction of CG depends on b and the initial guess, so it
  /// cannot be measured in compute); later solves reuse the chosen backend and its set-up.
  SolveReport solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    check_rhs(A_, b, ready_, name());
    SolveReport report;
    if (chosen_) {
      report = chosen_->solve(b, x);
    } else {
      const auto start = Clock::now();
      choose(b, x);
      const double setup_seconds = seconds_since(start);
      const auto solve_start = Clock::now();
      if (running_ != nullptr) {
        report = running_->finish(b, x, solve_start);
        running_ = nullptr;
      } else {
        report = chosen_->solve(b, x);
      }
      setup_seconds_ = setup_seconds;
    }
    report.setup_seconds = setup_seconds_;
    report.memory_bytes = std::max(report.memory_bytes, probe_bytes_);
    report.detail = detail_;
    return report;
  }

 private:
  // Iterations each CG candidate runs to measure its speed. On our morph systems (100 to 300 iterations to 1e-8
  // from s = t) the rate over iterations 20-40 predicted the iteration count within ~20%; over 10-20 it was off
  // by up to 7x, because of the slow start.
  static constexpr int kProbeIterations = 40;
  // Largest reduction of factorisation flops of METIS over AMD allowed for (see probe_cholmod): 5.7x measured on a
  // 124k-unknown morph system; the margin covers larger ones, where the gain grows.
  static constexpr double kMetisGain = 10.0;

  // Cheapest measurement of cg, cg-ic or cholmod, in sparse products: a CG probe runs kProbeIterations of them;
  // cholmod's AMD analysis took ~150 on our morph systems (0.03 s at 28k unknowns, 0.55 s at 250k).
  static constexpr double kProbeFloorMultiplies = kProbeIterations;

  struct Estimate {
    std::string backend;
    double remaining = std::numeric_limits<double>::infinity();  ///< seconds from now to the tolerance
    double total = std::numeric_limits<double>::infinity();      ///< seconds from scratch (probe included)
    std::string how;
  };

  /// A CG variant being measured: its solver, its own iterate and its estimate.
  struct Candidate {
    std::unique_ptr<PcgSolver> solver;
    Eigen::VectorXd x;
    Estimate estimate;
  };

  /// Sets up one CG variant and runs its probe from x, leaving it resumable.
  Estimate probe_cg(PcgSolver& solver, const Eigen::VectorXd& b, Eigen::VectorXd& x) {
    Estimate e;
    e.backend = solver.name();
    solver.compute_checked(A_, diagonal_);
    const double setup = solver.setup_seconds();
    const auto start = Clock::now();
    std::vector<double> h;
    solver.start(b, x);
    // Seconds per iteration from the second half only: the first iterations also pay for touching the CG
    // vectors for the first time.
    bool converged = solver.advance(b, x, kProbeIterations / 2, false, &h);
    // advance() records the residual where it stops at the limit, and the next call records it again.
    if (!converged) h.pop_back();
    const int first_half = solver.iterations();
    const auto second_half_start = Clock::now();
    if (!converged) converged = solver.advance(b, x, kProbeIterations, false, &h);
    const double seconds = seconds_since(start);
    const int k = solver.iterations();
    const double per_iteration =
        k > first_half ? seconds_since(second_half_start) / (k - first_half) : seconds / std::max(1, k);
    std::ostringstream how;
    how << e.backend << ": setup " << format_number(setup) << " s, " << format_number(per_iteration) << " s/iter";
    if (converged) {
      e.remaining = 0.0;
      how << ", converged in the probe (" << k << " iter)";
    } else {
      // history[i] is the residual after i iterations. CG's residual is not monotone: if the second half shows no
      // reduction, fall back to the whole probe, and failing that, to the iteration limit.
      const int half = k / 2;
      const double last = h[static_cast<std::size_t>(k)];
      double rate = std::pow(last / h[static_cast<std::size_t>(half)], 1.0 / (k - half));
      if (!(rate < 1.0)) rate = std::pow(last / h[0], 1.0 / k);
      double left = std::numeric_limits<double>::infinity();
      if (rate > 0.0 && rate < 1.0) left = std::log(options_.tolerance / last) / std::log(rate);
      left = std::max(0.0, std::min(left, static_cast<double>(options_.max_iterations - k)));
      e.remaining = per_iteration * left;
      how << ", rate " << format_number(rate, 5) << "/iter, ~" << static_cast<long long>(k + left) << " iter";
    }
    e.total = setup + seconds + e.remaining;
    how << " -> " << format_number(e.total) << " s";
    e.how = how.str();
    return e;
  }

  /// Estimates cholmod. A cheap AMD-only analysis first: its flop count bounds from above what cholmod's own
  /// ordering (AMD or METIS, the sparser) will cost, and METIS cuts them by a bounded factor (kMetisGain). If
  /// even kMetisGain times fewer flops at the dense rate are slower than the best estimate so far, cholmod cannot
  /// win and its expensive METIS analysis (seconds on a million tets) is skipped. Otherwise the real analysis
  /// runs, kept in `solver` for the factorisation if cholmod is chosen.
  Estimate probe_cholmod(CholmodSolver& solver, double best_remaining) {
    Estimate e;
    e.backend = solver.name();
    // The first call in a process measures the rates; that time counts as auto's set-up but not as cholmod's.
    const CholmodRate& dense_rate = cholmod_dense_rate();
    std::ostringstream how;
    CholmodSolver amd(true);
    amd.analyze_checked(A_);
    const double lower_bound = amd.flops() / kMetisGain * dense_rate.seconds_per_flop;
    if (lower_bound >= best_remaining) {
      how << "cholmod (rate measured in " << format_number(dense_rate.calibration_seconds) << " s once per process): ";
      e.total = amd.analyze_seconds() + lower_bound;
      how << "AMD analysis " << format_number(amd.analyze_seconds()) << " s, " << format_number(amd.flops())
          << " flop; even " << kMetisGain << "x fewer flop at " << format_number(1e-9 / dense_rate.seconds_per_flop)
          << " Gflop/s take >= " << format_number(lower_bound) << " s, so not analysed further";
      e.how = how.str();
      return e;
    }
    const CholmodRate& rate = cholmod_rate();
    how << "cholmod (rates measured in " << format_number(rate.calibration_seconds) << " s once per process): ";
    solver.analyze_checked(A_);
    const double factorize = rate.factorize_seconds(solver.flops(), solver.factor_entries());
    // One substitution plus up to two refinement steps.
    const double substitutions = 3.0 * solver.factor_entries() * rate.solve_per_entry;
    e.remaining = factorize + substitutions;
    e.total = amd.analyze_seconds() + solver.analyze_seconds() + e.remaining;
    how << "analyze " << format_number(solver.analyze_seconds()) << " s, " << format_number(solver.flops())
        << " flop at " << format_number(1e-9 / rate.seconds_per_flop) << " Gflop/s + "
        << format_number(solver.factor_entries()) << " entries in L at " << format_number(rate.seconds_per_entry * 1e9)
        << " ns -> " << format_number(e.total) << " s";
    e.how = how.str();
    return e;
  }

  /// Measures the candidates and keeps the one with the least estimated time from now on (what is already spent
  /// is spent): chosen_ set up, and running_ pointing at it when it is a CG variant with its probe to continue.
  void choose(const Eigen::VectorXd& b, Eigen::VectorXd& x) {
    const Eigen::Index n = A_.rows();
    if (x.size() != n || !x.allFinite()) x = Eigen::VectorXd::Zero(n);
    std::ostringstream detail;
    std::vector<Candidate> candidates;
    candidates.reserve(3);  // no reallocation: `best` points into it
    candidates.push_back({std::make_unique<PcgSolver>(options_, Preconditioner::Multigrid), x, {}});
    Candidate& amg = candidates.back();
    amg.solver->set_deflation(deflation_space_);
    amg.estimate = probe_cg(*amg.solver, b, amg.x);
    detail << amg.estimate.how;
    probe_bytes_ = amg.solver->memory_bytes();
    const Candidate* best = &amg;
    std::unique_ptr<CholmodSolver> cholmod;
    Estimate cholmod_estimate;
    if (amg.estimate.remaining > 0.0) {
      // One product (after a first one that warms the caches) prices the cheapest possible measurement.
      Eigen::VectorXd y;
      symmetric_multiply(A_, x, y);
      const auto start = Clock::now();
      symmetric_multiply(A_, x, y);
      const double floor = kProbeFloorMultiplies * seconds_since(start);
      if (floor >= amg.estimate.remaining) {
        detail << "; cg, cg-ic, cholmod: not measured (measuring one takes >= " << format_number(floor)
               << " s, more than cg-amg's " << format_number(amg.estimate.remaining) << " s to go)";
      } else {
        for (Preconditioner kind : {Preconditioner::Jacobi, Preconditioner::IncompleteCholesky}) {
          candidates.push_back({std::make_unique<PcgSolver>(options_, kind), x, {}});
          Candidate& c = candidates.back();
          c.solver->set_deflation(deflation_space_);
          c.estimate = probe_cg(*c.solver, b, c.x);
          detail << "; " << c.estimate.how;
          probe_bytes_ += c.solver->memory_bytes();
        }
        best = &candidates[0];
        for (const Candidate& c : candidates)
          if (c.estimate.remaining < best->estimate.remaining) best = &c;
        cholmod = std::make_unique<CholmodSolver>();
        cholmod_estimate = probe_cholmod(*cholmod, best->estimate.remaining);
        detail << "; " << cholmod_estimate.how;
        probe_bytes_ += cholmod->peak_bytes();
      }
    }
    if (cholmod && cholmod_estimate.remaining < best->estimate.remaining) {
      detail << "; chose cholmod (" << format_number(cholmod_estimate.remaining) << " s to go)";
      cholmod->factorize_analyzed();
      chosen_ = std::move(cholmod);
    } else {
      detail << "; chose " << best->estimate.backend << " (" << format_number(best->estimate.remaining) << " s to go)";
      Candidate& winner = candidates[static_cast<std::size_t>(best - candidates.data())];
      x = winner.x;
      running_ = winner.solver.get();
      chosen_ = std::move(winner.solver);
    }
    detail_ = "auto: " + detail.str();
  }

  SolveOptions options_;
  SparseMatrixD A_;
  Eigen::VectorXd diagonal_;
  std::unique_ptr<LinearSolver> chosen_;
  PcgSolver* running_ = nullptr;  // chosen_ when it is a CG variant whose probe the first solve continues
  std::string detail_;
  double setup_seconds_ = 0.0;
  std::int64_t probe_bytes_ = 0;
  bool ready_ = false;
};

}  // namespace

std::vector<std::string> solver_names() { return {"cholmod", "cg", "cg-ic", "cg-amg", "gauss-seidel", "ldlt", "auto"}; }

std::unique_ptr<LinearSolver> make_solver(const std::string& name, const SolveOptions& options) {
  if (name == "cholmod") return std::make_unique<CholmodSolver>();
  if (name == "cg") return std::make_unique<PcgSolver>(options, Preconditioner::Jacobi);
  if (name == "cg-ic") return std::make_unique<PcgSolver>(options, Preconditioner::IncompleteCholesky);
  if (name == "cg-amg") return std::make_unique<PcgSolver>(options, Preconditioner::Multigrid);
  if (name == "gauss-seidel") return std::make_unique<GaussSeidelSolver>(options);
  if (name == "ldlt") return std::make_unique<LdltSolver>();
  if (name == "auto") return std::make_unique<AutoSolver>(options);
  std::string choices;
  for (const auto& known : solver_names()) choices += (choices.empty() ? "" : ", ") + known;
  throw InvalidInput("unknown solver '" + name + "' (choose " + choices + ")");
}

std::string change_measure_name(ChangeMeasure measure) { return measure == ChangeMeasure::Total ? "total" : "mean"; }

ChangeMeasure parse_change_measure(const std::string& name) {
  if (name == "total") return ChangeMeasure::Total;
  if (name == "mean") return ChangeMeasure::Mean;
  throw InvalidInput("unknown change measure '" + name + "' (choose total, mean)");
}

void symmetric_multiply(const SparseMatrixD& A, const Eigen::VectorXd& x, Eigen::VectorXd& y) {
  if (A.rows() != A.cols() || x.size() != A.cols()) {
    throw InvalidInput("symmetric_multiply: sizes do not match (" + std::to_string(A.rows()) + " by " +
                       std::to_string(A.cols()) + " times " + std::to_string(x.size()) + ")");
  }
  if (!A.isCompressed()) throw InvalidInput("symmetric_multiply: matrix is not compressed");
  y.resize(A.rows());
  for_blocks(A.rows(), [&](Eigen::Index i) { y(i) = row_times(A, i, x); });
}

std::int64_t symmetric_multiply_bytes(const SparseMatrixD& A) {
  const auto n = static_cast<std::int64_t>(A.rows());
  return sparse_bytes(static_cast<std::int64_t>(A.nonZeros()), n) + 2 * n * kDoubleBytes;
}

}  // namespace morphmap
