// Fold-free layout of a disk with a fixed boundary (see chart_untangle.h; Garanzha et al. 2021).
#include "mesh/chart_untangle.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>

namespace morphmap {

namespace {

double chi(double d, double eps) { return 0.5 * (d + std::sqrt(eps * eps + d * d)); }

class Energy {
 public:
  Energy(const Eigen::MatrixX3i& F, const std::vector<int>& unknown, const std::vector<Eigen::Matrix2d>& inverse,
         const std::vector<double>& area, double theta)
      : F_(F), unknown_(unknown), inverse_(inverse), area_(area), theta_(theta) {}

  /// The energy at positions x (free vertices' coordinates z written into a copy of x) and its gradient by z.
  double operator()(const Eigen::MatrixX2d& x, double eps, Eigen::VectorXd* gradient) const {
    if (gradient != nullptr) gradient->setZero();
    double total = 0.0;
    for (Eigen::Index f = 0; f < F_.rows(); ++f) {
      const Eigen::Matrix2d J = jacobian(x, f);
      const double d = J.determinant();
      const double c = chi(d, eps);
      const double g = (1.0 - theta_) * J.squaredNorm() + theta_ * (d * d + 1.0);
      total += area_[std::size_t(f)] * g / c;
      if (gradient == nullptr) continue;
      Eigen::Matrix2d cofactor;
      cofactor << J(1, 1), -J(1, 0), -J(0, 1), J(0, 0);
      const double dc = c / std::sqrt(eps * eps + d * d);  // d chi / d D
      const Eigen::Matrix2d dJ = area_[std::size_t(f)] * ((2.0 * (1.0 - theta_) * J + 2.0 * theta_ * d * cofactor) / c -
                                                          (g / (c * c)) * dc * cofactor);
      const Eigen::Matrix2d dE = dJ * inverse_[std::size_t(f)].transpose();
      const int corner[3] = {F_(f, 0), F_(f, 1), F_(f, 2)};
      const Eigen::Vector2d by[3] = {-dE.col(0) - dE.col(1), dE.col(0), dE.col(1)};
      for (int k = 0; k < 3; ++k) {
        const int u = unknown_[std::size_t(corner[k])];
        if (u < 0) continue;
        (*gradient)(2 * u) += by[k].x();
        (*gradient)(2 * u + 1) += by[k].y();
      }
    }
    return total;
  }

  double smallest_det(const Eigen::MatrixX2d& x) const {
    double smallest = std::numeric_limits<double>::infinity();
    for (Eigen::Index f = 0; f < F_.rows(); ++f) {
      smallest = std::min(smallest, jacobian(x, f).determinant());
    }
    return smallest;
  }

 private:
  /// Triangle f's map from its reference shape to its position in x.
  Eigen::Matrix2d jacobian(const Eigen::MatrixX2d& x, Eigen::Index f) const {
    const Eigen::Vector2d p0 = x.row(F_(f, 0)).transpose();
    Eigen::Matrix2d E;
    E.col(0) = x.row(F_(f, 1)).transpose() - p0;
    E.col(1) = x.row(F_(f, 2)).transpose() - p0;
    return E * inverse_[std::size_t(f)];
  }

  const Eigen::MatrixX3i& F_;
  const std::vector<int>& unknown_;
  const std::vector<Eigen::Matrix2d>& inverse_;
  const std::vector<double>& area_;
  double theta_;
};

void scatter(const Eigen::VectorXd& z, const std::vector<int>& free_vertices, Eigen::MatrixX2d& x) {
  for (std::size_t i = 0; i < free_vertices.size(); ++i) {
    x(free_vertices[i], 0) = z(2 * Eigen::Index(i));
    x(free_vertices[i], 1) = z(2 * Eigen::Index(i) + 1);
  }
}

}  // namespace

ChartUntangleResult untangle_chart(Eigen::MatrixX2d& x, const std::vector<char>& fixed, const Eigen::MatrixX3i& F,
                                   const std::vector<Eigen::Matrix2d>& reference_inverse,
                                   const std::vector<double>& reference_area, const ChartUntangleOptions& options) {
  std::vector<int> unknown(std::size_t(x.rows()), -1), free_vertices;
  for (Eigen::Index v = 0; v < x.rows(); ++v)
    if (!fixed[std::size_t(v)]) {
      unknown[std::size_t(v)] = int(free_vertices.size());
      free_vertices.push_back(int(v));
    }
  const Energy energy(F, unknown, reference_inverse, reference_area, options.theta);
  ChartUntangleResult result;
  result.smallest_det_before = result.smallest_det_after = energy.smallest_det(x);
  if (free_vertices.empty()) {
    result.untangled = result.smallest_det_after > 0.0;
    return result;
  }
  Eigen::VectorXd z(2 * Eigen::Index(free_vertices.size()));
  for (std::size_t i = 0; i < free_vertices.size(); ++i) {
    z(2 * Eigen::Index(i)) = x(free_vertices[i], 0);
    z(2 * Eigen::Index(i) + 1) = x(free_vertices[i], 1);
  }
  // eps starts where chi of the smallest determinant is of the order of an undistorted triangle's (det 1).
  double eps = 1.0;
  double smallest = result.smallest_det_before;
  Eigen::MatrixX2d trial = x;
  auto value = [&](const Eigen::VectorXd& at, double e, Eigen::VectorXd* gradient) {
    scatter(at, free_vertices, trial);
    return energy(trial, e, gradient);
  };
  double previous = value(z, eps, nullptr);
  for (int round = 0; round < options.max_rounds; ++round) {
    ++result.rounds;
    // L-BFGS on the energy at this eps (two-loop recursion, backtracking line search with Armijo's condition).
    std::deque<std::pair<Eigen::VectorXd, Eigen::VectorXd>> pairs;  // (s, y)
    Eigen::VectorXd gradient(z.size()), next_gradient(z.size());
    double current = value(z, eps, &gradient);
    for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
      Eigen::VectorXd q = gradient;
      std::vector<double> alpha(pairs.size());
      for (std::size_t k = pairs.size(); k-- > 0;) {
        alpha[k] = pairs[k].first.dot(q) / pairs[k].second.dot(pairs[k].first);
        q -= alpha[k] * pairs[k].second;
      }
      if (!pairs.empty()) q *= pairs.back().first.dot(pairs.back().second) / pairs.back().second.squaredNorm();
      for (std::size_t k = 0; k < pairs.size(); ++k) {
        const double beta = pairs[k].second.dot(q) / pairs[k].second.dot(pairs[k].first);
        q += (alpha[k] - beta) * pairs[k].first;
      }
      Eigen::VectorXd direction = -q;
      double slope = gradient.dot(direction);
      if (!(slope < 0.0)) {  // not a descent direction: restart from steepest descent
        pairs.clear();
        direction = -gradient;
        slope = -gradient.squaredNorm();
        if (!(slope < 0.0)) break;
      }
      double step = pairs.empty() ? 1.0 / std::max(1.0, direction.lpNorm<Eigen::Infinity>()) : 1.0;
      Eigen::VectorXd candidate;
      double candidate_value = current;
      bool moved = false;
      for (int halving = 0; halving < 40; ++halving, step *= 0.5) {
        candidate = z + step * direction;
        candidate_value = value(candidate, eps, &next_gradient);
        if (std::isfinite(candidate_value) && candidate_value <= current + 1e-4 * step * slope) {
          moved = true;
          break;
        }
      }
      ++result.iterations;
      if (!moved) break;
      const Eigen::VectorXd s = candidate - z, y = next_gradient - gradient;
      z = candidate;
      gradient = next_gradient;
      const double improvement = current - candidate_value;
      current = candidate_value;
      if (s.dot(y) > 1e-16 * s.norm() * y.norm()) {
        pairs.emplace_back(s, y);
        if (int(pairs.size()) > options.history) pairs.pop_front();
      }
      if (improvement <= 1e-12 * std::abs(current)) break;
    }
    scatter(z, free_vertices, trial);
    smallest = energy.smallest_det(trial);
    // The schedule of the paper: eps follows the smallest determinant, by how much this round lowered the energy.
    const double sigma = std::max(1.0 - current / previous, 0.1);
    const double mu = (1.0 - sigma) * chi(smallest, eps);
    const bool converged = smallest > 0.0 && std::abs(previous - current) <= options.tolerance * std::abs(current);
    eps = smallest < mu ? 2.0 * std::sqrt(mu * (mu - smallest)) : 1e-13;
    previous = value(z, eps, nullptr);
    if (converged) break;
  }
  scatter(z, free_vertices, x);
  result.smallest_det_after = smallest;
  result.untangled = smallest > 0.0;
  return result;
}

}  // namespace morphmap
