#pragma once

// The hard decision's line that mild_offline --gt and mild_score print: precision and recall of each
// query's best candidate at the configuration's scoring/decision_probability, saying which it is.

#include <cstdio>
#include <string>

#include "mild_lcd/offline/evaluation.hpp"

namespace mild::tools {

inline std::string decisionLine(const Decision& d) {
  char line[256];
  std::snprintf(line, sizeof(line),
                "at the decision, probability >= %g (scoring/decision_probability): precision %.4f, recall %.4f "
                "(%zu right, %zu wrong)",
                d.threshold, d.precision, d.recall, d.right, d.wrong);
  return line;
}

}  // namespace mild::tools
