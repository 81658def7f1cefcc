#pragma once

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include "mild_lcd/features/camera_intrinsics.hpp"
#include "mild_lcd/features/descriptor.hpp"

namespace mild {

// Channel order of an 8-bit input image.
enum class PixelFormat { kGray, kBgr, kRgb, kBgra, kRgba };

// Keypoints and their binary descriptors, row i of one describing keypoint i of the other.
// Optionally the camera's intrinsics, and each keypoint's depth (metres along the optical axis,
// from a depth camera or the front-end's triangulation; 0 or not finite = unknown, and so is any
// depth outside [kMinDepthMetres, kMaxDepthMetres]), which make the relative pose of a loop metric
// (PnP) instead of up to scale.
struct Features {
  std::vector<cv::KeyPoint> keypoints;
  DescriptorList descriptors;
  CameraIntrinsics camera;
  std::vector<float> depths;  // empty, or one per keypoint
  // The descriptor width the sender declared (a Keyframe's descriptor_bytes), 0 when none: checked
  // against the database's even when there are no descriptors to check.
  int declared_bytes = 0;
  // Pixels of the frame per pixel of the image the keypoints were detected in: 1, or 1/s when
  // features/max_pixels shrank the frame by s before extraction (the keypoints are then mapped back
  // to the frame's pixels). Such keypoints are placed 1/s less precisely, and verification widens
  // its pixel tolerances by the coarser side's scale. A stored keyframe keeps it, in a map file
  // (format version 4) and in a team peer's pulled features (TeamFeatures.detection_scale); a
  // Keyframe message carries none (1).
  float detection_scale = 1.0f;
};

// The widest detection_scale that means anything (a 64-fold shrink: 7,680 x 4,320 frames under a
// 120 x 68 cap); verification widens its tolerances as much for a larger one and no more.
constexpr float kMaxDetectionScale = 64.0f;
// Whether `scale` can be a detection_scale: finite, 1 to kMaxDetectionScale. What a map file or a
// team peer brings is checked with it; a scale of 0 from a peer means "not sent", i.e. 1.
inline bool detectionScaleValid(float scale) { return scale >= 1.0f && scale <= kMaxDetectionScale; }
// A scale as verification follows it, stores it and sends it: within [1, kMaxDetectionScale]; one
// that is not a number, infinite or below 1 is 1 (a caller's absurd scale must not make every match
// an inlier), and a larger shrink is judged as the widest, so storing the widest loses nothing.
inline float boundedDetectionScale(float scale) {
  return std::isfinite(scale) && scale > 1.0f ? std::min(scale, kMaxDetectionScale) : 1.0f;
}

// The depths a keypoint may have: 1 cm to 10 km. Closer than any camera focuses, or farther than
// any depth sensor or triangulation measures, a depth is a unit or scale error (1e30 m gave loops
// 1e29 m long, 1e-30 m loops of exactly 0 m, both published as metric): it is taken as unknown.
constexpr float kMinDepthMetres = 0.01f;
constexpr float kMaxDepthMetres = 1e4f;
inline bool depthKnown(float depth) { return depth >= kMinDepthMetres && depth <= kMaxDepthMetres; }
// How many of `depths` were given but are not plausible: finite, not 0 (unknown), and outside the
// range above (negative included). NaN and infinities, depth cameras' marks of "no return" (REP
// 117), are unknown without being counted.
size_t depthsOutOfRange(const std::vector<float>& depths);

// Throws InvalidInput, naming the problem, when the camera is malformed (CameraIntrinsics::wellFormed)
// or there are depths but not one per keypoint.
void checkCameraAndDepths(const Features& features);

// The channel order OpenCV's decoders (imread, imdecode) give an image of `channels` channels: 1
// grey, 3 BGR, 4 BGRA; nullopt for any other count.
std::optional<PixelFormat> decodedPixelFormat(int channels);

// Converts an 8-bit image of the given format to one grey channel. Throws InvalidInput for an empty
// image, a depth other than 8 bits, or a channel count that does not match the format.
cv::Mat toGray(const cv::Mat& image, PixelFormat format);

// Detectors keep every keypoint that ties with the weakest one they retain (OpenCV's ORB), or have
// no cap at all (BRISK, AKAZE), so a tiled texture yields many times the wanted count. Keeps exactly
// the strongest `limit` keypoints and their descriptor rows, ties broken by octave and position so
// that the choice is deterministic, in the detector's order.
void keepStrongest(std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors, size_t limit);

// How many features an image of `pixels` pixels keeps when `count` is meant for an image of
// reference_pixels: count * sqrt(pixels / reference_pixels), at most 4 * count and at least 1;
// `count` itself when reference_pixels is 0. The square root keeps a large image's features about
// as dense per unit of scale as a small one's while its cost grows less than its area.
size_t featureBudget(int count, size_t pixels, double reference_pixels);

// Runs an OpenCV detector-descriptor on a grey image and keeps the strongest `limit` features.
// Images thinner than `min_side` pixels yield no features (detectors fail on them in their pyramid);
// any OpenCV failure becomes InvalidInput naming `name` and the image size. Descriptors must come
// out `bytes` wide.
Features detectAndDescribe(cv::Feature2D& detector, const cv::Mat& gray, size_t limit, int min_side, int bytes,
                           const char* name);

}  // namespace mild
