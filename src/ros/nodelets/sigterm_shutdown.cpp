#include "mild_lcd/ros/nodelets/sigterm_shutdown.hpp"

#include <signal.h>

#include <mutex>

#include <ros/init.h>

namespace mild_lcd {
namespace {

std::mutex g_mutex;
int g_users = 0;           // mild_lcd nodelets alive in this process
bool g_installed = false;  // SIGTERM's action is ours

// roscpp's own SIGINT handler does exactly this: it sets the flag its spinners poll.
void requestShutdown(int) { ros::requestShutdown(); }

}  // namespace

SigtermAsShutdown::SigtermAsShutdown() {
  std::lock_guard<std::mutex> lock(g_mutex);
  if (g_users++ > 0) return;
  struct sigaction current {};
  if (sigaction(SIGTERM, nullptr, &current) != 0) return;
  if ((current.sa_flags & SA_SIGINFO) != 0 || current.sa_handler != SIG_DFL) return;  // someone handles it
  struct sigaction mine {};
  mine.sa_handler = requestShutdown;
  sigemptyset(&mine.sa_mask);
  g_installed = sigaction(SIGTERM, &mine, nullptr) == 0;
}

SigtermAsShutdown::~SigtermAsShutdown() {
  std::lock_guard<std::mutex> lock(g_mutex);
  if (--g_users > 0 || !g_installed) return;
  struct sigaction current {};
  if (sigaction(SIGTERM, nullptr, &current) == 0 && current.sa_handler == requestShutdown) {
    struct sigaction fallback {};
    fallback.sa_handler = SIG_DFL;
    sigemptyset(&fallback.sa_mask);
    sigaction(SIGTERM, &fallback, nullptr);
  }
  g_installed = false;
}

bool SigtermAsShutdown::installed() {
  std::lock_guard<std::mutex> lock(g_mutex);
  return g_installed;
}

}  // namespace mild_lcd
