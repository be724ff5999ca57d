// Texture images (stb_image / stb_image_write).
#pragma once

#include <string>

#include "mesh/surface.h"

namespace morphmap {

/// Reads PNG/JPEG/BMP/TGA as RGB. Throws IoError "<path>: <problem>".
RgbImage read_image(const std::string& path);

/// Writes a PNG. Throws IoError.
void write_png(const std::string& path, const RgbImage& image);

/// size x size checkerboard of `squares` x `squares` cells in two colours, with a coloured
/// gradient so that orientation and position are visible.
RgbImage checkerboard(int size = 512, int squares = 16);

}  // namespace morphmap
