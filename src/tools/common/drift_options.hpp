#pragma once

// The odometry drift model's options (backend/trajectory.hpp), the same in every tool that
// simulates odometry (mild_make_bag, mild_pose_graph_eval). `seed_option` names the seed's option.

#include <string>

#include <CLI/CLI.hpp>

#include "mild_lcd/backend/trajectory.hpp"

namespace mild::tools {

inline void addDriftOptions(CLI::App& app, mild::backend::DriftModel& drift, const std::string& seed_option) {
  app.add_option(seed_option, drift.seed, "seed of the odometry's drift")->capture_default_str();
  app.add_option("--scale-error", drift.scale_error, "odometry scale error")->capture_default_str();
  app.add_option("--translation-noise", drift.translation_noise, "translation noise per metre")->capture_default_str();
  app.add_option("--heading-bias", drift.heading_bias, "heading bias, rad per metre")->capture_default_str();
  app.add_option("--heading-random-walk", drift.heading_random_walk, "heading random walk, rad per sqrt(m)")
      ->capture_default_str();
}

}  // namespace mild::tools
