// Tests of mesh files for the inputs and outputs (DESIGN.md, stages "load" and "outputs").
#include "io/mesh_io.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "mesh/errors.h"
#include "mesh/shapes.h"

namespace fs = std::filesystem;

namespace morphmap {
namespace {

class MeshIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static int counter = 0;
    dir_ = fs::temp_directory_path() /
           ("morphmap-mesh-io-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string write(const std::string& name, const std::string& content) const {
    const std::string path = (dir_ / name).string();
    std::ofstream(path, std::ios::binary) << content;
    return path;
  }

  template <typename Exception>
  std::string error_of(const std::string& path) const {
    try {
      read_surface(path);
    } catch (const Exception& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.rfind(path + ": ", 0), 0u) << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
      return m;
    } catch (const std::exception& e) {
      ADD_FAILURE() << "wrong exception type: " << e.what();
      return {};
    }
    ADD_FAILURE() << path << " was accepted";
    return {};
  }

  fs::path dir_;
};

// Little-endian bytes of a value, for hand-made binary PLY files.
template <typename T>
std::string bytes(T value) {
  std::string s(sizeof value, '\0');
  std::memcpy(s.data(), &value, sizeof value);
  return s;
}

const char* kCubeObj = R"(# unit cube, quads, per-corner uvs
mtllib cube.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
usemtl skin
f 1/1 4/2 3/3 2/4
f 5/1/1 6/2/1 7/3/1 8/4/1
f 1/1 2/2 6/3 5/4
f 2/1 3/2 7/3 6/4
f 3/1 4/2 8/3 7/4
f -5/1 -8/2 -4/3 -1/-1
)";

TEST_F(MeshIoTest, ObjQuadsUvsAndTexture) {
  const std::string obj = write("cube.obj", kCubeObj);
  write("cube.mtl", "newmtl other\nKd 1 0 0\nnewmtl skin\nKd 1 1 1\nmap_Kd -s 1 1 1 tex/skin.png\n");
  fs::create_directories(dir_ / "tex");
  write("tex/skin.png", "not checked here");
  const Surface s = read_surface(obj);
  EXPECT_EQ(s.name, obj);
  ASSERT_EQ(s.V.rows(), 8);
  ASSERT_EQ(s.F.rows(), 12);
  EXPECT_EQ(s.F.row(0), Eigen::RowVector3i(0, 3, 2));
  EXPECT_EQ(s.F.row(1), Eigen::RowVector3i(0, 2, 1));
  EXPECT_EQ(s.F.row(10), Eigen::RowVector3i(3, 0, 4));  // negative indices count back from the end
  ASSERT_TRUE(s.has_uv());
  EXPECT_EQ(s.UV.rows(), 4);
  EXPECT_EQ(s.FUV.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_EQ(s.FUV(11, 2), 3);
  EXPECT_EQ(fs::path(s.texture_path), (dir_ / "tex" / "skin.png").lexically_normal());
  EXPECT_NO_THROW(validate_surface(s, true));
  EXPECT_NEAR(signed_volume(s.V, s.F), 1.0, 1e-15);
}

TEST_F(MeshIoTest, ObjWithTwoTexturedMaterialsNamesTheOtherImages) {
  // One texture is carried (the first used); the others are listed so that the pipeline can say so.
  std::string text = kCubeObj;
  text.replace(text.find("f 3/1 4/2"), 0, "usemtl coat\n");
  const std::string obj = write("cube.obj", text);
  write("cube.mtl", "newmtl skin\nmap_Kd skin.png\nnewmtl coat\nmap_Kd coat.png\n");
  write("skin.png", "not checked here");
  write("coat.png", "not checked here");
  const Surface s = read_surface(obj);
  EXPECT_EQ(fs::path(s.texture_path).filename(), "skin.png");
  ASSERT_EQ(s.other_textures.size(), 1u);
  EXPECT_EQ(s.other_textures[0], "coat.png");
  EXPECT_TRUE(read_surface(write("one.obj", kCubeObj)).other_textures.empty());
}

TEST_F(MeshIoTest, ObjWithoutMtlOrTextureHasNoTexture) {
  const std::string obj = write("cube.obj", kCubeObj);
  EXPECT_TRUE(read_surface(obj).texture_path.empty());  // cube.mtl missing
  write("cube.mtl", "newmtl skin\nmap_Kd missing.png\n");
  const Surface s = read_surface(obj);
  EXPECT_TRUE(s.texture_path.empty());
  EXPECT_EQ(s.missing_texture, "missing.png");  // for the pipeline's warning
  EXPECT_TRUE(s.has_uv());
}

TEST_F(MeshIoTest, ObjWithPartialUvsHasNone) {
  const Surface s = read_surface(write("t.OBJ", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 1 3 2\n"));
  EXPECT_FALSE(s.has_uv());
  EXPECT_EQ(s.F.rows(), 2);
}

TEST_F(MeshIoTest, OffHeaderVariantsCommentsAndPolygons) {
  const Surface a = read_surface(write("a.off",
                                       "OFF\n# a comment\n\n4 2 0\n0 0 0\n1 0 0 # trailing\n1 1 0\n0 1 0\n"
                                       "4 0 1 2 3 255 0 0\n3 0 2 1\n"));
  EXPECT_EQ(a.V.rows(), 4);
  ASSERT_EQ(a.F.rows(), 3);
  EXPECT_EQ(a.F.row(1), Eigen::RowVector3i(0, 2, 3));
  EXPECT_EQ(a.F.row(2), Eigen::RowVector3i(0, 2, 1));
  EXPECT_DOUBLE_EQ(a.V(2, 1), 1.0);

  const Surface b = read_surface(write("b.off", "OFF 3 1 3\r\n0 0 0\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n"));
  EXPECT_EQ(b.F.rows(), 1);
  const Surface c = read_surface(write("c.off", "COFF\n3 1 0\n0 0 0 1 0 0 1\n1 0 0 1 0 0 1\n0 1 0 1 0 0 1\n3 0 1 2\n"));
  EXPECT_EQ(c.V.rows(), 3);
}

TEST_F(MeshIoTest, PlyAsciiSkipsOtherPropertiesAndElements) {
  const std::string ply = write("a.ply",
                                "ply\nformat ascii 1.0\ncomment hand-made\nelement vertex 4\nproperty float x\n"
                                "property float y\nproperty double z\nproperty uchar red\n"
                                "property list uchar int weights\nelement face 2\nproperty uchar flags\n"
                                "property list uchar int vertex_indices\nelement edge 1\nproperty int vertex1\n"
                                "property int vertex2\nend_header\n"
                                "0 0 0 255 0\n1 0 0 1 2 7 8\n0.5 1 0.25 3 1 9\n0 0 1 4 0\n"
                                "0 4 0 2 1 3\n1 3 0 1 2\n0 1\n");
  const Surface s = read_surface(ply);
  ASSERT_EQ(s.V.rows(), 4);
  EXPECT_DOUBLE_EQ(s.V(2, 0), 0.5);
  EXPECT_DOUBLE_EQ(s.V(2, 2), 0.25);
  ASSERT_EQ(s.F.rows(), 3);
  EXPECT_EQ(s.F.row(0), Eigen::RowVector3i(0, 2, 1));
  EXPECT_EQ(s.F.row(1), Eigen::RowVector3i(0, 1, 3));
  EXPECT_EQ(s.F.row(2), Eigen::RowVector3i(0, 1, 2));
  EXPECT_FALSE(s.has_uv());
}

std::string binary_ply_header(int vertices, int faces) {
  return "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(vertices) +
         "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar alpha\nelement face " +
         std::to_string(faces) + "\nproperty list uchar uint vertex_index\nproperty short tag\nend_header\n";
}

std::string binary_tetrahedron_body() {
  const float p[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const unsigned f[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  std::string body;
  for (const auto& v : p) body += bytes(v[0]) + bytes(v[1]) + bytes(v[2]) + bytes(std::uint8_t{7});
  for (const auto& t : f) body += bytes(std::uint8_t{3}) + bytes(t[0]) + bytes(t[1]) + bytes(t[2]) + bytes(short{-1});
  return body;
}

TEST_F(MeshIoTest, PlyBinaryLittleEndian) {
  const Surface s = read_surface(write("b.ply", binary_ply_header(4, 4) + binary_tetrahedron_body()));
  ASSERT_EQ(s.V.rows(), 4);
  ASSERT_EQ(s.F.rows(), 4);
  EXPECT_EQ(s.F.row(3), Eigen::RowVector3i(1, 2, 3));
  EXPECT_DOUBLE_EQ(s.V(3, 2), 1.0);
  EXPECT_NO_THROW(validate_surface(s, true));
  EXPECT_GT(signed_volume(s.V, s.F), 0.0);
}

TEST_F(MeshIoTest, StlAsciiAndBinaryAreWeldedIntoTheClosedSurface) {
  // The unit tetrahedron, each facet with its own corners (outward order), as ASCII and as binary STL (whose header
  // starts with "solid" too: the size tells them apart).
  const double corner[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const int facets[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  std::string ascii = "solid tet\n", binary = std::string("solid but binary").append(64, ' ') + bytes(std::uint32_t(4));
  for (const auto& f : facets) {
    ascii += " facet normal 0 0 0\n  outer loop\n";
    binary += bytes(0.0f) + bytes(0.0f) + bytes(0.0f);
    for (int c = 0; c < 3; ++c) {
      const double* p = corner[f[c]];
      ascii += "   vertex " + std::to_string(p[0]) + " " + std::to_string(p[1]) + " " + std::to_string(p[2]) + "\n";
      binary += bytes(float(p[0])) + bytes(float(p[1])) + bytes(float(p[2]));
    }
    ascii += "  endloop\n endfacet\n";
    binary += bytes(std::uint16_t(0));
  }
  ascii += "endsolid tet\n";
  for (const std::string& path : {write("a.stl", ascii), write("b.STL", binary)}) {
    SCOPED_TRACE(path);
    const Surface s = read_surface(path);
    ASSERT_EQ(s.V.rows(), 4);
    ASSERT_EQ(s.F.rows(), 4);
    const SurfaceCheck check = validate_surface(s, true);
    EXPECT_EQ(check.euler(), 2);
    EXPECT_NEAR(signed_volume(s.V, s.F), 1.0 / 6.0, 1e-12);
  }
  EXPECT_NE(error_of<InvalidInput>(write("c.stl", "not a mesh")).find("not an STL file"), std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("d.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nendloop\n"))
                .find("line 5: facet has 1 vertices, not 3"),
            std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("e.stl", "solid x\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"))
                .find("file ends inside a facet"),
            std::string::npos);
}

TEST_F(MeshIoTest, MissingFileIsIoError) {
  const std::string m = error_of<IoError>((dir_ / "nope.off").string());
  EXPECT_NE(m.find("cannot open file"), std::string::npos);
}

TEST_F(MeshIoTest, UnknownExtensionIsInvalidInput) {
  const std::string m = error_of<InvalidInput>(write("x.3ds", "solid"));
  EXPECT_NE(m.find("unknown mesh file extension '.3ds' (expected .obj, .off, .ply or .stl)"), std::string::npos) << m;
}

TEST_F(MeshIoTest, EmptyMeshIsInvalidInput) {
  EXPECT_NE(error_of<InvalidInput>(write("e.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n")).find("mesh has no faces"),
            std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("e.obj", "# nothing\nv 0 0 0\n")).find("mesh has no faces"),
            std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("e2.off", "")).find("mesh has no faces"), std::string::npos);
}

TEST_F(MeshIoTest, NonFiniteCoordinatesAreInvalidInput) {
  const std::string off = write("n.off", "OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n");
  EXPECT_EQ(error_of<InvalidInput>(off), off + ": vertex 1 has a non-finite coordinate");
  const std::string obj = write("n.obj", "v 0 0 0\nv 1 0 0\nv 0 1 inf\nf 1 2 3\n");
  EXPECT_EQ(error_of<InvalidInput>(obj), obj + ": vertex 2 has a non-finite coordinate");
  const std::string ply = write("n.ply",
                                "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
                                "property double z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                "end_header\n0 0 0\n1 0 0\n-inf 1 0\n3 0 1 2\n");
  EXPECT_EQ(error_of<InvalidInput>(ply), ply + ": vertex 2 has a non-finite coordinate");
}

TEST_F(MeshIoTest, IndicesOutOfRangeAreInvalidInput) {
  const std::string off = write("r.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 99\n");
  EXPECT_EQ(error_of<InvalidInput>(off), off + ": face 1 has vertex index 99 out of range [0, 4)");
  const std::string neg = write("neg.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n");
  EXPECT_EQ(error_of<InvalidInput>(neg), neg + ": face 0 has vertex index -1 out of range [0, 3)");
  const std::string obj = write("r.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n");
  EXPECT_EQ(error_of<InvalidInput>(obj), obj + ": line 5: face refers to vertex 9 but the file has 3 vertices");
  const std::string zero = write("z.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
  EXPECT_NE(error_of<InvalidInput>(zero).find("index 0"), std::string::npos);
  const std::string vt = write("vt.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n");
  EXPECT_NE(error_of<InvalidInput>(vt).find("texture coordinate 2"), std::string::npos);
  const std::string ply = write("r.ply",
                                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  EXPECT_EQ(error_of<InvalidInput>(ply), ply + ": face 0 has vertex index 3 out of range [0, 3)");
}

// A long file (40 k lines, faces with positive and negative indices in turn) reads exactly, and of two errors the
// first in the file is reported, with its line.
TEST_F(MeshIoTest, LongObjReadsAsOnePass) {
  const int n = 20000;
  std::vector<std::string> lines;
  for (int i = 0; i < n; ++i) {
    lines.push_back("v " + std::to_string(i) + " " + std::to_string(i % 7) + " 0.5");
    if (i < 2) continue;
    if (i % 2 == 0)
      lines.push_back("f -1 -2 -3");  // vertices i, i - 1, i - 2
    else
      lines.push_back("f " + std::to_string(i - 1) + " " + std::to_string(i) + " " + std::to_string(i + 1));
  }
  auto join = [](const std::vector<std::string>& all) {
    std::string text;
    for (const std::string& line : all) text += line + "\n";
    return text;
  };
  ASSERT_GT(lines.size(), 2u * 16384u);
  const Surface s = read_surface(write("long.obj", join(lines)));
  ASSERT_EQ(s.V.rows(), n);
  ASSERT_EQ(s.F.rows(), n - 2);
  for (int i = 0; i < n; ++i) ASSERT_EQ(s.V.row(i), Eigen::RowVector3d(i, i % 7, 0.5)) << i;
  for (int i = 2; i < n; ++i) {
    const Eigen::RowVector3i face =
        i % 2 == 0 ? Eigen::RowVector3i(i, i - 1, i - 2) : Eigen::RowVector3i(i - 2, i - 1, i);
    ASSERT_EQ(s.F.row(i - 2), face) << i;
  }
  // Two errors: the earlier one is reported.
  std::vector<std::string> bad = lines;
  bad[35000] = "f 1 2";
  bad[20000] = "v 0 0 zero";
  EXPECT_EQ(error_of<InvalidInput>(write("bad.obj", join(bad))),
            (dir_ / "bad.obj").string() + ": line 20001: bad number 'zero'");
  bad[20000] = lines[20000];
  EXPECT_NE(error_of<InvalidInput>(write("bad.obj", join(bad))).find("line 35001: face has 2 corners"),
            std::string::npos);
}

TEST_F(MeshIoTest, MalformedTextIsInvalidInput) {
  EXPECT_NE(error_of<InvalidInput>(write("m.obj", "v 0 0\nf 1 1 1\n")).find("line 1: vertex needs 3 coordinates"),
            std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("m2.obj", "v 0 0 zero\n")).find("line 1: bad number 'zero'"),
            std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("m3.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n")).find("at least 3"), std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("m.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n")).find("after 2 of 4 vertices"),
            std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("m2.off", "PLY\n3 1 0\n")).find("not an OFF file"), std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("m3.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n")).find("lists 2 of 3"),
            std::string::npos);
  EXPECT_NE(
      error_of<InvalidInput>(write("m.ply", "ply\nformat binary_big_endian 1.0\nend_header\n")).find("big-endian"),
      std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("m2.ply", "solid\n")).find("not a PLY file"), std::string::npos);
  EXPECT_NE(error_of<InvalidInput>(write("m3.ply", "ply\nformat ascii 1.0\nelement vertex 1\n")).find("end_header"),
            std::string::npos);
}

// The text readers take numbers with std::from_chars and fall back to strtod / strtoll where from_chars stops early,
// so every form strtod reads still reads, to the same double: a leading '+', hexadecimal floats, values from_chars
// rounds out of range, indices with '+'. Carriage returns are blanks; a NUL byte ends its line.
TEST_F(MeshIoTest, ObjNumbersReadAsStrtodReadsThem) {
  const std::string text =
      "v +1.5 0x1p-2 .25\r\n"
      "v 1e-320 -0 3.\n"
      "v 0.1 2.5e+1 -7\n"
      "f +1 2/ 3\n";
  const Surface s = read_surface(write("n.obj", text));
  ASSERT_EQ(s.V.rows(), 3);
  ASSERT_EQ(s.F.rows(), 1);
  EXPECT_EQ(s.V(0, 0), 1.5);
  EXPECT_EQ(s.V(0, 1), 0.25);
  EXPECT_EQ(s.V(0, 2), 0.25);
  EXPECT_EQ(s.V(1, 0), std::strtod("1e-320", nullptr));  // subnormal: strtod's ERANGE result is kept
  EXPECT_TRUE(std::signbit(s.V(1, 1)));
  EXPECT_EQ(s.V(1, 2), 3.0);
  EXPECT_EQ(s.V(2, 0), std::strtod("0.1", nullptr));
  EXPECT_EQ(s.V(2, 1), 25.0);
  EXPECT_EQ(s.F.row(0), Eigen::RowVector3i(0, 1, 2));
  EXPECT_NE(error_of<InvalidInput>(write("h.obj", "v 0 0 1e\n")).find("line 1: bad number '1e'"), std::string::npos);
  EXPECT_NE(
      error_of<InvalidInput>(write("i.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3x\n")).find("bad face corner '3x'"),
      std::string::npos);
  const Surface cut = read_surface(write("z.obj", std::string("v 0 0 0\nv 1 0 0\nv 0 1 0 ") + '\0' + " junk\nf 1 2 3"));
  EXPECT_EQ(cut.V.rows(), 3);
  EXPECT_EQ(cut.F.rows(), 1);
}

TEST_F(MeshIoTest, TruncatedBinaryPlyIsInvalidInput) {
  const std::string full = binary_ply_header(4, 4) + binary_tetrahedron_body();
  for (std::size_t cut : {full.size() - 1, full.size() - 20, binary_ply_header(4, 4).size() + 5}) {
    const std::string path = write("t" + std::to_string(cut) + ".ply", full.substr(0, cut));
    EXPECT_NE(error_of<InvalidInput>(path).find("truncated"), std::string::npos);
  }
  // A count far beyond the data must fail cleanly rather than attempt a huge allocation.
  const std::string huge = write("huge.ply", binary_ply_header(2000000000, 4) + binary_tetrahedron_body());
  EXPECT_NE(error_of<InvalidInput>(huge).find("truncated"), std::string::npos);
}

TEST_F(MeshIoTest, ObjRoundTripIsExactWithPerCornerUvs) {
  const Surface sphere = make_shape(parse_shape_spec("sphere:res=16,center=0.1/0.2/0.3,size=0.7"), std::nullopt);
  const TriIndices F = sphere.F, FUV = sphere.FUV;
  const std::string obj = (dir_ / "out.obj").string();
  write_obj(obj, sphere.V, F, sphere.UV, FUV, "out.mtl");
  write_mtl((dir_ / "out.mtl").string(), "out.png");
  write("out.png", "x");
  const Surface back = read_surface(obj);
  EXPECT_EQ(back.V, sphere.V);  // bit-exact
  EXPECT_EQ(back.F, sphere.F);
  EXPECT_EQ(back.UV, sphere.UV);
  EXPECT_EQ(back.FUV, sphere.FUV);
  EXPECT_EQ(fs::path(back.texture_path), (dir_ / "out.png").lexically_normal());
}

TEST_F(MeshIoTest, ObjRoundTripWithPerVertexAndNoUvs) {
  const Surface torus = make_shape(parse_shape_spec("torus:res=12"), std::nullopt);
  const TriIndices F = torus.F;
  const Eigen::MatrixXd uv = torus.V.leftCols(2);
  const std::string a = (dir_ / "a.obj").string(), b = (dir_ / "b.obj").string();
  write_obj(a, torus.V, F, uv, TriIndices(), "");
  write_obj(b, torus.V, F, Eigen::MatrixXd(), TriIndices(), "");
  const Surface ra = read_surface(a), rb = read_surface(b);
  EXPECT_EQ(ra.V, torus.V);
  EXPECT_EQ(ra.UV, uv);
  EXPECT_EQ(ra.FUV, torus.F);
  EXPECT_EQ(rb.F, torus.F);
  EXPECT_FALSE(rb.has_uv());
  EXPECT_TRUE(rb.texture_path.empty());
}

TEST_F(MeshIoTest, PlyRoundTripIsExact) {
  const Surface s = make_shape(parse_shape_spec("two-spheres:res=12,center=1e3/-2/0.1"), std::nullopt);
  const TriIndices F = s.F;
  const Eigen::MatrixXd uv = 0.5 * (s.V.leftCols(2).array() - 1e3).matrix();
  const std::string a = (dir_ / "a.ply").string(), b = (dir_ / "b.ply").string();
  write_ply(a, s.V, F, uv);
  write_ply(b, s.V, F, Eigen::MatrixXd());
  const Surface ra = read_surface(a), rb = read_surface(b);
  EXPECT_EQ(ra.V, s.V);
  EXPECT_EQ(ra.F, s.F);
  ASSERT_TRUE(ra.has_uv());
  EXPECT_LT((ra.UV - uv).cwiseAbs().maxCoeff(), 1e-4);  // u, v are stored as float
  EXPECT_EQ(ra.FUV, s.F);
  EXPECT_EQ(rb.V, s.V);
  EXPECT_FALSE(rb.has_uv());
}

TEST(PerVertexUv, SplitsVerticesAtTextureSeamsOnly) {
  // A square of two triangles sharing the edge 0-2; vertex 2's corners take two different UVs (a texture seam runs
  // through it), vertex 0's two corners the same UV under two indices (as the seam split writes them).
  Eigen::MatrixXd V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  TriIndices F(2, 3);
  F << 0, 1, 2, 0, 2, 3;
  Eigen::MatrixXd UV(6, 2);
  UV << 0, 0, 1, 0, 1, 1, 0, 0, 0.5, 0.5, 0, 1;
  TriIndices FUV(2, 3);
  FUV << 0, 1, 2, 3, 4, 5;
  const PerVertexUvMesh m = per_vertex_uv(V, F, UV, FUV);
  ASSERT_EQ(m.V.rows(), 5);  // vertex 2 twice
  EXPECT_EQ(m.vertex, (std::vector<int>{0, 1, 2, 2, 3}));
  EXPECT_EQ(m.F(0, 0), m.F(1, 0));  // vertex 0 stays one vertex: its UVs are equal
  EXPECT_NE(m.F(0, 2), m.F(1, 1));  // vertex 2 is split
  for (Eigen::Index f = 0; f < 2; ++f)
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(m.V.row(m.F(f, c)), V.row(F(f, c)));
      EXPECT_EQ(m.UV.row(m.F(f, c)), UV.row(FUV(f, c)));
    }
  TriIndices bad = FUV;
  bad(1, 2) = 6;
  EXPECT_THROW(per_vertex_uv(V, F, UV, bad), InvalidInput);
}

TEST_F(MeshIoTest, WritersStreamFilesLargerThanTheirBuffer) {
  // The writers hand their text to the file a megabyte at a time: files of several megabytes cross that boundary
  // many times, mid-line included, and must still read back bit for bit.
  const Surface sphere = make_shape(parse_shape_spec("sphere:res=320"), std::nullopt);
  const TriIndices F = sphere.F, FUV = sphere.FUV;
  const std::string obj = (dir_ / "big.obj").string(), ply = (dir_ / "big.ply").string();
  write_obj(obj, sphere.V, F, sphere.UV, FUV, "");
  write_ply(ply, sphere.V, F, Eigen::MatrixXd());
  EXPECT_GT(fs::file_size(obj), std::uintmax_t(3) << 20);
  EXPECT_GT(fs::file_size(ply), std::uintmax_t(2) << 20);
  const Surface from_obj = read_surface(obj), from_ply = read_surface(ply);
  EXPECT_EQ(from_obj.V, sphere.V);
  EXPECT_EQ(from_obj.F, sphere.F);
  EXPECT_EQ(from_obj.UV, sphere.UV);
  EXPECT_EQ(from_obj.FUV, sphere.FUV);
  EXPECT_EQ(from_ply.V, sphere.V);
  EXPECT_EQ(from_ply.F, sphere.F);
}

TEST_F(MeshIoTest, WritersRejectBadInput) {
  Eigen::MatrixXd V = Eigen::MatrixXd::Zero(3, 3);
  TriIndices F(1, 3);
  F << 0, 1, 3;
  EXPECT_THROW(write_obj((dir_ / "x.obj").string(), V, F, Eigen::MatrixXd(), TriIndices(), ""), InvalidInput);
  EXPECT_THROW(write_ply((dir_ / "x.ply").string(), V, F, Eigen::MatrixXd()), InvalidInput);
  F << 0, 1, 2;
  EXPECT_THROW(write_ply((dir_ / "x.ply").string(), V, F, Eigen::MatrixXd::Zero(2, 2)), InvalidInput);
  EXPECT_THROW(write_obj((dir_ / "no" / "x.obj").string(), V, F, Eigen::MatrixXd(), TriIndices(), ""), IoError);
}

TEST_F(MeshIoTest, SpotModelIfPresent) {
  const fs::path spot = "/work/shared/data/models/spot.obj";
  if (!fs::exists(spot)) GTEST_SKIP() << "test models not present";
  const Surface s = read_surface(spot.string());
  EXPECT_EQ(s.V.rows(), 2930);
  EXPECT_EQ(s.F.rows(), 5856);
  EXPECT_TRUE(s.has_uv());
  EXPECT_EQ(s.UV.rows(), 3225);
  EXPECT_NO_THROW(validate_surface(s, true));
  EXPECT_NEAR(signed_volume(s.V, s.F), 0.7183, 1e-3);
}

}  // namespace
}  // namespace morphmap
