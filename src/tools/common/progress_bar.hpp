#pragma once

#include <chrono>
#include <cstdio>
#include <string>

#include <unistd.h>

namespace mild::tools {

// A one-line progress bar with rate and ETA on a terminal; silent when stdout is not a TTY (logs,
// pipes, CI).
class ProgressBar {
 public:
  ProgressBar(size_t total, std::string label)
      : total_(total), label_(std::move(label)), enabled_(isatty(STDOUT_FILENO) == 1), start_(Clock::now()) {}

  void update(size_t done) {
    if (!enabled_) return;
    const auto now = Clock::now();
    if (done < total_ && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const double rate = elapsed > 0 ? static_cast<double>(done) / elapsed : 0.0;
    const double eta = rate > 0 ? static_cast<double>(total_ - done) / rate : 0.0;
    const int width = 30;
    const int filled = total_ ? static_cast<int>(width * done / total_) : width;
    std::string bar(static_cast<size_t>(filled), '#');
    bar.resize(width, '.');
    std::printf("\r%s [%s] %zu/%zu  %.1f/s  ETA %ds   ", label_.c_str(), bar.c_str(), done, total_, rate,
                static_cast<int>(eta));
    std::fflush(stdout);
  }

  void finish() {
    if (!enabled_) return;
    update(total_);
    std::printf("\n");
  }

 private:
  using Clock = std::chrono::steady_clock;
  size_t total_;
  std::string label_;
  bool enabled_;
  Clock::time_point start_;
  Clock::time_point last_draw_{};
};

}  // namespace mild::tools
