#pragma once

// A nodelet manager, like any roscpp process, handles SIGINT only: SIGTERM (docker stop, systemd's
// default KillSignal, kill) ends it at once, without unloading its nodelets, so a nodelet's
// ~save_on_shutdown never runs. While a mild_lcd nodelet is loaded, SIGTERM requests the same
// orderly shutdown as roscpp's SIGINT handler (ros::requestShutdown), unless the process already
// handles SIGTERM itself (the standalone node does, and so may a host application). The handler
// lives in this library: the last mild_lcd nodelet to go puts the default action back.

namespace mild_lcd {

class SigtermAsShutdown {
 public:
  SigtermAsShutdown();
  ~SigtermAsShutdown();
  SigtermAsShutdown(const SigtermAsShutdown&) = delete;
  SigtermAsShutdown& operator=(const SigtermAsShutdown&) = delete;

  // Whether SIGTERM is handled by this library now.
  static bool installed();
};

}  // namespace mild_lcd
