#pragma once

#include <stdexcept>
#include <string>

namespace mild {

// Every error mild_lcd throws on purpose; the three kinds below say whose move it is next.
// Every function that throws one leaves the object it was called on unchanged.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

// The caller's input cannot be used (descriptors, images, parameters, messages, file contents):
// fix the input.
class InvalidInput : public Error {
 public:
  explicit InvalidInput(const std::string& what) : Error(what) {}
};

// The file system failed (cannot create, write, rename, read): fix the disk or the permissions.
class IoError : public Error {
 public:
  explicit IoError(const std::string& what) : Error(what) {}
};

// A limit was reached (a configured bound, the 2^32 features of an index, memory): the input may be
// fine, but not here, not at this size.
class CapacityError : public Error {
 public:
  explicit CapacityError(const std::string& what) : Error(what) {}
};

}  // namespace mild
