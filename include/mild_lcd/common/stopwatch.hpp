#pragma once

#include <chrono>

namespace mild {

using Clock = std::chrono::steady_clock;

// Milliseconds since `start`, for the per-step timings results report.
inline double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace mild
