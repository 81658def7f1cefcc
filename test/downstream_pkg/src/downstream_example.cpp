// What another package can do with mild_lcd through catkin: run the detector on images (core
// library), fill a LoopClosure message (generated messages) and close a loop in the example pose
// graph (mild_lcd_pose_graph). Exits 0 and prints "downstream: ok" when each part works.

#include <cmath>
#include <iostream>

#include <opencv2/imgproc.hpp>

#include <mild_lcd/LoopClosure.h>
#include <mild_lcd/backend/pose_graph.hpp>
#include <mild_lcd/detector/loop_detector.hpp>
#include <mild_lcd/detector/process_image.hpp>

int main() {
  // The detector: two textured frames, the second a shifted copy of the first.
  cv::Mat image(240, 320, CV_8UC1);
  cv::RNG rng(7);
  rng.fill(image, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(image, image, cv::Size(5, 5), 1.5);
  mild::LoopDetector detector;
  mild::processImage(detector, image, mild::PixelFormat::kGray, 0.0);
  const mild::DetectionResult second = mild::processImage(detector, image, mild::PixelFormat::kGray, 0.1);
  if (detector.map().size() != 2 || second.stats.features == 0) {
    std::cerr << "downstream: the detector did not store both keyframes\n";
    return 1;
  }

  // The messages.
  mild_lcd::LoopClosure closure;
  closure.query_id = second.query_id;
  closure.features = static_cast<int32_t>(second.stats.features);
  mild_lcd::LoopCandidate candidate;
  candidate.id = 0;
  candidate.accepted = true;
  closure.candidates.push_back(candidate);

  // The example back-end: a robot drives 4 m, turns back and returns; the loop to the start fixes
  // the odometry's heading error.
  mild::backend::PoseGraphParams plain;
  plain.robust_loss = "none";
  plain.odometry_rotation_per_rad = 0.05;  // the turn on the spot is not exact either
  mild::backend::PoseGraph2D graph(plain);
  graph.addKeyframe(0, {0.0, 0.0, 0.0});
  graph.addKeyframe(1, {4.0, 0.0, 0.0});
  graph.addKeyframe(2, {4.0, 0.0, 3.0});  // the odometry says 3.0 rad; truly pi
  mild::backend::LoopMeasurement loop;
  loop.query = 2;
  loop.candidate = 0;
  // Candidate 0 seen from keyframe 2: turned by pi (about the camera's y axis, which points down).
  loop.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(-mild::backend::kPi, Eigen::Vector3d::UnitY()));
  loop.translation = Eigen::Vector3d(0.0, 0.0, 1.0);  // straight ahead, unit (no depth)
  if (!graph.addLoop(loop)) {
    std::cerr << "downstream: the pose graph refused the loop\n";
    return 1;
  }
  graph.optimize();
  const double yaw = graph.estimate(2).yaw;
  if (std::abs(std::abs(yaw) - mild::backend::kPi) > std::abs(3.0 - mild::backend::kPi)) {
    std::cerr << "downstream: the loop did not correct the heading (" << yaw << ")\n";
    return 1;
  }
  std::cout << "downstream: ok (" << detector.map().size() << " keyframes, " << closure.candidates.size()
            << " candidate, heading " << yaw << " rad after the loop)\n";
  return 0;
}
