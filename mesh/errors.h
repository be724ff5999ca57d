// Exception hierarchy shared by every stage (pmp-library style). Messages name the function or
// file and the problem in one line; the command line maps InvalidInput and IoError to exit status 2.
#pragma once

#include <stdexcept>
#include <string>

namespace morphmap {

/// Base of every error morphmap throws on purpose.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

/// Bad user input: malformed or unusable mesh, unknown option value, resource guard refused a run.
class InvalidInput : public Error {
 public:
  using Error::Error;
};

/// A file could not be read or written.
class IoError : public Error {
 public:
  using Error::Error;
};

/// A mesh is not what a stage requires (not closed, not manifold, empty extraction).
class TopologyError : public Error {
 public:
  using Error::Error;
};

/// A linear solver failed (not SPD, no convergence, CHOLMOD error).
class SolverError : public Error {
 public:
  using Error::Error;
};

}  // namespace morphmap
