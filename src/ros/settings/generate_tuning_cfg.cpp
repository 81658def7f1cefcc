// Build step: writes the dynamic_reconfigure cfg of the runtime parameters (tuning_cfg.hpp) to the
// path given, for generate_dynamic_reconfigure_options. Rewrites it only when it changed, so that
// TuningConfig.h and what includes it are rebuilt only then.

#include <fstream>
#include <iostream>
#include <sstream>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/ros/settings/tuning_cfg.hpp"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: generate_tuning_cfg OUTPUT.cfg\n";
    return 2;
  }
  try {
    const std::string script = mild_lcd::tuningCfgScript();
    std::ostringstream before;
    if (std::ifstream in(argv[1]); in) before << in.rdbuf();
    if (before.str() == script) return 0;
    std::ofstream out(argv[1]);
    out << script;
    if (!out.flush()) {
      std::cerr << "generate_tuning_cfg: cannot write " << argv[1] << "\n";
      return 1;
    }
  } catch (const mild::InvalidInput& e) {
    std::cerr << "generate_tuning_cfg: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
