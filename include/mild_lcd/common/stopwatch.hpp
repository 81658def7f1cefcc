#pragma once

#include <chrono>

#include <time.h>

namespace mild {

using Clock = std::chrono::steady_clock;

// Milliseconds since `start`, for the per-step timings results report.
inline double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// CPU time of the calling thread in milliseconds: what a keyframe costs, unlike the wall clock
// unmoved by other processes sharing the cores (benchmarks on busy two-core machines). Work handed
// to other threads (verification/parallel_candidates) is not counted.
inline double threadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

}  // namespace mild
