// Built-in analytic inputs A and B (DESIGN.md, stage "load"): the paper's sphere, torus and two-sphere examples
// (§7), triangulated closed, manifold and outward-oriented so the morph's distance fields are well defined.
#include "mesh/shapes.h"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <set>
#include <vector>

#include "io/image.h"
#include "mesh/errors.h"

namespace morphmap {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kMinResolution = 4;
constexpr int kMaxResolution = 8192;

std::string format_number(double x) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, x);
  return std::string(buffer, result.ptr);
}

bool known_kind(const std::string& kind) { return kind == "sphere" || kind == "torus" || kind == "two-spheres"; }

[[noreturn]] void fail(const std::string& spec, const std::string& problem) {
  throw InvalidInput("shape '" + spec + "': " + problem);
}

double parse_number(const std::string& spec, const std::string& key, const std::string& text) {
  const char* begin = text.c_str();
  char* end = nullptr;
  const double value = std::strtod(begin, &end);
  if (text.empty() || end != begin + text.size() || !std::isfinite(value)) {
    fail(spec, "bad number '" + text + "' for key '" + key + "'");
  }
  return value;
}

// Appends a lat-long sphere: `rings` latitude bands from the north pole (+z) to the south pole, `segments`
// longitudes. Positions are shared across the seam at longitude 0 (the mesh stays closed); texture coordinates
// are split there so that u runs from 0 to 1 without wrapping.
void append_sphere(const Eigen::Vector3d& center, double radius, int segments, bool with_uv,
                   std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3i>& faces,
                   std::vector<Eigen::Vector2d>& uvs, std::vector<Eigen::Vector3i>& face_uvs) {
  const int rings = std::max(2, segments / 2);
  const int base = static_cast<int>(positions.size());
  const int north = base;
  const int south = base + 1 + (rings - 1) * segments;
  auto ring_vertex = [&](int i, int j) { return base + 1 + (i - 1) * segments + (j % segments); };

  positions.push_back(center + Eigen::Vector3d(0.0, 0.0, radius));
  for (int i = 1; i < rings; ++i) {
    const double theta = kPi * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double phi = 2.0 * kPi * j / segments;
      positions.push_back(center + radius * Eigen::Vector3d(std::sin(theta) * std::cos(phi),
                                                            std::sin(theta) * std::sin(phi), std::cos(theta)));
    }
  }
  positions.push_back(center + Eigen::Vector3d(0.0, 0.0, -radius));

  // Along theta then along phi is counter-clockwise seen from outside: d/dtheta x d/dphi points outward.
  auto vertex = [&](int i, int j) { return i == 0 ? north : (i == rings ? south : ring_vertex(i, j)); };
  for (int i = 0; i < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      // Each quad (i, j), (i+1, j), (i+1, j+1), (i, j+1) loses the triangle that degenerates at a pole.
      if (i != 0) faces.emplace_back(vertex(i, j), vertex(i + 1, j + 1), vertex(i, j + 1));
      if (i + 1 != rings) faces.emplace_back(vertex(i, j), vertex(i + 1, j), vertex(i + 1, j + 1));
    }
  }
  if (!with_uv) return;

  // UV grid of (rings + 1) x (segments + 1); on the pole rows each triangle gets its own corner at the middle of
  // its longitude span, which avoids a fan of zero-area triangles in texture space.
  const int uv_base = static_cast<int>(uvs.size());
  auto uv_index = [&](int i, int j) { return uv_base + i * (segments + 1) + j; };
  for (int i = 0; i <= rings; ++i) {
    for (int j = 0; j <= segments; ++j) {
      const bool pole = i == 0 || i == rings;
      const double u = pole ? std::min(1.0, (j + 0.5) / segments) : static_cast<double>(j) / segments;
      uvs.emplace_back(u, 1.0 - static_cast<double>(i) / rings);
    }
  }
  for (int i = 0; i < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      // A pole corner takes its own triangle's column j (see above).
      const int below = i + 1 == rings ? uv_index(i + 1, j) : uv_index(i + 1, j + 1);
      if (i != 0) face_uvs.emplace_back(uv_index(i, j), below, uv_index(i, j + 1));
      if (i + 1 != rings) face_uvs.emplace_back(uv_index(i, j), uv_index(i + 1, j), uv_index(i + 1, j + 1));
    }
  }
}

// Torus around the z axis: `segments` steps around the axis, enough steps around the tube for square-ish quads.
void append_torus(const Eigen::Vector3d& center, double major, double minor, int segments,
                  std::vector<Eigen::Vector3d>& positions, std::vector<Eigen::Vector3i>& faces) {
  const int tube = std::max(3, static_cast<int>(std::lround(segments * minor / major)));
  const int base = static_cast<int>(positions.size());
  for (int i = 0; i < segments; ++i) {
    const double phi = 2.0 * kPi * i / segments;
    for (int j = 0; j < tube; ++j) {
      const double psi = 2.0 * kPi * j / tube;
      const double w = major + minor * std::cos(psi);
      positions.push_back(center + Eigen::Vector3d(w * std::cos(phi), w * std::sin(phi), minor * std::sin(psi)));
    }
  }
  auto vertex = [&](int i, int j) { return base + (i % segments) * tube + (j % tube); };
  // d/dphi x d/dpsi points away from the tube's core circle.
  for (int i = 0; i < segments; ++i) {
    for (int j = 0; j < tube; ++j) {
      faces.emplace_back(vertex(i, j), vertex(i + 1, j), vertex(i + 1, j + 1));
      faces.emplace_back(vertex(i, j), vertex(i + 1, j + 1), vertex(i, j + 1));
    }
  }
}

}  // namespace

std::string shape_spec_string(const ShapeSpec& spec) {
  const ShapeSpec defaults;
  std::vector<std::string> items;
  if (spec.size) items.push_back("size=" + format_number(*spec.size));
  if (spec.center) {
    items.push_back("center=" + format_number(spec.center->x()) + "/" + format_number(spec.center->y()) + "/" +
                    format_number(spec.center->z()));
  }
  if (spec.resolution != defaults.resolution) items.push_back("res=" + std::to_string(spec.resolution));
  if (spec.kind == "torus" && spec.r_ratio != defaults.r_ratio)
    items.push_back("r_ratio=" + format_number(spec.r_ratio));
  if (spec.kind == "two-spheres" && spec.gap_ratio != defaults.gap_ratio) {
    items.push_back("gap_ratio=" + format_number(spec.gap_ratio));
  }
  if (spec.kind == "sphere" && !spec.texture) items.push_back("texture=0");
  std::string text = spec.kind;
  for (std::size_t i = 0; i < items.size(); ++i) text += (i == 0 ? ":" : ",") + items[i];
  return text;
}

namespace {

void check_spec(const std::string& text, const ShapeSpec& spec) {
  if (!known_kind(spec.kind)) fail(text, "unknown kind '" + spec.kind + "' (expected sphere, torus or two-spheres)");
  if (spec.size && !(std::isfinite(*spec.size) && *spec.size > 0.0)) fail(text, "size must be positive");
  if (spec.center && !spec.center->allFinite()) fail(text, "center must be finite");
  if (spec.resolution < kMinResolution || spec.resolution > kMaxResolution) {
    fail(text, "res must be in [" + std::to_string(kMinResolution) + ", " + std::to_string(kMaxResolution) + "]");
  }
  // r >= R makes a self-intersecting (horn or spindle) torus.
  if (!(spec.r_ratio > 0.0 && spec.r_ratio < 1.0)) fail(text, "r_ratio must be in (0, 1)");
  // A zero gap makes the spheres touch in a non-manifold point.
  if (!(std::isfinite(spec.gap_ratio) && spec.gap_ratio > 0.0)) fail(text, "gap_ratio must be positive");
}

}  // namespace

bool is_builtin_shape(const std::string& arg) { return known_kind(arg.substr(0, arg.find(':'))); }

ShapeSpec parse_shape_spec(const std::string& arg) {
  ShapeSpec spec;
  const std::size_t colon = arg.find(':');
  spec.kind = arg.substr(0, colon);
  if (!known_kind(spec.kind)) fail(arg, "unknown kind '" + spec.kind + "' (expected sphere, torus or two-spheres)");
  if (colon == std::string::npos) return spec;

  std::set<std::string> seen;
  const std::string params = arg.substr(colon + 1);
  std::size_t start = 0;
  while (start <= params.size()) {
    std::size_t comma = params.find(',', start);
    if (comma == std::string::npos) comma = params.size();
    const std::string item = params.substr(start, comma - start);
    start = comma + 1;
    if (item.empty()) {
      if (comma == params.size() && params.empty()) break;  // "sphere:" has no parameters
      fail(arg, "empty parameter");
    }
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos) fail(arg, "parameter '" + item + "' is not key=value");
    const std::string key = item.substr(0, eq);
    const std::string value = item.substr(eq + 1);
    if (!seen.insert(key).second) fail(arg, "key '" + key + "' given twice");
    if (key == "size") {
      spec.size = parse_number(arg, key, value);
    } else if (key == "center") {
      Eigen::Vector3d c;
      std::size_t from = 0;
      for (int k = 0; k < 3; ++k) {
        const std::size_t slash = k < 2 ? value.find('/', from) : value.size();
        if (slash == std::string::npos) fail(arg, "center '" + value + "' is not x/y/z");
        c(k) = parse_number(arg, key, value.substr(from, slash - from));
        from = slash + 1;
      }
      spec.center = c;
    } else if (key == "res") {
      const double r = parse_number(arg, key, value);
      if (r != std::floor(r) || std::abs(r) > 1e9) fail(arg, "res '" + value + "' is not an integer");
      spec.resolution = static_cast<int>(r);
    } else if (key == "r_ratio" && spec.kind == "torus") {
      spec.r_ratio = parse_number(arg, key, value);
    } else if (key == "gap_ratio" && spec.kind == "two-spheres") {
      spec.gap_ratio = parse_number(arg, key, value);
    } else if (key == "texture" && spec.kind == "sphere") {
      if (value == "1" || value == "true" || value == "yes") {
        spec.texture = true;
      } else if (value == "0" || value == "false" || value == "no") {
        spec.texture = false;
      } else {
        fail(arg, "texture must be 0 or 1, is '" + value + "'");
      }
    } else {
      std::string keys = "size, center, res";
      if (spec.kind == "sphere") keys += ", texture";
      if (spec.kind == "torus") keys += ", r_ratio";
      if (spec.kind == "two-spheres") keys += ", gap_ratio";
      fail(arg, "unknown key '" + key + "' for " + spec.kind + " (expected " + keys + ")");
    }
  }
  check_spec(arg, spec);
  return spec;
}

ShapeSpec resolve_shape_spec(const ShapeSpec& spec, const std::optional<Eigen::AlignedBox3d>& fit) {
  const bool use_fit = fit.has_value() && !fit->isEmpty();
  ShapeSpec placed = spec;
  if (!placed.center) placed.center = use_fit ? Eigen::Vector3d(fit->center()) : Eigen::Vector3d::Zero();
  if (!placed.size) {
    placed.size = use_fit ? 0.5 * fit->sizes().maxCoeff() : 1.0;
    if (!(*placed.size > 0.0))
      throw InvalidInput("shape '" + shape_spec_string(spec) + "': the box to fit has zero size");
  }
  return placed;
}

Surface make_shape(const ShapeSpec& spec, const std::optional<Eigen::AlignedBox3d>& fit) {
  const std::string name = shape_spec_string(spec);
  check_spec(name, spec);
  const ShapeSpec placed = resolve_shape_spec(spec, fit);
  const Eigen::Vector3d center = *placed.center;
  const double size = *placed.size;

  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector3i> faces;
  std::vector<Eigen::Vector2d> uvs;
  std::vector<Eigen::Vector3i> face_uvs;
  const bool textured = spec.kind == "sphere" && spec.texture;
  SignedDistance distance;
  if (spec.kind == "sphere") {
    append_sphere(center, size, spec.resolution, textured, positions, faces, uvs, face_uvs);
    distance = [center, size](const Eigen::Vector3d& x) { return (x - center).norm() - size; };
  } else if (spec.kind == "torus") {
    // Half of the largest extent is R + r = R (1 + r_ratio), across the hole.
    const double major = size / (1.0 + spec.r_ratio);
    const double minor = spec.r_ratio * major;
    append_torus(center, major, minor, spec.resolution, positions, faces);
    distance = [center, major, minor](const Eigen::Vector3d& x) {
      const Eigen::Vector3d p = x - center;
      return std::hypot(std::hypot(p.x(), p.y()) - major, p.z()) - minor;
    };
  } else {
    // Along x the pair spans 2 (2 rs + gap / 2) with gap = gap_ratio rs.
    const double radius = size / (2.0 + 0.5 * spec.gap_ratio);
    const Eigen::Vector3d offset(radius * (1.0 + 0.5 * spec.gap_ratio), 0.0, 0.0);
    std::vector<Eigen::Vector2d> no_uvs;
    std::vector<Eigen::Vector3i> no_face_uvs;
    append_sphere(center - offset, radius, spec.resolution, false, positions, faces, no_uvs, no_face_uvs);
    append_sphere(center + offset, radius, spec.resolution, false, positions, faces, no_uvs, no_face_uvs);
    // The spheres are disjoint, so the nearer one's distance is the union's, inside and out.
    distance = [center, offset, radius](const Eigen::Vector3d& x) {
      return std::min((x - center + offset).norm(), (x - center - offset).norm()) - radius;
    };
  }

  Surface surface;
  surface.name = name;
  surface.signed_distance = distance;
  surface.V.resize(static_cast<Eigen::Index>(positions.size()), 3);
  for (std::size_t i = 0; i < positions.size(); ++i) surface.V.row(static_cast<Eigen::Index>(i)) = positions[i];
  surface.F.resize(static_cast<Eigen::Index>(faces.size()), 3);
  for (std::size_t i = 0; i < faces.size(); ++i) surface.F.row(static_cast<Eigen::Index>(i)) = faces[i];
  if (textured) {
    surface.UV.resize(static_cast<Eigen::Index>(uvs.size()), 2);
    for (std::size_t i = 0; i < uvs.size(); ++i) surface.UV.row(static_cast<Eigen::Index>(i)) = uvs[i];
    surface.FUV.resize(static_cast<Eigen::Index>(face_uvs.size()), 3);
    for (std::size_t i = 0; i < face_uvs.size(); ++i) surface.FUV.row(static_cast<Eigen::Index>(i)) = face_uvs[i];
    surface.texture = std::make_shared<const RgbImage>(checkerboard());
  }
  return surface;
}

}  // namespace morphmap
