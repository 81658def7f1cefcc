#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace mild {

// A set of 64-bit keys for hot loops that fill it, test it, and start over thousands of times:
// open addressing kept at most half full, each slot stamped with the generation that wrote it, so
// that emptying bumps the generation instead of touching the slots.
class StampedSet {
 public:
  // Empties the set, with room for `expected` keys.
  void clear(size_t expected) {
    size_t size = kMinSlots;
    while (size < 2 * expected) size *= 2;
    if (size > slots_.size()) {
      slots_.assign(size, Slot{});
      generation_ = 0;
    }
    if (++generation_ == 0) {  // wrapped: old stamps could look current
      std::fill(slots_.begin(), slots_.end(), Slot{});
      generation_ = 1;
    }
  }

  // Adds key; true when it was not in the set yet. At most the `expected` keys of the last clear().
  bool insert(uint64_t key) {
    const size_t mask = slots_.size() - 1;
    for (size_t h = (key * 0x9E3779B97F4A7C15ull) >> 32 & mask;; h = (h + 1) & mask) {
      Slot& s = slots_[h];
      if (s.generation != generation_) {
        s = {key, generation_};
        return true;
      }
      if (s.key == key) return false;
    }
  }

 private:
  static constexpr size_t kMinSlots = 256;
  struct Slot {
    uint64_t key = 0;
    uint32_t generation = 0;
  };
  std::vector<Slot> slots_;
  uint32_t generation_ = 0;
};

}  // namespace mild
