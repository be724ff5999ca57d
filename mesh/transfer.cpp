// Texture transfer (paper §8.2): labels are points of A; their closest point on A's original mesh
// (CGAL AABB tree, kept in this file only because it is slow to compile) gives a face and barycentric
// weights that interpolate the corner UVs.
#include "mesh/transfer.h"

#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <string>

#include "mesh/errors.h"

namespace morphmap {

namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using Triangle3 = Kernel::Triangle_3;
using Point3 = Kernel::Point_3;
using TriangleIterator = std::vector<Triangle3>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, TriangleIterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;

// Weights of q (already on the triangle) in (a, b, c). A degenerate triangle is a segment or a point:
// project on its longest edge, which spans it, instead of inverting a singular Gram matrix.
Eigen::Vector3d barycentric_of(const Eigen::Vector3d& q, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                               const Eigen::Vector3d& c) {
  const Eigen::Vector3d e1 = b - a;
  const Eigen::Vector3d e2 = c - a;
  const Eigen::Vector3d d = q - a;
  const double g11 = e1.squaredNorm();
  const double g12 = e1.dot(e2);
  const double g22 = e2.squaredNorm();
  const double det = g11 * g22 - g12 * g12;
  Eigen::Vector3d w;
  if (det > 1e-12 * g11 * g22 && det > 0.0) {
    const double r1 = e1.dot(d);
    const double r2 = e2.dot(d);
    const double u = (g22 * r1 - g12 * r2) / det;
    const double v = (g11 * r2 - g12 * r1) / det;
    w << 1.0 - u - v, u, v;
  } else {
    const Eigen::Vector3d p[3] = {a, b, c};
    int longest = 0;
    double length = -1.0;
    for (int k = 0; k < 3; ++k) {
      const double l = (p[(k + 1) % 3] - p[k]).squaredNorm();
      if (l > length) {
        length = l;
        longest = k;
      }
    }
    w.setZero();
    if (length > 0.0) {
      const double u = std::clamp((q - p[longest]).dot(p[(longest + 1) % 3] - p[longest]) / length, 0.0, 1.0);
      w(longest) = 1.0 - u;
      w((longest + 1) % 3) = u;
    } else {
      w(0) = 1.0;
    }
  }
  // q lies on the triangle, so negative weights are rounding: clamp them to keep interpolation convex.
  w = w.cwiseMax(0.0);
  const double sum = w.sum();
  if (sum > 0.0)
    w /= sum;
  else
    w << 1.0, 0.0, 0.0;
  return w;
}

}  // namespace

struct SurfaceLocator::Impl {
  Eigen::MatrixXd V;
  Eigen::MatrixXi F;
  std::vector<Triangle3> triangles;
  Tree tree;
};

SurfaceLocator::SurfaceLocator(const Surface& surface) : impl_(std::make_unique<Impl>()) {
  const std::string name = surface.name.empty() ? std::string("SurfaceLocator") : surface.name;
  if (surface.F.rows() == 0 || surface.V.rows() == 0) throw InvalidInput(name + ": empty surface");
  if (surface.F.cols() != 3 || surface.V.cols() != 3) throw InvalidInput(name + ": V and F must have 3 columns");
  if (surface.F.minCoeff() < 0 || surface.F.maxCoeff() >= surface.V.rows())
    throw InvalidInput(name + ": face index out of range");
  if (!surface.V.allFinite()) throw InvalidInput(name + ": non-finite vertex");
  impl_->V = surface.V;
  impl_->F = surface.F;
  impl_->triangles.reserve(std::size_t(surface.F.rows()));
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f) {
    Point3 p[3];
    for (int k = 0; k < 3; ++k) {
      const auto v = surface.F(f, k);
      p[k] = Point3(surface.V(v, 0), surface.V(v, 1), surface.V(v, 2));
    }
    impl_->triangles.emplace_back(p[0], p[1], p[2]);
  }
  impl_->tree.insert(impl_->triangles.cbegin(), impl_->triangles.cend());
  // Build both the hierarchy and the distance-query KD tree now: lazy construction inside a const
  // query would serialise the first parallel queries on CGAL's mutex.
  impl_->tree.build();
  impl_->tree.accelerate_distance_queries();
}

SurfaceLocator::~SurfaceLocator() = default;

SurfaceHit SurfaceLocator::closest(const Eigen::Vector3d& query) const {
  const Point3 q(query.x(), query.y(), query.z());
  const auto [point, id] = impl_->tree.closest_point_and_primitive(q);
  SurfaceHit hit;
  hit.point = Eigen::Vector3d(point.x(), point.y(), point.z());
  hit.face = int(id - impl_->triangles.cbegin());
  hit.distance = (hit.point - query).norm();
  const auto& F = impl_->F;
  const auto& V = impl_->V;
  hit.barycentric = barycentric_of(hit.point, V.row(F(hit.face, 0)).transpose(), V.row(F(hit.face, 1)).transpose(),
                                   V.row(F(hit.face, 2)).transpose());
  return hit;
}

std::vector<SurfaceHit> SurfaceLocator::closest_all(const Eigen::MatrixXd& Q) const {
  if (Q.rows() > 0 && Q.cols() != 3) throw InvalidInput("SurfaceLocator::closest_all: queries must be #Q by 3");
  std::vector<SurfaceHit> hits(std::size_t(Q.rows()));
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, Q.rows(), 256), [&](const tbb::blocked_range<Eigen::Index>& r) {
    for (Eigen::Index i = r.begin(); i != r.end(); ++i) hits[std::size_t(i)] = closest(Q.row(i).transpose());
  });
  return hits;
}

Eigen::MatrixXd uv_at(const Surface& surface, const std::vector<SurfaceHit>& hits) {
  if (!surface.has_uv()) throw InvalidInput("uv_at: surface " + surface.name + " has no texture coordinates");
  if (surface.FUV.cols() != 3 || surface.UV.cols() != 2 || surface.FUV.minCoeff() < 0 ||
      surface.FUV.maxCoeff() >= surface.UV.rows())
    throw InvalidInput("uv_at: surface " + surface.name + " has texture indices out of range");
  Eigen::MatrixXd uv(Eigen::Index(hits.size()), 2);
  for (std::size_t i = 0; i < hits.size(); ++i) {
    const SurfaceHit& h = hits[i];
    if (h.face < 0 || h.face >= surface.FUV.rows())
      throw InvalidInput("uv_at: hit " + std::to_string(i) + " has no face");
    Eigen::Vector2d value = Eigen::Vector2d::Zero();
    for (int k = 0; k < 3; ++k) value += h.barycentric(k) * surface.UV.row(surface.FUV(h.face, k)).transpose();
    uv.row(Eigen::Index(i)) = value.transpose();
  }
  return uv;
}

Eigen::MatrixXd points_of(const std::vector<SurfaceHit>& hits) {
  Eigen::MatrixXd P(Eigen::Index(hits.size()), 3);
  for (std::size_t i = 0; i < hits.size(); ++i) P.row(Eigen::Index(i)) = hits[i].point.transpose();
  return P;
}

}  // namespace morphmap
