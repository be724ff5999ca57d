// Texture images for the texture carried from A to B (paper §6): reading the source texture and writing PNGs.
#include "io/image.h"

#include <stb_image.h>
#include <stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "mesh/errors.h"

namespace morphmap {

RgbImage read_image(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw IoError(path + ": is a directory, not an image");
  if (!std::ifstream(path, std::ios::binary)) throw IoError(path + ": cannot open file");
  int width = 0, height = 0, channels = 0;
  // Forcing 3 channels turns grey, grey+alpha and RGBA images into RGB.
  stbi_uc* data = stbi_load(path.c_str(), &width, &height, &channels, 3);
  if (data == nullptr) {
    const char* reason = stbi_failure_reason();
    throw IoError(path + ": cannot read image (" +
                  (reason != nullptr && *reason != '\0' ? reason : "corrupt or truncated") + ")");
  }
  RgbImage image;
  image.width = width;
  image.height = height;
  image.pixels.assign(data, data + 3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height));
  stbi_image_free(data);
  return image;
}

void write_png(const std::string& path, const RgbImage& image) {
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != 3 * static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height)) {
    throw InvalidInput(path + ": image is " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                       " with " + std::to_string(image.pixels.size()) + " bytes of pixels; cannot write it");
  }
  if (stbi_write_png(path.c_str(), image.width, image.height, 3, image.pixels.data(), 3 * image.width) == 0) {
    throw IoError(path + ": cannot write PNG");
  }
}

RgbImage checkerboard(int size, int squares) {
  if (size <= 0 || squares <= 0) {
    throw InvalidInput("checkerboard: size and squares must be positive, are " + std::to_string(size) + " and " +
                       std::to_string(squares));
  }
  RgbImage image;
  image.width = size;
  image.height = size;
  image.pixels.resize(3 * static_cast<std::size_t>(size) * static_cast<std::size_t>(size));
  for (int y = 0; y < size; ++y) {
    for (int x = 0; x < size; ++x) {
      const int cx = static_cast<int>(static_cast<long long>(x) * squares / size);
      const int cy = static_cast<int>(static_cast<long long>(y) * squares / size);
      const bool light = (cx + cy) % 2 == 0;
      // Red grows to the right and green downwards, so a flipped or shifted mapping is visible at a glance.
      const double u = (x + 0.5) / size;
      const double v = (y + 0.5) / size;
      const double base = light ? 1.0 : 0.35;
      const double rgb[3] = {base * (0.3 + 0.7 * u), base * (0.3 + 0.7 * v), base * (1.0 - 0.5 * u)};
      std::uint8_t* p = &image.pixels[3 * (static_cast<std::size_t>(y) * size + x)];
      for (int c = 0; c < 3; ++c) p[c] = static_cast<std::uint8_t>(std::clamp(std::lround(255.0 * rgb[c]), 0L, 255L));
    }
  }
  return image;
}

}  // namespace morphmap
