// Labels for stalled characteristics (see label_fill.h; paper §7).
#include "mesh/label_fill.h"

#include <Eigen/Geometry>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>
#include <chrono>
#include <cmath>
#include <string>

#include "mesh/adjacency.h"
#include "mesh/errors.h"
#include "mesh/surface.h"

namespace morphmap {

LabelFillResult fill_stalled_labels(const Eigen::MatrixXd& V, const TriIndices& F, const std::vector<char>& stalled,
                                    const SurfaceLocator& locator, Eigen::MatrixXd& labels,
                                    const LabelFillOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const Eigen::Index nv = V.rows();
  if (V.cols() != 3 || labels.rows() != nv || labels.cols() != 3 || stalled.size() != std::size_t(nv))
    throw InvalidInput("fill_stalled_labels: V and labels must be #V by 3 and stalled #V (" + std::to_string(nv) +
                       " vertices)");
  if (F.size() > 0 && (F.minCoeff() < 0 || F.maxCoeff() >= nv))
    throw InvalidInput("fill_stalled_labels: a triangle's vertex index is out of range");
  LabelFillResult result;
  auto finish = [&]() {
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  };
  if (!options.enabled) return finish();
  std::vector<char> fill = stalled;
  if (options.coincident && nv > 0) {
    const double tolerance =
        options.coincident_tolerance * (labels.colwise().maxCoeff() - labels.colwise().minCoeff()).norm();
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) {
        const int i = F(f, k), j = F(f, (k + 1) % 3);
        if (!((labels.row(i) - labels.row(j)).norm() <= tolerance)) continue;
        for (const int v : {i, j})
          if (!fill[std::size_t(v)]) fill[std::size_t(v)] = 1, ++result.coincident;
      }
  }

  // Patches: stalled vertices joined by B's edges; a patch is bounded when an edge leaves it to a traced vertex.
  DisjointSets patches(nv);
  std::vector<char> bounded(std::size_t(nv), 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int i = F(f, k), j = F(f, (k + 1) % 3);
      if (fill[std::size_t(i)] && fill[std::size_t(j)]) patches.unite(i, j);
    }
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int i = F(f, k), j = F(f, (k + 1) % 3);
      if (fill[std::size_t(i)] != fill[std::size_t(j)])
        bounded[std::size_t(patches.find(fill[std::size_t(i)] ? i : j))] = 1;
    }
  std::vector<int> unknown(std::size_t(nv), -1);
  int unknowns = 0;
  for (Eigen::Index v = 0; v < nv; ++v) {
    if (!fill[std::size_t(v)]) continue;
    const Eigen::Index root = patches.find(v);
    if (!bounded[std::size_t(root)]) {
      ++result.unbounded;
      continue;
    }
    if (root == v) ++result.patches;
    unknown[std::size_t(v)] = unknowns++;
  }
  if (unknowns == 0) return finish();

  // Mean value weights on B: each filled label is a convex combination of its neighbours', and the patch a Tutte
  // embedding of B's shape between the traced labels around it.
  std::vector<Eigen::Triplet<double>> triplets;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(unknowns, 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int i = F(f, k);
      const int row = unknown[std::size_t(i)];
      if (row < 0) continue;
      for (const auto& [j, w] : mean_value_weights(V, F, f, k)) {
        if (!std::isfinite(w) || !(w > 0.0)) continue;  // a degenerate corner adds nothing
        triplets.emplace_back(row, row, w);
        if (unknown[std::size_t(j)] >= 0)
          triplets.emplace_back(row, unknown[std::size_t(j)], -w);
        else
          rhs.row(row) += w * labels.row(j);
      }
    }
  Eigen::SparseMatrix<double> L(unknowns, unknowns);
  L.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::SparseLU<Eigen::SparseMatrix<double>> lu(L);
  if (lu.info() != Eigen::Success) return finish();  // a vertex with only degenerate corners: nothing changes
  const Eigen::MatrixXd solution = lu.solve(rhs);
  if (lu.info() != Eigen::Success || !solution.allFinite()) return finish();
  const std::vector<SurfaceHit> hits = locator.closest_all(solution);
  for (Eigen::Index v = 0; v < nv; ++v)
    if (unknown[std::size_t(v)] >= 0) labels.row(v) = hits[std::size_t(unknown[std::size_t(v)])].point.transpose();
  result.filled = unknowns;
  return finish();
}

}  // namespace morphmap
