// Variational implicit morph (Turk and O'Brien 1999; paper §5.1, equation 3). Written by hand: no Debian package
// fits and evaluates a 4D polyharmonic interpolant (CGAL interpolates in 2D/3D only); Eigen does the dense algebra.
#include "mesh/vim.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "mesh/errors.h"
#include "mesh/transfer.h"

namespace morphmap {
namespace {

using Clock = std::chrono::steady_clock;

/// Constraints of the interpolant: centres (x, y, z, tau) and the value G must take there.
struct Constraints {
  std::vector<Eigen::Vector4d> centre;
  std::vector<double> value;
  void add(const Eigen::Vector3d& x, double tau, double v) {
    centre.emplace_back(x.x(), x.y(), x.z(), tau);
    value.push_back(v);
  }
};

/// Unit outward vertex normals: the sum of the incident faces' area vectors (faces are counter-clockwise from
/// outside), normalised. Zero for a vertex with no incident area.
Eigen::MatrixXd vertex_normals(const Surface& S) {
  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(S.V.rows(), 3);
  for (Eigen::Index f = 0; f < S.F.rows(); ++f) {
    const Eigen::Vector3d a = S.V.row(S.F(f, 0)).transpose();
    const Eigen::Vector3d b = S.V.row(S.F(f, 1)).transpose();
    const Eigen::Vector3d c = S.V.row(S.F(f, 2)).transpose();
    const Eigen::RowVector3d area = (b - a).cross(c - a).transpose();
    for (int k = 0; k < 3; ++k) N.row(S.F(f, k)) += area;
  }
  for (Eigen::Index v = 0; v < N.rows(); ++v) {
    const double length = N.row(v).norm();
    if (length > 0.0) N.row(v) /= length;
  }
  return N;
}

void add_surface(const Surface& S, const char* which, int samples, double tau, double offset, Constraints& out) {
  const Eigen::MatrixXd N = vertex_normals(S);
  for (const int v : farthest_point_samples(S.V, samples)) {
    if (!(N.row(v).squaredNorm() > 0.0)) continue;  // no area around it: no normal to constrain
    const Eigen::Vector3d p = S.V.row(v).transpose();
    out.add(p, tau, 0.0);
    out.add(p + offset * N.row(v).transpose(), tau, offset);
  }
  if (out.centre.empty()) throw InvalidInput(std::string("build_vim_morph: surface ") + which + " has no samples");
}

inline double kernel(const Eigen::Vector4d& a, const Eigen::Vector4d& b) {
  const double r = (a - b).norm();
  return r * r * r;
}

/// Weights w (#centres) and polynomial coefficients (1, x, y, z, tau) of the interpolant through the constraints.
void solve_constraints(const Constraints& c, Eigen::VectorXd& w, Eigen::Matrix<double, 5, 1>& poly) {
  const Eigen::Index n = Eigen::Index(c.centre.size());
  if (n <= 5) throw InvalidInput("build_vim_morph: need more than 5 constraints (got " + std::to_string(n) + ")");
  Eigen::MatrixXd P(n, 5);
  Eigen::VectorXd f(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    P(i, 0) = 1.0;
    P.row(i).tail<4>() = c.centre[std::size_t(i)].transpose();
    f(i) = c.value[std::size_t(i)];
  }
  Eigen::MatrixXd M(n, n);
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, n, 64), [&](const tbb::blocked_range<Eigen::Index>& r) {
    for (Eigen::Index j = r.begin(); j != r.end(); ++j)
      for (Eigen::Index i = 0; i < n; ++i) M(i, j) = kernel(c.centre[std::size_t(i)], c.centre[std::size_t(j)]);
  });
  // w must be orthogonal to the polynomials (P^T w = 0): w = Q2 y with Q = [Q1 Q2] from P = Q R, and then
  // Q2^T Phi Q2 y = Q2^T f, a positive definite system for the order-2 conditionally positive definite r^3.
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(P);
  const auto Q = qr.householderQ();
  M.applyOnTheLeft(Q.adjoint());
  M.applyOnTheRight(Q);
  const Eigen::VectorXd g = Q.adjoint() * f;
  const Eigen::Index m = n - 5;
  const Eigen::LLT<Eigen::MatrixXd> llt(M.bottomRightCorner(m, m));
  if (llt.info() != Eigen::Success)
    throw SolverError("build_vim_morph: the constraint system is numerically singular (coincident samples?)");
  const Eigen::VectorXd y = llt.solve(g.tail(m));
  Eigen::VectorXd z = Eigen::VectorXd::Zero(n);
  z.tail(m) = y;
  w = Q * z;
  const Eigen::Matrix<double, 5, 1> rhs = g.head<5>() - M.topRightCorner(5, m) * y;
  poly = qr.matrixQR().topLeftCorner<5, 5>().triangularView<Eigen::Upper>().solve(rhs);
  if (!w.allFinite() || !poly.allFinite())
    throw SolverError("build_vim_morph: the constraint system gave non-finite weights");
}

}  // namespace

double vim_constraint_bytes(const VimOptions& options) {
  // The dense kernel matrix and its Cholesky factor, for 2 centres per sample of each surface and 16 corners.
  const double centres = 4.0 * options.samples + 16.0;
  return 2.0 * centres * centres * double(sizeof(double));
}

std::vector<int> farthest_point_samples(const Eigen::MatrixXd& V, int count) {
  const Eigen::Index n = V.rows();
  std::vector<int> picked;
  if (n == 0 || count <= 0) return picked;
  if (n <= count) {
    for (Eigen::Index i = 0; i < n; ++i) picked.push_back(int(i));
    return picked;
  }
  std::vector<double> distance(std::size_t(n), std::numeric_limits<double>::infinity());
  int next = 0;
  while (int(picked.size()) < count) {
    picked.push_back(next);
    const Eigen::RowVector3d p = V.row(next);
    double farthest = -1.0;
    int arg = -1;
    for (Eigen::Index i = 0; i < n; ++i) {
      double& d = distance[std::size_t(i)];
      d = std::min(d, (V.row(i) - p).squaredNorm());
      if (d > farthest) {
        farthest = d;
        arg = int(i);
      }
    }
    if (!(farthest > 0.0)) break;  // the rest coincide with picked points
    next = arg;
  }
  return picked;
}

MorphResult build_vim_morph(const Surface& A, const Surface& B, const MorphOptions& lattice, const VimOptions& options,
                            int time_steps) {
  const auto start = Clock::now();
  if (options.samples < 3) throw InvalidInput("build_vim_morph: samples must be at least 3");
  if (!(options.separation > 0.0)) throw InvalidInput("build_vim_morph: separation must be positive");
  if (!(options.normal_offset > 0.0)) throw InvalidInput("build_vim_morph: normal_offset must be positive");
  if (time_steps < 1) throw InvalidInput("build_vim_morph: time_steps must be at least 1");
  MorphResult result;
  result.method = "vim";
  result.field = morph_lattice(A, B, lattice);
  MorphField& field = result.field;
  const double separation = options.separation * field.extent;
  const double offset = options.normal_offset * field.extent;

  Constraints c;
  add_surface(A, "A", options.samples, 0.0, offset, c);
  add_surface(B, "B", options.samples, separation, offset, c);
  // The lattice box's corners at their distances from each shape: r^3 interpolants can turn negative far from their
  // centres, which would put spurious surfaces into the lattice's corners.
  const Eigen::Vector3d box_max = field.point(field.dims.x() - 1, field.dims.y() - 1, field.dims.z() - 1);
  for (int which = 0; which < 2; ++which) {
    const SurfaceLocator locator(which == 0 ? A : B);
    for (int corner = 0; corner < 8; ++corner) {
      const Eigen::Vector3d x((corner & 1) ? box_max.x() : field.origin.x(),
                              (corner & 2) ? box_max.y() : field.origin.y(),
                              (corner & 4) ? box_max.z() : field.origin.z());
      c.add(x, which == 0 ? 0.0 : separation, locator.closest(x).distance);
    }
  }
  Eigen::VectorXd w;
  Eigen::Matrix<double, 5, 1> poly;
  solve_constraints(c, w, poly);
  const Eigen::Index n = Eigen::Index(c.centre.size());
  result.rbf_centres = std::int64_t(n);
  // In parallel like the kernel matrix it re-evaluates (a max, so exact in any order).
  result.fit_residual = tbb::parallel_reduce(
      tbb::blocked_range<Eigen::Index>(0, n, 64), 0.0,
      [&](const tbb::blocked_range<Eigen::Index>& r, double worst) {
        for (Eigen::Index i = r.begin(); i != r.end(); ++i) {
          double g = poly(0) + poly.tail<4>().dot(c.centre[std::size_t(i)]);
          for (Eigen::Index j = 0; j < n; ++j) g += w(j) * kernel(c.centre[std::size_t(i)], c.centre[std::size_t(j)]);
          worst = std::max(worst, std::abs(g - c.value[std::size_t(i)]));
        }
        return worst;
      },
      [](double a, double b) { return std::max(a, b); });
  result.fit_seconds = std::chrono::duration<double>(Clock::now() - start).count();

  // Centres in two groups by plane (A's at tau = 0 with the A corners, B's at tau = separation), as arrays, so a
  // lattice point's spatial distances to all of them are computed once and reused at every time level.
  std::vector<Eigen::Index> group_a, group_b;
  for (Eigen::Index i = 0; i < n; ++i) (c.centre[std::size_t(i)](3) == 0.0 ? group_a : group_b).push_back(i);
  struct Group {
    Eigen::ArrayXd x, y, z, w;
    double tau = 0.0;
  };
  auto make_group = [&](const std::vector<Eigen::Index>& ids, double tau) {
    Group g;
    const Eigen::Index k = Eigen::Index(ids.size());
    g.x.resize(k), g.y.resize(k), g.z.resize(k), g.w.resize(k);
    for (Eigen::Index r = 0; r < k; ++r) {
      const Eigen::Vector4d& p = c.centre[std::size_t(ids[std::size_t(r)])];
      g.x(r) = p(0), g.y(r) = p(1), g.z(r) = p(2), g.w(r) = w(ids[std::size_t(r)]);
    }
    g.tau = tau;
    return g;
  };
  const Group groups[2] = {make_group(group_a, 0.0), make_group(group_b, separation)};

  const std::int64_t n3 = std::int64_t(field.dims.x()) * field.dims.y() * field.dims.z();
  const int levels = time_steps + 1;
  field.time_levels = levels;
  field.levels.assign(std::size_t(n3) * std::size_t(levels), 0.0f);
  tbb::enumerable_thread_specific<std::array<Eigen::ArrayXd, 2>> scratch;
  tbb::parallel_for(tbb::blocked_range<int>(0, field.dims.z()), [&](const tbb::blocked_range<int>& range) {
    std::array<Eigen::ArrayXd, 2>& d2 = scratch.local();
    for (int k = range.begin(); k != range.end(); ++k)
      for (int j = 0; j < field.dims.y(); ++j)
        for (int i = 0; i < field.dims.x(); ++i) {
          const Eigen::Vector3d p = field.point(i, j, k);
          for (int g = 0; g < 2; ++g)
            d2[g] = (groups[g].x - p.x()).square() + (groups[g].y - p.y()).square() + (groups[g].z - p.z()).square();
          const std::int64_t q = field.index(i, j, k);
          for (int l = 0; l < levels; ++l) {
            const double tau = separation * double(l) / time_steps;
            double value = poly(0) + poly(1) * p.x() + poly(2) * p.y() + poly(3) * p.z() + poly(4) * tau;
            for (int g = 0; g < 2; ++g) {
              const double dt = tau - groups[g].tau;
              value += (groups[g].w * (d2[g] + dt * dt).sqrt().cube()).sum();
            }
            field.levels[std::size_t(l) * std::size_t(n3) + std::size_t(q)] = float(value);
          }
        }
  });
  field.dA.assign(field.levels.begin(), field.levels.begin() + n3);
  field.dB.assign(field.levels.end() - n3, field.levels.end());
  result.lattice_points = n3;
  result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return result;
}

}  // namespace morphmap
