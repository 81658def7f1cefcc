#pragma once

#include <string>
#include <vector>

#include "mild_lcd/offline/evaluation.hpp"

namespace mild::tools {

// Writes pr_curve.png (precision-recall curve) and loops_matrix.png (detected closures against
// ground truth, as the seed paper's "Detected closure VS ground truth closure" figure) into dir,
// and reliability.png (with the hard decision marked: `decision`, at the configuration's
// scoring/decision_probability), by handing the data to scripts/plot_offline.py (matplotlib).
// Throws InvalidInput on failure.
void writeOfflinePlots(const std::string& dir, const GroundTruth& truth, const std::vector<ScoredPair>& candidates,
                       const Metrics& metrics, const Decision& decision, size_t frames, int min_gap);

// Path of a helper script shipped in scripts/ (source tree) or the installed share folder.
std::string findScript(const std::string& name);

}  // namespace mild::tools
