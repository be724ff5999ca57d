// Headless pictures of textured surfaces (Embree ray casting): single renders and the contact sheet of a
// morph (A, in-between slices, B) in the manner of the paper's Figures 1 and 9.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "mesh/surface.h"

namespace morphmap {

enum class RenderMode {
  automatic,  ///< texture if the surface has UVs and a texture, checker if it has UVs only, else shaded
  texture,    ///< the surface's texture, bilinear, through its per-corner UVs
  checker,    ///< io/image.h's checkerboard in place of the texture (shows stretch and orientation)
  heat,       ///< a per-face scalar (e.g. L2 stretch) through a blue-yellow-red colour map
  shaded,     ///< plain grey Lambert shading
};

/// Parses "auto", "texture", "checker", "heat", "shaded"; throws InvalidInput naming the text.
RenderMode parse_render_mode(const std::string& text);
std::string render_mode_name(RenderMode mode);

struct RenderOptions {
  int width = 480;                                         ///< image width in pixels
  int height = 480;                                        ///< image height in pixels
  Eigen::Vector3d view = Eigen::Vector3d(0.35, 0.4, 1.0);  ///< direction from the scene centre towards the camera
  Eigen::Vector3d up = Eigen::Vector3d::UnitY();  ///< world direction shown upwards (replaced if parallel to view)
  double fov_degrees = 30.0;                      ///< field of view across the smaller image side
  std::array<std::uint8_t, 3> background = {255, 255, 255};  ///< colour of pixels that hit nothing
  RenderMode mode = RenderMode::automatic;                   ///< what colours the surface
  int checker_squares = 16;                                  ///< squares per side of the checkerboard in checker mode
  double heat_low = 1.0;                                     ///< face value shown blue (1 = no stretch)
  double heat_high = 2.0;                                    ///< face value shown red (and above)
  int samples = 2;                                          ///< rays per pixel per axis on a fixed grid (anti-aliasing)
  double ambient = 0.3;                                     ///< light that reaches every visible point, in [0, 1]
  Eigen::Vector3d light = Eigen::Vector3d(-0.4, 0.6, 1.0);  ///< direction towards the light in camera axes
                                                            ///< (x right, y up, z towards the viewer)
  Eigen::Vector3d frame_center = Eigen::Vector3d::Zero();   ///< centre of the ball the camera fits (looks at)
  double frame_radius = 0.0;  ///< radius of that ball; 0 = the surface's own: its box centre and farthest vertex
};

/// Throws InvalidInput naming the first bad field (size, view, up, field of view, samples, squares).
void validate_render_options(const RenderOptions& options);

struct RenderResult {
  RgbImage image;
  RenderMode mode = RenderMode::shaded;  ///< the mode used (automatic resolved)
  std::int64_t hit_pixels = 0;           ///< pixels where at least one ray hit the surface
  double seconds = 0.0;
};

/// Renders `surface` (any triangle mesh; need not be closed) as seen from options.view with one light and
/// an ambient term. `face_values` (#F values, NaN shown magenta) are required in heat mode and ignored
/// otherwise. Pixels are independent, so the image does not depend on the thread count.
/// Throws InvalidInput (bad options, mode needing UVs/texture/values the surface lacks) naming the surface,
/// IoError (texture file unreadable).
RenderResult render_surface(const Surface& surface, const RenderOptions& options = {},
                            const Eigen::VectorXd& face_values = Eigen::VectorXd());

/// Renders the panels (e.g. A, slices in increasing t, B) with one camera fitted to all of them and puts
/// them side by side, left to right, separated by `gap` background pixels. Each panel is
/// options.width x options.height.
RenderResult render_contact_sheet(const std::vector<Surface>& panels, const RenderOptions& options = {}, int gap = 8);

/// Writes `image` as PNG to a temporary name beside `path` and renames it into place.
void write_png_atomically(const std::string& path, const RgbImage& image);

}  // namespace morphmap
