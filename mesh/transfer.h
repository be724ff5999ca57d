// Texture transfer (paper §8.2): a label (a point of A) becomes a texture coordinate through the
// closest point of A's original mesh and its barycentric interpolation of the corner UVs.
#pragma once

#include <Eigen/Core>
#include <limits>
#include <memory>
#include <vector>

#include "mesh/surface.h"

namespace morphmap {

/// Closest point on a triangle surface.
struct SurfaceHit {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();        ///< closest point on the surface
  int face = -1;                                          ///< triangle of the surface holding it
  Eigen::Vector3d barycentric = Eigen::Vector3d::Zero();  ///< weights of the face's three corners
  double distance = 0.0;
};

/// Closest-point queries on a fixed surface (Embree BVH, distances exact in double precision), safe to call from
/// many threads. A point equally close to several faces (a vertex, an edge) reports the lowest-numbered one, so hits
/// do not depend on the thread count. closest() throws InvalidInput for a non-finite query.
class SurfaceLocator {
 public:
  explicit SurfaceLocator(const Surface& surface);
  /// Queries answered on a moved copy of `surface` (its faces over the vertex positions `search_V`, #V by 3) and
  /// reported on `surface` itself, at the same face and barycentric weights: SurfaceHit::point is those weights of
  /// the face's corners on `surface`, SurfaceHit::distance the distance from the query to the moved copy.
  SurfaceLocator(const Surface& surface, const Eigen::MatrixXd& search_V);
  ~SurfaceLocator();
  SurfaceLocator(const SurfaceLocator&) = delete;
  SurfaceLocator& operator=(const SurfaceLocator&) = delete;

  SurfaceHit closest(const Eigen::Vector3d& query) const;
  /// closest() with the search started from face `hint` (-1: none), which bounds its radius from the start: the
  /// same hit, found faster when the hint is near it. With a finite `within`, only faces closer than it count (the
  /// search prunes everything beyond it from the start): the same hit as closest() when that is closer, else one
  /// with face -1 and an infinite distance.
  SurfaceHit closest_near(const Eigen::Vector3d& query, int hint,
                          double within = std::numeric_limits<double>::infinity()) const;
  /// One hit per row of Q (#Q by 3), TBB-parallel, order preserved; each query hinted by the previous one's face
  /// and bounded by `within` as in closest_near.
  std::vector<SurfaceHit> closest_all(const Eigen::MatrixXd& Q,
                                      double within = std::numeric_limits<double>::infinity()) const;
  /// Where the segment from a to b crosses the surface: the parameters t in [0, 1] of a + t (b - a), ascending, at
  /// most `limit` of them. Hits closer together than `separation` (in t) count once: a segment through a shared
  /// edge or vertex meets two or more faces there. With `directions`, also whether the segment leaves (+1: along the
  /// face's normal, (p1 - p0) x (p2 - p0)) or enters (-1) the surface at each.
  std::vector<double> crossings(const Eigen::Vector3d& a, const Eigen::Vector3d& b, int limit, double separation = 1e-4,
                                std::vector<int>* directions = nullptr) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Texture coordinates at the hits: #hits by 2, interpolated from the hit face's corner UVs.
/// Requires surface.has_uv().
Eigen::MatrixXd uv_at(const Surface& surface, const std::vector<SurfaceHit>& hits);

/// Points of the hits: #hits by 3.
Eigen::MatrixXd points_of(const std::vector<SurfaceHit>& hits);

}  // namespace morphmap
