// Tests of the built-in analytic inputs (DESIGN.md, stage "load"): closed, manifold, outward, placed as asked.
#include "mesh/shapes.h"

#include <gtest/gtest.h>

#include <cmath>

#include "mesh/errors.h"

namespace morphmap {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string error_of(const std::string& spec) {
  try {
    parse_shape_spec(spec);
  } catch (const InvalidInput& e) {
    return e.what();
  }
  ADD_FAILURE() << "spec '" << spec << "' was accepted";
  return {};
}

void expect_closed_outward(const Surface& s) {
  SCOPED_TRACE(s.name);
  const SurfaceCheck c = check_surface(s.F, s.V.rows());
  EXPECT_TRUE(c.closed());
  EXPECT_TRUE(c.manifold());
  EXPECT_EQ(c.inconsistent_edges, 0);
  EXPECT_GT(signed_volume(s.V, s.F), 0.0);
  EXPECT_NO_THROW(validate_surface(s, true));
  // No vertex is unused: every one is a corner of some face.
  std::vector<int> used(s.V.rows(), 0);
  for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) used[s.F(f, k)] = 1;
  }
  EXPECT_EQ(std::count(used.begin(), used.end(), 0), 0);
}

TEST(ShapeSpecParse, DefaultsAndAllKeys) {
  const ShapeSpec plain = parse_shape_spec("sphere");
  EXPECT_EQ(plain.kind, "sphere");
  EXPECT_FALSE(plain.size.has_value());
  EXPECT_FALSE(plain.center.has_value());
  EXPECT_EQ(plain.resolution, 96);

  const ShapeSpec full = parse_shape_spec("sphere:size=0.5,center=1/-2/3.5,res=64,texture=0");
  EXPECT_DOUBLE_EQ(*full.size, 0.5);
  EXPECT_EQ(*full.center, Eigen::Vector3d(1, -2, 3.5));
  EXPECT_EQ(full.resolution, 64);
  EXPECT_FALSE(full.texture);

  EXPECT_DOUBLE_EQ(parse_shape_spec("torus:r_ratio=0.3").r_ratio, 0.3);
  EXPECT_DOUBLE_EQ(parse_shape_spec("two-spheres:gap_ratio=0.25").gap_ratio, 0.25);
  EXPECT_NO_THROW(parse_shape_spec("sphere:"));
}

TEST(ShapeSpecParse, RejectsBadSpecsNamingThem) {
  EXPECT_EQ(error_of("cube"), "shape 'cube': unknown kind 'cube' (expected sphere, torus or two-spheres)");
  EXPECT_EQ(error_of("sphere:radius=2").rfind("shape 'sphere:radius=2': unknown key 'radius'", 0), 0u);
  EXPECT_EQ(error_of("sphere:size=abc"), "shape 'sphere:size=abc': bad number 'abc' for key 'size'");
  EXPECT_EQ(error_of("sphere:size=1x").rfind("shape 'sphere:size=1x': bad number", 0), 0u);
  EXPECT_NE(error_of("sphere:r_ratio=0.3").find("unknown key 'r_ratio'"), std::string::npos);
  EXPECT_NE(error_of("torus:gap_ratio=0.3").find("unknown key 'gap_ratio'"), std::string::npos);
  EXPECT_NE(error_of("sphere:center=1/2").find("is not x/y/z"), std::string::npos);
  EXPECT_NE(error_of("sphere:res=10.5").find("not an integer"), std::string::npos);
  EXPECT_NE(error_of("sphere:res=2").find("res must be in"), std::string::npos);
  EXPECT_NE(error_of("sphere:size=-1").find("size must be positive"), std::string::npos);
  EXPECT_NE(error_of("sphere:size=nan").find("bad number"), std::string::npos);
  EXPECT_NE(error_of("torus:r_ratio=1.5").find("r_ratio must be in (0, 1)"), std::string::npos);
  EXPECT_NE(error_of("two-spheres:gap_ratio=0").find("gap_ratio must be positive"), std::string::npos);
  EXPECT_NE(error_of("sphere:size").find("not key=value"), std::string::npos);
  EXPECT_NE(error_of("sphere:size=1,size=2").find("given twice"), std::string::npos);
  EXPECT_NE(error_of("sphere:size=1,").find("empty parameter"), std::string::npos);
}

TEST(ShapeSpecParse, RecognisesBuiltinNames) {
  EXPECT_TRUE(is_builtin_shape("sphere"));
  EXPECT_TRUE(is_builtin_shape("torus:r_ratio=0.2"));
  EXPECT_TRUE(is_builtin_shape("two-spheres"));
  EXPECT_FALSE(is_builtin_shape("sphere.obj"));
  EXPECT_FALSE(is_builtin_shape("models/bunny.off"));
  EXPECT_FALSE(is_builtin_shape(""));
}

TEST(ShapeMake, SphereIsClosedOutwardWithVolume) {
  const Surface s = make_shape(parse_shape_spec("sphere:res=64"), std::nullopt);
  expect_closed_outward(s);
  EXPECT_EQ(s.name, "sphere:res=64");
  EXPECT_NEAR(signed_volume(s.V, s.F), 4.0 / 3.0 * kPi, 0.02 * 4.0 / 3.0 * kPi);
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) EXPECT_NEAR(s.V.row(i).norm(), 1.0, 1e-12);
}

TEST(ShapeMake, SphereUvsAreInUnitSquareWithoutWrapAround) {
  const Surface s = make_shape(parse_shape_spec("sphere:res=32"), std::nullopt);
  ASSERT_TRUE(s.has_uv());
  ASSERT_TRUE(s.has_texture());
  ASSERT_NE(s.texture, nullptr);
  EXPECT_GT(s.texture->width, 0);
  EXPECT_EQ(s.FUV.rows(), s.F.rows());
  EXPECT_GE(s.UV.minCoeff(), 0.0);
  EXPECT_LE(s.UV.maxCoeff(), 1.0);
  for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
    const Eigen::Vector2d a = s.UV.row(s.FUV(f, 0)), b = s.UV.row(s.FUV(f, 1)), c = s.UV.row(s.FUV(f, 2));
    // A triangle crossing the seam would span almost the whole u range; every one is also counter-clockwise.
    const double span = std::max({a.x(), b.x(), c.x()}) - std::min({a.x(), b.x(), c.x()});
    EXPECT_LT(span, 0.1) << "face " << f;
    const double twice_area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    EXPECT_GT(twice_area, 0.0) << "face " << f;
  }
  // The seam splits UVs, not positions.
  EXPECT_GT(s.UV.rows(), s.V.rows());
}

TEST(ShapeMake, UntexturedSphereHasNoUv) {
  const Surface s = make_shape(parse_shape_spec("sphere:texture=0,res=16"), std::nullopt);
  EXPECT_FALSE(s.has_uv());
  EXPECT_FALSE(s.has_texture());
  expect_closed_outward(s);
}

TEST(ShapeMake, TorusIsClosedOutwardWithGenusOne) {
  const Surface s = make_shape(parse_shape_spec("torus:r_ratio=0.3"), std::nullopt);
  expect_closed_outward(s);
  EXPECT_FALSE(s.has_texture());
  // Euler characteristic V - E + F = 0 for a torus; E = 3F/2 on a closed triangle mesh.
  EXPECT_EQ(s.V.rows() - 3 * s.F.rows() / 2 + s.F.rows(), 0);
  const double major = 1.0 / 1.3, minor = 0.3 * major;
  EXPECT_NEAR(signed_volume(s.V, s.F), 2.0 * kPi * kPi * major * minor * minor,
              0.02 * 2.0 * kPi * kPi * major * minor * minor);
  const Eigen::AlignedBox3d box = bounding_box(s.V);
  EXPECT_NEAR(box.max().x(), 1.0, 1e-12);
  EXPECT_NEAR(box.max().z(), minor, 1e-3);
}

TEST(ShapeMake, TwoSpheresAreTwoClosedComponentsWithTheGap) {
  const Surface s = make_shape(parse_shape_spec("two-spheres:gap_ratio=0.25,res=48"), std::nullopt);
  expect_closed_outward(s);
  EXPECT_FALSE(s.has_texture());
  EXPECT_EQ(s.V.rows() - 3 * s.F.rows() / 2 + s.F.rows(), 4);  // two spheres: chi = 2 + 2
  const double radius = 1.0 / (2.0 + 0.125);
  double left_max = -1e9, right_min = 1e9;
  for (Eigen::Index i = 0; i < s.V.rows(); ++i) {
    if (s.V(i, 0) < 0) left_max = std::max(left_max, s.V(i, 0));
    if (s.V(i, 0) > 0) right_min = std::min(right_min, s.V(i, 0));
  }
  EXPECT_NEAR(right_min - left_max, 0.25 * radius, 1e-12);
  EXPECT_NEAR(bounding_box(s.V).max().x(), 1.0, 1e-12);
}

TEST(ShapeMake, FitsTheGivenBox) {
  const Eigen::AlignedBox3d box(Eigen::Vector3d(-1, -2, -3), Eigen::Vector3d(3, 2, 1));  // a cube of half-size 2
  for (const char* spec : {"sphere", "torus", "two-spheres"}) {
    SCOPED_TRACE(spec);
    const Surface s = make_shape(parse_shape_spec(spec), box);
    const Eigen::AlignedBox3d b = bounding_box(s.V);
    EXPECT_TRUE(box.contains(b.min() + Eigen::Vector3d::Constant(1e-9)));
    EXPECT_TRUE(box.contains(b.max() - Eigen::Vector3d::Constant(1e-9)));
    EXPECT_NEAR(0.5 * b.sizes().maxCoeff(), 2.0, 1e-9);
    EXPECT_LT((b.center() - box.center()).norm(), 1e-9);
    expect_closed_outward(s);
  }
}

TEST(ShapeMake, ExplicitSizeAndCenterWinOverTheBox) {
  const Eigen::AlignedBox3d box(Eigen::Vector3d(-10, -10, -10), Eigen::Vector3d(10, 10, 10));
  const Surface s = make_shape(parse_shape_spec("sphere:size=0.5,center=1/2/3"), box);
  const Eigen::AlignedBox3d b = bounding_box(s.V);
  EXPECT_NEAR((b.center() - Eigen::Vector3d(1, 2, 3)).norm(), 0.0, 1e-12);
  EXPECT_NEAR(0.5 * b.sizes().maxCoeff(), 0.5, 1e-12);
  EXPECT_EQ(s.name, "sphere:size=0.5,center=1/2/3");
}

TEST(ShapeMake, ResolvedSpecTextRebuildsTheFittedShapeExactly) {
  // What `map` records in report.json (inputs.source_shape) and `stretch` reads back: the same vertices, bit for bit.
  const Eigen::AlignedBox3d box(Eigen::Vector3d(-0.31, 0.1, -2.7), Eigen::Vector3d(1.9, 0.77, 0.3));
  for (const char* spec : {"sphere", "torus:r_ratio=0.3,res=40", "two-spheres:gap_ratio=0.25", "sphere:size=0.7"}) {
    SCOPED_TRACE(spec);
    const ShapeSpec resolved = resolve_shape_spec(parse_shape_spec(spec), box);
    ASSERT_TRUE(resolved.center.has_value() && resolved.size.has_value());
    const std::string text = shape_spec_string(resolved);
    const Surface fitted = make_shape(parse_shape_spec(spec), box);
    const Surface rebuilt = make_shape(parse_shape_spec(text), std::nullopt);
    ASSERT_EQ(rebuilt.V.rows(), fitted.V.rows()) << text;
    EXPECT_TRUE((rebuilt.V.array() == fitted.V.array()).all()) << text;
    EXPECT_EQ(shape_spec_string(parse_shape_spec(text)), text);
  }
  // Without a box: the origin and size 1.
  const ShapeSpec alone = resolve_shape_spec(parse_shape_spec("torus"), std::nullopt);
  EXPECT_EQ(shape_spec_string(alone), "torus:size=1,center=0/0/0");
}

TEST(ShapeMake, RejectsInvalidSpecStructs) {
  ShapeSpec spec;
  spec.kind = "cone";
  EXPECT_THROW(make_shape(spec, std::nullopt), InvalidInput);
  spec.kind = "torus";
  spec.r_ratio = 2.0;
  EXPECT_THROW(make_shape(spec, std::nullopt), InvalidInput);
}

}  // namespace
}  // namespace morphmap
