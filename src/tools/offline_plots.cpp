#include "offline_plots.hpp"

#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "mild_lcd/common/errors.hpp"

namespace fs = std::filesystem;

namespace mild::tools {

std::string findScript(const std::string& name) {
  const std::vector<fs::path> places = {fs::path(MILD_SOURCE_SCRIPTS_DIR) / name,
                                        fs::path(MILD_INSTALL_SCRIPTS_DIR) / name};
  for (const auto& p : places) {
    if (fs::exists(p)) return p.string();
  }
  throw InvalidInput("cannot find helper script " + name + " (looked in " + places[0].string() + " and " +
                     places[1].string() + ")");
}

void writeOfflinePlots(const std::string& dir, const GroundTruth& truth, const std::vector<ScoredPair>& candidates,
                       const Metrics& metrics, const Decision& decision, size_t frames, int min_gap) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw InvalidInput(dir + ": cannot create the plots folder (" + ec.message() + ")");

  nlohmann::json data;
  data["frames"] = frames;
  data["recall_at_100_precision"] = metrics.recall_at_100_precision;
  data["average_precision"] = metrics.average_precision;
  data["max_f1"] = metrics.max_f1;
  for (const auto& p : metrics.curve) data["curve"].push_back({p.score, p.precision, p.recall});
  for (const auto& [i, j] : truth.right) data["truth"].push_back({i, j});
  for (const auto& [i, j] : truth.dont_care) data["dont_care"].push_back({i, j});
  for (const auto& c : bestPerQuery(candidates, min_gap)) data["detections"].push_back({c.query, c.candidate, c.score});
  const Reliability rel = reliability(truth, candidates, 10, min_gap);
  for (const auto& b : rel.bins)
    data["reliability"].push_back({b.lower, b.upper, b.count, b.mean_score, b.fraction_right});
  data["expected_calibration_error"] = rel.expected_calibration_error;
  data["decision"] = {{"threshold", decision.threshold},
                      {"precision", decision.precision},
                      {"recall", decision.recall},
                      {"right", decision.right},
                      {"wrong", decision.wrong}};
  const fs::path json_path = fs::path(dir) / "plot_data.json";
  std::ofstream(json_path) << data.dump();

  const std::string command =
      "/usr/bin/python3 '" + findScript("plot_offline.py") + "' '" + json_path.string() + "' '" + dir + "'";
  if (std::system(command.c_str()) != 0) throw InvalidInput("plotting failed: " + command);
}

}  // namespace mild::tools
