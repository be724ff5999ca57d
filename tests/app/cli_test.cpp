// The `morphmap` command as a user meets it: bad input exits 2 with one line naming the problem and
// writes nothing; the demo writes every output.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "app/pipeline.h"
#include "io/image.h"
#include "tests/command_line.h"

namespace fs = std::filesystem;

namespace {

using morphmap::test::CommandRun;
using morphmap::test::run_command;

class Cli : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = morphmap::test::fresh_test_dir("morphmap_cli_"); }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  // Runs `map` with a bad input and checks status 2, one line naming `needle`, and no output.
  void expect_rejected(const std::string& args, const std::string& needle) {
    const fs::path out = dir_ / "out";
    const CommandRun r = run_command("map " + args + " -o " + out.string() + " --voxels 16 --time-steps 4");
    EXPECT_EQ(r.status, 2) << r.output;
    EXPECT_NE(r.output.find(needle), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
    EXPECT_FALSE(fs::exists(out)) << "output directory was created";
  }
  fs::path dir_;
};

const char* kTetraOff = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";

TEST_F(Cli, MissingFile) { expect_rejected((dir_ / "nope.obj").string() + " sphere", "nope.obj"); }

TEST_F(Cli, EmptyMesh) {
  const std::string p = write("empty.off", "OFF\n0 0 0\n");
  expect_rejected(p + " sphere", "empty.off");
}

TEST_F(Cli, NonFiniteCoordinate) {
  const std::string p =
      write("nan.off", "OFF\n4 4 0\n0 0 0\n1 0 0\n0 nan 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n");
  expect_rejected("sphere " + p, "nan.off");
}

TEST_F(Cli, FaceIndexOutOfRange) {
  const std::string p =
      write("range.off", "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 9\n3 1 2 3\n");
  expect_rejected(p + " sphere", "range.off");
}

TEST_F(Cli, NotClosed) {
  const std::string p = write("open.off", "OFF\n4 3 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n");
  expect_rejected(p + " sphere", "not closed");
}

TEST_F(Cli, NotManifold) {
  // Two tetrahedra sharing one vertex only: closed, but the shared vertex is not manifold.
  const std::string p = write("bowtie.off",
                              "OFF\n7 8 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n-1 0 0\n0 -1 0\n0 0 -1\n"
                              "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n3 0 4 5\n3 0 6 4\n3 0 5 6\n3 4 6 5\n");
  expect_rejected(p + " sphere", "not manifold");
}

TEST_F(Cli, UnknownOptionValues) {
  const std::string p = write("tet.off", kTetraOff);
  expect_rejected("sphere torus --solver magic", "magic");
  expect_rejected("sphere torus --align sideways", "sideways");
  expect_rejected("sphere torus --slices 1.5", "1.5");
  expect_rejected("cube torus", "cube");
  expect_rejected("sphere:radius=2 torus", "radius");
  expect_rejected("sphere torus --method teleport", "teleport");
  expect_rejected("sphere torus --source-projection nearest", "nearest");
  expect_rejected("sphere torus --seams sideways", "sideways");
  expect_rejected("sphere torus --zero-snap 0.9", "0.9");
  expect_rejected("sphere torus --seam-threshold -0.5", "-0.5");
  expect_rejected("sphere torus --fold-repair maybe", "maybe");
  expect_rejected("sphere torus --target-mesh " + (dir_ / "absent.obj").string(), "absent.obj");
}

// The fold repair runs by default and --fold-repair off skips it; --seam-threshold reaches the seam split.
TEST_F(Cli, FoldRepairIsOnByDefaultAndSeamThresholdIsUsed) {
  auto report = [&](const std::string& name, const std::string& options) {
    const fs::path out = dir_ / name;
    const CommandRun r = run_command("map sphere torus --voxels 16 --time-steps 4 -o " + out.string() + " " + options);
    EXPECT_EQ(r.status, 0) << r.output;
    std::ifstream in(out / "report.json");
    return nlohmann::json::parse(in);
  };
  const nlohmann::json on = report("on", "--seam-threshold 0.1");
  ASSERT_TRUE(on.contains("fold_repair"));
  EXPECT_TRUE(on["fold_repair"]["enabled"].get<bool>());
  EXPECT_DOUBLE_EQ(on["seams"]["threshold_diagonals"].get<double>(), 0.1);
  EXPECT_DOUBLE_EQ(on["options"]["seam_threshold"].get<double>(), 0.1);
  const nlohmann::json off = report("off", "--fold-repair off");
  EXPECT_FALSE(off.contains("fold_repair"));
  EXPECT_DOUBLE_EQ(off["seams"]["threshold_diagonals"].get<double>(), 0.25);
}

// Reads the `v` lines of an OBJ file.
std::vector<Eigen::Vector3d> obj_vertices(const fs::path& path) {
  std::vector<Eigen::Vector3d> V;
  std::ifstream in(path);
  std::string tag;
  for (std::string line; std::getline(in, line);) {
    std::istringstream fields(line);
    Eigen::Vector3d v;
    if (fields >> tag && tag == "v" && fields >> v.x() >> v.y() >> v.z()) V.push_back(v);
  }
  return V;
}

TEST_F(Cli, TargetMeshGetsALabelPerVertexWithEveryMethod) {
  // An octahedron of radius 0.8 around a sphere of radius 0.5: every method maps it nearly radially.
  const std::string octahedron = write("octahedron.off",
                                       "OFF\n6 8 0\n0.8 0 0\n-0.8 0 0\n0 0.8 0\n0 -0.8 0\n0 0 0.8\n0 0 -0.8\n"
                                       "3 0 2 4\n3 2 1 4\n3 1 3 4\n3 3 0 4\n3 2 0 5\n3 1 2 5\n3 3 1 5\n3 0 3 5\n");
  for (const std::string method : {"closest-point", "upwind", "trace"}) {
    const fs::path out = dir_ / method;
    const CommandRun r = run_command("map sphere:size=0.5,center=0/0/0 " + octahedron + " --target-mesh " + octahedron +
                                     " --method " + method + " --voxels 16 --time-steps 4 -o " + out.string());
    ASSERT_EQ(r.status, 0) << r.output;
    const nlohmann::json report = nlohmann::json::parse(std::ifstream(out / "report.json"));
    EXPECT_EQ(report["options"]["method"], method);
    const std::vector<Eigen::Vector3d> V = obj_vertices(out / "target.obj");
    EXPECT_GE(V.size(), 6u) << method;  // texture seams may add vertices, never remove the octahedron's
    EXPECT_GE(report["counts"]["target_triangles"].get<int>(), 8) << method;
    std::ifstream labels(out / "labels.txt");
    std::size_t i = 0;
    for (Eigen::Vector3d l; labels >> l.x() >> l.y() >> l.z(); ++i) {
      ASSERT_LT(i, V.size()) << method;
      EXPECT_NEAR(l.norm(), 0.5, 0.02) << method;
      EXPECT_LT(std::acos(std::clamp(l.normalized().dot(V[i].normalized()), -1.0, 1.0)), 0.2) << method << " " << i;
    }
    EXPECT_EQ(i, V.size()) << method;
  }
}

TEST_F(Cli, AllocatorTunablesAreSetOnceAndCanBeRefused) {
  // The binary re-executes itself with its glibc tunables and OpenBLAS's thread timeout (app/allocator.h);
  // report.json says what was in force.
  auto allocator = [&](const std::string& env, const std::string& name) {
    const fs::path out = dir_ / name;
    const std::string command = "env -u GLIBC_TUNABLES -u MORPHMAP_NO_ALLOCATOR_TUNING -u OPENBLAS_THREAD_TIMEOUT " +
                                env + " " + MORPHMAP_BINARY + " map sphere torus --voxels 10 --time-steps 4 -o " +
                                out.string() + " 2>&1";
    EXPECT_EQ(std::system(command.c_str()), 0) << command;
    return nlohmann::json::parse(std::ifstream(out / "report.json"))["allocator"];
  };
  auto tunables = [&](const std::string& env, const std::string& name) {
    return allocator(env, name)["glibc_tunables"].get<std::string>();
  };
  const std::string ours = tunables("", "default");
  EXPECT_EQ(ours.find("glibc.malloc.hugetlb=1"), 0u) << ours;
  EXPECT_EQ(ours.find("glibc.malloc.hugetlb", 1), std::string::npos) << "appended twice: " << ours;
  EXPECT_EQ(tunables("MORPHMAP_NO_ALLOCATOR_TUNING=1", "refused"), "");
  // The user's own tunables are kept in front of ours; a user who sets hugetlb decides alone.
  EXPECT_EQ(tunables("GLIBC_TUNABLES=glibc.malloc.arena_max=2", "appended"), "glibc.malloc.arena_max=2:" + ours);
  EXPECT_EQ(tunables("GLIBC_TUNABLES=glibc.malloc.hugetlb=0", "user"), "glibc.malloc.hugetlb=0");
  // OpenBLAS's spin: ours unless the user set one, also where the user's hugetlb leaves the tunables alone.
  auto timeout = [&](const std::string& env, const std::string& name) {
    return allocator(env, name)["openblas_thread_timeout"].get<std::string>();
  };
  EXPECT_EQ(timeout("", "timeout-default"), "20");
  EXPECT_EQ(timeout("OPENBLAS_THREAD_TIMEOUT=12", "timeout-user"), "12");
  EXPECT_EQ(timeout("GLIBC_TUNABLES=glibc.malloc.hugetlb=0", "timeout-user-tunables"), "20");
  EXPECT_EQ(timeout("MORPHMAP_NO_ALLOCATOR_TUNING=1", "timeout-refused"), "");
}

TEST_F(Cli, TopologyTheLatticeChangesIsReported) {
  // Two unit cubes 0.1 apart; at 7 voxels (h = 0.3) no lattice point falls in the gap, so without the thin-feature
  // pass (which moves points into the gap) the extracted target is one closed surface where the input has two.
  std::ostringstream obj;
  for (const double x0 : {0.0, 1.1}) {
    for (int c = 0; c < 8; ++c) obj << "v " << x0 + (c & 1) << ' ' << ((c >> 1) & 1) << ' ' << ((c >> 2) & 1) << '\n';
  }
  // Outward triangles of the cube with corners 1..8 (bit 0: x, bit 1: y, bit 2: z).
  const int faces[12][3] = {{1, 3, 4}, {1, 4, 2}, {5, 6, 8}, {5, 8, 7}, {1, 2, 6}, {1, 6, 5},
                            {3, 7, 8}, {3, 8, 4}, {1, 5, 7}, {1, 7, 3}, {2, 4, 8}, {2, 8, 6}};
  for (const int offset : {0, 8})
    for (const auto& f : faces) obj << "f " << f[0] + offset << ' ' << f[1] + offset << ' ' << f[2] + offset << '\n';
  const std::string cubes = write("cubes.obj", obj.str());
  const fs::path out = dir_ / "cubes";
  const CommandRun r =
      run_command("map sphere " + cubes + " -o " + out.string() + " --voxels 7 --time-steps 4 --thin-features off");
  ASSERT_EQ(r.status, 0) << r.output;
  const nlohmann::json topology = nlohmann::json::parse(std::ifstream(out / "report.json"))["topology"];
  EXPECT_EQ(topology["target"]["input_components"], 2) << topology.dump();
  EXPECT_EQ(topology["target"]["input_euler"], 4) << topology.dump();
  EXPECT_EQ(topology["target"]["extracted_components"], 1) << topology.dump();
  EXPECT_EQ(topology["target"]["extracted_euler"], 2) << topology.dump();
  EXPECT_EQ(topology["source"]["extracted_euler"], topology["source"]["input_euler"]) << topology.dump();
  ASSERT_EQ(topology["warnings"].size(), 1u) << topology.dump();
  EXPECT_NE(r.output.find("warning: the target as extracted"), std::string::npos) << r.output;
  // At 40 voxels the gap holds lattice points and both cubes survive; a torus keeps its handle: no warning.
  const fs::path fine = dir_ / "fine";
  ASSERT_EQ(run_command("map sphere " + cubes + " -o " + fine.string() + " --voxels 40 --time-steps 4").status, 0);
  EXPECT_TRUE(nlohmann::json::parse(std::ifstream(fine / "report.json"))["topology"]["warnings"].empty());
  const fs::path torus = dir_ / "torus";
  const CommandRun t = run_command("map sphere torus -o " + torus.string() + " --voxels 12 --time-steps 4");
  ASSERT_EQ(t.status, 0) << t.output;
  EXPECT_EQ(t.output.find("warning"), std::string::npos) << t.output;
}

TEST_F(Cli, LauncherRunsTheProgramBesideIt) {
  // `morphmap` only sets the tunables and executes morphmap-run from its own folder (app/launcher.cpp): a copy
  // without the program says which file it could not run, with the shell's status for a missing command.
  const fs::path lone = dir_ / "morphmap";
  fs::copy_file(MORPHMAP_BINARY, lone);
  FILE* pipe = popen((lone.string() + " --help 2>&1").c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  std::array<char, 4096> buffer{};
  while (fgets(buffer.data(), int(buffer.size()), pipe)) output += buffer.data();
  const int raw = pclose(pipe);
  EXPECT_EQ(WIFEXITED(raw) ? WEXITSTATUS(raw) : -1, 127) << output;
  EXPECT_NE(output.find((dir_ / "morphmap-run").string()), std::string::npos) << output;
  // Beside the program it is the program: its help, status 0.
  const CommandRun help = run_command("--help");
  EXPECT_EQ(help.status, 0) << help.output;
  EXPECT_NE(help.output.find("SUBCOMMAND"), std::string::npos) << help.output;
}

TEST_F(Cli, MemoryGuardRefusesBeforeAllocating) {
  expect_rejected("sphere torus --max-memory 100M", "--max-memory");
  expect_rejected("sphere torus --max-memory lots", "lots");
  expect_rejected("sphere torus --max-memory 5Q", "5Q");
  expect_rejected("sphere torus --max-memory 8GQ", "8GQ");
  // 8GB and 8GiB are 8G; a size beyond 64 bits is no limit (its cast to an integer was undefined).
  EXPECT_EQ(morphmap::parse_memory_size("8GB"), morphmap::parse_memory_size("8G"));
  EXPECT_EQ(morphmap::parse_memory_size("512MiB"), 512LL << 20);
  EXPECT_EQ(morphmap::parse_memory_size("99999999999999999999G"), std::numeric_limits<long long>::max());
  EXPECT_EQ(morphmap::parse_memory_size("2000000000"), 2000000000LL);
  // The variational morph's dense constraint system is refused before it is built.
  expect_rejected("sphere torus --morph vim --vim-samples 5000 --max-memory 1G", "--vim-samples");
  expect_rejected("sphere torus --morph spline", "--morph");
  // The lattice is checked before the morph allocates it: 2000 voxels a side is 8 billion points.
  const fs::path big = dir_ / "big";
  const CommandRun r = run_command("map sphere torus -o " + big.string() + " --voxels 2000 --max-memory 8G");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--max-memory: the lattice alone (8"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(big));
}

TEST_F(Cli, RerunLeavesNoEarlierOutputsBesideTheNewReport) {
  // A map with --ply and a slice, then one without either into the same folder: the old target.ply and slice would
  // stand beside a report that does not describe them. The user's own files stay.
  const fs::path out = dir_ / "rerun";
  const std::string map = "map sphere torus -o " + out.string() + " --voxels 12 --time-steps 3";
  ASSERT_EQ(run_command(map + " --ply --slices 0.25").status, 0);
  ASSERT_TRUE(fs::exists(out / "target.ply") && fs::exists(out / "slice_0.25.obj"));
  std::ofstream(out / "notes.txt") << "mine";
  ASSERT_EQ(run_command(map + " --slices 0.5").status, 0);
  EXPECT_FALSE(fs::exists(out / "target.ply"));
  EXPECT_FALSE(fs::exists(out / "slice_0.25.obj"));
  EXPECT_TRUE(fs::exists(out / "slice_0.5.obj"));
  EXPECT_TRUE(fs::exists(out / "notes.txt"));
  EXPECT_TRUE(fs::exists(out / "report.json"));
}

TEST_F(Cli, NumericOptionsNameTheirRangeAndTheValue) {
  // CLI11's validators called a word "not in range" and printed the largest double in full as the bound.
  expect_rejected("sphere torus --trace-step -1", "--trace-step: must be a positive number, not '-1'");
  expect_rejected("sphere torus --tolerance 1e-9x", "--tolerance: must be a positive number, not '1e-9x'");
  expect_rejected("sphere torus --compression-seed -1",
                  "--compression-seed: must be zero or a positive number, not '-1'");
  expect_rejected("sphere torus --zero-snap 0.5", "--zero-snap: must be a number from 0 to 0.45, not '0.5'");
  expect_rejected("sphere torus --threads 1.5", "--threads: must be a whole number of at least 0, not '1.5'");
  expect_rejected("sphere torus --trace-smoothing 101",
                  "--trace-smoothing: must be a whole number from 0 to 100, not '101'");
  // An explicit voxel size is held to --voxels' 4 to 4096 voxels across the shapes: 1e-5 crashed (the lattice's point
  // count overflowed), 100 extracted nothing.
  expect_rejected("sphere torus --voxel-size 1e-5", "voxel size 1e-05 puts 200000 voxels across");
  expect_rejected("sphere torus --voxel-size 100", "voxel size 100 puts 0.02 voxels across");
  const CommandRun r = run_command("map sphere torus -o " + (dir_ / "v").string() + " --voxels abc");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("--voxels: must be a whole number from 4 to 4096, not 'abc'"), std::string::npos) << r.output;
  // In range, they run.
  EXPECT_EQ(run_command("map sphere torus -o " + (dir_ / "ok").string() +
                        " --voxels 12 --time-steps 3 --zero-snap 0.45 --trace-step 0.5 --threads 1")
                .status,
            0);
}

TEST_F(Cli, StretchReadsAMapAndRejectsBadLabels) {
  const fs::path out = dir_ / "map";
  ASSERT_EQ(run_command("map sphere torus -o " + out.string() + " --voxels 16 --time-steps 4").status, 0);
  const CommandRun ok = run_command("stretch " + (out / "target.obj").string() + " --labels " +
                                    (out / "labels.txt").string() + " --source sphere");
  ASSERT_EQ(ok.status, 0) << ok.output;
  EXPECT_EQ(ok.output.find("note:"), std::string::npos) << ok.output;
  const nlohmann::json j = nlohmann::json::parse(ok.output.substr(ok.output.find('{')));
  EXPECT_GT(j["triangles"].get<std::int64_t>(), 0);
  EXPECT_GT(j["mean_l2"].get<double>(), 0.0);
  // The same figures as the map's report (the sphere placed from report.json's inputs.source_shape; fitted to
  // target.obj's box it came out 0.5% larger than the one `map` fitted to the built-in torus, and every figure moved).
  const nlohmann::json report = nlohmann::json::parse(std::ifstream(out / "report.json"));
  const auto expect_report_figures = [&](const nlohmann::json& figures) {
    for (const auto& [key, value] : report["stretch"].items()) {
      if (key == "seconds") continue;
      ASSERT_TRUE(figures.contains(key)) << key;
      EXPECT_NEAR(figures[key].get<double>(), value.get<double>(), 1e-6 * std::abs(value.get<double>()) + 1e-12) << key;
    }
  };
  expect_report_figures(j);
  // Without the report beside the target the sphere is fitted to target.obj's box, and a note says so; the placed
  // spec from the report gives the map's figures again.
  const fs::path copy = dir_ / "copy";
  fs::create_directories(copy);
  for (const char* name : {"target.obj", "labels.txt"}) fs::copy_file(out / name, copy / name);
  const std::string copied =
      "stretch " + (copy / "target.obj").string() + " --labels " + (copy / "labels.txt").string();
  const CommandRun fitted = run_command(copied + " --source sphere");
  ASSERT_EQ(fitted.status, 0) << fitted.output;
  EXPECT_NE(fitted.output.find("note: sphere fitted to"), std::string::npos) << fitted.output;
  const CommandRun placed =
      run_command(copied + " --source '" + report["inputs"]["source_shape"].get<std::string>() + "'");
  ASSERT_EQ(placed.status, 0) << placed.output;
  expect_report_figures(nlohmann::json::parse(placed.output));
  // A labels file with one line too few names the file and the count.
  const std::string short_labels = write("short.txt", "0 0 0\n1 1 1\n");
  const CommandRun bad =
      run_command("stretch " + (out / "target.obj").string() + " --labels " + short_labels + " --source sphere");
  EXPECT_EQ(bad.status, 2) << bad.output;
  EXPECT_NE(bad.output.find("short.txt"), std::string::npos) << bad.output;
}

TEST_F(Cli, ChangeThresholdStopsGaussSeidel) {
  // The paper's stopping rule: a larger threshold stops the diffusion after fewer sweeps, each run below its own.
  std::map<double, nlohmann::json> solver;
  for (double threshold : {1e-3, 1e-5}) {
    const fs::path out = dir_ / ("gs" + std::to_string(threshold));
    std::ostringstream args;
    args << "map sphere torus -o " << out.string() << " --voxels 12 --time-steps 4 --solver gauss-seidel"
         << " --change-threshold " << threshold;
    const CommandRun r = run_command(args.str());
    ASSERT_EQ(r.status, 0) << r.output;
    solver[threshold] = nlohmann::json::parse(std::ifstream(out / "report.json"))["solver"];
    EXPECT_EQ(solver[threshold]["name"], "gauss-seidel");
    EXPECT_LT(solver[threshold]["change"].get<double>(), threshold);
  }
  EXPECT_LT(solver[1e-3]["iterations"].get<int>(), solver[1e-5]["iterations"].get<int>());
  expect_rejected("sphere torus --change-threshold -1", "change-threshold");
}

TEST_F(Cli, TextureOptionGivesTheSourceAnImage) {
  // A 2 x 1 PNG (red, blue): the output's texture must be exactly this image, not the built-in sphere's.
  const fs::path png = dir_ / "tex.png";
  {
    const unsigned char pixels[] = {255, 0, 0, 0, 0, 255};
    morphmap::RgbImage image;
    image.width = 2;
    image.height = 1;
    image.pixels.assign(pixels, pixels + 6);
    morphmap::write_png(png.string(), image);
  }
  const fs::path out = dir_ / "textured";
  const CommandRun r =
      run_command("map sphere torus --texture " + png.string() + " -o " + out.string() + " --voxels 12 --time-steps 4");
  ASSERT_EQ(r.status, 0) << r.output;
  const morphmap::RgbImage back = morphmap::read_image((out / "texture.png").string());
  EXPECT_EQ(back.width, 2);
  EXPECT_EQ(back.height, 1);
  EXPECT_EQ(back.pixels, (std::vector<unsigned char>{255, 0, 0, 0, 0, 255}));
  std::ifstream mtl(out / "target.mtl");
  const std::string text((std::istreambuf_iterator<char>(mtl)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("map_Kd texture.png"), std::string::npos) << text;
  expect_rejected("sphere torus --texture " + (dir_ / "missing.png").string(), "missing.png");
  expect_rejected("sphere torus --texture " + write("bad.png", "not an image"), "bad.png");
  expect_rejected(write("tet.off", kTetraOff) + " sphere --texture " + png.string(), "texture coordinates");
}

TEST_F(Cli, HelpOnEveryCommand) {
  for (const char* cmd : {"--help", "map --help", "demo --help"}) {
    const CommandRun r = run_command(cmd);
    EXPECT_EQ(r.status, 0) << cmd;
    EXPECT_NE(r.output.find("--"), std::string::npos) << cmd;
  }
}

TEST_F(Cli, DemoWritesEveryOutput) {
  const fs::path out = dir_ / "demo";
  const CommandRun r = run_command("demo -o " + out.string() + " --voxels 20 --time-steps 5 --threads 2");
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* name : {"target.obj", "target.mtl", "texture.png", "labels.txt", "report.json", "slice_0.25.obj",
                           "slice_0.5.obj", "slice_0.75.obj"})
    EXPECT_TRUE(fs::exists(out / name)) << name;
  const nlohmann::json report = nlohmann::json::parse(std::ifstream(out / "report.json"));
  for (const char* key : {"vertices", "tets", "target_vertices", "target_triangles"})
    EXPECT_GT(report["counts"][key].get<std::int64_t>(), 0) << key;
  EXPECT_EQ(report["solver"]["name"], "cg-amg");
  EXPECT_TRUE(report["trace"].contains("stalled"));
  EXPECT_TRUE(report["trace"].contains("descended"));
  EXPECT_GT(report["peak_memory_bytes"].get<std::int64_t>(), 0);
  // The kernel's CPU time is a part of the whole.
  EXPECT_GE(report["system_cpu_seconds"].get<double>(), 0.0);
  EXPECT_LE(report["system_cpu_seconds"].get<double>(), report["cpu_seconds"].get<double>());
  // --max-memory refuses by the estimate, so it must not fall short of what the run then takes.
  EXPECT_GE(report["memory_estimate_bytes"].get<std::int64_t>(), report["peak_memory_bytes"].get<std::int64_t>());
  // labels.txt has one line per vertex of target.obj.
  std::ifstream obj(out / "target.obj"), labels(out / "labels.txt");
  std::string line;
  std::int64_t vertices = 0, label_lines = 0;
  while (std::getline(obj, line)) vertices += line.rfind("v ", 0) == 0;
  while (std::getline(labels, line)) ++label_lines;
  EXPECT_EQ(vertices, report["counts"]["target_vertices"].get<std::int64_t>());
  EXPECT_EQ(label_lines, vertices);
  for (const auto& entry : fs::directory_iterator(out))
    EXPECT_EQ(entry.path().filename().string().rfind(".staging", 0), std::string::npos) << "staging left behind";
}

}  // namespace
