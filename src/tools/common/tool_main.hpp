#pragma once

// The one way every mild_lcd tool parses its options, runs and exits: 0 on success, 2 for bad input
// (options, files, parameters, ground truth), 1 for any other failure (the file system, a limit, an
// unexpected error). Errors go to stderr as "<tool>: error: <message>".

#include <exception>
#include <functional>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>

#include "mild_lcd/common/errors.hpp"

namespace mild::tools {

constexpr int kExitFailure = 1;
constexpr int kExitBadInput = 2;

inline int toolMain(CLI::App& app, int argc, char** argv, const std::function<int()>& body) {
  const std::string tool = app.get_name().empty() ? "mild_lcd" : app.get_name();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // prints the usage or the option error
    return code == 0 ? 0 : kExitBadInput;
  }
  try {
    return body();
  } catch (const InvalidInput& e) {
    std::cerr << tool << ": error: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << tool << ": error: " << e.what() << "\n";
    return kExitFailure;
  }
}

}  // namespace mild::tools
