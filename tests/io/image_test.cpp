// Tests of texture images (paper §6: the texture carried from A to B).
#include "io/image.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <set>

#include "mesh/errors.h"

namespace fs = std::filesystem;

namespace morphmap {
namespace {

class ImageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static int counter = 0;
    dir_ =
        fs::temp_directory_path() / ("morphmap-image-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST(ImageCheckerboard, SizeCellsAndGradient) {
  const RgbImage image = checkerboard(64, 4);
  ASSERT_EQ(image.width, 64);
  ASSERT_EQ(image.height, 64);
  ASSERT_EQ(image.pixels.size(), 3u * 64 * 64);
  auto pixel = [&](int x, int y) {
    const std::uint8_t* p = &image.pixels[3 * (y * 64 + x)];
    return std::array<int, 3>{p[0], p[1], p[2]};
  };
  // Neighbouring cells differ in brightness; the same cell colour differs across the image (the gradient).
  const auto a = pixel(8, 8), b = pixel(24, 8), c = pixel(40, 8);
  EXPECT_GT(a[0] + a[1] + a[2], b[0] + b[1] + b[2]);
  EXPECT_NE(a, c);
  std::set<std::array<int, 3>> colours;
  for (int y = 0; y < 64; y += 4) {
    for (int x = 0; x < 64; x += 4) colours.insert(pixel(x, y));
  }
  EXPECT_GT(colours.size(), 16u);
  EXPECT_THROW(checkerboard(0, 4), InvalidInput);
}

TEST_F(ImageTest, PngRoundTripIsExact) {
  const RgbImage image = checkerboard(40, 5);
  const std::string path = (dir_ / "c.png").string();
  write_png(path, image);
  const RgbImage back = read_image(path);
  EXPECT_EQ(back.width, 40);
  EXPECT_EQ(back.height, 40);
  EXPECT_EQ(back.pixels, image.pixels);
}

TEST_F(ImageTest, ErrorsNameThePath) {
  const std::string missing = (dir_ / "missing.png").string();
  try {
    read_image(missing);
    ADD_FAILURE() << "missing file was read";
  } catch (const IoError& e) {
    EXPECT_EQ(std::string(e.what()), missing + ": cannot open file");
  }
  const std::string junk = (dir_ / "junk.png").string();
  std::ofstream(junk) << "this is not an image";
  try {
    read_image(junk);
    ADD_FAILURE() << "junk was read";
  } catch (const IoError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(junk + ": cannot read image", 0), 0u) << e.what();
  }
  EXPECT_THROW(write_png((dir_ / "no" / "such" / "dir.png").string(), checkerboard(8, 2)), IoError);
  RgbImage bad;
  bad.width = 4;
  bad.height = 4;
  bad.pixels.resize(5);
  EXPECT_THROW(write_png((dir_ / "bad.png").string(), bad), Error);
}

}  // namespace
}  // namespace morphmap
