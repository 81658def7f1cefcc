// libFuzzer target: Keyframe and Image messages as the nodelet receives them, converted for the
// core and processed. Messages are built field by field from the input (FuzzedDataProvider), so
// the fuzzer explores what a publisher can send, not roscpp's own wire decoder.
#include <fuzzer/FuzzedDataProvider.h>

#include <memory>
#include <vector>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/detector/process_image.hpp"
#include "mild_lcd/ros/input/image_decoding.hpp"
#include "mild_lcd/ros/input/input_admission.hpp"
#include "mild_lcd/ros/messages/message_conversions.hpp"

namespace {

// One detector per feature source: images go through ORB, BRISK or AKAZE (their pyramids and
// borders fail differently on tiny images), keyframes of any descriptor_bytes meet a 32- or
// 64-byte database.
mild::LoopDetector& detector(int which) {
  static std::vector<std::unique_ptr<mild::LoopDetector>> detectors = [] {
    std::vector<std::unique_ptr<mild::LoopDetector>> out;
    for (const char* type : {"orb", "brisk", "akaze"}) {
      mild::DetectorParams p;
      p.features.type = type;
      p.database.index.expected_features = 10000;
      p.candidates.exclusion_frames = 2;
      out.push_back(std::make_unique<mild::LoopDetector>(p));
    }
    return out;
  }();
  return *detectors[static_cast<size_t>(which)];
}

mild_lcd::KeyPoint keypoint(FuzzedDataProvider& in) {
  mild_lcd::KeyPoint k;
  k.x = in.ConsumeFloatingPoint<float>();
  k.y = in.ConsumeFloatingPoint<float>();
  k.size = in.ConsumeFloatingPoint<float>();
  k.angle = in.ConsumeFloatingPoint<float>();
  k.response = in.ConsumeFloatingPoint<float>();
  k.octave = in.ConsumeIntegral<int32_t>();
  return k;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzedDataProvider in(data, size);
  try {
    if (in.ConsumeBool()) {
      mild_lcd::Keyframe msg;
      msg.has_id = in.ConsumeBool();
      msg.id = in.ConsumeIntegral<uint64_t>();
      msg.header.stamp.sec = in.ConsumeIntegral<uint32_t>();
      const size_t n = in.ConsumeIntegralInRange<size_t>(0, 64);
      for (size_t i = 0; i < n; ++i) msg.keypoints.push_back(keypoint(in));
      msg.descriptor_bytes = in.ConsumeBool() ? 0 : in.ConsumeIntegralInRange<uint32_t>(0, 80);
      msg.descriptors = in.ConsumeBytes<uint8_t>(in.ConsumeIntegralInRange<size_t>(0, 64 * 65));
      if (in.ConsumeBool()) {  // intrinsics: K[0], K[4], K[2], K[5] any double (zero, negative, NaN, huge)
        for (size_t k : {0, 4, 2, 5}) msg.camera_info.K[k] = in.ConsumeFloatingPoint<double>();
      }
      if (in.ConsumeBool()) {  // depths: one per keypoint, or a wrong count
        const size_t depths = in.ConsumeBool() ? n : in.ConsumeIntegralInRange<size_t>(0, 70);
        for (size_t i = 0; i < depths; ++i) msg.depths.push_back(in.ConsumeFloatingPoint<float>());
      }
      mild_lcd::checkedInputBytes(msg, mild_lcd::InputLimits{});  // as the node does when it queues one
      const mild::Features f = mild_lcd::featuresFromMsg(msg);
      std::optional<uint64_t> id;
      if (msg.has_id) id = msg.id;
      detector(in.ConsumeBool() ? 1 : 0).process(mild::Observation::ofFeatures(f, msg.header.stamp.toSec(), id));
    } else {
      const int which = in.ConsumeIntegralInRange<int>(0, 2);
      sensor_msgs::Image msg;
      msg.encoding = in.PickValueInArray<std::string>(
          {"mono8", "bgr8", "rgb8", "bgra8", "rgba8", "mono16", "16UC1", "32FC1", "8UC1", "yuv422", ""});
      msg.width = in.ConsumeIntegralInRange<uint32_t>(0, 96);
      msg.height = in.ConsumeIntegralInRange<uint32_t>(0, 96);
      msg.step = in.ConsumeIntegralInRange<uint32_t>(0, 400);
      msg.is_bigendian = in.ConsumeBool();
      const bool exact = in.ConsumeBool();  // mostly exactly step x height, as an image must be
      msg.data = in.ConsumeRemainingBytes<uint8_t>();
      if (exact) msg.data.resize(static_cast<size_t>(msg.step) * msg.height);
      const mild_lcd::DecodedImage image = mild_lcd::imageFromMsg(msg);
      mild::processImage(detector(which), image.image, image.format, 0.0);
    }
  } catch (const mild::Error&) {
  }
  return 0;
}
