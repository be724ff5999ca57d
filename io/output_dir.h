// Crash-safe output: files are written into a staging folder inside the output directory and
// renamed into place only when the whole run succeeded, so no half-written output is ever seen.
#pragma once

#include <functional>
#include <string>
#include <vector>

namespace morphmap {

class OutputDir {
 public:
  /// Creates `dir` if needed (IoError if impossible) and a fresh staging folder inside it.
  explicit OutputDir(const std::string& dir);
  /// Removes the staging folder and everything in it unless commit() ran.
  ~OutputDir();
  OutputDir(const OutputDir&) = delete;
  OutputDir& operator=(const OutputDir&) = delete;

  /// Path in the staging folder at which to write the output `name` (a plain file name).
  std::string staged(const std::string& name);
  /// Renames every staged file into `dir` (each rename atomic; report.json-like files named in
  /// `last` are renamed after all others, so their presence means the rest is complete). With `earlier_output`,
  /// the files of `dir` it names (an earlier run's outputs) that this run does not write are removed first, after the
  /// `last` files, so that a rerun with fewer outputs (no --ply, other slices) leaves none of the old ones beside the
  /// new report, and a crash in between leaves no report.
  void commit(const std::vector<std::string>& last = {},
              const std::function<bool(const std::string&)>& earlier_output = {});
  const std::string& dir() const { return dir_; }

 private:
  std::string dir_;
  std::string staging_;
  std::vector<std::string> names_;
  bool committed_ = false;
};

/// Writes `text` to `path` through a temporary file in the same folder and an atomic rename.
void write_text_atomically(const std::string& path, const std::string& text);

/// Peak resident memory of this process (getrusage), in bytes.
long long peak_memory_bytes();

}  // namespace morphmap
