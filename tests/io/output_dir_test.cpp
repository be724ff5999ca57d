// Tests of crash-safe output (DESIGN.md, stage "outputs"): nothing half-written is ever visible.
#include "io/output_dir.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "mesh/errors.h"

namespace fs = std::filesystem;

namespace morphmap {
namespace {

class OutputDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    static int counter = 0;
    root_ =
        fs::temp_directory_path() / ("morphmap-out-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
    fs::create_directories(root_);
  }
  void TearDown() override { fs::remove_all(root_); }

  static std::vector<std::string> entries(const fs::path& dir) {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }
  static std::string read(const fs::path& path) {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }

  fs::path root_;
};

TEST_F(OutputDirTest, NothingVisibleWithoutCommit) {
  const fs::path dir = root_ / "a" / "b";
  {
    OutputDir out(dir.string());
    EXPECT_TRUE(fs::is_directory(dir));
    const std::string staged = out.staged("mesh.obj");
    EXPECT_NE(fs::path(staged).parent_path(), dir);
    EXPECT_EQ(fs::path(staged).parent_path().parent_path(), dir);
    EXPECT_EQ(fs::path(staged).parent_path().filename().string().rfind(".staging-", 0), 0u);
    std::ofstream(staged) << "v 0 0 0\n";
    EXPECT_FALSE(fs::exists(dir / "mesh.obj"));
  }
  EXPECT_TRUE(entries(dir).empty());
}

TEST_F(OutputDirTest, CommitMovesEverythingAndRemovesStaging) {
  fs::create_directories(root_ / "out");
  std::ofstream(root_ / "out" / "report.json") << "old";
  {
    OutputDir out((root_ / "out").string());
    std::ofstream(out.staged("mesh.obj")) << "mesh";
    std::ofstream(out.staged("report.json")) << "new";
    std::ofstream(out.staged("texture.png")) << "png";
    out.staged("never_written.txt");
    out.commit({"report.json"});
    EXPECT_THROW(out.staged("late.txt"), IoError);
  }
  EXPECT_EQ(entries(root_ / "out"), (std::vector<std::string>{"mesh.obj", "report.json", "texture.png"}));
  EXPECT_EQ(read(root_ / "out" / "report.json"), "new");
  EXPECT_EQ(read(root_ / "out" / "mesh.obj"), "mesh");
}

TEST_F(OutputDirTest, CommitRemovesAnEarlierRunsOutputsThatThisRunDoesNotWrite) {
  // An earlier run wrote a slice and a PLY; this one writes neither. Files the predicate does not name stay.
  const fs::path dir = root_ / "rerun";
  fs::create_directories(dir);
  for (const char* name : {"report.json", "target.obj", "target.ply", "slice_0.25.obj", "notes.txt"})
    std::ofstream(dir / name) << "old";
  {
    OutputDir out(dir.string());
    std::ofstream(out.staged("target.obj")) << "new";
    std::ofstream(out.staged("slice_0.5.obj")) << "new";
    std::ofstream(out.staged("report.json")) << "new";
    out.commit({"report.json"}, [](const std::string& name) { return name != "notes.txt"; });
  }
  EXPECT_EQ(entries(dir), (std::vector<std::string>{"notes.txt", "report.json", "slice_0.5.obj", "target.obj"}));
  EXPECT_EQ(read(dir / "report.json"), "new");
  EXPECT_EQ(read(dir / "target.obj"), "new");
  EXPECT_EQ(read(dir / "notes.txt"), "old");
}

TEST_F(OutputDirTest, TwoAtOnceUseDifferentStagingFolders) {
  OutputDir a(root_.string()), b(root_.string());
  EXPECT_NE(fs::path(a.staged("x")).parent_path(), fs::path(b.staged("x")).parent_path());
  EXPECT_EQ(a.dir(), root_.string());
}

TEST_F(OutputDirTest, RejectsBadNamesAndUncreatableDirs) {
  OutputDir out(root_.string());
  EXPECT_THROW(out.staged("sub/file.txt"), InvalidInput);
  EXPECT_THROW(out.staged(".."), InvalidInput);
  EXPECT_THROW(out.staged(""), InvalidInput);
  std::ofstream(root_ / "file") << "x";
  EXPECT_THROW(OutputDir((root_ / "file").string()), IoError);
  EXPECT_THROW(OutputDir((root_ / "file" / "sub").string()), IoError);
}

TEST_F(OutputDirTest, WriteTextAtomicallyReplacesAndLeavesNoTemporaries) {
  const fs::path path = root_ / "report.json";
  write_text_atomically(path.string(), "{\"a\": 1}\n");
  EXPECT_EQ(read(path), "{\"a\": 1}\n");
  write_text_atomically(path.string(), "{}\n");
  EXPECT_EQ(read(path), "{}\n");
  EXPECT_EQ(entries(root_), std::vector<std::string>{"report.json"});
  EXPECT_THROW(write_text_atomically((root_ / "missing" / "x.json").string(), "{}"), IoError);
}

TEST(OutputDirMemory, PeakMemoryIsPositive) { EXPECT_GT(peak_memory_bytes(), 1024LL * 1024); }

}  // namespace
}  // namespace morphmap
