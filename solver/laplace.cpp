// Laplace-Beltrami operator on the tetrahedral 3-manifold in R^4 and the harmonic field s (paper §6.1,
// equation 4 in its 3D cotangent form). The P1 stiffness vol * G^T G of each tet is computed from the Gram
// matrix of its edge vectors, so it lives in the tet's own 3D hull and needs no 3D embedding; its
// off-diagonals are the -(1/6) l_kl cot(theta_kl) weights of the paper's operator.
#include "solver/laplace.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/errors.h"
#include "mesh/quality.h"
#include "mesh/stopwatch.h"

namespace morphmap {
namespace {

// det(E^T E) <= product of its diagonal (Hadamard), and the determinant of a 3x3 Gram matrix carries an
// absolute rounding error of a few ulps of that product. Below this ratio the volume and the inverse are
// rounding noise, and a tet that flat is treated as having none.
constexpr double kDegenerateGramRatio = 1e-14;

// Rows per assembly block: fixed so the work split, and with it every bit of the result, is the same for any
// thread count (each row is summed by one task in incident-tet order anyway).
constexpr Eigen::Index kBlockRows = 2048;

void check_mesh_arrays(const Points4& V, const TetIndices& T, const char* who) {
  if (V.cols() != 4) {
    std::ostringstream msg;
    msg << who << ": vertex array has " << V.cols() << " columns, expected 4 (x, y, z, tau)";
    throw InvalidInput(msg.str());
  }
  if (T.size() == 0) return;
  const auto [lo, hi] = index_range(T);
  if (lo < 0 || hi >= V.rows()) {
    std::ostringstream msg;
    msg << who << ": tet vertex index " << (lo < 0 ? lo : hi) << " outside [0, " << V.rows() << ")";
    throw InvalidInput(msg.str());
  }
}

/// Every tet's local stiffness vol * grad_i . grad_j, packed (#T by 6, see PackedStiffness), and its volume (0 for a
/// degenerate tet, whose entries are then 0).
void local_stiffness(const Points4& V, const TetIndices& T, PackedStiffness& L, Eigen::VectorXd& vol) {
  const Eigen::Index tets = T.rows();
  L.resize(tets, 6);
  vol.resize(tets);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, tets, 4096), [&](const tbb::blocked_range<Eigen::Index>& r) {
    for (Eigen::Index t = r.begin(); t != r.end(); ++t) {
      Eigen::Matrix<double, 4, 3> E;
      Eigen::Matrix3d gram_inverse;
      double volume = 0.0;
      if (!tet_frame(V, T, t, E, gram_inverse, volume)) {
        L.row(t).setZero();
        vol(t) = 0.0;
        continue;
      }
      // Gradients of hats 1..3 are E Gram^-1 e_i, so their dot products are Gram^-1 itself (hat 0's, minus their
      // sum, is what unpack_stiffness derives). Its upper triangle serves (i, j) and (j, i): K is bitwise symmetric.
      const Eigen::Matrix3d& M = gram_inverse;
      L(t, 0) = volume * M(0, 0);
      L(t, 1) = volume * M(0, 1);
      L(t, 2) = volume * M(0, 2);
      L(t, 3) = volume * M(1, 1);
      L(t, 4) = volume * M(1, 2);
      L(t, 5) = volume * M(2, 2);
      vol(t) = volume;
    }
  });
}

/// Which tets carry stiffness (volume > 0), one byte a tet: the assembly's test, kept instead of the 8-byte volumes,
/// which the assembly does not otherwise read, so they can be released before the matrix is allocated.
std::vector<std::uint8_t> stiffness_mask(const Eigen::VectorXd& vol) {
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(vol.size()));
  for (Eigen::Index t = 0; t < vol.size(); ++t) mask[static_cast<std::size_t>(t)] = vol(t) > 0.0 ? 1 : 0;
  return mask;
}

/// Rows of K = sum of local stiffness restricted to the `unknown` vertices (#V entries: the row/column index of
/// the vertex, or -1 for a fixed vertex), assembled straight into compressed storage: A (#unknowns square,
/// both triangles) and, when b is given, b = -K_IB s with the fixed vertices' values s. Written by hand because
/// Eigen's setFromTriplets is sequential and needs a 16-entry triplet per tet (256 bytes a tet); here every row
/// is one task: it walks its vertex's star (tets with stiffness, in tet order), so each entry is summed in the same
/// order whatever the thread count, and (i, j) and (j, i) add the same doubles in the same order.
void assemble_rows(const TetIndices& T, const VertexTets& stars, const PackedStiffness& L,
                   const std::vector<std::uint8_t>& has_stiffness, const std::vector<int>& unknown, int unknowns,
                   const Eigen::VectorXd* s, SparseMatrixD& A, Eigen::VectorXd* b) {
  const Eigen::Index n = static_cast<Eigen::Index>(unknown.size());
  // Vertex of each unknown, in unknown order (the numbering is monotone in the vertex index).
  std::vector<int> vertex_of(static_cast<std::size_t>(unknowns));
  for (Eigen::Index v = 0; v < n; ++v)
    if (unknown[static_cast<std::size_t>(v)] >= 0)
      vertex_of[static_cast<std::size_t>(unknown[static_cast<std::size_t>(v)])] = int(v);

  // Per-thread scratch: slot[col] = position of column col in the row being built, -1 when absent.
  struct Scratch {
    std::vector<int> slot;
    std::vector<std::pair<int, double>> row;
  };
  tbb::enumerable_thread_specific<Scratch> scratch([&] {
    return Scratch{std::vector<int>(std::size_t(unknowns), -1), {}};
  });
  // Builds row u into scratch.row (columns sorted) and returns b's entry for it.
  auto build_row = [&](Scratch& w, int u, bool values) {
    const int v = vertex_of[static_cast<std::size_t>(u)];
    w.row.clear();
    double rhs = 0.0;
    for (std::int64_t q = stars.first(v); q < stars.last(v); ++q) {
      const int t = stars.tet(q);
      if (!has_stiffness[std::size_t(t)]) continue;  // degenerate
      int li = 0;
      while (T(t, li) != v) ++li;
      double K[4];
      if (values) stiffness_row(L.row(t).data(), li, K);
      for (int lj = 0; lj < 4; ++lj) {
        const int col_vertex = T(t, lj);
        const int col = unknown[static_cast<std::size_t>(col_vertex)];
        const double value = values ? K[lj] : 0.0;
        if (col < 0) {
          if (values && s != nullptr) rhs -= value * (*s)(col_vertex);
          continue;
        }
        int& slot = w.slot[static_cast<std::size_t>(col)];
        if (slot < 0) {
          slot = int(w.row.size());
          w.row.emplace_back(col, value);
        } else {
          w.row[static_cast<std::size_t>(slot)].second += value;
        }
      }
    }
    for (const auto& e : w.row) w.slot[static_cast<std::size_t>(e.first)] = -1;
    // The counting pass needs only the row's length.
    if (values) std::sort(w.row.begin(), w.row.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
    return rhs;
  };

  const Eigen::Index blocks = (unknowns + kBlockRows - 1) / kBlockRows;
  A.resize(unknowns, unknowns);
  A.data().clear();
  int* outer = A.outerIndexPtr();
  outer[0] = 0;
  tbb::parallel_for(Eigen::Index(0), blocks, [&](Eigen::Index block) {
    Scratch& w = scratch.local();
    const int end = int(std::min<Eigen::Index>(unknowns, (block + 1) * kBlockRows));
    for (int u = int(block * kBlockRows); u < end; ++u) {
      build_row(w, u, false);
      outer[u + 1] = int(w.row.size());
    }
  });
  for (int u = 0; u < unknowns; ++u) outer[u + 1] += outer[u];
  A.resizeNonZeros(outer[unknowns]);
  if (b != nullptr) b->setZero(unknowns);
  int* inner = A.innerIndexPtr();
  double* value = A.valuePtr();
  tbb::parallel_for(Eigen::Index(0), blocks, [&](Eigen::Index block) {
    Scratch& w = scratch.local();
    const int end = int(std::min<Eigen::Index>(unknowns, (block + 1) * kBlockRows));
    for (int u = int(block * kBlockRows); u < end; ++u) {
      const double rhs = build_row(w, u, true);
      if (b != nullptr) (*b)(u) = rhs;
      int k = outer[u];
      for (const auto& e : w.row) {
        inner[k] = e.first;
        value[k] = e.second;
        ++k;
      }
    }
  });
}

// tet_frame, the Gram inverse only when asked for (the gradient stage reads E and the volume alone).
bool frame_of(const Points4& V, const TetIndices& T, Eigen::Index t, Eigen::Matrix<double, 4, 3>& E,
              Eigen::Matrix3d* gram_inverse, double& volume) {
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
  if (gram_inverse != nullptr) *gram_inverse = gram.inverse();
  volume = std::sqrt(det) / 6.0;
  return true;
}

}  // namespace

bool tet_frame(const Points4& V, const TetIndices& T, Eigen::Index t, Eigen::Matrix<double, 4, 3>& E,
               Eigen::Matrix3d& gram_inverse, double& volume) {
  return frame_of(V, T, t, E, &gram_inverse, volume);
}

bool tet_frame(const Points4& V, const TetIndices& T, Eigen::Index t, Eigen::Matrix<double, 4, 3>& E, double& volume) {
  return frame_of(V, T, t, E, nullptr, volume);
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
  check_mesh_arrays(V, T, "cotangent_stiffness");
  PackedStiffness L;
  Eigen::VectorXd vol;
  local_stiffness(V, T, L, vol);
  std::vector<int> all(static_cast<std::size_t>(V.rows()));
  std::iota(all.begin(), all.end(), 0);
  SparseMatrixD K;
  assemble_rows(T, build_vertex_tets(T, V.rows()), L, stiffness_mask(vol), all, int(V.rows()), nullptr, K, nullptr);
  return K;
}

DirichletSystem dirichlet_system(const TetMesh4& mesh, const SharedStars& stars, QualityResult* quality) {
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
  PackedStiffness L;
  Eigen::VectorXd vol;
  local_stiffness(V, T, L, vol);
  system.degenerate_tets = (vol.array() <= 0.0).count();
  const SharedStars shared_stars = stars_or_build(stars, T, n);  // built once for the quality pass and the rows
  // Timed apart from the assembly: it is the quality stage's work, done here while the stiffness exists, its edge
  // figures after the assembly, from its rows.
  std::vector<std::uint8_t> usable;
  if (quality != nullptr) *quality = quality_angles_from_stiffness(mesh, L, vol, usable);

  // The assembly reads only which tets carry stiffness: the volumes (8 bytes a tet) and, below, the component
  // tables (24 bytes a vertex) are released before it allocates the matrix, at what is the run's peak of memory
  // (the local stiffness is live then).
  const std::vector<std::uint8_t> has_stiffness = stiffness_mask(vol);
  vol = Eigen::VectorXd();

  int unknowns = 0;
  {
    // Components through tets that carry stiffness only: a vertex held by degenerate tets alone would have
    // an empty row in K, so it must count as its own (floating) component.
    system.component_root = component_labels(T, n, &has_stiffness);
    const std::vector<int>& root = system.component_root;
    std::vector<char> anchored(static_cast<std::size_t>(n), 0);  // per root: touches A or B
    std::vector<double> time_sum(static_cast<std::size_t>(n), 0.0);
    std::vector<Eigen::Index> size(static_cast<std::size_t>(n), 0);
    for (Eigen::Index i = 0; i < n; ++i) {
      const auto r = static_cast<std::size_t>(root[static_cast<std::size_t>(i)]);
      if (mesh.side[static_cast<std::size_t>(i)] != VertexSide::Interior) anchored[r] = 1;
      time_sum[r] += mesh.time_of(i);
      ++size[r];
    }

    // Unknowns: interior vertices of anchored components, numbered in vertex order.
    system.s.setZero(n);
    system.unknown.assign(static_cast<std::size_t>(n), -1);
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
  }

  // A = K_II and b = -K_IB s_B, assembled directly: K itself is never formed.
  system.x0.resize(unknowns);
  for (Eigen::Index j = 0; j < n; ++j) {
    const int uj = system.unknown[static_cast<std::size_t>(j)];
    if (uj >= 0) system.x0(uj) = mesh.time_of(j);
  }
  assemble_rows(T, *shared_stars, L, has_stiffness, system.unknown, unknowns, &system.s, system.A, &system.b);
  if (quality != nullptr) {
    // The rows hold the quality stage's sums only where both skip the same tets (quality's mean-volume test can
    // skip more than tet_frame's shape test; on the Table II morphs it does not).
    const AssembledRows rows{&system.unknown, system.A.outerIndexPtr(), system.A.innerIndexPtr(), system.A.valuePtr()};
    add_edge_figures(*quality, mesh, L, usable, shared_stars, usable == has_stiffness ? &rows : nullptr);
  }
  system.assemble_seconds = seconds_since(assemble_start) - (quality != nullptr ? quality->seconds : 0.0);
  return system;
}

namespace {

/// Splits each cell of `sorted` (grouped by cell) into the connected parts of its unknowns along the couplings of A
/// (symmetric, compressed, so each column's rows are sorted), numbers the parts within the cell in the order the
/// cell's unknowns are sorted, and regroups the cell by part (a stable sort, keeping each part's order). Written by
/// hand: the sets are a union-find restricted to each cell, which no library here offers for a sparse matrix.
template <class Point>
void split_cells(const SparseMatrixD& A, std::vector<Point>& sorted) {
  std::vector<std::size_t> begin;
  for (std::size_t k = 0; k < sorted.size(); ++k)
    if (k == 0 || sorted[k].cell != sorted[k - 1].cell) begin.push_back(k);
  begin.push_back(sorted.size());
  const std::size_t cells = begin.size() - 1;
  // Per unknown its cell's rank: 4 bytes, read at random by the search (the Points are 24).
  std::vector<int> cell(sorted.size()), part(sorted.size(), -1);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells, 16), [&](const auto& r) {
    for (std::size_t c = r.begin(); c != r.end(); ++c)
      for (std::size_t k = begin[c]; k < begin[c + 1]; ++k) cell[std::size_t(sorted[k].index)] = int(c);
  });
  // Union-find over each coupling within a cell once (A's rows are sorted, so a row's upper half follows its
  // diagonal), a set's root its smallest unknown, which makes the roots independent of the order of the unions. Row
  // blocks join their own couplings side by side (a union there writes only the block's entries); the couplings
  // between blocks, few because a row's columns lie near it, are joined after them. A set never leaves its cell, so
  // the per-cell pass below touches disjoint entries too.
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  const int n = int(sorted.size());
  std::vector<int> parent(sorted.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int a) {
    while (parent[std::size_t(a)] != a) {
      parent[std::size_t(a)] = parent[std::size_t(parent[std::size_t(a)])];
      a = parent[std::size_t(a)];
    }
    return a;
  };
  auto join = [&](int a, int b) {
    const int x = find(a), y = find(b);
    if (x != y) parent[std::size_t(std::max(x, y))] = std::min(x, y);
  };
  constexpr int kUnionRows = 8192;
  const int blocks = (n + kUnionRows - 1) / kUnionRows;
  std::vector<std::vector<std::pair<int, int>>> between(static_cast<std::size_t>(blocks));
  tbb::parallel_for(0, blocks, [&](int block) {
    const int first = block * kUnionRows, last = std::min(n, first + kUnionRows);
    for (int i = first; i < last; ++i) {
      const int own = cell[std::size_t(i)];
      for (const int* e = std::upper_bound(inner + outer[i], inner + outer[i + 1], i); e != inner + outer[i + 1]; ++e) {
        if (cell[std::size_t(*e)] != own) continue;
        if (*e < last)
          join(i, *e);
        else
          between[std::size_t(block)].emplace_back(i, *e);
      }
    }
  });
  for (const auto& pairs : between)
    for (const auto& [a, b] : pairs) join(a, b);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells, 2), [&](const auto& r) {
    for (std::size_t c = r.begin(); c != r.end(); ++c) {
      // Parts numbered in the order the cell's unknowns are sorted (part: a root's number).
      int parts = 0;
      for (std::size_t k = begin[c]; k < begin[c + 1]; ++k) {
        const int root = find(sorted[k].index);
        if (part[std::size_t(root)] < 0) part[std::size_t(root)] = parts++;
        sorted[k].part = part[std::size_t(root)];
      }
      if (parts > 1)
        std::stable_sort(sorted.begin() + std::ptrdiff_t(begin[c]), sorted.begin() + std::ptrdiff_t(begin[c + 1]),
                         [](const Point& a, const Point& b) { return a.part < b.part; });
    }
  });
}

/// space_time_cells for one cell size.
DeflationSpace cells_of(const TetMesh4& mesh, const std::vector<int>& unknown, int unknowns, double cell_voxels,
                        const SparseMatrixD* couplings) {
  DeflationSpace space;
  const double size = cell_voxels * mesh.voxel_size;
  if (!(size > 0.0) || unknowns == 0 || mesh.vertex_count() == 0) return space;
  const int levels = std::max(1, mesh.time_steps);  // time intervals: hats at the levels 0..levels
  const Eigen::Vector3d origin = mesh.V.leftCols<3>().colwise().minCoeff().transpose();
  // Each unknown: its cell's key, its position u in time (in intervals) and its index.
  struct Point {
    std::int64_t cell;
    double u;
    int index;
    int part;  // the connected part of the cell (split_cells), 0 without couplings
  };
  std::vector<Point> points(static_cast<std::size_t>(unknowns));
  const Eigen::Index n = mesh.vertex_count();
  constexpr std::int64_t kCellsPerAxis = std::int64_t(1) << 20;
  tbb::parallel_for(Eigen::Index(0), n, [&](Eigen::Index v) {
    const int i = unknown[static_cast<std::size_t>(v)];
    if (i < 0) return;
    std::int64_t key = 0;
    for (int k = 0; k < 3; ++k) {
      const auto c = static_cast<std::int64_t>(std::floor((mesh.V(v, k) - origin(k)) / size));
      key = key * kCellsPerAxis + std::clamp<std::int64_t>(c, 0, kCellsPerAxis - 1);
    }
    const double u = std::clamp(mesh.time_of(v), 0.0, 1.0) * levels;
    points[static_cast<std::size_t>(i)] = {key, u, i, 0};
  });
  std::vector<Point> sorted = points;
  tbb::parallel_sort(sorted.begin(), sorted.end(), [](const Point& a, const Point& b) {
    return a.cell != b.cell ? a.cell < b.cell : a.u != b.u ? a.u < b.u : a.index < b.index;
  });
  if (couplings != nullptr) split_cells(*couplings, sorted);
  // Per cell, its hats in increasing level, each kept when an unknown of the cell lies where the hat is at least
  // kSeparation, at a t past the one the previous kept hat took by at least kSeparation intervals: then the cell's
  // columns are independent (the square matrix of the kept hats at the points they took is totally positive with
  // a positive diagonal), and not nearly dependent. kept[c * (levels + 1) + j] is hat j of cell c's column, once
  // numbered, kUnnumbered before, or kDropped.
  constexpr double kSeparation = 0.01;
  constexpr int kDropped = -1, kUnnumbered = -2;
  std::vector<std::int64_t> cell_of(static_cast<std::size_t>(unknowns));  // the cell's rank among the cells
  std::vector<int> kept;
  std::int64_t cells = 0;
  for (std::size_t first = 0; first < sorted.size();) {
    std::size_t last = first;
    while (last < sorted.size() && sorted[last].cell == sorted[first].cell && sorted[last].part == sorted[first].part)
      ++last;
    const std::size_t base = kept.size();
    kept.resize(base + std::size_t(levels) + 1, kDropped);
    double taken = -std::numeric_limits<double>::infinity();
    std::size_t at = first;
    for (int j = 0; j <= levels; ++j) {
      while (at < last && !(sorted[at].u >= std::max(j - 1 + kSeparation, taken + kSeparation))) ++at;
      if (at == last) break;
      if (sorted[at].u <= j + 1 - kSeparation) {
        kept[base + std::size_t(j)] = kUnnumbered;
        taken = sorted[at].u;
      }
    }
    for (std::size_t k = first; k < last; ++k) cell_of[static_cast<std::size_t>(sorted[k].index)] = cells;
    ++cells;
    first = last;
  }
  // Columns numbered in order of first use by the unknowns (the extraction's order), so that a block of rows
  // touches few of them.
  space.column.setConstant(unknowns, 2, -1);
  space.weight.setZero(unknowns, 2);
  int columns = 0;
  for (int i = 0; i < unknowns; ++i) {
    const double u = points[static_cast<std::size_t>(i)].u;
    const int j = std::min(static_cast<int>(u), levels - 1);
    const double w = u - j;
    const std::size_t base = static_cast<std::size_t>(cell_of[static_cast<std::size_t>(i)]) * (std::size_t(levels) + 1);
    int e = 0;
    for (int h = 0; h < 2; ++h) {
      const double weight = h == 0 ? 1.0 - w : w;
      int& column = kept[base + std::size_t(j + h)];
      if (!(weight > 0.0) || column == kDropped) continue;
      if (column == kUnnumbered) column = columns++;
      space.column(i, e) = column;
      space.weight(i, e) = weight;
      ++e;
    }
  }
  space.columns = columns;
  return space;
}

}  // namespace

DeflationSpace space_time_cells(const TetMesh4& mesh, const std::vector<int>& unknown, int unknowns, double cell_voxels,
                                int max_columns, const SparseMatrixD* couplings) {
  if (couplings != nullptr && (couplings->rows() != unknowns || couplings->cols() != unknowns))
    throw InvalidInput("space_time_cells: the couplings matrix must be #unknowns by #unknowns");
  DeflationSpace space = cells_of(mesh, unknown, unknowns, cell_voxels, couplings);
  for (double voxels = cell_voxels; space.columns > std::max(1, max_columns);) {
    voxels *= 1.5;
    space = cells_of(mesh, unknown, unknowns, voxels, couplings);
  }
  return space;
}

LaplaceResult solve_harmonic(const TetMesh4& mesh, const LaplaceOptions& options, const SharedStars& stars) {
  const auto start = Clock::now();
  // Before the expensive part, so a typo in the backend name fails fast.
  // The assembly makes A exactly symmetric (assemble_rows), so the solver's input check need not search for it.
  SolveOptions solve = options.solve;
  solve.symmetric_by_construction = true;
  std::unique_ptr<LinearSolver> solver = make_solver(options.solver, solve);
  LaplaceResult result;
  DirichletSystem system = dirichlet_system(mesh, stars, options.measure_quality ? &result.quality : nullptr);

  result.assemble_seconds = system.assemble_seconds;
  result.degenerate_tets = system.degenerate_tets;
  result.component_root = std::move(system.component_root);
  result.floating_components = system.floating_components;
  result.floating_vertices = system.floating_vertices;
  result.unknowns = system.A.rows();
  result.s = std::move(system.s);
  // Direct backends ignore x; the iterative ones (gauss-seidel included) start from it.
  Eigen::VectorXd x = options.warm_start ? std::move(system.x0) : Eigen::VectorXd::Zero(system.A.rows());
  if (result.unknowns > 0) {
    solver->set_deflation(space_time_cells(mesh, system.unknown, int(result.unknowns), options.deflation_cell_voxels,
                                           kMaxDeflationColumns, &system.A));
    solver->compute(std::move(system.A));  // handed over, not copied: A is not needed after this
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
