#pragma once

#include <stdexcept>
#include <string>

namespace mild {

// Thrown when input from a caller (descriptors, images, parameters, files) cannot be used.
// Every function that throws it leaves the object it was called on unchanged.
class InvalidInput : public std::invalid_argument {
 public:
  explicit InvalidInput(const std::string& what) : std::invalid_argument(what) {}
};

}  // namespace mild
