// Headless pictures of the morph's surfaces (paper Figures 1 and 9): Embree casts one fixed grid of rays per
// pixel; colour comes from the texture, a checkerboard or a per-face scalar through per-corner UVs and
// Embree's barycentrics, lit by one directional light plus ambient.
#include "io/render.h"

#include <embree3/rtcore.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>

#include "io/image.h"
#include "mesh/errors.h"

namespace morphmap {
namespace {

using Rgb = Eigen::Vector3d;  // components in [0, 1]

// Owns an Embree device and scene holding one triangle mesh.
class EmbreeScene {
 public:
  EmbreeScene(const Eigen::MatrixXd& V, const Eigen::MatrixXi& F, const std::string& name) {
    device_ = rtcNewDevice(nullptr);
    if (device_ == nullptr) throw IoError(name + ": cannot create an Embree device");
    scene_ = rtcNewScene(device_);
    // ROBUST: watertight traversal, so no ray slips through a shared edge between two triangles.
    rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_ROBUST);
    RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vertices = static_cast<float*>(
        rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), V.rows()));
    auto* indices = static_cast<unsigned*>(
        rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), F.rows()));
    if (vertices == nullptr || indices == nullptr) {
      rtcReleaseGeometry(geometry);
      throw IoError(name + ": Embree cannot allocate the mesh buffers");
    }
    for (Eigen::Index i = 0; i < V.rows(); ++i)
      for (int c = 0; c < 3; ++c) vertices[3 * i + c] = static_cast<float>(V(i, c));
    for (Eigen::Index f = 0; f < F.rows(); ++f)
      for (int c = 0; c < 3; ++c) indices[3 * f + c] = static_cast<unsigned>(F(f, c));
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(scene_, geometry);
    rtcReleaseGeometry(geometry);
    rtcCommitScene(scene_);
    if (rtcGetDeviceError(device_) != RTC_ERROR_NONE) throw IoError(name + ": Embree could not build the scene");
  }
  ~EmbreeScene() {
    if (scene_ != nullptr) rtcReleaseScene(scene_);
    if (device_ != nullptr) rtcReleaseDevice(device_);
  }
  EmbreeScene(const EmbreeScene&) = delete;
  EmbreeScene& operator=(const EmbreeScene&) = delete;

  // First hit along origin + t * direction (t > 0): face index or -1, with Embree's barycentrics (u, v) of
  // corners 1 and 2.
  int intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double& u, double& v) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rh;
    rh.ray.org_x = float(origin.x());
    rh.ray.org_y = float(origin.y());
    rh.ray.org_z = float(origin.z());
    rh.ray.dir_x = float(direction.x());
    rh.ray.dir_y = float(direction.y());
    rh.ray.dir_z = float(direction.z());
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = std::numeric_limits<float>::infinity();
    rh.ray.time = 0.0f;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene_, &context, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return -1;
    u = rh.hit.u;
    v = rh.hit.v;
    return static_cast<int>(rh.hit.primID);
  }

 private:
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
};

struct Camera {
  Eigen::Vector3d eye, forward, right, up;
  double half_width = 0.0, half_height = 0.0;  // image plane extent at distance 1
};

// Smallest ball about the box centre of V holding every vertex (tighter than the box's corners).
std::pair<Eigen::Vector3d, double> bounding_ball(const Eigen::MatrixXd& V) {
  const Eigen::Vector3d center = bounding_box(V).center();
  return {center, std::sqrt((V.rowwise() - center.transpose()).rowwise().squaredNorm().maxCoeff())};
}

Camera fit_camera(const Eigen::Vector3d& center, double radius_in, const RenderOptions& o) {
  Camera c;
  const Eigen::Vector3d view = o.view.normalized();
  c.forward = -view;
  Eigen::Vector3d up = o.up.normalized();
  if (std::abs(up.dot(view)) > 0.999)
    up = std::abs(view.y()) < 0.9 ? Eigen::Vector3d::UnitY() : Eigen::Vector3d::UnitZ();
  c.right = c.forward.cross(up).normalized();
  c.up = c.right.cross(c.forward);
  const double half = std::tan(0.5 * o.fov_degrees * M_PI / 180.0);
  const double aspect = double(o.width) / double(o.height);
  c.half_width = aspect >= 1.0 ? half * aspect : half;
  c.half_height = aspect >= 1.0 ? half : half / aspect;
  // The bounding sphere fits inside the narrower half angle.
  const double radius = std::max(radius_in, 1e-12);
  const double distance = radius / std::sin(std::atan(std::min(c.half_width, c.half_height)));
  c.eye = center + 1.1 * distance * view;  // 10% margin around the ball
  return c;
}

// Blue (low) - pale yellow - red (high), ColorBrewer RdYlBu reversed.
Rgb heat_colour(double value, double low, double high) {
  if (!std::isfinite(value)) return Rgb(1.0, 0.0, 1.0);
  static const Rgb stops[5] = {Rgb(49, 54, 149) / 255.0, Rgb(116, 173, 209) / 255.0, Rgb(255, 255, 191) / 255.0,
                               Rgb(244, 109, 67) / 255.0, Rgb(165, 0, 38) / 255.0};
  const double x = std::clamp((value - low) / std::max(high - low, 1e-12), 0.0, 1.0) * 4.0;
  const int i = std::min(3, int(x));
  return stops[i] + (x - i) * (stops[i + 1] - stops[i]);
}

// Bilinear lookup with repeat wrapping; v = 0 is the image's bottom row (OBJ convention).
Rgb sample_texture(const RgbImage& image, double u, double v) {
  const double x = (u - std::floor(u)) * image.width - 0.5;
  const double y = (1.0 - (v - std::floor(v))) * image.height - 0.5;
  const double fx = std::floor(x), fy = std::floor(y);
  const double ax = x - fx, ay = y - fy;
  const long long x0 = (long long)fx, y0 = (long long)fy;
  const double weights[4] = {(1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay};
  double rgb[3] = {0.0, 0.0, 0.0};
  for (int k = 0; k < 4; ++k) {
    const long long px = (((x0 + (k & 1)) % image.width) + image.width) % image.width;
    const long long py = (((y0 + (k >> 1)) % image.height) + image.height) % image.height;
    const std::uint8_t* p = &image.pixels[3 * (std::size_t(py) * std::size_t(image.width) + std::size_t(px))];
    for (int c = 0; c < 3; ++c) rgb[c] += weights[k] * p[c];
  }
  return Rgb(rgb[0], rgb[1], rgb[2]) / 255.0;
}

Eigen::MatrixXd vertex_normals(const Eigen::MatrixXd& V, const Eigen::MatrixXi& F) {
  Eigen::MatrixXd N = Eigen::MatrixXd::Zero(V.rows(), 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {  // area weighted: the cross product's length is twice the area
    const Eigen::Vector3d a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    const Eigen::RowVector3d n = (b - a).cross(c - a).transpose();
    for (int k = 0; k < 3; ++k) N.row(F(f, k)) += n;
  }
  for (Eigen::Index i = 0; i < N.rows(); ++i) {
    const double len = N.row(i).norm();
    if (len > 0.0) N.row(i) /= len;
  }
  return N;
}

}  // namespace

void validate_render_options(const RenderOptions& o) {
  if (o.width <= 0 || o.height <= 0 || o.width > 16384 || o.height > 16384)
    throw InvalidInput("render: image size " + std::to_string(o.width) + "x" + std::to_string(o.height) +
                       " is not in 1..16384");
  if (!o.view.allFinite() || o.view.norm() == 0.0)
    throw InvalidInput("render: view direction must be a non-zero vector");
  if (!o.up.allFinite() || o.up.norm() == 0.0) throw InvalidInput("render: up direction must be a non-zero vector");
  if (!(o.fov_degrees > 0.0 && o.fov_degrees < 170.0))
    throw InvalidInput("render: field of view must be in (0, 170) degrees");
  if (o.samples < 1 || o.samples > 8) throw InvalidInput("render: samples per axis must be in 1..8");
  if (!o.frame_center.allFinite() || !std::isfinite(o.frame_radius) || o.frame_radius < 0.0)
    throw InvalidInput("render: frame centre and radius must be finite, the radius non-negative");
  if (o.checker_squares < 1) throw InvalidInput("render: checker squares must be positive");
}

RenderMode parse_render_mode(const std::string& text) {
  if (text == "auto") return RenderMode::automatic;
  if (text == "texture") return RenderMode::texture;
  if (text == "checker") return RenderMode::checker;
  if (text == "heat") return RenderMode::heat;
  if (text == "shaded") return RenderMode::shaded;
  throw InvalidInput("render: unknown mode '" + text + "' (auto, texture, checker, heat, shaded)");
}

std::string render_mode_name(RenderMode mode) {
  switch (mode) {
    case RenderMode::automatic:
      return "auto";
    case RenderMode::texture:
      return "texture";
    case RenderMode::checker:
      return "checker";
    case RenderMode::heat:
      return "heat";
    case RenderMode::shaded:
      return "shaded";
  }
  return "?";
}

RenderResult render_surface(const Surface& surface, const RenderOptions& options, const Eigen::VectorXd& face_values) {
  const auto start = std::chrono::steady_clock::now();
  validate_render_options(options);
  const std::string& name = surface.name.empty() ? std::string("surface") : surface.name;
  if (surface.F.rows() == 0 || surface.V.rows() == 0) throw InvalidInput(name + ": no triangles to render");
  if (surface.F.minCoeff() < 0 || surface.F.maxCoeff() >= surface.V.rows())
    throw InvalidInput(name + ": face index out of range");

  RenderResult result;
  result.mode = options.mode;
  if (result.mode == RenderMode::automatic)
    result.mode =
        surface.has_uv() ? (surface.has_texture() ? RenderMode::texture : RenderMode::checker) : RenderMode::shaded;
  if ((result.mode == RenderMode::texture || result.mode == RenderMode::checker) && !surface.has_uv())
    throw InvalidInput(name + ": has no texture coordinates for " + render_mode_name(result.mode) + " rendering");
  if (result.mode == RenderMode::texture && !surface.has_texture()) throw InvalidInput(name + ": has no texture");
  if (result.mode == RenderMode::heat && face_values.size() != surface.F.rows())
    throw InvalidInput(name + ": heat map needs one value per triangle (" + std::to_string(face_values.size()) +
                       " for " + std::to_string(surface.F.rows()) + " triangles)");
  if (surface.has_uv() && (surface.FUV.minCoeff() < 0 || surface.FUV.maxCoeff() >= surface.UV.rows()))
    throw InvalidInput(name + ": texture coordinate index out of range");

  std::shared_ptr<const RgbImage> texture;
  if (result.mode == RenderMode::texture)
    texture = surface.texture ? surface.texture : std::make_shared<const RgbImage>(read_image(surface.texture_path));
  else if (result.mode == RenderMode::checker)
    texture = std::make_shared<const RgbImage>(checkerboard(1024, options.checker_squares));

  const EmbreeScene scene(surface.V, surface.F, name);
  const Eigen::MatrixXd N = vertex_normals(surface.V, surface.F);
  auto [center, radius] = bounding_ball(surface.V);
  if (options.frame_radius > 0.0) {
    center = options.frame_center;
    radius = options.frame_radius;
  }
  const Camera camera = fit_camera(center, radius, options);
  const Eigen::Vector3d light =
      (options.light.x() * camera.right + options.light.y() * camera.up - options.light.z() * camera.forward)
          .normalized();
  const Rgb background = Rgb(options.background[0], options.background[1], options.background[2]) / 255.0;

  // Colour seen along one ray.
  auto shade = [&](const Eigen::Vector3d& direction, bool& hit) -> Rgb {
    double u = 0.0, v = 0.0;
    const int f = scene.intersect(camera.eye, direction, u, v);
    hit = f >= 0;
    if (!hit) return background;
    const double w[3] = {1.0 - u - v, u, v};
    const Eigen::Vector3d a = surface.V.row(surface.F(f, 0)), b = surface.V.row(surface.F(f, 1)),
                          c = surface.V.row(surface.F(f, 2));
    Eigen::Vector3d geometric = (b - a).cross(c - a);
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) normal += w[k] * N.row(surface.F(f, k)).transpose();
    if (normal.norm() < 1e-12) normal = geometric;
    // Two-sided: open slices and inside views are lit like the outside.
    if (geometric.dot(direction) > 0.0) geometric = -geometric;
    if (normal.dot(geometric) < 0.0) normal = -normal;
    normal.normalize();
    const double lambert = std::max(0.0, normal.dot(light));
    const double intensity = options.ambient + (1.0 - options.ambient) * lambert;

    Rgb albedo(0.8, 0.8, 0.8);
    if (texture) {
      Eigen::Vector2d uv = Eigen::Vector2d::Zero();
      for (int k = 0; k < 3; ++k) uv += w[k] * surface.UV.row(surface.FUV(f, k)).transpose();
      albedo = sample_texture(*texture, uv.x(), uv.y());
    } else if (result.mode == RenderMode::heat) {
      albedo = heat_colour(face_values(f), options.heat_low, options.heat_high);
    }
    return intensity * albedo;
  };

  RgbImage& image = result.image;
  image.width = options.width;
  image.height = options.height;
  image.pixels.assign(3 * std::size_t(options.width) * std::size_t(options.height), 0);
  const int s = options.samples;
  std::atomic<std::int64_t> hits{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, options.height), [&](const tbb::blocked_range<int>& rows) {
    std::int64_t local_hits = 0;
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int x = 0; x < options.width; ++x) {
        Rgb sum = Rgb::Zero();
        bool centre_hit = false;
        for (int sy = 0; sy < s; ++sy) {
          for (int sx = 0; sx < s; ++sx) {
            const double px = 2.0 * (x + (sx + 0.5) / s) / options.width - 1.0;
            const double py = 1.0 - 2.0 * (y + (sy + 0.5) / s) / options.height;
            const Eigen::Vector3d direction =
                (camera.forward + px * camera.half_width * camera.right + py * camera.half_height * camera.up)
                    .normalized();
            bool hit = false;
            sum += shade(direction, hit);
            centre_hit = centre_hit || hit;
          }
        }
        if (centre_hit) ++local_hits;
        sum /= double(s * s);
        std::uint8_t* p = &image.pixels[3 * (std::size_t(y) * std::size_t(options.width) + std::size_t(x))];
        for (int c = 0; c < 3; ++c) p[c] = std::uint8_t(std::clamp(std::lround(255.0 * sum(c)), 0L, 255L));
      }
    }
    hits += local_hits;
  });
  result.hit_pixels = hits.load();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

RenderResult render_contact_sheet(const std::vector<Surface>& panels, const RenderOptions& options, int gap) {
  const auto start = std::chrono::steady_clock::now();
  if (panels.empty()) throw InvalidInput("contact sheet: no surfaces to render");
  if (gap < 0) throw InvalidInput("contact sheet: negative gap");
  RenderOptions panel_options = options;
  if (!(panel_options.frame_radius > 0.0)) {
    Eigen::AlignedBox3d box;
    for (const Surface& s : panels) box.extend(bounding_box(s.V));
    panel_options.frame_center = box.center();
    for (const Surface& s : panels)
      panel_options.frame_radius =
          std::max(panel_options.frame_radius,
                   std::sqrt((s.V.rowwise() - box.center().transpose()).rowwise().squaredNorm().maxCoeff()));
  }

  RenderResult sheet;
  const int n = int(panels.size());
  RgbImage& image = sheet.image;
  image.width = n * options.width + (n - 1) * gap;
  image.height = options.height;
  image.pixels.resize(3 * std::size_t(image.width) * std::size_t(image.height));
  for (std::size_t i = 0; i < image.pixels.size(); ++i) image.pixels[i] = options.background[i % 3];
  for (int i = 0; i < n; ++i) {
    const RenderResult panel = render_surface(panels[std::size_t(i)], panel_options);
    sheet.mode = panel.mode;
    sheet.hit_pixels += panel.hit_pixels;
    const int x0 = i * (options.width + gap);
    for (int y = 0; y < options.height; ++y)
      std::copy_n(&panel.image.pixels[3 * std::size_t(y) * std::size_t(options.width)], 3 * options.width,
                  &image.pixels[3 * (std::size_t(y) * std::size_t(image.width) + std::size_t(x0))]);
  }
  sheet.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return sheet;
}

void write_png_atomically(const std::string& path, const RgbImage& image) {
  const std::filesystem::path target(path);
  const std::filesystem::path temp =
      target.parent_path() / ("." + target.filename().string() + ".tmp" + std::to_string(::getpid()));
  try {
    write_png(temp.string(), image);
  } catch (const IoError&) {
    std::error_code ignored;
    std::filesystem::remove(temp, ignored);
    throw IoError(path + ": cannot write PNG");
  }
  std::error_code ec;
  std::filesystem::rename(temp, target, ec);
  if (ec) {
    std::filesystem::remove(temp, ec);
    throw IoError(path + ": cannot write PNG (rename failed)");
  }
}

}  // namespace morphmap
