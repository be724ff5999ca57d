// Wall-clock timing shared by every stage's result struct (seconds per stage in report.json).
#pragma once

#include <chrono>

namespace morphmap {

using Clock = std::chrono::steady_clock;

/// Seconds elapsed since `start`.
inline double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

}  // namespace morphmap
