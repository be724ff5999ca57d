// Texture transfer (paper §8.2): labels are points of A; their closest point on A's original mesh gives a face and
// barycentric weights that interpolate the corner UVs. Closest points come from Embree point queries (rtcPointQuery)
// over a single-precision BVH of the faces that only prunes; every face it offers is measured exactly in double
// precision (Ericson, Real-Time Collision Detection §5.1.5), and the query radius keeps a margin over Embree's
// rounding so that no face that could win, or tie, is pruned.
#include "mesh/transfer.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "mesh/errors.h"

namespace morphmap {

namespace {

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

Eigen::Vector3d closest_on_segment(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double length = ab.squaredNorm();
  if (!(length > 0.0)) return a;
  return a + std::clamp((p - a).dot(ab) / length, 0.0, 1.0) * ab;
}

// Ericson's Voronoi-region test. Its vertex tests are exact for any triangle and each edge branch returns the foot
// on that edge, so only its divisions need guards: a repeated vertex makes an edge's denominator zero, and a
// collinear (zero-area) triangle leaves the face branch with a zero or rounding-signed denominator; such a triangle
// is the union of its edges.
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return d1 - d3 > 0.0 ? Eigen::Vector3d(a + d1 / (d1 - d3) * ab) : a;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return d2 - d6 > 0.0 ? Eigen::Vector3d(a + d2 / (d2 - d6) * ac) : a;
  const double va = d3 * d6 - d5 * d4;
  const double e = d4 - d3, f = d5 - d6;
  if (va <= 0.0 && e >= 0.0 && f >= 0.0) return e + f > 0.0 ? Eigen::Vector3d(b + e / (e + f) * (c - b)) : b;
  const double denom = va + vb + vc;
  if (denom > 0.0 && std::isfinite(1.0 / denom)) {
    const Eigen::Vector3d inside = a + ab * (vb / denom) + ac * (vc / denom);
    if (inside.allFinite()) return inside;
  }
  Eigen::Vector3d best = closest_on_segment(p, a, b);
  for (const Eigen::Vector3d& x : {closest_on_segment(p, b, c), closest_on_segment(p, c, a)})
    if ((x - p).squaredNorm() < (best - p).squaredNorm()) best = x;
  return best;
}

// The least float not below x: a query radius that never undercuts the distance it stands for.
float float_above(double x) {
  if (!(x < double(FLT_MAX))) return std::numeric_limits<float>::infinity();
  float f = float(x);
  if (double(f) < x) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

// Embree reports errors through a callback on the thread whose call failed; the call's caller then throws. The code
// is a plain thread_local so that the check after every query costs one load.
thread_local RTCError embree_error = RTC_ERROR_NONE;
thread_local std::string embree_message;

void record_embree_error(void*, RTCError code, const char* message) {
  if (embree_error != RTC_ERROR_NONE) return;  // keep the first: later ones usually follow from it
  embree_error = code;
  embree_message = message != nullptr ? message : "";
}

const char* error_name(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE:
      return "no error";
    case RTC_ERROR_INVALID_ARGUMENT:
      return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION:
      return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY:
      return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU:
      return "unsupported CPU";
    case RTC_ERROR_CANCELLED:
      return "cancelled";
    default:
      return "unknown error";
  }
}

void throw_if_embree_failed(const std::string& function, RTCDevice device) {
  RTCError code = embree_error;
  std::string message = embree_message;
  embree_error = RTC_ERROR_NONE;
  embree_message.clear();
  // The device keeps its own sticky code too (also set before the callback exists, by rtcNewDevice).
  const RTCError sticky = rtcGetDeviceError(device);
  if (code == RTC_ERROR_NONE) code = sticky;
  if (code == RTC_ERROR_NONE) return;
  throw Error(function + " failed: Embree " + error_name(code) + (message.empty() ? "" : ": " + message));
}

struct Corners {
  Eigen::Vector3d p[3];
};

// Embree drops a triangle with a vertex coordinate beyond FLT_LARGE (1.8e18) and squares node distances in float:
// past this reach (from the mesh's box centre) the faces, or a query, are scanned instead.
constexpr double kFloatReach = 1e17;

// The best face so far by (squared distance, face index): a lexicographic minimum, so the answer is the same
// whatever order the BVH (built in parallel) offers the faces in.
struct Search {
  const std::vector<Corners>* faces = nullptr;
  Eigen::Vector3d query = Eigen::Vector3d::Zero();
  double slack = 0.0;  ///< absolute error of Embree's node distances from rounding the query and vertices to float
  double best_d2 = std::numeric_limits<double>::infinity();
  int best_face = -1;
  Eigen::Vector3d best_point = Eigen::Vector3d::Zero();

  bool visit(unsigned face) {
    const Corners& t = (*faces)[face];
    const Eigen::Vector3d x = closest_on_triangle(query, t.p[0], t.p[1], t.p[2]);
    const double d2 = (x - query).squaredNorm();
    if (d2 < best_d2 || (d2 == best_d2 && int(face) < best_face)) {
      best_d2 = d2;
      best_face = int(face);
      best_point = x;
      return true;
    }
    return false;
  }

  // Above the best distance by more than Embree's rounding (relative 1e-6 covers its float squares and sums, slack
  // the rounded query and vertices), so a node at exactly the best distance, which may hold a tie, is still visited.
  float radius() const { return float_above((std::sqrt(best_d2) + slack) * (1.0 + 1e-6)); }
};

bool visit_face(RTCPointQueryFunctionArguments* args) {
  auto* search = static_cast<Search*>(args->userPtr);
  if (!search->visit(args->primID)) return false;
  const float r = search->radius();
  if (!(r < args->query->radius)) return false;
  args->query->radius = r;
  return true;
}

}  // namespace

struct SurfaceLocator::Impl {
  std::vector<Corners> faces;
  std::vector<Corners> reported;  ///< the surface's own corners when the search runs on a moved copy, else empty
  Eigen::Vector3d shift = Eigen::Vector3d::Zero();  ///< box centre: Embree's float frame, precise near the mesh
  double extent = 0.0;                              ///< largest |coordinate| of a vertex in that frame
  // One device per locator: it takes 0.2 ms to create, and a shared static one would be released during static
  // destruction, in no defined order with TBB's.
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;

  Impl() = default;
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;
  ~Impl() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (device != nullptr) rtcReleaseDevice(device);
  }
};

SurfaceLocator::SurfaceLocator(const Surface& surface) : SurfaceLocator(surface, surface.V) {}

SurfaceLocator::SurfaceLocator(const Surface& surface, const Eigen::MatrixXd& search_V)
    : impl_(std::make_unique<Impl>()) {
  const std::string name = surface.name.empty() ? std::string("SurfaceLocator") : surface.name;
  if (surface.F.rows() == 0 || surface.V.rows() == 0) throw InvalidInput(name + ": empty surface");
  if (surface.F.cols() != 3 || surface.V.cols() != 3) throw InvalidInput(name + ": V and F must have 3 columns");
  if (surface.F.minCoeff() < 0 || surface.F.maxCoeff() >= surface.V.rows())
    throw InvalidInput(name + ": face index out of range");
  if (!surface.V.allFinite()) throw InvalidInput(name + ": non-finite vertex");
  if (search_V.rows() != surface.V.rows() || search_V.cols() != 3 || !search_V.allFinite())
    throw InvalidInput(name + ": the search positions must be #V by 3 and finite");
  Impl& m = *impl_;
  const bool moved = &search_V != &surface.V;
  m.faces.resize(std::size_t(surface.F.rows()));
  if (moved) m.reported.resize(m.faces.size());
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, surface.F.rows(), 4096),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      for (Eigen::Index f = r.begin(); f != r.end(); ++f)
                        for (int k = 0; k < 3; ++k) {
                          m.faces[std::size_t(f)].p[k] = search_V.row(surface.F(f, k)).transpose();
                          if (moved) m.reported[std::size_t(f)].p[k] = surface.V.row(surface.F(f, k)).transpose();
                        }
                    });
  const Eigen::AlignedBox3d box = bounding_box(search_V);
  m.shift = box.center();
  m.extent = (box.max() - m.shift).cwiseMax(m.shift - box.min()).maxCoeff();
  if (!(m.extent < kFloatReach)) return;  // closest() scans

  m.device = rtcNewDevice(nullptr);
  if (m.device == nullptr) throw_if_embree_failed(name + ": rtcNewDevice", nullptr);
  rtcSetDeviceErrorFunction(m.device, record_embree_error, nullptr);
  m.scene = rtcNewScene(m.device);
  throw_if_embree_failed(name + ": rtcNewScene", m.device);
  // MEDIUM builds in two thirds of the time of a user geometry and a fifth of HIGH (spatial splits), with the same
  // query speed (bench/bench_locator.cpp); the hits do not depend on the tree. Embree keeps zero-area triangles (it
  // drops only out-of-range indices and non-finite or huge vertices), which the tests check.
  rtcSetSceneBuildQuality(m.scene, RTC_BUILD_QUALITY_MEDIUM);
  RTCGeometry geometry = rtcNewGeometry(m.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  throw_if_embree_failed(name + ": rtcNewGeometry", m.device);
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                               3 * sizeof(float), std::size_t(surface.V.rows())));
  auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                 3 * sizeof(unsigned), std::size_t(surface.F.rows())));
  if (vertices == nullptr || indices == nullptr) {
    rtcReleaseGeometry(geometry);
    throw_if_embree_failed(name + ": rtcSetNewGeometryBuffer", m.device);
    throw Error(name + ": rtcSetNewGeometryBuffer failed");
  }
  for (Eigen::Index i = 0; i < search_V.rows(); ++i)
    for (int c = 0; c < 3; ++c) vertices[3 * i + c] = float(search_V(i, c) - m.shift(c));
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) indices[3 * f + c] = unsigned(surface.F(f, c));
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(m.scene, geometry);
  rtcReleaseGeometry(geometry);
  throw_if_embree_failed(name + ": rtcCommitGeometry", m.device);
  rtcCommitScene(m.scene);
  throw_if_embree_failed(name + ": rtcCommitScene", m.device);
}

SurfaceLocator::~SurfaceLocator() = default;

SurfaceHit SurfaceLocator::closest(const Eigen::Vector3d& query) const { return closest_near(query, -1); }

SurfaceHit SurfaceLocator::closest_near(const Eigen::Vector3d& query, int hint, double within) const {
  if (!query.allFinite()) throw InvalidInput("SurfaceLocator::closest: non-finite query point");
  const Impl& m = *impl_;
  Search search;
  search.faces = &m.faces;
  search.query = query;
  if (within < std::numeric_limits<double>::infinity()) search.best_d2 = within * within;
  // A face near the answer, visited first, bounds the search radius from the start: Embree then prunes every node
  // farther than it instead of descending from an infinite radius. The answer is the lexicographic minimum of
  // (distance, face) over the faces within the radius, which the bound's margin keeps, so it is the same.
  if (hint >= 0 && std::size_t(hint) < m.faces.size()) search.visit(unsigned(hint));
  const Eigen::Vector3d local = query - m.shift;
  const double reach = local.cwiseAbs().maxCoeff();
  if (m.scene != nullptr && reach < kFloatReach) {
    // Rounding the query and the vertices to float moves each coordinate by at most half an ulp, 2^-24 of its
    // magnitude: sqrt(3) 2^-24 (|q| + |v|) in distance, well inside 4 FLT_EPSILON = 2^-21 of the sum.
    search.slack = 4.0 * FLT_EPSILON * (m.extent + reach);
    RTCPointQuery point;
    point.x = float(local.x());
    point.y = float(local.y());
    point.z = float(local.z());
    point.time = 0.0f;
    point.radius = search.best_d2 < std::numeric_limits<double>::infinity() ? search.radius()
                                                                            : std::numeric_limits<float>::infinity();
    RTCPointQueryContext context;
    rtcInitPointQueryContext(&context);
    rtcPointQuery(m.scene, &point, &context, visit_face, &search);
    if (embree_error != RTC_ERROR_NONE) throw_if_embree_failed("SurfaceLocator::closest: rtcPointQuery", m.device);
  } else {
    for (std::size_t f = 0; f < m.faces.size(); ++f) search.visit(unsigned(f));
  }
  SurfaceHit hit;
  if (search.best_face < 0) {
    if (within < std::numeric_limits<double>::infinity()) {
      hit.distance = std::numeric_limits<double>::infinity();
      return hit;
    }
    throw Error("SurfaceLocator::closest: the point query found no face");
  }
  hit.point = search.best_point;
  hit.face = search.best_face;
  hit.distance = (hit.point - query).norm();
  const Corners& t = m.faces[std::size_t(hit.face)];
  hit.barycentric = barycentric_of(hit.point, t.p[0], t.p[1], t.p[2]);
  if (!m.reported.empty()) {
    const Corners& r = m.reported[std::size_t(hit.face)];
    hit.point = hit.barycentric(0) * r.p[0] + hit.barycentric(1) * r.p[1] + hit.barycentric(2) * r.p[2];
  }
  return hit;
}

std::vector<SurfaceHit> SurfaceLocator::closest_all(const Eigen::MatrixXd& Q, double within) const {
  if (Q.rows() > 0 && Q.cols() != 3) throw InvalidInput("SurfaceLocator::closest_all: queries must be #Q by 3");
  std::vector<SurfaceHit> hits(std::size_t(Q.rows()));
  // Callers pass queries in a coherent order (lattice points, mesh vertices), so each query starts from the face
  // of the one before it (closest_near; the same hits as closest()).
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, Q.rows(), 256), [&](const tbb::blocked_range<Eigen::Index>& r) {
    int hint = -1;
    for (Eigen::Index i = r.begin(); i != r.end(); ++i) {
      hits[std::size_t(i)] = closest_near(Q.row(i).transpose(), hint, within);
      if (hits[std::size_t(i)].face >= 0) hint = hits[std::size_t(i)].face;
    }
  });
  return hits;
}

namespace {

// Parameter t in [0, 1] where the segment a + t (b - a) meets the triangle, or -1 (Moller and Trumbore 1997). Only
// for the scan of surfaces too large for Embree's float frame.
double segment_hit(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Corners& tri) {
  const Eigen::Vector3d dir = b - a;
  const Eigen::Vector3d e1 = tri.p[1] - tri.p[0], e2 = tri.p[2] - tri.p[0];
  const Eigen::Vector3d p = dir.cross(e2);
  const double det = e1.dot(p);
  if (det == 0.0) return -1.0;
  const Eigen::Vector3d s = a - tri.p[0];
  const double u = s.dot(p) / det;
  if (u < 0.0 || u > 1.0) return -1.0;
  const Eigen::Vector3d q = s.cross(e1);
  const double v = dir.dot(q) / det;
  if (v < 0.0 || u + v > 1.0) return -1.0;
  const double t = e2.dot(q) / det;
  return t >= 0.0 && t <= 1.0 ? t : -1.0;
}

}  // namespace

std::vector<double> SurfaceLocator::crossings(const Eigen::Vector3d& a, const Eigen::Vector3d& b, int limit,
                                              double separation, std::vector<int>* directions) const {
  if (!a.allFinite() || !b.allFinite()) throw InvalidInput("SurfaceLocator::crossings: non-finite segment");
  const Impl& m = *impl_;
  const Eigen::Vector3d la = a - m.shift, lb = b - m.shift;
  std::vector<double> hits;
  if (directions != nullptr) directions->clear();
  const auto direction = [&](std::size_t face) {
    const Corners& t = m.faces[face];
    return (b - a).dot((t.p[1] - t.p[0]).cross(t.p[2] - t.p[0])) >= 0.0 ? 1 : -1;
  };
  if (m.scene != nullptr && la.cwiseAbs().maxCoeff() < kFloatReach && lb.cwiseAbs().maxCoeff() < kFloatReach) {
    // Embree returns the nearest hit past tnear: cast again from just past each one.
    float from = 0.0f;
    while (int(hits.size()) < limit && from <= 1.0f) {
      RTCRayHit ray;
      ray.ray.org_x = float(la.x());
      ray.ray.org_y = float(la.y());
      ray.ray.org_z = float(la.z());
      ray.ray.dir_x = float(lb.x() - la.x());
      ray.ray.dir_y = float(lb.y() - la.y());
      ray.ray.dir_z = float(lb.z() - la.z());
      ray.ray.tnear = from;
      ray.ray.tfar = 1.0f;
      ray.ray.time = 0.0f;
      ray.ray.mask = 0xFFFFFFFFu;
      ray.ray.id = 0;
      ray.ray.flags = 0;
      ray.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      ray.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      RTCIntersectContext context;
      rtcInitIntersectContext(&context);
      rtcIntersect1(m.scene, &context, &ray);
      if (embree_error != RTC_ERROR_NONE) throw_if_embree_failed("SurfaceLocator::crossings: rtcIntersect1", m.device);
      if (ray.hit.geomID == RTC_INVALID_GEOMETRY_ID) break;
      hits.push_back(double(ray.ray.tfar));
      if (directions != nullptr) directions->push_back(direction(ray.hit.primID));
      from = std::nextafter(float(double(ray.ray.tfar) + separation), 2.0f);
    }
    return hits;
  }
  std::vector<std::pair<double, std::size_t>> all;
  for (std::size_t f = 0; f < m.faces.size(); ++f) {
    const double t = segment_hit(a, b, m.faces[f]);
    if (t >= 0.0) all.emplace_back(t, f);
  }
  std::sort(all.begin(), all.end());
  for (const auto& [t, f] : all)
    if (int(hits.size()) < limit && (hits.empty() || t > hits.back() + separation)) {
      hits.push_back(t);
      if (directions != nullptr) directions->push_back(direction(f));
    }
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
