// `morphmap batch`: manifest checking, Table II rows, failing jobs, resuming, and a batch killed mid-run.
#include "app/batch.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <thread>

#include "mesh/errors.h"
#include "tests/command_line.h"

namespace fs = std::filesystem;

namespace morphmap {
namespace {

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// summary.csv as rows of fields (RFC 4180 quotes), header first.
std::vector<std::vector<std::string>> read_csv(const fs::path& p) {
  std::vector<std::vector<std::string>> rows;
  const std::string text = read_text(p);
  std::vector<std::string> row;
  std::string field;
  bool quoted = false;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (quoted) {
      if (c == '"' && i + 1 < text.size() && text[i + 1] == '"')
        field += text[++i];
      else if (c == '"')
        quoted = false;
      else
        field += c;
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      row.push_back(field);
      field.clear();
    } else if (c == '\n') {
      row.push_back(field);
      field.clear();
      rows.push_back(row);
      row.clear();
    } else {
      field += c;
    }
  }
  return rows;
}

// The column named `name` of data row `r` (1-based: row 0 is the header).
std::string cell(const std::vector<std::vector<std::string>>& csv, std::size_t r, const std::string& name) {
  const auto& header = csv.at(0);
  const auto it = std::find(header.begin(), header.end(), name);
  if (it == header.end()) return "<no column " + name + ">";
  return csv.at(r).at(std::size_t(it - header.begin()));
}

using test::CommandRun;
using test::run_command;

// Starts `morphmap batch manifest -o out` in the background, output discarded.
pid_t start_batch(const fs::path& manifest, const fs::path& out) {
  const pid_t pid = fork();
  if (pid == 0) {
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, 1);
    ::dup2(null, 2);
    ::execl(MORPHMAP_BINARY, MORPHMAP_BINARY, "batch", manifest.c_str(), "-o", out.c_str(), (char*)nullptr);
    ::_exit(127);
  }
  return pid;
}

// True when a live process has `needle` in its command line (a job's folder: its `map` child still runs).
bool process_running_with(const std::string& needle) {
  for (const auto& entry : fs::directory_iterator("/proc")) {
    const std::string name = entry.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::string cmdline = read_text(entry.path() / "cmdline");
    std::replace(cmdline.begin(), cmdline.end(), '\0', ' ');
    if (cmdline.find(needle) != std::string::npos && cmdline.find(" map ") != std::string::npos) {
      const std::string stat = read_text(entry.path() / "stat");  // a zombie has exited already
      const std::size_t paren = stat.rfind(')');
      if (paren != std::string::npos && paren + 2 < stat.size() && stat[paren + 2] == 'Z') continue;
      return true;
    }
  }
  return false;
}

const char* kTiny = R"("source": "sphere", "target": "torus", "voxels": 8, "time-steps": 2)";

class Batch : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = test::fresh_test_dir("morphmap_batch_"); }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p;
  }
  // parse_manifest must throw InvalidInput whose message names the manifest and every needle.
  void expect_manifest_error(const std::string& text, const std::vector<std::string>& needles) {
    const std::string path = (dir_ / "m.json").string();
    try {
      parse_manifest(text, path);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const InvalidInput& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find(path), std::string::npos) << message;
      for (const std::string& needle : needles) EXPECT_NE(message.find(needle), std::string::npos) << message;
    }
  }
  fs::path dir_;
};

TEST_F(Batch, ManifestErrorsNameManifestAndJob) {
  expect_manifest_error("{\"jobs\": [", {"not valid JSON"});
  expect_manifest_error("{\"jobs\": []}", {"non-empty"});
  expect_manifest_error("{\"jobs\": [{}], \"extra\": 1}", {"extra"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + "}, {\"target\": \"torus\"}]}", {"job 2", "source"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"name\": \"a\", \"voxel\": 9}]}",
                        {"job 1 (a)", "unknown key 'voxel'"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"time_steps\": 4}]}",
                        {"unknown key 'time_steps'", "did you mean 'time-steps'?"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"output\": \"x\"}]}", {"output"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"solver\": \"magic\"}]}", {"job 1", "magic"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"voxels\": \"lots\"}]}", {"job 1", "lots"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"max-memory\": \"5Q\"}]}", {"job 1", "5Q"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"ply\": \"yes\"}]}", {"ply", "flag"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"name\": \"../up\"}]}", {"name"});
  // A job folder named like the batch's summaries made the summary's rename fail after the job had run.
  for (const char* own : {"summary.csv", "summary.md"})
    expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"name\": \"" + own + "\"}]}", {own, "summary"});
  expect_manifest_error(std::string("{\"jobs\": [{") + kTiny + ", \"name\": \"a\"}, {" + kTiny + ", \"name\": \"a\"}]}",
                        {"job 2", "twice"});
}

TEST_F(Batch, ManifestBuildsMapArguments) {
  const std::string path = (dir_ / "m.json").string();
  const std::vector<BatchJob> jobs = parse_manifest(
      R"({"defaults": {"time-steps": 3, "voxels": 12},
          "jobs": [{"name": "a", "source": "sphere", "target": "meshes/b.off", "voxels": 9, "ply": true,
                    "compare-solvers": ["gauss-seidel", "cholmod"], "tolerance": 1e-08},
                   {"source": "/abs/x.obj", "target": "torus:r_ratio=0.3"}]})",
      path);
  ASSERT_EQ(jobs.size(), 2u);
  EXPECT_EQ(jobs[0].name, "a");
  EXPECT_EQ(jobs[1].name, "job-2");
  const std::vector<std::string> a = {"sphere",
                                      (dir_ / "meshes/b.off").string(),
                                      "--compare-solvers",
                                      "gauss-seidel,cholmod",
                                      "--ply",
                                      "--time-steps",
                                      "3",
                                      "--tolerance",
                                      "1e-08",
                                      "--voxels",
                                      "9"};
  EXPECT_EQ(jobs[0].args, a);
  const std::vector<std::string> b = {"/abs/x.obj", "torus:r_ratio=0.3", "--time-steps", "3", "--voxels", "12"};
  EXPECT_EQ(jobs[1].args, b);
}

TEST_F(Batch, SummaryRowTakesDiffusionAndSolveFromEitherSide) {
  nlohmann::json report = {
      {"counts", {{"tets", 1234}}},
      {"options", {{"time_steps", 10}}},
      {"solver",
       {{"name", "cg"}, {"iterations", 57}, {"residual", 3e-11}, {"setup_seconds", 0.5}, {"solve_seconds", 1.5}}},
      {"compare",
       {{"solves",
         {{{"name", "gauss-seidel"},
           {"iterations", 400},
           {"change", 9e-6},
           {"setup_seconds", 0.0},
           {"solve_seconds", 7.0}}}}}},
      {"transport", {{"wavefronts", 88}}},
      {"seconds", {{"transport", 0.25}, {"compare", 7.5}, {"total", 12.0}}},
      {"peak_memory_bytes", 1 << 30},
      {"cpu_seconds", 20.5},
      {"system_cpu_seconds", 0.75}};
  SummaryRow row = summary_row("t", report.dump());
  EXPECT_DOUBLE_EQ(*row.cpu_seconds, 20.5);
  EXPECT_DOUBLE_EQ(*row.system_cpu_seconds, 0.75);
  EXPECT_EQ(row.status, "ok");
  EXPECT_EQ(*row.tets, 1234);
  EXPECT_EQ(*row.time_steps, 10);
  EXPECT_EQ(*row.diffusion_iterations, 400);
  EXPECT_DOUBLE_EQ(*row.diffusion_seconds, 7.0);
  EXPECT_DOUBLE_EQ(*row.diffusion_change, 9e-6);
  EXPECT_EQ(row.solve_backend, "cg");
  EXPECT_EQ(*row.solve_iterations, 57);
  EXPECT_DOUBLE_EQ(*row.solve_seconds, 2.0);
  EXPECT_EQ(*row.label_passes, 88);
  EXPECT_DOUBLE_EQ(*row.total_seconds, 12.0);
  EXPECT_DOUBLE_EQ(*row.map_seconds, 4.5);
  // The map solved by Gauss-Seidel and compared with CHOLMOD: the columns swap sources.
  report["solver"]["name"] = "gauss-seidel";
  report["compare"]["solves"][0]["name"] = "cholmod";
  row = summary_row("t", report.dump());
  EXPECT_EQ(*row.diffusion_iterations, 57);
  EXPECT_EQ(row.solve_backend, "cholmod");
  EXPECT_EQ(*row.solve_iterations, 400);
  // No comparison: no diffusion column.
  report.erase("compare");
  report["solver"]["name"] = "cholmod";
  row = summary_row("t", report.dump());
  EXPECT_FALSE(row.diffusion_iterations.has_value());
  EXPECT_DOUBLE_EQ(*row.label_seconds, 0.25);
  // A traced map runs no upwind sweep: label propagation is the tracing, which has no passes.
  report.erase("transport");
  report["seconds"].erase("transport");
  report["trace"] = {{"seconds", 0.75}};
  row = summary_row("t", report.dump());
  EXPECT_FALSE(row.label_passes.has_value());
  EXPECT_DOUBLE_EQ(*row.label_seconds, 0.75);
  EXPECT_EQ(row.warnings, "");
  // Topology warnings are joined into one cell.
  report["topology"] = {{"warnings", {"the target, as extracted, has two parts", "and a handle"}}};
  row = summary_row("t", report.dump());
  EXPECT_EQ(row.warnings, "the target, as extracted, has two parts; and a handle");
  // The inputs' warnings (a texture that is not there) come first.
  report["inputs"] = {{"warnings", {"a.obj: no texture"}}};
  row = summary_row("t", report.dump());
  EXPECT_EQ(row.warnings, "a.obj: no texture; the target, as extracted, has two parts; and a handle");
  // Errors with commas and quotes survive the CSV.
  SummaryRow failed;
  failed.job = "f";
  failed.status = "failed";
  failed.error = "x.off: line 3, \"bad\"";
  write("s.csv", summary_csv({row, failed}));
  const auto csv = read_csv(dir_ / "s.csv");
  ASSERT_EQ(csv.size(), 3u);
  EXPECT_EQ(cell(csv, 2, "error"), failed.error);
  EXPECT_EQ(cell(csv, 1, "tets"), "1234");
  EXPECT_EQ(cell(csv, 1, "warnings"), row.warnings);
  EXPECT_EQ(cell(csv, 2, "warnings"), "");
  EXPECT_NE(summary_markdown({row, failed}).find("| f | failed |"), std::string::npos);
  // Every Markdown line has the heading's cells, and the warning sits under "warnings" (the heading once lacked it,
  // so each warning stood under "error").
  std::istringstream md(summary_markdown({row, failed}));
  std::vector<std::vector<std::string>> table;
  for (std::string line; std::getline(md, line);) {
    std::vector<std::string> cells;
    std::string cell;
    for (std::size_t i = 1; i < line.size(); ++i) {  // no cell of these rows holds an escaped '|'
      if (line[i] == '|') {
        cells.push_back(cell.size() >= 2 ? cell.substr(1, cell.size() - 2) : cell);
        cell.clear();
      } else {
        cell += line[i];
      }
    }
    table.push_back(cells);
  }
  ASSERT_EQ(table.size(), 4u);
  for (const auto& line : table) EXPECT_EQ(line.size(), table[0].size());
  const auto warnings = std::find(table[0].begin(), table[0].end(), "warnings");
  ASSERT_NE(warnings, table[0].end());
  EXPECT_EQ(table[2][std::size_t(warnings - table[0].begin())], row.warnings);
  EXPECT_EQ(table[0].back(), "error");
  EXPECT_EQ(table[3].back(), failed.error);
  // The peak memory in GiB under its own heading, the kernel's CPU seconds under theirs.
  const auto column = [&](const char* heading) {
    const auto it = std::find(table[0].begin(), table[0].end(), heading);
    EXPECT_NE(it, table[0].end()) << heading;
    return std::size_t(it - table[0].begin());
  };
  EXPECT_EQ(table[2][column("peak memory")], "1 GiB");
  EXPECT_EQ(table[2][column("sys s")], "0.75");
  EXPECT_EQ(cell(csv, 1, "system_cpu_seconds"), "0.75");
}

TEST_F(Batch, PlannedStagesAreTheStagesMapReports) {
  // The status line names the stage after the last one `map --progress` reported; the plan it reads that from must be
  // what map really reports, for every option that adds or drops a stage.
  const std::vector<std::string> variants = {
      "", ", \"fold-repair\": \"off\"", ", \"method\": \"upwind\", \"critical-points\": true",
      ", \"method\": \"closest-point\"", ", \"compare-solvers\": [\"gauss-seidel\"], \"fold-repair\": \"off\""};
  for (std::size_t v = 0; v < variants.size(); ++v) {
    const std::vector<BatchJob> jobs =
        parse_manifest(std::string("{\"jobs\": [{") + kTiny + variants[v] + "}]}", (dir_ / "m.json").string());
    ASSERT_EQ(jobs.size(), 1u);
    std::string args;
    for (const std::string& a : jobs[0].args) args += " '" + a + "'";
    const fs::path out = dir_ / ("run" + std::to_string(v));
    const CommandRun r = run_command("map" + args + " --progress -o " + out.string());
    ASSERT_EQ(r.status, 0) << r.output;
    std::vector<std::string> reported;
    std::istringstream lines(r.output);
    const std::string tag = "[morphmap] ";
    for (std::string line; std::getline(lines, line);) {
      if (line.rfind(tag, 0) != 0 || line.find(" s  (elapsed ") == std::string::npos) continue;  // not "wrote ..."
      std::string name = line.substr(tag.size(), line.find("  ", tag.size()) - tag.size());
      // The name is padded to 10 characters before the seconds: cut at the first digit after it.
      name = name.substr(0, name.find_last_not_of(" 0123456789.") + 1);
      reported.push_back(name);
    }
    EXPECT_EQ(reported, planned_stages(jobs[0].args)) << "variant " << v << ":" << args << "\n" << r.output;
  }
}

TEST_F(Batch, BadManifestRunsNothing) {
  const fs::path m = write("m.json", std::string("{\"jobs\": [{") + kTiny + "}, {\"source\": \"sphere\"}]}");
  const CommandRun r = run_command("batch " + m.string() + " -o " + (dir_ / "out").string());
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_NE(r.output.find("m.json"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("job 2"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "out" / "job-1")) << "a job ran before the manifest was checked";
}

TEST_F(Batch, FailingJobsAreRecordedAndTheBatchGoesOn) {
  const fs::path m = write("m.json", std::string("{\"jobs\": [") +
                                         "{\"name\": \"missing\", \"source\": \"nope.off\", "
                                         "\"target\": \"torus\"}, {\"name\": \"guard\", " +
                                         kTiny + ", \"max-memory\": \"1M\"}, {\"name\": \"ok\", " + kTiny +
                                         ", \"compare-solvers\": [\"gauss-seidel\"]}]}");
  const fs::path out = dir_ / "out";
  const CommandRun r = run_command("batch " + m.string() + " -o " + out.string());
  EXPECT_EQ(r.status, 1) << r.output;
  const auto csv = read_csv(out / "summary.csv");
  ASSERT_EQ(csv.size(), 4u) << read_text(out / "summary.csv");
  EXPECT_EQ(cell(csv, 1, "status"), "failed");
  EXPECT_NE(cell(csv, 1, "error").find("nope.off"), std::string::npos) << cell(csv, 1, "error");
  EXPECT_EQ(cell(csv, 2, "status"), "failed");
  EXPECT_NE(cell(csv, 2, "error").find("--max-memory"), std::string::npos) << cell(csv, 2, "error");
  EXPECT_EQ(cell(csv, 3, "status"), "ok");
  EXPECT_GT(std::stoll(cell(csv, 3, "tets")), 0);
  EXPECT_EQ(cell(csv, 3, "time_steps"), "2");
  EXPECT_EQ(cell(csv, 3, "solve_backend"), "cg-amg");
  EXPECT_GT(std::stoi(cell(csv, 3, "diffusion_iterations")), 0);
  // Below the threshold 1e-5, up to the rounding of the CSV text.
  EXPECT_LE(std::stod(cell(csv, 3, "diffusion_conv")), 1.001e-5);
  EXPECT_GT(std::stoll(cell(csv, 3, "peak_memory_bytes")), 0);
  EXPECT_FALSE(fs::exists(out / "missing" / "report.json"));
  EXPECT_TRUE(fs::exists(out / "ok" / "report.json"));
  EXPECT_NE(read_text(out / "summary.md").find("| guard | failed |"), std::string::npos);
  // All good now: the failed jobs run again, the complete one does not.
  const auto ok_time = fs::last_write_time(out / "ok" / "report.json");
  const fs::path fixed = write("m.json", std::string("{\"jobs\": [{\"name\": \"ok\", ") + kTiny +
                                             ", \"compare-solvers\": [\"gauss-seidel\"]}]}");
  EXPECT_EQ(run_command("batch " + fixed.string() + " -o " + out.string()).status, 0);
  EXPECT_EQ(fs::last_write_time(out / "ok" / "report.json"), ok_time);
}

TEST_F(Batch, RerunSkipsCompleteJobsAndRedoesChangedOnes) {
  const fs::path out = dir_ / "out";
  const fs::path m =
      write("m.json", std::string("{\"jobs\": [{\"name\": \"a\", ") + kTiny + "}, {\"name\": \"b\", " + kTiny + "}]}");
  ASSERT_EQ(run_command("batch " + m.string() + " -o " + out.string()).status, 0);
  const std::string first = read_text(out / "summary.csv");
  const auto a_time = fs::last_write_time(out / "a" / "report.json");
  const auto b_time = fs::last_write_time(out / "b" / "report.json");
  std::this_thread::sleep_for(std::chrono::milliseconds(20));  // so that a rewritten report gets a later time
  ASSERT_EQ(run_command("batch " + m.string() + " -o " + out.string()).status, 0);
  EXPECT_EQ(fs::last_write_time(out / "a" / "report.json"), a_time);
  EXPECT_EQ(fs::last_write_time(out / "b" / "report.json"), b_time);
  EXPECT_EQ(read_text(out / "summary.csv"), first);  // rows come from the same reports
  // Changing b's options makes its old report stale.
  const fs::path changed = write("m.json", std::string("{\"jobs\": [{\"name\": \"a\", ") + kTiny +
                                               "}, {\"name\": \"b\", " + kTiny + ", \"time-steps\": 3}]}");
  ASSERT_EQ(run_command("batch " + changed.string() + " -o " + out.string()).status, 0);
  EXPECT_EQ(fs::last_write_time(out / "a" / "report.json"), a_time);
  EXPECT_NE(fs::last_write_time(out / "b" / "report.json"), b_time);
  EXPECT_EQ(read_csv(out / "summary.csv").at(2).at(3), "3");
}

// A batch SIGKILLed at the wrong moment leaves hidden temporaries that no job rerun owns: a summary it was writing
// (write_text_atomically's temporary in the batch folder) or, in a job that completed, the empty staging folder
// `map` removes just after renaming report.json into place. A rerun removes them, skipped job or not, and leaves
// the user's own files alone.
TEST_F(Batch, RerunRemovesLeftoversOfAKilledBatchAndKeepsOtherFiles) {
  const fs::path out = dir_ / "out";
  const fs::path m = write("m.json", std::string("{\"jobs\": [{\"name\": \"a\", ") + kTiny + "}]}");
  ASSERT_EQ(run_command("batch " + m.string() + " -o " + out.string()).status, 0);
  const auto a_time = fs::last_write_time(out / "a" / "report.json");
  const std::vector<fs::path> leftovers = {out / ".summary.csv.tmp-4242-1", out / ".summary.md.tmp-4242-2",
                                           out / "a" / ".staging-4242-3", out / "a" / ".labels.txt.tmp-4242-4"};
  for (const fs::path& p : leftovers) {
    if (p.filename().string().rfind(".staging-", 0) == 0)
      fs::create_directory(p);
    else
      std::ofstream(p) << "partial";
  }
  const std::vector<fs::path> kept = {out / ".notes.tmp-mine", out / "notes.txt"};
  for (const fs::path& p : kept) std::ofstream(p) << "mine";
  const CommandRun rerun = run_command("batch " + m.string() + " -o " + out.string());
  ASSERT_EQ(rerun.status, 0) << rerun.output;
  EXPECT_EQ(fs::last_write_time(out / "a" / "report.json"), a_time) << "the complete job ran again";
  for (const fs::path& p : leftovers) EXPECT_FALSE(fs::exists(p)) << p;
  for (const fs::path& p : kept) EXPECT_TRUE(fs::exists(p)) << p;
}

// Kills a batch while its second job runs, then reruns it: the rerun skips the first job, finishes the others, and
// its summary matches an uninterrupted batch's.
class BatchKilled : public Batch, public ::testing::WithParamInterface<int> {};

TEST_P(BatchKilled, RerunFinishesTheRemainingJobs) {
  // Job "slow" takes long enough (half a second or more) for the kill to land inside it.
  const std::string manifest = std::string("{\"jobs\": [{\"name\": \"first\", ") + kTiny +
                               "}, {\"name\": \"slow\", \"source\": \"sphere\", \"target\": \"torus\", \"voxels\": 14, "
                               "\"time-steps\": 4}, {\"name\": \"last\", " +
                               kTiny + "}]}";
  const fs::path m = write("m.json", manifest);
  const fs::path reference = dir_ / "reference", out = dir_ / "out";
  ASSERT_EQ(run_command("batch " + m.string() + " -o " + reference.string()).status, 0);

  const pid_t batch = start_batch(m, out);
  ASSERT_GT(batch, 0);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (!fs::exists(out / "first" / "report.json") && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  ASSERT_TRUE(fs::exists(out / "first" / "report.json"));
  ::kill(batch, GetParam());
  int raw = 0;
  ::waitpid(batch, &raw, 0);
  if (GetParam() == SIGKILL) {
    EXPECT_TRUE(WIFSIGNALED(raw));
  } else {
    ASSERT_TRUE(WIFEXITED(raw));
    EXPECT_EQ(WEXITSTATUS(raw), 130);
  }
  ASSERT_FALSE(fs::exists(out / "slow" / "report.json")) << "the kill did not land during job 'slow'";
  // The job's `map` died with the batch (no orphan finishing into the folder later).
  const auto orphan_deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (process_running_with((out / "slow").string()) && std::chrono::steady_clock::now() < orphan_deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_FALSE(process_running_with((out / "slow").string()));
  EXPECT_FALSE(fs::exists(out / "last" / "report.json"));
  // Whatever summary exists is whole: header and one row per job.
  if (fs::exists(out / "summary.csv")) {
    const auto partial = read_csv(out / "summary.csv");
    ASSERT_EQ(partial.size(), 4u);
    EXPECT_EQ(cell(partial, 1, "status"), "ok");
    EXPECT_NE(cell(partial, 2, "status"), "ok");
  }

  const auto first_time = fs::last_write_time(out / "first" / "report.json");
  const CommandRun rerun = run_command("batch " + m.string() + " -o " + out.string());
  ASSERT_EQ(rerun.status, 0) << rerun.output;
  EXPECT_EQ(fs::last_write_time(out / "first" / "report.json"), first_time) << "the complete job ran again";
  const auto ours = read_csv(out / "summary.csv"), theirs = read_csv(reference / "summary.csv");
  ASSERT_EQ(ours.size(), 4u);
  ASSERT_EQ(theirs.size(), ours.size());
  for (std::size_t r = 1; r < ours.size(); ++r)
    for (const char* column :
         {"job", "status", "tets", "time_steps", "solve_backend", "solve_iterations", "label_passes"})
      EXPECT_EQ(cell(ours, r, column), cell(theirs, r, column)) << "row " << r << " column " << column;
  for (const auto& entry : fs::recursive_directory_iterator(out)) {
    const std::string name = entry.path().filename().string();
    EXPECT_TRUE(name.rfind(".staging-", 0) != 0 && name.find(".tmp-") == std::string::npos)
        << "leftover " << entry.path();
  }
}

INSTANTIATE_TEST_SUITE_P(Signals, BatchKilled, ::testing::Values(SIGKILL, SIGINT),
                         [](const ::testing::TestParamInfo<int>& info) {
                           return std::string(info.param == SIGKILL ? "SIGKILL" : "SIGINT");
                         });

}  // namespace
}  // namespace morphmap
