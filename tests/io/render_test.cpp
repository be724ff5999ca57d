// Pictures of known scenes: a textured quad facing the camera and a lit sphere, checked pixel by pixel
// against the camera model and the Lambert + ambient shading of io/render.h; the `render` command's errors.
#include "io/render.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>

#include "io/image.h"
#include "mesh/errors.h"
#include "mesh/shapes.h"
#include "tests/command_line.h"

namespace fs = std::filesystem;

namespace morphmap {
namespace {

// The square [-1, 1]^2 in the plane z = 0, facing +z, with u along x and v along y.
Surface textured_quad() {
  Surface s;
  s.V.resize(4, 3);
  s.V << -1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0;
  s.F.resize(2, 3);
  s.F << 0, 1, 2, 0, 2, 3;
  s.UV.resize(4, 2);
  s.UV << 0, 0, 1, 0, 1, 1, 0, 1;
  s.FUV = s.F;
  // Three texels across: red, green, blue. u = 1/6, 1/2, 5/6 are their centres.
  auto texture = std::make_shared<RgbImage>();
  texture->width = 3;
  texture->height = 1;
  texture->pixels = {255, 0, 0, 0, 255, 0, 0, 0, 255};
  s.texture = texture;
  s.name = "quad";
  return s;
}

Surface sphere(int res) {
  return make_shape(parse_shape_spec("sphere:size=1,center=0/0/0,res=" + std::to_string(res)), std::nullopt);
}

std::array<int, 3> pixel(const RgbImage& image, int x, int y) {
  const std::uint8_t* p = &image.pixels[3 * (std::size_t(y) * image.width + x)];
  return {p[0], p[1], p[2]};
}

// Intensity of a surface whose normal faces the viewer (camera axis z), for the default light and ambient.
double facing_intensity(const RenderOptions& o) {
  return o.ambient + (1.0 - o.ambient) * std::max(0.0, o.light.normalized().z());
}

TEST(Render, QuadShowsTheTextureColoursWhereTheyAre) {
  RenderOptions o;
  o.width = o.height = 65;  // odd: the centre pixel's ray is the camera axis
  o.view = Eigen::Vector3d(0, 0, 1);
  o.samples = 1;
  const RenderResult r = render_surface(textured_quad(), o);
  EXPECT_EQ(r.mode, RenderMode::texture);
  ASSERT_EQ(r.image.width, 65);
  ASSERT_EQ(r.image.height, 65);
  // Corners see the background.
  for (auto [x, y] : {std::pair{0, 0}, {64, 0}, {0, 64}, {64, 64}})
    EXPECT_EQ(pixel(r.image, x, y), (std::array<int, 3>{255, 255, 255}));
  // The centre is u = 0.5 exactly: the green texel's centre, shaded by the facing intensity.
  const int lit = int(std::lround(255.0 * facing_intensity(o)));
  EXPECT_EQ(pixel(r.image, 32, 32), (std::array<int, 3>{0, lit, 0}));
  // Where the quad spans the image: find its extent on the middle row, then look at u = 1/6 and 5/6.
  int left = 0, right = 64;
  while (left < 64 && pixel(r.image, left, 32)[0] == 255 && pixel(r.image, left, 32)[1] == 255) ++left;
  while (right > 0 && pixel(r.image, right, 32)[0] == 255 && pixel(r.image, right, 32)[1] == 255) --right;
  ASSERT_LT(left, 25);
  ASSERT_GT(right, 39);
  EXPECT_NEAR(left + right, 64, 1);  // centred
  const int x_red = int(std::lround(left + (right - left) / 6.0)),
            x_blue = int(std::lround(right - (right - left) / 6.0));
  const std::array<int, 3> red = pixel(r.image, x_red, 32), blue = pixel(r.image, x_blue, 32);
  EXPECT_NEAR(red[0], lit, 0.15 * lit);
  EXPECT_LT(red[1], 0.15 * lit);
  EXPECT_EQ(red[2], 0);
  EXPECT_NEAR(blue[2], lit, 0.15 * lit);
  EXPECT_LT(blue[1], 0.15 * lit);
  EXPECT_EQ(blue[0], 0);
  // v runs upwards: the image's top row of the quad is v = 1, the same texel row here, so rows agree.
  EXPECT_EQ(pixel(r.image, 32, 32 - 10), pixel(r.image, 32, 32 + 10));
}

TEST(Render, SphereDiscAndShadingFollowTheCameraAndLight) {
  RenderOptions o;
  o.width = o.height = 201;
  o.view = Eigen::Vector3d(0, 0, 1);
  o.samples = 1;
  o.mode = RenderMode::shaded;
  o.frame_radius = 3.0;  // the ball about the origin the camera fits
  const RenderResult r = render_surface(sphere(128), o);
  // Camera at distance D on the axis: the unit sphere's silhouette has radius tan(asin(1 / D)) on the image
  // plane at distance 1, whose half extent is tan(fov / 2).
  const double half = std::tan(0.5 * o.fov_degrees * M_PI / 180.0);
  const double D = 1.1 * o.frame_radius / std::sin(std::atan(half));
  const double radius_px = (1.0 / std::sqrt(D * D - 1.0)) / half * 0.5 * o.width;
  EXPECT_NEAR(double(r.hit_pixels), M_PI * radius_px * radius_px, 0.04 * M_PI * radius_px * radius_px);

  // Brightest pixel: normal along the light (upper left, towards the viewer), full Lambert on grey 0.8.
  int best = -1, bx = 0, by = 0;
  for (int y = 0; y < o.height; ++y)
    for (int x = 0; x < o.width; ++x)
      if (pixel(r.image, x, y)[0] != 255 && pixel(r.image, x, y)[0] > best)
        best = pixel(r.image, x, y)[0], bx = x, by = y;
  EXPECT_NEAR(best, 0.8 * 255.0, 3.0);
  EXPECT_LT(bx, 100);  // left of centre
  EXPECT_LT(by, 100);  // above centre
  // Lower right, where the normal faces away from the light: ambient only.
  // (0.66, -0.66) of the radius: normal about (0.66, -0.66, 0.36), facing away from the light (-0.4, 0.6, 1).
  const int off = int(std::lround(0.66 * radius_px));
  EXPECT_NEAR(pixel(r.image, 100 + off, 100 + off)[0], std::lround(0.8 * 255.0 * o.ambient), 1);
  // Brighter where the normal faces the light.
  EXPECT_GT(pixel(r.image, 100 - off / 2, 100 - off / 2)[0], pixel(r.image, 100 + off / 2, 100 + off / 2)[0] + 40);
}

TEST(Render, ImagesDoNotDependOnTheThreadCount) {
  const Surface s = sphere(64);
  RenderOptions o;
  o.width = 96;
  o.height = 64;
  o.mode = RenderMode::checker;
  o.checker_squares = 8;
  Eigen::VectorXd heat(s.F.rows());
  for (Eigen::Index f = 0; f < heat.size(); ++f) heat(f) = 1.0 + double(f % 17) / 8.0;
  RenderResult one, two, heat_one, heat_two;
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 1);
    one = render_surface(s, o);
    o.mode = RenderMode::heat;
    heat_one = render_surface(s, o, heat);
    o.mode = RenderMode::checker;
  }
  {
    tbb::global_control c(tbb::global_control::max_allowed_parallelism, 2);
    two = render_surface(s, o);
    o.mode = RenderMode::heat;
    heat_two = render_surface(s, o, heat);
  }
  EXPECT_GT(one.hit_pixels, 1000);
  EXPECT_EQ(one.image.pixels, two.image.pixels);
  EXPECT_EQ(heat_one.image.pixels, heat_two.image.pixels);
  EXPECT_NE(one.image.pixels, heat_one.image.pixels);
}

TEST(Render, HeatMapColoursFacesByValue) {
  Surface q = textured_quad();
  RenderOptions o;
  o.width = o.height = 65;
  o.view = Eigen::Vector3d(0, 0, 1);
  o.samples = 1;
  o.mode = RenderMode::heat;
  // Face 0 (below the diagonal, lower right) at heat_high: red; face 1 (upper left) at heat_low: blue.
  Eigen::VectorXd values(2);
  values << o.heat_high, o.heat_low;
  const RenderResult r = render_surface(q, o, values);
  const std::array<int, 3> lower_right = pixel(r.image, 40, 40), upper_left = pixel(r.image, 24, 24);
  EXPECT_GT(lower_right[0], 2 * lower_right[2]);
  EXPECT_GT(upper_left[2], 2 * upper_left[0]);
  values(0) = std::nan("");
  const std::array<int, 3> nan = pixel(render_surface(q, o, values).image, 40, 40);
  EXPECT_EQ(nan[1], 0);
  EXPECT_EQ(nan[0], nan[2]);  // magenta
  EXPECT_THROW(render_surface(q, o, Eigen::VectorXd(3)), InvalidInput);
}

TEST(Render, ContactSheetSharesOneCamera) {
  Surface a = textured_quad(), b = textured_quad();
  b.V.col(0).array() += 2.0;  // B sits right of A
  RenderOptions o;
  o.width = o.height = 40;
  o.view = Eigen::Vector3d(0, 0, 1);
  o.samples = 1;
  const RenderResult sheet = render_contact_sheet({a, a, b}, o, 4);
  ASSERT_EQ(sheet.image.width, 3 * 40 + 2 * 4);
  ASSERT_EQ(sheet.image.height, 40);
  // Panels 0 and 1 are the same surface under the same camera: identical pixels.
  for (int y = 0; y < 40; ++y)
    for (int x = 0; x < 40; ++x) ASSERT_EQ(pixel(sheet.image, x, y), pixel(sheet.image, 44 + x, y));
  // The camera frames A and B together, so A is drawn left of the panel's centre and B right of it.
  auto centroid_x = [&](int x0) {
    double sum = 0.0, n = 0.0;
    for (int y = 0; y < 40; ++y)
      for (int x = 0; x < 40; ++x)
        if (pixel(sheet.image, x0 + x, y) != std::array<int, 3>{255, 255, 255}) sum += x, n += 1;
    return sum / n;
  };
  EXPECT_LT(centroid_x(0), 17.0);
  EXPECT_GT(centroid_x(88), 22.0);
}

TEST(Render, RejectsWhatItCannotDraw) {
  Surface q = textured_quad();
  RenderOptions o;
  o.width = 0;
  EXPECT_THROW(render_surface(q, o), InvalidInput);
  o.width = 16;
  o.view = Eigen::Vector3d::Zero();
  EXPECT_THROW(render_surface(q, o), InvalidInput);
  o.view = Eigen::Vector3d(0, 0, 1);
  o.mode = RenderMode::texture;
  Surface bare = q;
  bare.UV.resize(0, 2);
  bare.FUV.resize(0, 3);
  try {
    render_surface(bare, o);
    FAIL() << "rendered a texture without UVs";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("quad"), std::string::npos) << e.what();
  }
  o.mode = RenderMode::automatic;
  EXPECT_EQ(render_surface(bare, o).mode, RenderMode::shaded);
}

// The command line: exit 2 with one line naming the file, and no PNG left behind.
using test::CommandRun;
using test::run_command;

class RenderCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::fresh_test_dir("morphmap_render_");
    std::ofstream(dir_ / "quad.obj") << "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                        "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n";
    // A closed octahedron: the source of a stretch map must be closed.
    std::ofstream(dir_ / "octa.obj") << "v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n"
                                        "f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n";
  }
  void TearDown() override { fs::remove_all(dir_); }
  void expect_rejected(const std::string& args, const std::string& needle) {
    const CommandRun r = run_command("render " + args + " -o " + (dir_ / "out.png").string());
    EXPECT_EQ(r.status, 2) << r.output;
    EXPECT_NE(r.output.find(needle), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
    EXPECT_FALSE(fs::exists(dir_ / "out.png"));
  }
  fs::path dir_;
};

TEST_F(RenderCli, WritesThePicture) {
  const CommandRun r = run_command("render " + (dir_ / "quad.obj").string() + " -o " + (dir_ / "out.png").string() +
                                   " --size 48x32 --view 0,0,1 --checker 4");
  ASSERT_EQ(r.status, 0) << r.output;
  const RgbImage image = read_image((dir_ / "out.png").string());
  EXPECT_EQ(image.width, 48);
  EXPECT_EQ(image.height, 32);
  EXPECT_NE(pixel(image, 24, 16), (std::array<int, 3>{255, 255, 255}));
  EXPECT_EQ(pixel(image, 0, 0), (std::array<int, 3>{255, 255, 255}));
  // Identity labels: a stretch heat map of L2 = 1 everywhere (blue).
  std::ofstream(dir_ / "labels.txt") << "1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n";
  const CommandRun heat = run_command("render " + (dir_ / "octa.obj").string() + " -o " + (dir_ / "heat.png").string() +
                                      " --size 48x32 --view 0,0,1 --heat " + (dir_ / "labels.txt").string() +
                                      " --source " + (dir_ / "octa.obj").string());
  ASSERT_EQ(heat.status, 0) << heat.output;
  const std::array<int, 3> centre = pixel(read_image((dir_ / "heat.png").string()), 24, 16);
  EXPECT_GT(centre[2], 2 * centre[0]);
}

TEST_F(RenderCli, BadInputExitsTwoNamingTheFile) {
  expect_rejected((dir_ / "missing.obj").string(), "missing.obj");
  std::ofstream(dir_ / "broken.obj") << "v 0 0 0\nf 1 2 3\n";
  expect_rejected((dir_ / "broken.obj").string(), "broken.obj");
  expect_rejected((dir_ / "quad.obj").string() + " --size 0x10", "size");
  expect_rejected((dir_ / "quad.obj").string() + " --size big", "--size");
  std::ofstream(dir_ / "short.txt") << "0 0 0\n";
  expect_rejected((dir_ / "octa.obj").string() + " --heat " + (dir_ / "short.txt").string() + " --source " +
                      (dir_ / "octa.obj").string(),
                  "short.txt");
  expect_rejected((dir_ / "quad.obj").string() + " --heat " + (dir_ / "short.txt").string(), "--source");
  // Unwritable output: the directory does not exist.
  const CommandRun r =
      run_command("render " + (dir_ / "quad.obj").string() + " -o " + (dir_ / "no/such/out.png").string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("out.png"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace morphmap
