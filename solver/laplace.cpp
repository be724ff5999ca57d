// Laplace-Beltrami operator on the tetrahedral 3-manifold in R^4 and the harmonic field s (paper §6.1,
// equation 4 in its 3D cotangent form). The P1 stiffness vol * G^T G of each tet is computed from the Gram
// matrix of its edge vectors, so it lives in the tet's own 3D hull and needs no 3D embedding; its
// off-diagonals are the -(1/6) l_kl cot(theta_kl) weights of the paper's operator.
#include "solver/laplace.h"

#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <sstream>
#include <vector>

#include "mesh/errors.h"
#include "mesh/stopwatch.h"

namespace morphmap {
namespace {

// det(E^T E) <= product of its diagonal (Hadamard), and the determinant of a 3x3 Gram matrix carries an
// absolute rounding error of a few ulps of that product. Below this ratio the volume and the inverse are
// rounding noise, and a tet that flat is treated as having none.
constexpr double kDegenerateGramRatio = 1e-14;

// Tets per assembly chunk: fixed so the triplet order, and hence the summation order of duplicates in
// setFromTriplets, is the same for any thread count.
constexpr Eigen::Index kChunkTets = 8192;

void check_mesh_arrays(const Points4& V, const TetIndices& T, const char* who) {
  if (V.cols() != 4) {
    std::ostringstream msg;
    msg << who << ": vertex array has " << V.cols() << " columns, expected 4 (x, y, z, tau)";
    throw InvalidInput(msg.str());
  }
  if (T.size() == 0) return;
  const int lo = T.minCoeff();
  const int hi = T.maxCoeff();
  if (lo < 0 || hi >= V.rows()) {
    std::ostringstream msg;
    msg << who << ": tet vertex index " << (lo < 0 ? lo : hi) << " outside [0, " << V.rows() << ")";
    throw InvalidInput(msg.str());
  }
}

/// K = sum vol * G_t^T G_t from precomputed gradients; tets with zero volume are skipped.
SparseMatrixD assemble_stiffness(const TetIndices& T, const Eigen::MatrixXd& G, const Eigen::VectorXd& vol,
                                 Eigen::Index vertex_count) {
  using Triplet = Eigen::Triplet<double, int>;
  const Eigen::Index tets = T.rows();
  const Eigen::Index chunks = (tets + kChunkTets - 1) / kChunkTets;

  // Count first so every chunk writes its own slice of one buffer: no per-thread vectors to merge and the
  // chunk order is the buffer order.
  std::vector<std::size_t> offset(static_cast<std::size_t>(chunks) + 1, 0);
  tbb::parallel_for(Eigen::Index(0), chunks, [&](Eigen::Index chunk) {
    const Eigen::Index end = std::min(tets, (chunk + 1) * kChunkTets);
    std::size_t count = 0;
    for (Eigen::Index t = chunk * kChunkTets; t < end; ++t) count += vol(t) > 0.0 ? 16 : 0;
    offset[static_cast<std::size_t>(chunk) + 1] = count;
  });
  std::partial_sum(offset.begin(), offset.end(), offset.begin());

  std::vector<Triplet> triplets(offset.back());
  tbb::parallel_for(Eigen::Index(0), chunks, [&](Eigen::Index chunk) {
    const Eigen::Index end = std::min(tets, (chunk + 1) * kChunkTets);
    std::size_t k = offset[static_cast<std::size_t>(chunk)];
    for (Eigen::Index t = chunk * kChunkTets; t < end; ++t) {
      if (!(vol(t) > 0.0)) continue;
      for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) {
          // The same product for (i, j) and (j, i), summed in the same tet order: K is bitwise symmetric.
          const double value = vol(t) * G.row(4 * t + i).dot(G.row(4 * t + j));
          triplets[k++] = Triplet(T(t, i), T(t, j), value);
        }
      }
    }
  });

  SparseMatrixD K(vertex_count, vertex_count);
  K.setFromTriplets(triplets.begin(), triplets.end());
  K.makeCompressed();
  return K;
}

/// Union-find with path halving; roots are the smallest index of their set so labels are deterministic.
class DisjointSets {
 public:
  explicit DisjointSets(Eigen::Index n) : parent_(static_cast<std::size_t>(n)) {
    std::iota(parent_.begin(), parent_.end(), 0);
  }
  Eigen::Index find(Eigen::Index a) {
    while (parent_[static_cast<std::size_t>(a)] != a) {
      parent_[static_cast<std::size_t>(a)] = parent_[static_cast<std::size_t>(parent_[static_cast<std::size_t>(a)])];
      a = parent_[static_cast<std::size_t>(a)];
    }
    return a;
  }
  void unite(Eigen::Index a, Eigen::Index b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (a < b) std::swap(a, b);
    parent_[static_cast<std::size_t>(a)] = b;
  }

 private:
  std::vector<Eigen::Index> parent_;
};

}  // namespace

bool tet_frame(const Points4& V, const TetIndices& T, Eigen::Index t, Eigen::Matrix<double, 4, 3>& E,
               Eigen::Matrix3d& gram_inverse, double& volume) {
  const Eigen::Vector4d v0 = V.row(T(t, 0)).transpose();
  for (int k = 0; k < 3; ++k) E.col(k) = V.row(T(t, k + 1)).transpose() - v0;
  const Eigen::Matrix3d gram = E.transpose() * E;
  const double det = gram.determinant();
  const double hadamard = gram(0, 0) * gram(1, 1) * gram(2, 2);
  // Written as !(a > b) so that NaN coordinates also land here instead of spreading into K.
  if (!(det > kDegenerateGramRatio * hadamard) || !std::isfinite(det)) {
    volume = 0.0;
    return false;
  }
  gram_inverse = gram.inverse();
  volume = std::sqrt(det) / 6.0;
  return true;
}

void barycentric_gradients(const Points4& V, const TetIndices& T, Eigen::MatrixXd& G, Eigen::VectorXd& vol) {
  check_mesh_arrays(V, T, "barycentric_gradients");
  const Eigen::Index tets = T.rows();
  G.setZero(4 * tets, 4);
  vol.setZero(tets);
  tbb::parallel_for(Eigen::Index(0), tets, [&](Eigen::Index t) {
    Eigen::Matrix<double, 4, 3> E;
    Eigen::Matrix3d gram_inverse;
    double volume = 0.0;
    if (!tet_frame(V, T, t, E, gram_inverse, volume)) return;
    // Hat i (i = 1..3) is the affine function with E^T grad = e_i inside the hull: grad = E Gram^-1 e_i.
    const Eigen::Matrix<double, 4, 3> grads = E * gram_inverse;
    for (int i = 0; i < 3; ++i) G.row(4 * t + i + 1) = grads.col(i).transpose();
    // The hats sum to one, so their gradients sum to zero; this also makes K 1 = 0 up to rounding.
    G.row(4 * t) = -(grads.col(0) + grads.col(1) + grads.col(2)).transpose();
    vol(t) = volume;
  });
}

SparseMatrixD cotangent_stiffness(const Points4& V, const TetIndices& T) {
  Eigen::MatrixXd G;
  Eigen::VectorXd vol;
  barycentric_gradients(V, T, G, vol);
  return assemble_stiffness(T, G, vol, V.rows());
}

DirichletSystem dirichlet_system(const TetMesh4& mesh) {
  const Points4& V = mesh.V;
  const TetIndices& T = mesh.T;
  const Eigen::Index n = V.rows();
  check_mesh_arrays(V, T, "solve_harmonic");
  if (static_cast<Eigen::Index>(mesh.side.size()) != n) {
    std::ostringstream msg;
    msg << "solve_harmonic: side has " << mesh.side.size() << " entries for " << n << " vertices";
    throw InvalidInput(msg.str());
  }
  if (!(mesh.time_scale > 0.0) || !std::isfinite(mesh.time_scale)) {
    throw InvalidInput("solve_harmonic: time_scale must be positive and finite");
  }

  DirichletSystem system;
  const auto assemble_start = Clock::now();
  Eigen::MatrixXd G;
  Eigen::VectorXd vol;
  barycentric_gradients(V, T, G, vol);
  const SparseMatrixD K = assemble_stiffness(T, G, vol, n);
  system.assemble_seconds = seconds_since(assemble_start);
  system.degenerate_tets = (vol.array() <= 0.0).count();

  // Components through tets that carry stiffness only: a vertex held by degenerate tets alone would have
  // an empty row in K, so it must count as its own (floating) component.
  DisjointSets sets(n);
  for (Eigen::Index t = 0; t < T.rows(); ++t) {
    if (!(vol(t) > 0.0)) continue;
    for (int k = 1; k < 4; ++k) sets.unite(T(t, 0), T(t, k));
  }
  std::vector<Eigen::Index> root(static_cast<std::size_t>(n));
  std::vector<char> anchored(static_cast<std::size_t>(n), 0);  // per root: touches A or B
  std::vector<double> time_sum(static_cast<std::size_t>(n), 0.0);
  std::vector<Eigen::Index> size(static_cast<std::size_t>(n), 0);
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto r = static_cast<std::size_t>(sets.find(i));
    root[static_cast<std::size_t>(i)] = static_cast<Eigen::Index>(r);
    if (mesh.side[static_cast<std::size_t>(i)] != VertexSide::Interior) anchored[r] = 1;
    time_sum[r] += mesh.time_of(i);
    ++size[r];
  }

  // Unknowns: interior vertices of anchored components, numbered in vertex order.
  system.s.setZero(n);
  system.unknown.assign(static_cast<std::size_t>(n), -1);
  int unknowns = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto r = static_cast<std::size_t>(root[static_cast<std::size_t>(i)]);
    const VertexSide side = mesh.side[static_cast<std::size_t>(i)];
    if (side == VertexSide::A) {
      system.s(i) = 0.0;
    } else if (side == VertexSide::B) {
      system.s(i) = 1.0;
    } else if (!anchored[r]) {
      // A component born and dying inside the morph has no boundary data: its harmonic s is any constant.
      // Its mean morph time keeps it ordered with the rest of the morph for the causal sweep.
      system.s(i) = time_sum[r] / static_cast<double>(size[r]);
      ++system.floating_vertices;
      if (static_cast<std::size_t>(i) == r) ++system.floating_components;
    } else {
      system.unknown[static_cast<std::size_t>(i)] = unknowns++;
    }
  }

  // K_II in CSC, built column by column (the numbering is monotone so rows stay sorted), and the
  // right-hand side -K_IB s_B read from the same columns because K is symmetric.
  system.A.resize(unknowns, unknowns);
  system.b = Eigen::VectorXd::Zero(unknowns);
  system.x0.resize(unknowns);
  system.A.reserve(K.nonZeros());
  for (Eigen::Index j = 0; j < n; ++j) {
    const int uj = system.unknown[static_cast<std::size_t>(j)];
    if (uj < 0) continue;
    system.A.startVec(uj);
    for (SparseMatrixD::InnerIterator it(K, j); it; ++it) {
      const int ui = system.unknown[static_cast<std::size_t>(it.row())];
      if (ui >= 0) {
        system.A.insertBack(ui, uj) = it.value();
      } else {
        system.b(uj) -= it.value() * system.s(it.row());
      }
    }
    system.x0(uj) = mesh.time_of(j);
  }
  system.A.finalize();
  return system;
}

LaplaceResult solve_harmonic(const TetMesh4& mesh, const LaplaceOptions& options) {
  const auto start = Clock::now();
  // Before the expensive part, so a typo in the backend name fails fast.
  std::unique_ptr<LinearSolver> solver = make_solver(options.solver, options.solve);
  DirichletSystem system = dirichlet_system(mesh);

  LaplaceResult result;
  result.assemble_seconds = system.assemble_seconds;
  result.degenerate_tets = system.degenerate_tets;
  result.floating_components = system.floating_components;
  result.floating_vertices = system.floating_vertices;
  result.unknowns = system.A.rows();
  result.s = std::move(system.s);
  // Direct backends ignore x; the iterative ones (gauss-seidel included) start from it.
  Eigen::VectorXd x = options.warm_start ? system.x0 : Eigen::VectorXd::Zero(system.A.rows());
  if (result.unknowns > 0) {
    solver->compute(system.A);
    result.report = solver->solve(system.b, x);
    for (Eigen::Index i = 0; i < result.s.size(); ++i) {
      const int u = system.unknown[static_cast<std::size_t>(i)];
      if (u >= 0) result.s(i) = x(u);
    }
  } else {
    result.report.backend = solver->name();
  }
  result.seconds = seconds_since(start);
  return result;
}

}  // namespace morphmap
