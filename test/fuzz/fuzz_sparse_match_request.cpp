// libFuzzer target: sparse_match service requests (ids or descriptors, keypoints, any sizes) served
// against a small stored database. Every request must get a response; failures come back as
// success = false with a message.
#include <fuzzer/FuzzedDataProvider.h>

#include <random>

#include "mild_lcd/ros/services/sparse_match_service.hpp"

namespace {

mild::Features storedFeatures(uint64_t id) {
  std::mt19937_64 rng(id);
  mild::Features f;
  for (int i = 0; i < 40; ++i) {
    mild::Descriptor d;  // ORB's 32 bytes: the words past them stay zero
    for (int w = 0; w < d.numWords(); ++w) d.words[w] = rng();
    f.descriptors.push_back(d);
    f.keypoints.emplace_back(static_cast<float>(rng() % 320), static_cast<float>(rng() % 240), 7.0f);
  }
  return f;
}

std::vector<mild_lcd::KeyPoint> keypoints(FuzzedDataProvider& in) {
  std::vector<mild_lcd::KeyPoint> out(in.ConsumeIntegralInRange<size_t>(0, 48));
  for (auto& k : out) {
    k.x = in.ConsumeFloatingPoint<float>();
    k.y = in.ConsumeFloatingPoint<float>();
    k.octave = in.ConsumeIntegral<int32_t>();
  }
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const mild::GeometricVerifier verifier{mild::VerificationParams{}};
  FuzzedDataProvider in(data, size);
  mild_lcd::SparseMatch::Request request;
  request.query_id = in.ConsumeIntegralInRange<uint64_t>(0, 6);
  request.train_id = in.ConsumeIntegralInRange<uint64_t>(0, 6);
  request.use_descriptors = in.ConsumeBool();
  request.descriptor_bytes = in.ConsumeBool() ? 0 : in.ConsumeIntegralInRange<uint32_t>(0, 80);
  request.query_descriptors = in.ConsumeBytes<uint8_t>(in.ConsumeIntegralInRange<size_t>(0, 48 * 64 + 5));
  request.train_descriptors = in.ConsumeBytes<uint8_t>(in.ConsumeIntegralInRange<size_t>(0, 48 * 64 + 5));
  request.query_keypoints = keypoints(in);
  request.train_keypoints = keypoints(in);
  const auto stored = [](uint64_t id) -> std::optional<mild::Features> {
    if (id >= 5) return std::nullopt;  // ids 0..4 are stored
    return storedFeatures(id);
  };
  const mild_lcd::SparseMatch::Response response = mild_lcd::sparseMatch(request, stored, verifier);
  if (!response.success && response.message.empty()) __builtin_trap();  // a failure must say why
  if (response.model_fitted && response.inlier_mask.size() != response.matches.size()) __builtin_trap();
  return 0;
}
