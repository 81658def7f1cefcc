#include "bench/synthetic_keyframes.hpp"

#include <algorithm>

#include "mild_lcd/common/errors.hpp"

namespace mild::tools {

SyntheticKeyframes::SyntheticKeyframes(std::vector<DescriptorList> frames, size_t features_per_keyframe, int min_flips,
                                       int max_flips)
    : features_(features_per_keyframe), min_flips_(min_flips), max_flips_(max_flips) {
  for (auto& f : frames) {
    if (!f.empty()) frames_.push_back(std::move(f));
  }
  if (frames_.empty()) throw InvalidInput("no real frame with features to build synthetic keyframes from");
  if (min_flips < 0 || max_flips < min_flips || max_flips > frames_.front().front().bits()) {
    throw InvalidInput("bad flip range");
  }
}

DescriptorList SyntheticKeyframes::replicate(const DescriptorList& main, const DescriptorList& filler,
                                             std::mt19937_64& rng) const {
  DescriptorList out;
  out.reserve(features_);
  for (size_t i = 0; out.size() < features_ && i < main.size(); ++i) out.push_back(main[i]);
  for (size_t i = 0; out.size() < features_; ++i) out.push_back(filler[i % filler.size()]);
  std::uniform_int_distribution<int> flips(min_flips_, max_flips_), bit(0, main.front().bits() - 1);
  for (Descriptor& d : out) {
    for (int f = flips(rng); f > 0; --f) d.flip(bit(rng));  // repeats cancel: d is at most max_flips away
  }
  std::shuffle(out.begin(), out.end(), rng);
  return out;
}

DescriptorList SyntheticKeyframes::keyframe(uint64_t k) const {
  std::mt19937_64 rng(0x9E3779B97F4A7C15ull * (k + 1));
  const size_t n = frames_.size();
  return replicate(frames_[k % n], frames_[(k * 7 + 3) % n], rng);
}

DescriptorList SyntheticKeyframes::query(uint64_t q) const {
  std::mt19937_64 rng(0xC2B2AE3D27D4EB4Full * (q + 1));
  const size_t n = frames_.size();
  const uint64_t frame = (q * 131 + 17) % n;
  return replicate(frames_[frame], frames_[(frame * 7 + 3) % n], rng);
}

}  // namespace mild::tools
