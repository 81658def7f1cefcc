#include "mild_lcd/detector/process_image.hpp"

#include "mild_lcd/detector/feature_front_end.hpp"

namespace mild {

DetectionResult processImage(LoopDetector& detector, const cv::Mat& image, PixelFormat format, double stamp,
                             std::optional<uint64_t> id, const CameraIntrinsics& camera) {
  const FeatureFrontEnd front_end(detector.params().features);
  return detector.process(front_end.extract(Observation::ofImage(image, format, stamp, id, camera)));
}

DetectionResult processImage(RobotTeam& team, size_t robot, const cv::Mat& image, PixelFormat format, double stamp,
                             std::optional<uint64_t> id, const CameraIntrinsics& camera) {
  const FeatureFrontEnd front_end(team.params().features);
  return team.process(front_end.extract(Observation::ofImage(image, format, stamp, id, camera, robot)));
}

}  // namespace mild
