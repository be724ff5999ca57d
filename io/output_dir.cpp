// Crash-safe output of the pipeline's results (DESIGN.md, stage "outputs"): a staging folder inside the output
// directory, renamed into place only after the whole run succeeded.
#include "io/output_dir.h"

#include <fcntl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <system_error>

#include "mesh/errors.h"

namespace fs = std::filesystem;

namespace morphmap {

namespace {

// Several OutputDirs and temporary files may coexist in one process; pid + counter keeps their names apart.
std::atomic<unsigned long> name_counter{0};

std::string unique_suffix() {
  return std::to_string(static_cast<long long>(::getpid())) + "-" + std::to_string(name_counter.fetch_add(1));
}

bool is_plain_file_name(const std::string& name) {
  return !name.empty() && name != "." && name != ".." && name.find('/') == std::string::npos &&
         name.find('\0') == std::string::npos;
}

}  // namespace

OutputDir::OutputDir(const std::string& dir) : dir_(dir) {
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (ec || !fs::is_directory(dir_)) {
    throw IoError(dir_ + ": cannot create output directory" + (ec ? " (" + ec.message() + ")" : std::string()));
  }
  // A stale staging folder of an earlier process with the same pid must not be reused.
  for (;;) {
    const std::string candidate = (fs::path(dir_) / (".staging-" + unique_suffix())).string();
    if (fs::create_directory(candidate, ec)) {
      staging_ = candidate;
      break;
    }
    if (ec) throw IoError(candidate + ": cannot create staging folder (" + ec.message() + ")");
  }
}

OutputDir::~OutputDir() {
  if (committed_ || staging_.empty()) return;
  std::error_code ec;
  fs::remove_all(staging_, ec);  // a destructor must not throw; a leftover hidden folder is harmless
}

std::string OutputDir::staged(const std::string& name) {
  if (committed_) throw IoError(dir_ + ": output '" + name + "' staged after commit");
  if (!is_plain_file_name(name)) throw InvalidInput(dir_ + ": output name '" + name + "' is not a plain file name");
  if (std::find(names_.begin(), names_.end(), name) == names_.end()) names_.push_back(name);
  return (fs::path(staging_) / name).string();
}

void OutputDir::commit(const std::vector<std::string>& last,
                       const std::function<bool(const std::string&)>& earlier_output) {
  if (committed_) return;
  // Whatever landed in the staging folder is output, also files written there without staged().
  std::vector<std::string> present;
  std::error_code ec;
  for (fs::directory_iterator it(staging_, ec), end; !ec && it != end; it.increment(ec)) {
    present.push_back(it->path().filename().string());
  }
  if (ec) throw IoError(staging_ + ": cannot list staging folder (" + ec.message() + ")");
  std::sort(present.begin(), present.end());
  std::vector<std::string> order;
  for (const std::string& name : present) {
    if (std::find(last.begin(), last.end(), name) == last.end()) order.push_back(name);
  }
  for (const std::string& name : last) {  // in the caller's order, after everything else
    if (std::binary_search(present.begin(), present.end(), name) &&
        std::find(order.begin(), order.end(), name) == order.end()) {
      order.push_back(name);
    }
  }
  if (earlier_output) {
    std::vector<std::string> stale;
    for (fs::directory_iterator it(dir_, ec), end; !ec && it != end; it.increment(ec)) {
      const std::string name = it->path().filename().string();
      if (it->is_regular_file() && earlier_output(name) && !std::binary_search(present.begin(), present.end(), name))
        stale.push_back(name);
    }
    if (ec) throw IoError(dir_ + ": cannot list output directory (" + ec.message() + ")");
    // The reports first: without one the folder is recognisably incomplete until the new one lands.
    std::stable_partition(stale.begin(), stale.end(), [&](const std::string& name) {
      return std::find(last.begin(), last.end(), name) != last.end();
    });
    for (const std::string& name : last) {
      if (std::binary_search(present.begin(), present.end(), name)) {
        fs::remove(fs::path(dir_) / name, ec);  // replaced below anyway; removed now for the order above
        if (ec) throw IoError((fs::path(dir_) / name).string() + ": cannot remove (" + ec.message() + ")");
      }
    }
    for (const std::string& name : stale) {
      fs::remove(fs::path(dir_) / name, ec);
      if (ec) throw IoError((fs::path(dir_) / name).string() + ": cannot remove earlier output (" + ec.message() + ")");
    }
  }
  for (const std::string& name : order) {
    const fs::path from = fs::path(staging_) / name;
    const fs::path to = fs::path(dir_) / name;
    fs::rename(from, to, ec);
    if (ec) throw IoError(to.string() + ": cannot move output into place (" + ec.message() + ")");
  }
  fs::remove(staging_, ec);
  committed_ = true;
}

void write_text_atomically(const std::string& path, const std::string& text) {
  const fs::path target(path);
  const fs::path folder = target.has_parent_path() ? target.parent_path() : fs::path(".");
  const std::string temp = (folder / ("." + target.filename().string() + ".tmp-" + unique_suffix())).string();
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) throw IoError(path + ": cannot create temporary file (" + std::strerror(errno) + ")");
  const char* data = text.data();
  std::size_t left = text.size();
  bool ok = true;
  while (left > 0) {
    const ssize_t n = ::write(fd, data, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      ok = false;
      break;
    }
    data += n;
    left -= static_cast<std::size_t>(n);
  }
  // fsync before rename: otherwise a crash can leave the new name pointing at an empty file.
  const int saved_errno = ok ? 0 : errno;
  ok = ok && ::fsync(fd) == 0;
  ok = (::close(fd) == 0) && ok;
  if (!ok) {
    const std::string reason = std::strerror(saved_errno != 0 ? saved_errno : errno);
    ::unlink(temp.c_str());
    throw IoError(path + ": cannot write file (" + reason + ")");
  }
  std::error_code ec;
  fs::rename(temp, target, ec);
  if (ec) {
    ::unlink(temp.c_str());
    throw IoError(path + ": cannot rename temporary file into place (" + ec.message() + ")");
  }
}

long long peak_memory_bytes() {
  struct rusage usage {};
  if (::getrusage(RUSAGE_SELF, &usage) != 0) return 0;
  return static_cast<long long>(usage.ru_maxrss) * 1024;  // Linux reports kilobytes
}

}  // namespace morphmap
