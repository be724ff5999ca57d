// Label propagation along the flow T (paper §7, equation 6 and §7.1): an upwind scheme on the tet
// mesh. Each vertex takes the labels of the face where its -T ray leaves its star, so L stays constant
// along characteristics. The paper iterates this to convergence; we compute every vertex's upwind face
// first and then visit vertices in wavefronts of that dependency graph, so one pass is exact.
// Written by hand: no library offers upwind transport on a simplicial 3-manifold in R^4.
#include "solver/transport.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <chrono>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "mesh/adjacency.h"
#include "mesh/errors.h"

namespace morphmap {

namespace {

// The space a vertex's star is projected into: the star's tangent 3-space (with an orthonormal basis),
// or, for a folded star, all of R^4 (each tet's own hull is used).
struct Frame {
  Eigen::Matrix4d project = Eigen::Matrix4d::Identity();
  Eigen::Matrix<double, 4, 3> basis = Eigen::Matrix<double, 4, 3>::Zero();
  bool tangent = false;
};

// Coefficients c with E c the projection of `dir` onto the span of E (the columns are the edges from v
// to the three opposite vertices). False for a (near) flat configuration, whose span is undefined.
bool span_coefficients(const Frame& frame, const Eigen::Matrix<double, 4, 3>& E, const Eigen::Vector4d& dir,
                       Eigen::Vector3d& c) {
  if (frame.tangent) {
    // In the tangent space's own coordinates the system is square: LU of the 3x3 edge matrix has E's
    // conditioning, like QR, at a fraction of the cost (QR was a quarter of a whole run).
    const Eigen::Matrix3d E3 = frame.basis.transpose() * E;
    const double scale = E3.col(0).norm() * E3.col(1).norm() * E3.col(2).norm();
    if (!(std::abs(E3.determinant()) > 1e-12 * scale)) return false;
    c = E3.partialPivLu().solve(frame.basis.transpose() * dir);
    return c.allFinite();
  }
  // Householder QR works with the conditioning of E, not of E^T E: the sliver tets that iso-surfacing
  // makes next to lattice points would otherwise lose half the digits (measured: identity-morph
  // label errors of 7e-4 voxels with the normal equations).
  const Eigen::ColPivHouseholderQR<Eigen::Matrix<double, 4, 3>> qr(E);
  const Eigen::Matrix3d R = qr.matrixR().topLeftCorner<3, 3>().triangularView<Eigen::Upper>();
  // |R(2,2)| / |R(0,0)| bounds the inverse condition number: a (near) flat tet has no 3D span.
  if (!(std::abs(R(0, 0)) > 0.0) || std::abs(R(2, 2)) <= 1e-12 * std::abs(R(0, 0))) return false;
  c = qr.solve(dir);
  return c.allFinite();
}

// Where the -T ray of one vertex leaves its star.
struct UpwindFace {
  std::array<int, 3> ids{{-1, -1, -1}};
  Eigen::Vector3d weights = Eigen::Vector3d::Zero();
  bool exact = false;
};

class Sweep {
 public:
  Sweep(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& field, const TransportOptions& options,
        const SharedStars& stars)
      : mesh_(mesh),
        s_(s),
        field_(field),
        options_(options),
        stars_(stars_or_build(stars, mesh.T, mesh.vertex_count())),
        adj_(*stars_) {
    if (options.star_tangent_space) {
      tet_normal_.resize(static_cast<std::size_t>(mesh.tet_count()));
      tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, mesh.tet_count()), [&](const auto& r) {
        for (Eigen::Index t = r.begin(); t != r.end(); ++t) {
          const Eigen::Vector4d v0 = mesh.V.row(mesh.T(t, 0)).transpose();
          tet_normal_[std::size_t(t)] =
              cross4(mesh.V.row(mesh.T(t, 1)).transpose() - v0, mesh.V.row(mesh.T(t, 2)).transpose() - v0,
                     mesh.V.row(mesh.T(t, 3)).transpose() - v0);
        }
      });
    }
  }

  std::int64_t first(int v) const { return adj_.first(v); }
  std::int64_t last(int v) const { return adj_.last(v); }
  int tet(std::int64_t j) const { return adj_.tet(j); }

  // Projection onto the star's tangent space (paper §7.1): per-tet hulls of a bent star leave gaps
  // between their cones where -T fits no tet; one common projection makes the projected tets tile.
  Frame projector(int v) const {
    Frame frame;
    if (!options_.star_tangent_space) return frame;
    Eigen::Vector4d normal = Eigen::Vector4d::Zero();
    double magnitude = 0.0;
    for (std::int64_t j = first(v); j < last(v); ++j) {
      normal += tet_normal_[std::size_t(tet(j))];
      magnitude += tet_normal_[std::size_t(tet(j))].norm();
    }
    // A star whose normals cancel (a fold) has no tangent space: use each tet's own hull there.
    if (!(normal.norm() > 1e-6 * magnitude)) return frame;
    const Eigen::Vector4d n = normal.normalized();
    frame.project -= n * n.transpose();
    // Householder reflection taking n to an axis: its other three columns are an orthonormal basis of n's complement.
    int k = 0;
    n.cwiseAbs().maxCoeff(&k);
    Eigen::Vector4d u = n;
    u(k) += n(k) >= 0.0 ? 1.0 : -1.0;
    const Eigen::Matrix4d H = Eigen::Matrix4d::Identity() - 2.0 * u * u.transpose() / u.squaredNorm();
    for (int col = 0, out = 0; col < 4; ++col)
      if (col != k) frame.basis.col(out++) = H.col(col);
    frame.tangent = true;
    return frame;
  }

  // The three vertices of tet t other than v, and the projected edge matrix from v to them.
  bool opposite(int v, int t, const Frame& frame, std::array<int, 3>& ids, Eigen::Matrix<double, 4, 3>& E) const {
    int n = 0;
    for (int k = 0; k < 4; ++k)
      if (mesh_.T(t, k) != v && n < 3) ids[std::size_t(n++)] = mesh_.T(t, k);
    if (n != 3) return false;  // a tet with a repeated vertex has no opposite face
    const Eigen::Vector4d p = mesh_.V.row(v).transpose();
    for (int k = 0; k < 3; ++k) E.col(k) = frame.project * (mesh_.V.row(ids[std::size_t(k)]).transpose() - p);
    return true;
  }

  // The face the -T ray leaves through, ignoring which vertices are done. Among tets that contain the
  // ray (several when it runs along a face or edge) the one with the largest smallest weight wins.
  UpwindFace exact_face(int v) const {
    UpwindFace best;
    const Frame frame = projector(v);
    const Eigen::Vector4d back = -(frame.project * field_.row(v).transpose());
    const double back_norm = back.norm();
    if (!(back_norm > 0.0)) return best;
    double best_min = -std::numeric_limits<double>::infinity();
    for (std::int64_t j = first(v); j < last(v); ++j) {
      std::array<int, 3> ids;
      Eigen::Matrix<double, 4, 3> E;
      Eigen::Vector3d c;
      if (!opposite(v, tet(j), frame, ids, E) || !span_coefficients(frame, E, back, c)) continue;
      const double sum = c.sum();
      if (!(sum > 0.0) || (E * c).norm() <= 1e-9 * back_norm) continue;
      const Eigen::Vector3d w = c / sum;
      if (w.minCoeff() < -options_.barycentric_tolerance || w.minCoeff() <= best_min) continue;
      best_min = w.minCoeff();
      best.ids = ids;
      best.weights = w.cwiseMax(0.0);
      best.weights /= best.weights.sum();
      best.exact = true;
    }
    // Vertices with negligible weight are not read, so they are not dependencies either.
    for (int k = 0; k < 3; ++k)
      if (best.exact && best.weights(k) <= options_.barycentric_tolerance) best.ids[std::size_t(k)] = -1;
    return best;
  }

  // Fallback among tets whose opposite vertices are all done: the clamped exit point that best lines
  // up with -T. False when no incident tet is done.
  bool projected_face(int v, const std::vector<char>& done, UpwindFace& face) const {
    const Frame frame = projector(v);
    const Eigen::Vector4d back = -(frame.project * field_.row(v).transpose());
    const double back_norm = back.norm();
    double best_alignment = -std::numeric_limits<double>::infinity();
    bool have = false;
    for (std::int64_t j = first(v); j < last(v); ++j) {
      std::array<int, 3> ids;
      Eigen::Matrix<double, 4, 3> E;
      if (!opposite(v, tet(j), frame, ids, E)) continue;
      if (!done[std::size_t(ids[0])] || !done[std::size_t(ids[1])] || !done[std::size_t(ids[2])]) continue;
      Eigen::Vector3d c;
      Eigen::Vector3d w =
          span_coefficients(frame, E, back, c) ? Eigen::Vector3d(c.cwiseMax(0.0)) : Eigen::Vector3d::Zero();
      if (!(w.sum() > 0.0)) w.setConstant(1.0);
      w /= w.sum();
      const Eigen::Vector4d d = E * w;
      const double alignment = (back_norm > 0.0 && d.norm() > 0.0) ? back.dot(d) / (back_norm * d.norm()) : -2.0;
      if (!have || alignment > best_alignment) {
        have = true;
        best_alignment = alignment;
        face.ids = ids;
        face.weights = w;
      }
    }
    return have;
  }

 private:
  const TetMesh4& mesh_;
  const Eigen::VectorXd& s_;
  const Eigen::MatrixXd& field_;
  const TransportOptions& options_;
  SharedStars stars_;
  const VertexTets& adj_;
  std::vector<Eigen::Vector4d> tet_normal_;
};

}  // namespace

TransportResult transport_labels(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                                 const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& unreached,
                                 const TransportOptions& options, const SharedStars& stars) {
  if (mesh.V.cols() != 4) throw InvalidInput("transport_labels: mesh.V must be #V by 4");
  const Eigen::MatrixXd positions = mesh.V.leftCols(3);
  return transport_values(
      mesh, s, vertex_field, positions,
      [&](const Eigen::Vector3d& x) -> Eigen::RowVectorXd { return (unreached ? unreached(x) : x).transpose(); },
      options, stars);
}

TransportResult transport_values(const TetMesh4& mesh, const Eigen::VectorXd& s, const Eigen::MatrixXd& vertex_field,
                                 const Eigen::MatrixXd& source,
                                 const std::function<Eigen::RowVectorXd(const Eigen::Vector3d&)>& unreached,
                                 const TransportOptions& options, const SharedStars& stars) {
  const auto start = std::chrono::steady_clock::now();
  const Eigen::Index nv = mesh.vertex_count();
  if (mesh.V.cols() != 4) throw InvalidInput("transport_labels: mesh.V must be #V by 4");
  if (s.size() != nv)
    throw InvalidInput("transport_labels: s has " + std::to_string(s.size()) + " entries, mesh has " +
                       std::to_string(nv) + " vertices");
  if (vertex_field.rows() != nv || vertex_field.cols() != 4)
    throw InvalidInput("transport_labels: vertex_field must be #V by 4");
  if (mesh.side.size() != static_cast<std::size_t>(nv))
    throw InvalidInput("transport_labels: mesh.side must have #V entries");
  if (!s.allFinite() || !vertex_field.allFinite()) throw InvalidInput("transport_labels: s or vertex_field not finite");
  if (mesh.T.size() > 0 && (mesh.T.minCoeff() < 0 || mesh.T.maxCoeff() >= nv))
    throw InvalidInput("transport_labels: tet index out of range");
  if (source.rows() != nv || source.cols() < 1) throw InvalidInput("transport_values: source must be #V by k, k >= 1");
  const Eigen::Index width = source.cols();

  TransportResult result;
  result.labels = Eigen::MatrixXd::Zero(nv, width);
  if (options.record_upwind) {
    result.upwind = Eigen::MatrixXi::Constant(nv, 3, -1);
    result.wave = Eigen::VectorXi::Constant(nv, -1);
  }
  const Sweep sweep(mesh, s, vertex_field, options, stars);
  auto before = [&](int a, int b) { return s(a) < s(b) || (s(a) == s(b) && a < b); };

  // 1. Every vertex's exact upwind face, independent of any order (parallel).
  std::vector<UpwindFace> face(static_cast<std::size_t>(nv));
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, nv), [&](const auto& r) {
    for (Eigen::Index v = r.begin(); v != r.end(); ++v)
      if (mesh.side[std::size_t(v)] != VertexSide::A) face[std::size_t(v)] = sweep.exact_face(int(v));
  });

  // 2. Dependencies: the vertices a label reads. A vertex without an exact face waits for its star
  // neighbours that come earlier in s, so its fallback sees everything upwind of it.
  std::vector<std::int64_t> dep_offset(static_cast<std::size_t>(nv) + 1, 0);
  std::vector<int> deps;
  for (Eigen::Index v = 0; v < nv; ++v) {
    const std::size_t begin = deps.size();
    if (mesh.side[std::size_t(v)] != VertexSide::A) {
      const UpwindFace& f = face[std::size_t(v)];
      if (f.exact) {
        for (int id : f.ids)
          if (id >= 0) deps.push_back(id);
      } else {
        for (std::int64_t j = sweep.first(int(v)); j < sweep.last(int(v)); ++j)
          for (int k = 0; k < 4; ++k) {
            const int u = mesh.T(sweep.tet(j), k);
            if (u != v && before(u, int(v))) deps.push_back(u);
          }
      }
      std::sort(deps.begin() + std::ptrdiff_t(begin), deps.end());
      deps.erase(std::unique(deps.begin() + std::ptrdiff_t(begin), deps.end()), deps.end());
    }
    dep_offset[std::size_t(v) + 1] = std::int64_t(deps.size());
  }
  std::vector<int> waiting(static_cast<std::size_t>(nv), 0);
  std::vector<std::int64_t> out_offset(static_cast<std::size_t>(nv) + 1, 0);
  for (Eigen::Index v = 0; v < nv; ++v) {
    waiting[std::size_t(v)] = int(dep_offset[std::size_t(v) + 1] - dep_offset[std::size_t(v)]);
    for (std::int64_t j = dep_offset[std::size_t(v)]; j < dep_offset[std::size_t(v) + 1]; ++j)
      ++out_offset[std::size_t(deps[std::size_t(j)]) + 1];
  }
  for (std::size_t i = 1; i < out_offset.size(); ++i) out_offset[i] += out_offset[i - 1];
  std::vector<int> dependents(static_cast<std::size_t>(out_offset.back()));
  {
    std::vector<std::int64_t> fill(out_offset.begin(), out_offset.end() - 1);
    for (Eigen::Index v = 0; v < nv; ++v)
      for (std::int64_t j = dep_offset[std::size_t(v)]; j < dep_offset[std::size_t(v) + 1]; ++j)
        dependents[std::size_t(fill[std::size_t(deps[std::size_t(j)])]++)] = int(v);
  }

  // 3. Wavefronts: a vertex is labelled once everything it reads is final. Labels within a wavefront
  // are independent, so the parallel loop gives the same result for any thread count. When no vertex
  // is ready the rest is held up by a dependency cycle: the earliest vertex in s breaks it by fallback.
  std::vector<int> order(static_cast<std::size_t>(nv));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), before);
  std::vector<char> done(static_cast<std::size_t>(nv), 0);
  enum Kind : std::uint8_t { kExact, kProjected, kNeighbours, kUnreached };
  std::vector<std::uint8_t> kind(static_cast<std::size_t>(nv), kExact);
  std::vector<int> front, next;
  for (Eigen::Index v = 0; v < nv; ++v)
    if (waiting[std::size_t(v)] == 0) front.push_back(int(v));
  std::size_t order_pos = 0;
  Eigen::Index finished = 0;
  std::vector<char> forced(static_cast<std::size_t>(nv), 0);

  auto label_one = [&](int v) {
    if (mesh.side[std::size_t(v)] == VertexSide::A) {
      result.labels.row(v) = source.row(v);
      return;
    }
    const UpwindFace& f = face[std::size_t(v)];
    UpwindFace use = f;
    if (!f.exact || forced[std::size_t(v)]) {
      if (sweep.projected_face(v, done, use)) {
        kind[std::size_t(v)] = kProjected;
      } else {
        // A local minimum of s: the labelled neighbours are the best causal estimate available.
        Eigen::RowVectorXd sum = Eigen::RowVectorXd::Zero(width);
        int count = 0, shown = 0;
        int last_u = -1;
        std::vector<int> nb;
        for (std::int64_t j = sweep.first(v); j < sweep.last(v); ++j)
          for (int k = 0; k < 4; ++k) {
            const int u = mesh.T(sweep.tet(j), k);
            if (u != v && done[std::size_t(u)]) nb.push_back(u);
          }
        std::sort(nb.begin(), nb.end());
        for (int u : nb) {
          if (u == last_u) continue;
          last_u = u;
          sum += result.labels.row(u);
          if (options.record_upwind && shown < 3) result.upwind(v, shown++) = u;
          ++count;
        }
        if (count > 0) {
          result.labels.row(v) = sum / count;
          kind[std::size_t(v)] = kNeighbours;
        } else {
          // Nothing flows in (a component born mid-morph): the caller decides, by default the vertex itself.
          const Eigen::Vector3d x = mesh.V.row(v).head<3>().transpose();
          if (unreached) {
            const Eigen::RowVectorXd value = unreached(x);
            if (value.size() != width) throw InvalidInput("transport_values: unreached() returned the wrong width");
            result.labels.row(v) = value;
          } else {
            result.labels.row(v) = source.row(v);
          }
          kind[std::size_t(v)] = kUnreached;
        }
        return;
      }
    }
    Eigen::RowVectorXd label = Eigen::RowVectorXd::Zero(width);
    for (int k = 0; k < 3; ++k)
      if (use.ids[std::size_t(k)] >= 0) label += use.weights(k) * result.labels.row(use.ids[std::size_t(k)]);
    result.labels.row(v) = label;
    if (options.record_upwind)
      for (int k = 0; k < 3; ++k) result.upwind(v, k) = use.ids[std::size_t(k)];
  };

  auto release = [&](const std::vector<int>& wave) {
    for (int v : wave) done[std::size_t(v)] = 1;
    next.clear();
    for (int v : wave)
      for (std::int64_t j = out_offset[std::size_t(v)]; j < out_offset[std::size_t(v) + 1]; ++j) {
        const int u = dependents[std::size_t(j)];
        if (--waiting[std::size_t(u)] == 0 && !done[std::size_t(u)]) next.push_back(u);
      }
    std::sort(next.begin(), next.end());
  };

  while (finished < nv) {
    if (front.empty()) {
      while (done[std::size_t(order[order_pos])]) ++order_pos;
      const int v = order[order_pos];
      forced[std::size_t(v)] = 1;
      ++result.cycle_breaks;
      front.push_back(v);
    }
    // Launching a parallel loop costs more than labelling a small wavefront (most are: 44k wavefronts
    // of 80 vertices on average for cow -> horse); either way each label reads only earlier waves.
    if (front.size() < 256) {
      for (int v : front) label_one(v);
    } else {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, front.size(), 64), [&](const auto& r) {
        for (std::size_t i = r.begin(); i != r.end(); ++i) label_one(front[i]);
      });
    }
    if (options.record_upwind)
      for (int v : front) result.wave(v) = int(result.wavefronts);
    finished += Eigen::Index(front.size());
    ++result.wavefronts;
    release(front);
    // A forced vertex may also become ready later through its dependencies: it is done, skip it then.
    front.clear();
    for (int u : next)
      if (!done[std::size_t(u)]) front.push_back(u);
  }

  for (Eigen::Index v = 0; v < nv; ++v) {
    if (mesh.side[std::size_t(v)] == VertexSide::A) continue;
    switch (kind[std::size_t(v)]) {
      case kExact:
        ++result.upwind_exact;
        break;
      case kProjected:
        ++result.fallback_projected;
        break;
      case kNeighbours:
        ++result.fallback_neighbours;
        break;
      case kUnreached:
        ++result.fallback_unreached;
        break;
    }
  }
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace morphmap
