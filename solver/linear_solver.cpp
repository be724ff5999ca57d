// Sparse SPD solvers for the Laplace system of paper §6.1. The paper iterates Gauss-Seidel diffusion or
// runs conjugate gradients on the implicit step; we offer a supernodal Cholesky factorisation (CHOLMOD)
// and a Jacobi-preconditioned CG whose result does not depend on the number of threads.
#include "solver/linear_solver.h"

#include <cholmod.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

#include "mesh/errors.h"

namespace morphmap {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Relative tolerance of the symmetry check: assembly sums the same products for (i, j) and (j, i), so
// a real system is symmetric to rounding; anything larger is a caller's bug, not noise.
constexpr double kSymmetryTolerance = 1e-12;

// Rows per block of the CG kernels. Fixed (not derived from the thread count) so that the partial sums
// of every dot product, and hence every iterate, are bitwise identical for any number of threads.
constexpr Eigen::Index kBlockRows = 4096;

/// Rejects what a Cholesky or CG solve cannot handle, naming the backend in the message.
/// Returns the diagonal (every entry positive).
Eigen::VectorXd check_spd_input(const SparseMatrixD& A, const std::string& backend) {
  if (A.rows() != A.cols()) {
    std::ostringstream msg;
    msg << backend << ": matrix is not square (" << A.rows() << " by " << A.cols() << ")";
    throw SolverError(msg.str());
  }
  const Eigen::Index n = A.cols();
  double max_abs = 0.0;
  for (Eigen::Index j = 0; j < n; ++j) {
    for (SparseMatrixD::InnerIterator it(A, j); it; ++it) {
      if (!std::isfinite(it.value())) {
        std::ostringstream msg;
        msg << backend << ": matrix has a non-finite entry at (" << it.row() << ", " << j << ")";
        throw SolverError(msg.str());
      }
      max_abs = std::max(max_abs, std::abs(it.value()));
    }
  }

  // One flag per column, filled in parallel, then scanned in order so the reported column is always
  // the first offending one.
  std::vector<char> bad_diagonal(static_cast<std::size_t>(n), 0);
  std::vector<char> bad_symmetry(static_cast<std::size_t>(n), 0);
  Eigen::VectorXd diagonal = Eigen::VectorXd::Zero(n);
  const double tolerance = kSymmetryTolerance * max_abs;
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, n, 1024), [&](const tbb::blocked_range<Eigen::Index>& range) {
    for (Eigen::Index j = range.begin(); j != range.end(); ++j) {
      for (SparseMatrixD::InnerIterator it(A, j); it; ++it) {
        const Eigen::Index i = it.row();
        if (i == j) diagonal(j) += it.value();
        // coeff() is a binary search in a compressed column.
        else if (std::abs(it.value() - A.coeff(j, i)) > tolerance) bad_symmetry[static_cast<std::size_t>(j)] = 1;
      }
      if (!(diagonal(j) > 0.0)) bad_diagonal[static_cast<std::size_t>(j)] = 1;
    }
  });
  for (Eigen::Index j = 0; j < n; ++j) {
    if (bad_symmetry[static_cast<std::size_t>(j)]) {
      std::ostringstream msg;
      msg << backend << ": matrix is not symmetric (column " << j << ", tolerance " << tolerance << ")";
      throw SolverError(msg.str());
    }
    if (bad_diagonal[static_cast<std::size_t>(j)]) {
      std::ostringstream msg;
      msg << backend << ": matrix has a non-positive diagonal entry (column " << j << ")";
      throw SolverError(msg.str());
    }
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
double relative_residual(const SparseMatrixD& A, const Eigen::VectorXd& b, const Eigen::VectorXd& x) {
  const double b_norm = b.norm();
  const double r_norm = (b - A * x).norm();
  return b_norm > 0.0 ? r_norm / b_norm : r_norm;
}

// ---------------------------------------------------------------------------------------------------------------
// CHOLMOD

class CholmodSolver final : public LinearSolver {
 public:
  CholmodSolver() {
    cholmod_l_start(&common_);
    common_.supernodal = CHOLMOD_SUPERNODAL;
    // nmethods = 0: CHOLMOD orders with AMD and also tries METIS (keeping the sparser factor) whenever
    // AMD's fill looks poor, which is the case for the 3D-mesh Laplacians we solve.
    common_.nmethods = 0;
    // Failures surface as SolverError with our own message; CHOLMOD's printing would only duplicate them.
    common_.print = 0;
  }
  ~CholmodSolver() override {
    free_factor();
    cholmod_l_finish(&common_);
  }
  CholmodSolver(const CholmodSolver&) = delete;
  CholmodSolver& operator=(const CholmodSolver&) = delete;

  std::string name() const override { return "cholmod"; }

  void compute(const SparseMatrixD& A) override {
    const auto start = Clock::now();
    ready_ = false;
    free_factor();
    A_ = A;
    A_.makeCompressed();
    check_spd_input(A_, name());
    const Eigen::Index n = A_.cols();
    if (n > 0) factorize_lower();
    setup_seconds_ = seconds_since(start);
    ready_ = true;
  }

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
    return report;
  }

 private:
  static constexpr int kRefinementSteps = 2;

  Eigen::VectorXd back_substitute(const Eigen::VectorXd& rhs) {
    const Eigen::Index n = rhs.size();
    cholmod_dense* B = cholmod_l_allocate_dense(static_cast<std::size_t>(n), 1, static_cast<std::size_t>(n),
                                                CHOLMOD_REAL, &common_);
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

  /// Hands CHOLMOD the lower triangle (stype = -1): it reads only one triangle of a symmetric matrix.
  void factorize_lower() {
    const Eigen::Index n = A_.cols();
    std::size_t lower_nnz = 0;
    for (Eigen::Index j = 0; j < n; ++j) {
      for (SparseMatrixD::InnerIterator it(A_, j); it; ++it) {
        if (it.row() >= j) ++lower_nnz;
      }
    }
    cholmod_sparse* S = cholmod_l_allocate_sparse(static_cast<std::size_t>(n), static_cast<std::size_t>(n), lower_nnz,
                                                  1, 1, -1, CHOLMOD_REAL, &common_);
    if (S == nullptr) throw SolverError("cholmod: out of memory allocating the matrix");
    auto* p = static_cast<SuiteSparse_long*>(S->p);
    auto* i = static_cast<SuiteSparse_long*>(S->i);
    auto* v = static_cast<double*>(S->x);
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

    factor_ = cholmod_l_analyze(S, &common_);
    if (factor_ == nullptr) {
      cholmod_l_free_sparse(&S, &common_);
      throw SolverError("cholmod: symbolic analysis failed (status " + std::to_string(common_.status) + ")");
    }
    cholmod_l_factorize(S, factor_, &common_);
    cholmod_l_free_sparse(&S, &common_);
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

  cholmod_common common_{};
  cholmod_factor* factor_ = nullptr;
  SparseMatrixD A_;  // kept for the true residual of every solve
  double setup_seconds_ = 0.0;
  bool ready_ = false;
};

// ---------------------------------------------------------------------------------------------------------------
// Conjugate gradients

class CgSolver final : public LinearSolver {
 public:
  explicit CgSolver(const SolveOptions& options) : options_(options) {}

  std::string name() const override { return "cg"; }

  void compute(const SparseMatrixD& A) override {
    const auto start = Clock::now();
    ready_ = false;
    A_ = A;
    A_.makeCompressed();
    inverse_diagonal_ = check_spd_input(A_, name()).cwiseInverse();
    setup_seconds_ = seconds_since(start);
    ready_ = true;
  }

  SolveReport solve(const Eigen::VectorXd& b, Eigen::VectorXd& x) override {
    check_rhs(A_, b, ready_, name());
    const auto start = Clock::now();
    const Eigen::Index n = A_.rows();
    if (x.size() != n || !x.allFinite()) x = Eigen::VectorXd::Zero(n);

    SolveReport report;
    report.backend = name();
    report.setup_seconds = setup_seconds_;

    const Eigen::Index blocks = (n + kBlockRows - 1) / kBlockRows;
    partial_a_.assign(static_cast<std::size_t>(blocks), 0.0);
    partial_b_.assign(static_cast<std::size_t>(blocks), 0.0);

    const double b_norm = std::sqrt(dot(b, b));
    if (b_norm == 0.0) {
      // The unique solution; CG would divide by |b| = 0.
      x.setZero();
      report.solve_seconds = seconds_since(start);
      return report;
    }
    const double target = options_.tolerance * b_norm;

    Eigen::VectorXd r(n), z(n), p(n), q(n);
    double rr = residual(b, x, r);
    double rz = precondition(r, z);
    p = z;
    int iterations = 0;
    while (true) {
      if (std::sqrt(rr) <= target) {
        // The recurrence for r drifts from b - A x; accept only the true residual, else restart from it.
        rr = residual(b, x, r);
        if (std::sqrt(rr) <= target) break;
        rz = precondition(r, z);
        p = z;
      }
      if (iterations >= options_.max_iterations) {
        std::ostringstream msg;
        msg << "cg: no convergence after " << iterations << " iterations (relative residual "
            << std::sqrt(rr) / b_norm << ", tolerance " << options_.tolerance << ")";
        throw SolverError(msg.str());
      }
      const double pq = multiply_dot(p, q);
      if (!(pq > 0.0) || !std::isfinite(pq)) {
        throw SolverError("cg: matrix is not positive definite (p^T A p = " + std::to_string(pq) + ")");
      }
      const double alpha = rz / pq;
      const double rz_next = update(alpha, p, q, x, r, z, rr);
      const double beta = rz_next / rz;
      rz = rz_next;
      for_blocks(n, [&](Eigen::Index i) { p(i) = z(i) + beta * p(i); });
      ++iterations;
    }
    report.iterations = iterations;
    report.residual = relative_residual(A_, b, x);
    report.solve_seconds = seconds_since(start);
    return report;
  }

 private:
  /// Runs f(i) for every row, in parallel over the fixed row blocks.
  template <typename F>
  static void for_blocks(Eigen::Index n, const F& f) {
    const Eigen::Index blocks = (n + kBlockRows - 1) / kBlockRows;
    tbb::parallel_for(Eigen::Index(0), blocks, [&](Eigen::Index block) {
      const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
      for (Eigen::Index i = block * kBlockRows; i < end; ++i) f(i);
    });
  }

  /// Sum of per-block partial sums in block order: the same bits for any thread count.
  template <typename F>
  double block_sum(Eigen::Index n, std::vector<double>& partial, const F& row_term) {
    const Eigen::Index blocks = (n + kBlockRows - 1) / kBlockRows;
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

  /// Row i of A times v. A is symmetric, so row i is column i of the CSC storage.
  double row_times(Eigen::Index i, const Eigen::VectorXd& v) const {
    const int* inner = A_.innerIndexPtr();
    const double* values = A_.valuePtr();
    const int end = A_.outerIndexPtr()[i + 1];
    double sum = 0.0;
    for (int k = A_.outerIndexPtr()[i]; k < end; ++k) sum += values[k] * v(inner[k]);
    return sum;
  }

  double dot(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
    return block_sum(a.size(), partial_a_, [&](Eigen::Index i) { return a(i) * b(i); });
  }

  /// r = b - A x; returns |r|^2.
  double residual(const Eigen::VectorXd& b, const Eigen::VectorXd& x, Eigen::VectorXd& r) {
    return block_sum(b.size(), partial_a_, [&](Eigen::Index i) {
      r(i) = b(i) - row_times(i, x);
      return r(i) * r(i);
    });
  }

  /// z = D^-1 r; returns r.z.
  double precondition(const Eigen::VectorXd& r, Eigen::VectorXd& z) {
    return block_sum(r.size(), partial_a_, [&](Eigen::Index i) {
      z(i) = inverse_diagonal_(i) * r(i);
      return r(i) * z(i);
    });
  }

  /// q = A p; returns p.q.
  double multiply_dot(const Eigen::VectorXd& p, Eigen::VectorXd& q) {
    return block_sum(p.size(), partial_a_, [&](Eigen::Index i) {
      q(i) = row_times(i, p);
      return p(i) * q(i);
    });
  }

  /// x += alpha p, r -= alpha q, z = D^-1 r in one pass; returns r.z and sets rr = r.r.
  double update(double alpha, const Eigen::VectorXd& p, const Eigen::VectorXd& q, Eigen::VectorXd& x,
                Eigen::VectorXd& r, Eigen::VectorXd& z, double& rr) {
    const Eigen::Index n = p.size();
    const Eigen::Index blocks = (n + kBlockRows - 1) / kBlockRows;
    tbb::parallel_for(Eigen::Index(0), blocks, [&](Eigen::Index block) {
      const Eigen::Index end = std::min(n, (block + 1) * kBlockRows);
      double rz_sum = 0.0, rr_sum = 0.0;
      for (Eigen::Index i = block * kBlockRows; i < end; ++i) {
        x(i) += alpha * p(i);
        r(i) -= alpha * q(i);
        z(i) = inverse_diagonal_(i) * r(i);
        rz_sum += r(i) * z(i);
        rr_sum += r(i) * r(i);
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
  SparseMatrixD A_;
  Eigen::VectorXd inverse_diagonal_;
  std::vector<double> partial_a_, partial_b_;
  double setup_seconds_ = 0.0;
  bool ready_ = false;
};

}  // namespace

std::vector<std::string> solver_names() { return {"cholmod", "cg"}; }

std::unique_ptr<LinearSolver> make_solver(const std::string& name, const SolveOptions& options) {
  if (name == "cholmod") return std::make_unique<CholmodSolver>();
  if (name == "cg") return std::make_unique<CgSolver>(options);
  throw InvalidInput("unknown solver '" + name + "' (choose cholmod, cg)");
}

}  // namespace morphmap
