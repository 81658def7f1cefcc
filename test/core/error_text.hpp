#pragma once

// The text of the error a call throws, for tests that check a message names what was wrong.

#include <exception>
#include <functional>
#include <string>

namespace mild::test {

// What f throws, or "" when it does not.
inline std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

}  // namespace mild::test
