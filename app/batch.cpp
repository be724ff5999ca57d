// `morphmap batch` (paper §9, Table II): a manifest of `map` jobs run one after another.
//
// Each job runs as a child process (fork + exec of the morphmap binary's `map`), not in-process: a job that
// crashes or is killed by the kernel's OOM killer then fails alone and the batch goes on; each job's peak
// memory (getrusage in the child) is its own, not the running maximum of the batch; and memory a job frees
// (or fragments) cannot slow the next one. The cost, one exec per job, is milliseconds against runs of
// seconds to minutes. The child is killed if the batch dies (PR_SET_PDEATHSIG), so a killed batch leaves no
// orphan writing into a folder that a rerun is working on.
//
// Crash safety rests on two atomic renames: `map` stages its outputs and renames report.json into place last,
// and the batch writes job.json (the job's arguments) before starting it, after removing any report.json left
// from other arguments. A folder is complete exactly when it holds report.json and a job.json equal to the
// job's current one; anything else (outputs moved in but no report, a stale staging folder) is rerun.
#include "app/batch.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <nlohmann/json.hpp>
#include <sstream>

#include "app/cli_options.h"
#include "io/output_dir.h"
#include "mesh/errors.h"
#include "mesh/shapes.h"
#include "mesh/stopwatch.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace morphmap {
namespace {

// ---------------------------------------------------------------------------------------------- manifest

bool is_plain_name(const std::string& name) {
  if (name.empty() || name == "." || name == ".." || name[0] == '.') return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.';
  });
}

// A manifest value as the one command-line word `map` would get.
std::string scalar_text(const json& value, const std::string& where) {
  if (value.is_string()) return value.get<std::string>();
  if (value.is_number_integer() || value.is_number_unsigned() || value.is_number_float()) return value.dump();
  throw InvalidInput(where + " must be a string or a number");
}

// Relative mesh paths in a manifest are relative to the manifest's folder, not to the caller's.
std::string resolve_mesh(const std::string& spec, const fs::path& base) {
  if (is_builtin_shape(spec) || fs::path(spec).is_absolute()) return spec;
  return (base / spec).lexically_normal().string();
}

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path + ": cannot open file");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// ---------------------------------------------------------------------------------------------- summary

template <typename T>
std::optional<T> optional_at(const json& j, const json::json_pointer& pointer) {
  if (!j.contains(pointer)) return std::nullopt;
  const json& v = j.at(pointer);
  if (!v.is_number()) return std::nullopt;
  return v.get<T>();
}

std::string number(const std::optional<double>& v, int precision) {
  if (!v) return {};
  std::ostringstream s;
  s << std::setprecision(precision) << *v;
  return s.str();
}

template <typename T>
std::string integer(const std::optional<T>& v) {
  return v ? std::to_string(*v) : std::string();
}

std::string csv_field(const std::string& text) {
  if (text.find_first_of(",\"\n\r") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}

std::string md_cell(const std::string& text) {
  if (text.empty()) return "–";
  std::string cell;
  for (char c : text) cell += c == '|' ? std::string("\\|") : c == '\n' ? std::string(" ") : std::string(1, c);
  return cell;
}

// The summary's columns: CSV name, Markdown heading and Markdown alignment, in the order of cells() (one list for
// both writers, so that the two tables cannot drift apart: summary.md once lacked the warnings heading).
struct Column {
  const char* csv;
  const char* heading;
  const char* align;
};
const std::vector<Column> kColumns = {{"job", "job", "---"},
                                      {"status", "status", "---"},
                                      {"tets", "tets", "--:"},
                                      {"time_steps", "time steps", "--:"},
                                      {"diffusion_iterations", "diffusion iters", "--:"},
                                      {"diffusion_seconds", "diffusion s", "--:"},
                                      {"diffusion_conv", "diffusion conv", "--:"},
                                      {"solve_backend", "solver", "---"},
                                      {"solve_iterations", "solve iters", "--:"},
                                      {"solve_seconds", "solve s", "--:"},
                                      {"solve_residual", "solve residual", "--:"},
                                      {"label_passes", "label passes", "--:"},
                                      {"label_seconds", "label s", "--:"},
                                      {"map_seconds", "map s", "--:"},
                                      {"total_seconds", "total s", "--:"},
                                      {"cpu_seconds", "cpu s", "--:"},
                                      {"system_cpu_seconds", "sys s", "--:"},
                                      {"peak_memory_bytes", "peak memory", "--:"},
                                      {"warnings", "warnings", "---"},
                                      {"error", "error", "---"}};
constexpr std::size_t kPeakMemoryColumn = 17;

std::vector<std::string> cells(const SummaryRow& r) {
  return {r.job,
          r.status,
          integer(r.tets),
          integer(r.time_steps),
          integer(r.diffusion_iterations),
          number(r.diffusion_seconds, 4),
          number(r.diffusion_change, 3),
          r.solve_backend,
          integer(r.solve_iterations),
          number(r.solve_seconds, 4),
          number(r.solve_residual, 3),
          integer(r.label_passes),
          number(r.label_seconds, 4),
          number(r.map_seconds, 4),
          number(r.total_seconds, 4),
          number(r.cpu_seconds, 4),
          number(r.system_cpu_seconds, 4),
          integer(r.peak_memory_bytes),
          r.warnings,
          r.error};
}

// ---------------------------------------------------------------------------------------------- running

volatile std::sig_atomic_t stop_requested = 0;

void request_stop(int) { stop_requested = 1; }

// SIGINT/SIGTERM stop the running job and end the batch with a summary; the previous handlers come back after.
class StopSignals {
 public:
  StopSignals() {
    stop_requested = 0;
    struct sigaction action {};
    action.sa_handler = request_stop;
    sigemptyset(&action.sa_mask);
    action.sa_flags = 0;  // no SA_RESTART: poll() returns at once
    sigaction(SIGINT, &action, &old_int_);
    sigaction(SIGTERM, &action, &old_term_);
  }
  ~StopSignals() {
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
  }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

 private:
  struct sigaction old_int_ {};
  struct sigaction old_term_ {};
};

// One redrawn line on a terminal; nothing otherwise.
class StatusLine {
 public:
  explicit StatusLine(bool enabled) : enabled_(enabled) {}
  void show(const std::string& text) const {
    if (enabled_) std::fprintf(stderr, "\r\033[K%s", text.c_str());
  }
  void finish(const std::string& text) const {
    if (enabled_) std::fprintf(stderr, "\r\033[K%s\n", text.c_str());
  }

 private:
  bool enabled_;
};

struct ChildOutcome {
  int exit_code = -1;           ///< exit status, or -1 when killed by a signal
  int signal = 0;               ///< the signal that killed it
  double seconds = 0.0;         ///< wall time
  long long max_rss_bytes = 0;  ///< the child's peak resident memory (wait4)
  std::string last_line;        ///< its last non-empty line of output (the error of a failed run)
  bool stopped = false;         ///< killed because the batch was asked to stop
};

// Runs `argv` (argv[0] = the executable) with stdout and stderr into `log_path`, calling `on_line` with each
// line and `on_tick` about four times a second.
template <typename OnLine, typename OnTick>
ChildOutcome run_child(const std::vector<std::string>& argv, const std::string& log_path, OnLine on_line,
                       OnTick on_tick) {
  ChildOutcome outcome;
  std::ofstream log(log_path, std::ios::trunc);
  if (!log) throw IoError(log_path + ": cannot open for writing");
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    throw IoError(std::string("batch: cannot create a pipe (") + std::strerror(errno) + ")");
  std::vector<char*> cargv;
  for (const std::string& a : argv) cargv.push_back(const_cast<char*>(a.c_str()));
  cargv.push_back(nullptr);
  const pid_t parent = ::getpid();
  const auto start = Clock::now();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw IoError(std::string("batch: cannot start a job (") + std::strerror(errno) + ")");
  }
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);  // the batch died before prctl took effect
    ::dup2(fds[1], STDOUT_FILENO);
    ::dup2(fds[1], STDERR_FILENO);
    ::execv(cargv[0], cargv.data());
    const std::string message = "morphmap batch: cannot run " + argv[0] + " (" + std::strerror(errno) + ")\n";
    [[maybe_unused]] const ssize_t n = ::write(STDERR_FILENO, message.data(), message.size());
    ::_exit(127);
  }
  ::close(fds[1]);
  std::string pending;
  bool killed = false;
  for (;;) {
    if (stop_requested && !killed) {
      ::kill(pid, SIGKILL);
      killed = outcome.stopped = true;
    }
    pollfd p{fds[0], POLLIN, 0};
    const int ready = ::poll(&p, 1, 250);
    if (ready < 0 && errno != EINTR) break;
    if (ready > 0) {
      char buffer[4096];
      const ssize_t n = ::read(fds[0], buffer, sizeof buffer);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;  // end of output: the child has exited or closed its descriptors
      log.write(buffer, n);
      log.flush();
      pending.append(buffer, std::size_t(n));
      for (std::size_t eol; (eol = pending.find('\n')) != std::string::npos;) {
        const std::string line = pending.substr(0, eol);
        pending.erase(0, eol + 1);
        if (line.find_first_not_of(" \t\r") != std::string::npos) outcome.last_line = line;
        on_line(line);
      }
    }
    on_tick(seconds_since(start));
  }
  ::close(fds[0]);
  if (pending.find_first_not_of(" \t\r") != std::string::npos) outcome.last_line = pending;
  int status = 0;
  struct rusage usage {};
  while (::wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
  }
  outcome.seconds = seconds_since(start);
  outcome.max_rss_bytes = static_cast<long long>(usage.ru_maxrss) * 1024;
  if (WIFEXITED(status)) outcome.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) outcome.signal = WTERMSIG(status);
  if (stop_requested) outcome.stopped = true;
  return outcome;
}

// Holds an exclusive lock on DIR/.batch.lock for the batch's lifetime: two batches in one folder would rerun
// each other's jobs.
class FolderLock {
 public:
  explicit FolderLock(const std::string& dir) {
    const std::string path = (fs::path(dir) / ".batch.lock").string();
    fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) throw IoError(path + ": cannot open lock file (" + std::strerror(errno) + ")");
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      ::close(fd_);
      throw IoError(dir + ": another batch is running in this folder");
    }
  }
  ~FolderLock() { ::close(fd_); }  // closing releases the lock
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

 private:
  int fd_ = -1;
};

std::string job_record(const BatchJob& job) { return json{{"name", job.name}, {"args", job.args}}.dump(2) + "\n"; }

bool job_complete(const fs::path& dir, const BatchJob& job) {
  std::error_code ec;
  if (!fs::is_regular_file(dir / "report.json", ec) || !fs::is_regular_file(dir / "job.json", ec)) return false;
  try {
    return read_file((dir / "job.json").string()) == job_record(job);
  } catch (const Error&) {
    return false;
  }
}

// Removes the staging folders and temporary files of killed processes (io/output_dir.cpp's names) from a job
// folder; the lock makes sure no live process owns them. Also for complete jobs: `map` renames report.json into
// place before it removes its (then empty) staging folder, so a batch killed between the two leaves one behind.
void remove_leftovers(const fs::path& dir) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind(".staging-", 0) == 0 || (name[0] == '.' && name.find(".tmp-") != std::string::npos)) {
      std::error_code ignored;
      fs::remove_all(it->path(), ignored);
    }
  }
}

// The temporary files of summaries that a killed batch was writing (write_text_atomically's names for
// summary.csv and summary.md). Only those: the batch's folder may hold the user's own files.
void remove_summary_leftovers(const fs::path& dir) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if ((name.rfind(".summary.csv.tmp-", 0) == 0 || name.rfind(".summary.md.tmp-", 0) == 0) && it->is_regular_file()) {
      std::error_code ignored;
      fs::remove(it->path(), ignored);
    }
  }
}

// Before (re)running a job: no report.json that could be taken for this run's, no leftovers of killed runs.
void prepare_job_folder(const fs::path& dir, const BatchJob& job) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir)) throw IoError(dir.string() + ": cannot create job folder");
  fs::remove(dir / "report.json", ec);
  if (ec) throw IoError((dir / "report.json").string() + ": cannot remove stale report (" + ec.message() + ")");
  remove_leftovers(dir);
  write_text_atomically((dir / "job.json").string(), job_record(job));
}

// The stage after the one a progress line (without its "[morphmap] " tag) reports finished, "finishing" after the
// last, or "" when the line names no planned stage.
std::string next_stage(const std::string& line, const std::vector<std::string>& plan) {
  for (std::size_t k = 0; k < plan.size(); ++k)
    if (line.rfind(plan[k] + " ", 0) == 0) return k + 1 < plan.size() ? plan[k + 1] : std::string("finishing");
  return {};
}

std::string seconds_text(double s) {
  std::ostringstream t;
  t << std::fixed << std::setprecision(1) << s << " s";
  return t.str();
}

void write_summary(const std::string& dir, const std::vector<SummaryRow>& rows) {
  write_text_atomically((fs::path(dir) / "summary.csv").string(), summary_csv(rows));
  write_text_atomically((fs::path(dir) / "summary.md").string(), summary_markdown(rows));
}

}  // namespace

std::vector<std::string> planned_stages(const std::vector<std::string>& args) {
  const auto has = [&](const char* name) { return std::find(args.begin(), args.end(), name) != args.end(); };
  // An option's value, or `otherwise` when the option is not given.
  const auto value = [&](const char* name, const char* otherwise) {
    const auto at = std::find(args.begin(), args.end(), name);
    return at != args.end() && at + 1 != args.end() ? *(at + 1) : std::string(otherwise);
  };
  const std::string method = value("--method", "trace");
  const bool closest = method == "closest-point";
  std::vector<std::string> stages = {"load", "morph", "extract", closest ? "quality" : "laplace"};
  if (has("--critical-points")) stages.emplace_back("critical points");
  if (has("--compare-solvers") && !closest) stages.emplace_back("compare");
  if (!closest) stages.emplace_back("gradient");
  if (method == "upwind") stages.emplace_back("transport");
  stages.emplace_back("map");
  if (!closest && value("--fold-repair", "on") != "off") stages.emplace_back("repair");
  for (const char* rest : {"transfer", "seams", "write"}) stages.emplace_back(rest);
  return stages;
}

std::vector<BatchJob> parse_manifest(const std::string& text, const std::string& path) {
  json manifest;
  try {
    manifest = json::parse(text);
  } catch (const json::exception& e) {
    throw InvalidInput(path + ": not valid JSON (" + e.what() + ")");
  }
  json defaults = json::object(), jobs;
  if (manifest.is_array()) {
    jobs = manifest;
  } else if (manifest.is_object()) {
    for (const auto& item : manifest.items())
      if (item.key() != "jobs" && item.key() != "defaults")
        throw InvalidInput(path + ": unknown key '" + item.key() + "' (a manifest has \"jobs\" and \"defaults\")");
    if (!manifest.contains("jobs")) throw InvalidInput(path + ": no \"jobs\" array");
    jobs = manifest["jobs"];
    if (manifest.contains("defaults")) defaults = manifest["defaults"];
    if (!defaults.is_object()) throw InvalidInput(path + ": \"defaults\" must be an object of map options");
    for (const char* key : {"name", "source", "target"})
      if (defaults.contains(key)) throw InvalidInput(path + ": \"defaults\" cannot set '" + key + "'");
  } else {
    throw InvalidInput(path + ": a manifest is an object with a \"jobs\" array");
  }
  if (!jobs.is_array() || jobs.empty()) throw InvalidInput(path + ": \"jobs\" must be a non-empty array");

  const fs::path base = fs::path(path).parent_path();
  std::vector<BatchJob> result;
  for (std::size_t i = 0; i < jobs.size(); ++i) {
    std::string where = path + ": job " + std::to_string(i + 1);
    if (!jobs[i].is_object()) throw InvalidInput(where + ": not an object");
    json merged = defaults;
    merged.update(jobs[i]);  // the job's own keys override the defaults
    BatchJob job;
    job.name = "job-" + std::to_string(i + 1);
    if (merged.contains("name")) {
      if (!merged["name"].is_string()) throw InvalidInput(where + ": \"name\" must be a string");
      job.name = merged["name"].get<std::string>();
      where += " (" + job.name + ")";
      if (!is_plain_name(job.name))
        throw InvalidInput(where + ": name must be letters, digits, '-', '_' or '.' (it names the job's folder)");
      if (job.name == "summary.csv" || job.name == "summary.md")
        throw InvalidInput(where + ": name '" + job.name + "' is the batch's own summary file, not a job folder");
    }
    for (const BatchJob& other : result)
      if (other.name == job.name) throw InvalidInput(where + ": name '" + job.name + "' used twice");
    for (const char* key : {"source", "target"}) {
      if (!merged.contains(key)) throw InvalidInput(where + ": missing \"" + key + "\"");
      if (!merged[key].is_string() || merged[key].get<std::string>().empty())
        throw InvalidInput(where + ": \"" + key + "\" must be a mesh file or a built-in shape");
      job.args.push_back(resolve_mesh(merged[key].get<std::string>(), base));
    }

    // `map`'s own parser checks every option, so a manifest accepts exactly what the command line does.
    CLI::App parser;
    PipelineOptions options;
    parser.add_option("SOURCE", options.source)->required();
    parser.add_option("TARGET", options.target)->required();
    add_pipeline_options(parser, options);
    for (const auto& item : merged.items()) {
      const std::string& key = item.key();
      if (key == "name" || key == "source" || key == "target") continue;
      const CLI::Option* option = parser.get_option_no_throw("--" + key);
      if (option == nullptr) {
        // Keys are map's option names without the dashes; JSON habits write them with underscores.
        std::string dashed = key;
        std::replace(dashed.begin(), dashed.end(), '_', '-');
        std::string hint;
        if (key == "output" || key == "o") hint = " (the batch names each job's folder)";
        if (dashed != key && parser.get_option_no_throw("--" + dashed) != nullptr)
          hint = " (did you mean '" + dashed + "'?)";
        throw InvalidInput(where + ": unknown key '" + key + "'" + hint);
      }
      const std::string flag = "--" + key, what = where + ": '" + key + "'";
      if (option->get_expected_max() == 0) {  // a flag
        if (!item.value().is_boolean()) throw InvalidInput(what + " is a flag: true or false");
        if (item.value().get<bool>()) job.args.push_back(flag);
      } else if (item.value().is_array()) {
        std::string joined;
        for (const json& element : item.value()) joined += (joined.empty() ? "" : ",") + scalar_text(element, what);
        if (joined.empty()) continue;  // an empty list means the default
        job.args.insert(job.args.end(), {flag, joined});
      } else {
        job.args.insert(job.args.end(), {flag, scalar_text(item.value(), what)});
      }
    }
    std::vector<std::string> reversed(job.args.rbegin(), job.args.rend());  // CLI11 takes them last first
    try {
      parser.parse(reversed);
    } catch (const CLI::ParseError& e) {
      throw InvalidInput(where + ": " + e.what());
    } catch (const Error& e) {
      throw InvalidInput(where + ": " + e.what());
    }
    result.push_back(std::move(job));
  }
  return result;
}

std::vector<BatchJob> read_manifest(const std::string& path) { return parse_manifest(read_file(path), path); }

SummaryRow summary_row(const std::string& job, const std::string& report_json) {
  json r;
  try {
    r = json::parse(report_json);
  } catch (const json::exception& e) {
    throw InvalidInput(job + ": report.json is not valid JSON (" + e.what() + ")");
  }
  SummaryRow row;
  row.job = job;
  row.status = "ok";
  row.tets = optional_at<std::int64_t>(r, "/counts/tets"_json_pointer);
  row.time_steps = optional_at<int>(r, "/options/time_steps"_json_pointer);
  // The map's own solve and the comparison solves, as (name, report) pairs; the row's diffusion column is the
  // Gauss-Seidel one and its implicit/direct column the first other one.
  std::vector<const json*> solves;
  if (r.contains("solver")) solves.push_back(&r["solver"]);
  if (r.contains("/compare/solves"_json_pointer))
    for (const json& c : r["compare"]["solves"]) solves.push_back(&c);
  const json* diffusion = nullptr;
  const json* direct = nullptr;
  for (const json* s : solves) {
    const bool gauss_seidel = s->value("name", std::string()) == "gauss-seidel";
    if (gauss_seidel && !diffusion) diffusion = s;
    if (!gauss_seidel && !direct) direct = s;
  }
  auto seconds_of = [](const json& s) { return s.value("setup_seconds", 0.0) + s.value("solve_seconds", 0.0); };
  if (diffusion) {
    row.diffusion_iterations = diffusion->value("iterations", 0);
    row.diffusion_seconds = seconds_of(*diffusion);
    row.diffusion_change = diffusion->value("change", 0.0);
  }
  if (direct) {
    row.solve_backend = direct->value("name", std::string());
    row.solve_iterations = direct->value("iterations", 0);
    row.solve_seconds = seconds_of(*direct);
    row.solve_residual = direct->value("residual", 0.0);
  }
  row.label_passes = optional_at<std::int64_t>(r, "/transport/wavefronts"_json_pointer);
  // Label propagation: the upwind sweep's (--method upwind), else the tracing's, which has no passes.
  row.label_seconds = optional_at<double>(r, "/seconds/transport"_json_pointer);
  if (!row.label_seconds) row.label_seconds = optional_at<double>(r, "/trace/seconds"_json_pointer);
  row.total_seconds = optional_at<double>(r, "/seconds/total"_json_pointer);
  row.peak_memory_bytes = optional_at<std::int64_t>(r, "/peak_memory_bytes"_json_pointer);
  row.cpu_seconds = optional_at<double>(r, "/cpu_seconds"_json_pointer);
  row.system_cpu_seconds = optional_at<double>(r, "/system_cpu_seconds"_json_pointer);
  if (row.total_seconds)
    row.map_seconds = *row.total_seconds - optional_at<double>(r, "/seconds/compare"_json_pointer).value_or(0.0);
  for (const json::json_pointer& list : {"/inputs/warnings"_json_pointer, "/topology/warnings"_json_pointer})
    if (r.contains(list) && r[list].is_array())
      for (const json& w : r[list])
        if (w.is_string()) row.warnings += (row.warnings.empty() ? "" : "; ") + w.get<std::string>();
  return row;
}

std::string summary_csv(const std::vector<SummaryRow>& rows) {
  std::string text;
  for (std::size_t c = 0; c < kColumns.size(); ++c) text += std::string(c ? "," : "") + kColumns[c].csv;
  text += '\n';
  for (const SummaryRow& row : rows) {
    const std::vector<std::string> values = cells(row);
    for (std::size_t c = 0; c < values.size(); ++c) text += (c ? "," : "") + csv_field(values[c]);
    text += '\n';
  }
  return text;
}

std::string summary_markdown(const std::vector<SummaryRow>& rows) {
  std::string heading = "|", rule = "|";
  for (const Column& c : kColumns) {
    heading += std::string(" ") + c.heading + " |";
    rule += std::string(c.align) + "|";
  }
  std::string text = heading + "\n" + rule + "\n";
  for (const SummaryRow& row : rows) {
    std::vector<std::string> values = cells(row);
    if (row.peak_memory_bytes)
      values[kPeakMemoryColumn] = number(double(*row.peak_memory_bytes) / (1024.0 * 1024.0 * 1024.0), 3) + " GiB";
    text += "|";
    for (const std::string& v : values) text += " " + md_cell(v) + " |";
    text += '\n';
  }
  return text;
}

BatchResult run_batch(const BatchOptions& options) {
  const std::vector<BatchJob> jobs = read_manifest(options.manifest);  // all checked before anything runs
  std::error_code ec;
  fs::create_directories(options.output_dir, ec);
  if (ec || !fs::is_directory(options.output_dir))
    throw IoError(options.output_dir + ": cannot create output directory" + (ec ? " (" + ec.message() + ")" : ""));
  const FolderLock lock(options.output_dir);
  remove_summary_leftovers(options.output_dir);  // a batch killed while it wrote a summary (SIGKILL)
  const StopSignals signals;
  const StatusLine status(options.progress);
  const auto batch_start = Clock::now();

  BatchResult result;
  for (const BatchJob& job : jobs) {
    SummaryRow pending;
    pending.job = job.name;
    pending.status = "pending";
    result.rows.push_back(pending);
  }
  const std::string n = std::to_string(jobs.size());
  for (std::size_t i = 0; i < jobs.size() && !stop_requested; ++i) {
    const BatchJob& job = jobs[i];
    const fs::path dir = fs::path(options.output_dir) / job.name;
    const std::string label = "[batch] job " + std::to_string(i + 1) + "/" + n + " " + job.name;
    SummaryRow& row = result.rows[i];
    if (job_complete(dir, job)) {
      try {
        row = summary_row(job.name, read_file((dir / "report.json").string()));
        remove_leftovers(dir);
        ++result.succeeded;
        ++result.skipped;
        status.finish(label + ": complete, skipped");
        write_summary(options.output_dir, result.rows);
        continue;
      } catch (const Error&) {  // an unreadable report is not complete: run the job again
      }
    }
    prepare_job_folder(dir, job);
    std::vector<std::string> argv = {options.executable, "map"};
    argv.insert(argv.end(), job.args.begin(), job.args.end());
    argv.insert(argv.end(), {"-o", dir.string(), "--progress"});
    const std::vector<std::string> plan = planned_stages(job.args);
    std::string stage = "load";
    const ChildOutcome run = run_child(
        argv, (dir / "map.log").string(),
        [&](const std::string& line) {
          const std::string tag = "[morphmap] ";
          if (line.rfind(tag, 0) != 0) return;
          const std::string next = next_stage(line.substr(tag.size()), plan);
          if (!next.empty()) stage = next;
        },
        [&](double seconds) {
          status.show(label + ": " + stage + "  " + seconds_text(seconds) + "  (batch " +
                      seconds_text(seconds_since(batch_start)) + ")");
        });
    // report.json was removed before the start, so if it is there this run wrote it, and wrote it last: the job is
    // complete even if a stop request killed `map` on its way out.
    std::error_code missing;
    const bool complete = fs::is_regular_file(dir / "report.json", missing);
    if (run.stopped && !complete) {
      row.status = "interrupted";
      result.interrupted = true;
      status.finish(label + ": interrupted");
      write_summary(options.output_dir, result.rows);
      break;
    }
    if (complete) {
      row = summary_row(job.name, read_file((dir / "report.json").string()));
      ++result.succeeded;
      status.finish(label + ": ok  " + seconds_text(run.seconds));
    } else {
      row.status = "failed";
      row.total_seconds = run.seconds;
      row.peak_memory_bytes = run.max_rss_bytes;
      if (run.signal != 0)
        row.error =
            "killed by signal " + std::to_string(run.signal) + (run.signal == SIGKILL ? " (out of memory?)" : "");
      else if (!run.last_line.empty())
        row.error = run.last_line.rfind("morphmap: ", 0) == 0 ? run.last_line.substr(10) : run.last_line;
      else
        row.error = "exit status " + std::to_string(run.exit_code);
      ++result.failed;
      status.finish(label + ": failed");
      std::fprintf(stderr, "morphmap batch: job %s failed: %s\n", job.name.c_str(), row.error.c_str());
    }
    write_summary(options.output_dir, result.rows);
  }
  if (stop_requested) result.interrupted = true;
  write_summary(options.output_dir, result.rows);
  status.finish("[batch] " + std::to_string(result.succeeded) + " of " + n + " jobs ok (" +
                std::to_string(result.skipped) + " complete before), " + std::to_string(result.failed) + " failed" +
                (result.interrupted ? ", interrupted" : "") + "; " + seconds_text(seconds_since(batch_start)) +
                "; summary in " + (fs::path(options.output_dir) / "summary.md").string());
  return result;
}

}  // namespace morphmap
