// Tests of input validation for A and B (DESIGN.md, stage "load"): edge topology, closedness, measures.
#include "mesh/surface.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <tuple>

#include "mesh/errors.h"
#include "mesh/shapes.h"

namespace morphmap {
namespace {

// Unit tetrahedron with outward faces.
Surface tetrahedron() {
  Surface s;
  s.name = "tet";
  s.V.resize(4, 3);
  s.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  s.F.resize(4, 3);
  s.F << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;
  return s;
}

template <typename Exception, typename Function>
std::string message_of(Function&& f) {
  try {
    f();
  } catch (const Exception& e) {
    return e.what();
  }
  ADD_FAILURE() << "no exception of the expected type";
  return {};
}

TEST(SurfaceCheck, ClosedTetrahedronIsClosedManifoldConsistent) {
  const Surface s = tetrahedron();
  const SurfaceCheck c = check_surface(s.F, s.V.rows());
  EXPECT_TRUE(c.closed());
  EXPECT_TRUE(c.manifold());
  EXPECT_EQ(c.boundary_edges, 0);
  EXPECT_EQ(c.nonmanifold_edges, 0);
  EXPECT_EQ(c.inconsistent_edges, 0);
  EXPECT_EQ(c.nonmanifold_vertices, 0);
  EXPECT_EQ(c.degenerate_faces, 0);
  EXPECT_NO_THROW(validate_surface(s, true));
}

TEST(SurfaceCheck, CountsEulerCharacteristicAndComponents) {
  const Surface tet = tetrahedron();
  const SurfaceCheck one = check_surface(tet.F, tet.V.rows());
  EXPECT_EQ(one.vertices, 4);
  EXPECT_EQ(one.edges, 6);
  EXPECT_EQ(one.faces, 4);
  EXPECT_EQ(one.euler(), 2);
  EXPECT_EQ(one.components, 1);
  // Two disjoint copies, and an unused vertex that must not count.
  Eigen::MatrixXi F(8, 3);
  F << tet.F, tet.F.array() + 5;
  const SurfaceCheck two = check_surface(F, 9);
  EXPECT_EQ(two.vertices, 8);
  EXPECT_EQ(two.euler(), 4);
  EXPECT_EQ(two.components, 2);
  // The built-in shapes: a sphere, a torus (one handle), two spheres.
  const Eigen::AlignedBox3d box(Eigen::Vector3d::Constant(-1.0), Eigen::Vector3d::Constant(1.0));
  for (const auto& [spec, euler, components] :
       {std::tuple<const char*, int, int>{"sphere", 2, 1}, {"torus", 0, 1}, {"two-spheres", 4, 2}}) {
    const Surface shape = make_shape(parse_shape_spec(spec), box);
    const SurfaceCheck c = validate_surface(shape, true);
    EXPECT_EQ(c.euler(), euler) << spec;
    EXPECT_EQ(c.components, components) << spec;
    EXPECT_EQ(c.edges * 2, c.faces * 3) << spec;  // closed
  }
}

TEST(SurfaceCheck, MissingFaceLeavesThreeBoundaryEdges) {
  Surface s = tetrahedron();
  s.F.conservativeResize(3, 3);
  const SurfaceCheck c = check_surface(s.F, s.V.rows());
  EXPECT_EQ(c.boundary_edges, 3);
  EXPECT_FALSE(c.closed());
  EXPECT_TRUE(c.manifold());
  const std::string m = message_of<InvalidInput>([&] { validate_surface(s, true); });
  EXPECT_EQ(m, "tet: surface is not closed (3 boundary edges)");
  EXPECT_NO_THROW(validate_surface(s, false));
}

TEST(SurfaceCheck, ThreeFacesOnAnEdgeAreNonManifold) {
  Surface s = tetrahedron();
  s.V.conservativeResize(5, 3);
  s.V.row(4) << 1, 1, -1;
  s.F.conservativeResize(5, 3);
  s.F.row(4) << 0, 1, 4;
  const SurfaceCheck c = check_surface(s.F, s.V.rows());
  EXPECT_EQ(c.nonmanifold_edges, 1);
  EXPECT_EQ(c.boundary_edges, 2);
  EXPECT_FALSE(c.manifold());
}

TEST(SurfaceCheck, TwoTetrahraSharingAVertexMakeANonManifoldVertex) {
  Surface s = tetrahedron();
  Surface t = tetrahedron();
  // Mirror the second copy through the origin (keeping orientation by flipping faces) so only vertex 0 is shared.
  Surface both;
  both.name = "bowtie";
  both.V.resize(7, 3);
  both.V.topRows(4) = s.V;
  both.V.bottomRows(3) = -t.V.bottomRows(3);
  both.F.resize(8, 3);
  both.F.topRows(4) = s.F;
  for (int f = 0; f < 4; ++f) {
    for (int k = 0; k < 3; ++k) {
      const int v = t.F(f, 2 - k);
      both.F(4 + f, k) = v == 0 ? 0 : v + 3;
    }
  }
  const SurfaceCheck c = check_surface(both.F, both.V.rows());
  EXPECT_TRUE(c.closed());
  EXPECT_EQ(c.nonmanifold_edges, 0);
  EXPECT_EQ(c.inconsistent_edges, 0);
  EXPECT_EQ(c.nonmanifold_vertices, 1);
  const std::string m = message_of<InvalidInput>([&] { validate_surface(both, true); });
  EXPECT_NE(m.find("bowtie: surface is not manifold ("), std::string::npos) << m;
  EXPECT_NE(m.find("1 non-manifold vertices"), std::string::npos) << m;
}

TEST(SurfaceCheck, FlippedFaceIsInconsistent) {
  Surface s = tetrahedron();
  std::swap(s.F(3, 1), s.F(3, 2));
  const SurfaceCheck c = check_surface(s.F, s.V.rows());
  EXPECT_EQ(c.inconsistent_edges, 3);
  EXPECT_TRUE(c.closed());
  const std::string m = message_of<InvalidInput>([&] { validate_surface(s, true); });
  EXPECT_NE(m.find("tet: surface is not consistently oriented"), std::string::npos) << m;
}

TEST(SurfaceCheck, RepeatedIndexIsDegenerate) {
  Surface s = tetrahedron();
  s.F.row(3) << 1, 2, 2;
  const SurfaceCheck c = check_surface(s.F, s.V.rows());
  EXPECT_EQ(c.degenerate_faces, 1);
  EXPECT_FALSE(c.manifold());
}

TEST(SurfaceCheck, LargeMeshIsFast) {
  ShapeSpec spec = parse_shape_spec("sphere:res=320,texture=0");
  const Surface s = make_shape(spec, std::nullopt);
  ASSERT_GT(s.F.rows(), 100000);
  const auto start = std::chrono::steady_clock::now();
  const SurfaceCheck c = check_surface(s.F, s.V.rows());
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_TRUE(c.closed());
  EXPECT_TRUE(c.manifold());
  EXPECT_LT(seconds, 1.0);
}

TEST(SurfaceValidate, RejectsEmptyNonFiniteAndOutOfRange) {
  Surface empty;
  empty.name = "e.obj";
  EXPECT_EQ(message_of<InvalidInput>([&] { validate_surface(empty, false); }), "e.obj: mesh has no faces");

  Surface nan = tetrahedron();
  nan.V(2, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(message_of<InvalidInput>([&] { validate_surface(nan, false); }),
            "tet: vertex 2 has a non-finite coordinate");

  Surface inf = tetrahedron();
  inf.V(3, 0) = -std::numeric_limits<double>::infinity();
  EXPECT_EQ(message_of<InvalidInput>([&] { validate_surface(inf, false); }),
            "tet: vertex 3 has a non-finite coordinate");

  Surface range = tetrahedron();
  range.F(1, 2) = 9;
  EXPECT_EQ(message_of<InvalidInput>([&] { validate_surface(range, false); }),
            "tet: face 1 has vertex index 9 out of range [0, 4)");

  Surface uv = tetrahedron();
  uv.UV = Eigen::MatrixXd::Zero(2, 2);
  uv.FUV = Eigen::MatrixXi::Zero(4, 3);
  EXPECT_NO_THROW(validate_surface(uv, true));
  uv.FUV(0, 0) = 2;
  EXPECT_NE(message_of<InvalidInput>([&] { validate_surface(uv, true); }).find("texture index 2"), std::string::npos);
}

TEST(SurfaceMeasures, TetrahedronVolumeAreaBox) {
  const Surface s = tetrahedron();
  EXPECT_NEAR(signed_volume(s.V, s.F), 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(surface_area(s.V, s.F), 1.5 + std::sqrt(3.0) / 2.0, 1e-15);
  Eigen::MatrixXi flipped = s.F.rowwise().reverse();
  EXPECT_NEAR(signed_volume(s.V, flipped), -1.0 / 6.0, 1e-15);
  const Eigen::AlignedBox3d box = bounding_box(s.V);
  EXPECT_EQ(box.min(), Eigen::Vector3d::Zero());
  EXPECT_EQ(box.max(), Eigen::Vector3d::Ones());
  EXPECT_TRUE(bounding_box(Eigen::MatrixXd(0, 3)).isEmpty());
}

TEST(SurfaceMeasures, VolumeDoesNotDependOnTranslation) {
  Surface s = tetrahedron();
  s.V.rowwise() += Eigen::RowVector3d(1e6, -2e6, 3e6);
  EXPECT_NEAR(signed_volume(s.V, s.F), 1.0 / 6.0, 1e-9);
}

TEST(SurfaceOrient, InwardFacesAndTheirTextureCornersAreTurnedOutward) {
  Surface s = tetrahedron();
  EXPECT_FALSE(orient_outward(s));  // outward already: untouched
  EXPECT_EQ(s.F, tetrahedron().F);
  s.F = tetrahedron().F.rowwise().reverse();
  s.UV = Eigen::MatrixXd::Random(12, 2);
  s.FUV.resize(4, 3);
  s.FUV << 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11;
  const Eigen::MatrixXi inward = s.F, inward_uv = s.FUV;
  EXPECT_TRUE(orient_outward(s));
  EXPECT_NEAR(signed_volume(s.V, s.F), 1.0 / 6.0, 1e-15);
  EXPECT_TRUE(check_surface(s.F, s.V.rows()).inconsistent_edges == 0);
  for (Eigen::Index f = 0; f < 4; ++f) {  // each corner keeps its texture coordinate
    EXPECT_EQ(s.F(f, 0), inward(f, 0));
    EXPECT_EQ(s.F(f, 1), inward(f, 2));
    EXPECT_EQ(s.FUV(f, 1), inward_uv(f, 2));
    EXPECT_EQ(s.FUV(f, 2), inward_uv(f, 1));
  }
}

TEST(SurfaceWeld, TriangleSoupBecomesTheClosedSurface) {
  const Surface tet = tetrahedron();
  Surface soup;
  soup.V.resize(12, 3);
  soup.F.resize(4, 3);
  for (Eigen::Index f = 0; f < 4; ++f)
    for (int c = 0; c < 3; ++c) {
      soup.V.row(3 * f + c) = tet.V.row(tet.F(f, c));
      soup.F(f, c) = int(3 * f + c);
    }
  EXPECT_FALSE(check_surface(soup.F, soup.V.rows()).closed());
  EXPECT_EQ(weld_coincident_vertices(soup), 8);
  ASSERT_EQ(soup.V.rows(), 4);
  const SurfaceCheck check = check_surface(soup.F, soup.V.rows());
  EXPECT_TRUE(check.closed() && check.manifold() && check.inconsistent_edges == 0);
  EXPECT_NEAR(signed_volume(soup.V, soup.F), 1.0 / 6.0, 1e-15);
  for (Eigen::Index f = 0; f < 4; ++f)
    for (int c = 0; c < 3; ++c) EXPECT_EQ(soup.V.row(soup.F(f, c)), tet.V.row(tet.F(f, c)));
  // Nothing to merge: untouched, unused vertices included.
  Surface spare = tet;
  spare.V.conservativeResize(5, 3);
  spare.V.row(4) << 7, 7, 7;
  EXPECT_EQ(weld_coincident_vertices(spare), 0);
  EXPECT_EQ(spare.V.rows(), 5);
  EXPECT_EQ(spare.F, tet.F);
}

}  // namespace
}  // namespace morphmap
