#include "mild_lcd/ros/conversions.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <ros/serialization.h>
#include <sensor_msgs/image_encodings.h>
#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>

#include "mild_lcd/common/errors.hpp"

namespace mild_lcd {
namespace enc = sensor_msgs::image_encodings;

namespace {

struct Layout {
  const char* encoding;
  int type;
  mild::PixelFormat format;
};

// Encodings handed to the core without conversion.
constexpr Layout kDirect[] = {
    {"mono8", CV_8UC1, mild::PixelFormat::kGray}, {"8UC1", CV_8UC1, mild::PixelFormat::kGray},
    {"bgr8", CV_8UC3, mild::PixelFormat::kBgr},   {"rgb8", CV_8UC3, mild::PixelFormat::kRgb},
    {"bgra8", CV_8UC4, mild::PixelFormat::kBgra}, {"rgba8", CV_8UC4, mild::PixelFormat::kRgba},
};

constexpr Layout kMono16{"mono16", CV_16UC1, mild::PixelFormat::kGray};

// The layout of an accepted encoding; InvalidInput for any other.
const Layout& layoutOf(const std::string& encoding) {
  for (const Layout& l : kDirect) {
    if (encoding == l.encoding) return l;
  }
  if (encoding == enc::MONO16 || encoding == enc::TYPE_16UC1) return kMono16;
  throw mild::InvalidInput("unsupported image encoding '" + encoding +
                           "' (accepted: mono8, mono16, bgr8, rgb8, bgra8, rgba8)");
}

void refuseLargerThan(uint64_t width, uint64_t height, uint64_t max_pixels, const char* what) {
  if (width * height > max_pixels) {
    throw mild::InvalidInput(std::string(what) + " of " + std::to_string(width) + " x " + std::to_string(height) +
                             " pixels is larger than ~max_image_pixels (" + std::to_string(max_pixels) + ")");
  }
}

// What a message holds besides its payload (header, encoding, camera_info, ...) is small.
template <class Msg>
size_t checkedOverhead(const Msg& msg, size_t payload_bytes, const char* what) {
  const size_t total = ros::serialization::serializationLength(msg);
  if (total - payload_bytes > kMaxMessageOverheadBytes) {
    throw mild::InvalidInput(std::string(what) + " holds " + std::to_string(total - payload_bytes) +
                             " bytes besides its payload (header, strings, camera_info), more than " +
                             std::to_string(kMaxMessageOverheadBytes));
  }
  return total;
}

// Wraps the message buffer; checkedInputBytes has made sure that it holds height rows of step bytes.
cv::Mat wrap(const sensor_msgs::Image& msg, int type) {
  return cv::Mat(static_cast<int>(msg.height), static_cast<int>(msg.width), type, const_cast<uint8_t*>(msg.data.data()),
                 msg.step);
}

uint32_t bigEndian(const uint8_t* p, int bytes) {
  uint32_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | p[i];
  return v;
}

}  // namespace

std::optional<cv::Size> compressedImageSize(const std::vector<uint8_t>& data) {
  const size_t n = data.size();
  const uint8_t* d = data.data();
  static constexpr uint8_t kPng[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  if (n >= 24 && std::equal(kPng, kPng + 8, d) && std::equal(d + 12, d + 16, "IHDR")) {
    const uint32_t w = bigEndian(d + 16, 4), h = bigEndian(d + 20, 4);
    if (w > INT32_MAX || h > INT32_MAX) return cv::Size(INT32_MAX, INT32_MAX);
    return cv::Size(static_cast<int>(w), static_cast<int>(h));
  }
  if (n >= 4 && d[0] == 0xFF && d[1] == 0xD8) {  // JPEG: walk the markers to the frame header
    size_t pos = 2;
    while (pos + 4 <= n) {
      if (d[pos] != 0xFF) return std::nullopt;
      const uint8_t marker = d[pos + 1];
      if (marker == 0xFF) {  // fill byte
        ++pos;
        continue;
      }
      if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD9)) {  // no length field
        pos += 2;
        continue;
      }
      const size_t length = bigEndian(d + pos + 2, 2);
      const bool frame_header = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
      if (frame_header) {
        if (pos + 9 > n) return std::nullopt;
        return cv::Size(static_cast<int>(bigEndian(d + pos + 7, 2)), static_cast<int>(bigEndian(d + pos + 5, 2)));
      }
      if (length < 2) return std::nullopt;
      pos += 2 + length;
    }
  }
  return std::nullopt;
}

size_t checkedInputBytes(const sensor_msgs::Image& msg, const InputLimits& limits) {
  if (msg.width == 0 || msg.height == 0) {
    throw mild::InvalidInput("empty image (" + std::to_string(msg.width) + " x " + std::to_string(msg.height) + ")");
  }
  refuseLargerThan(msg.width, msg.height, limits.max_image_pixels, "image");
  if (msg.width > 1u << 15 || msg.height > 1u << 15) throw mild::InvalidInput("image larger than 32768 pixels a side");
  const Layout& layout = layoutOf(msg.encoding);
  const uint64_t pixel_bytes = static_cast<uint64_t>(CV_ELEM_SIZE(layout.type));
  const uint64_t row_bytes = msg.width * pixel_bytes;
  if (msg.step < row_bytes) {
    throw mild::InvalidInput("image step " + std::to_string(msg.step) + " is smaller than a row of " +
                             std::to_string(msg.width) + " pixels (" + std::to_string(row_bytes) + " bytes)");
  }
  // OpenCV refuses (throws on) rows that do not start on a whole sample, e.g. an odd step in mono16.
  if (msg.step % CV_ELEM_SIZE1(layout.type) != 0) {
    throw mild::InvalidInput("image step " + std::to_string(msg.step) + " is not a multiple of the " +
                             std::to_string(CV_ELEM_SIZE1(layout.type)) + "-byte sample of " + msg.encoding);
  }
  const uint64_t declared = static_cast<uint64_t>(msg.step) * msg.height;
  if (msg.data.size() != declared) {
    throw mild::InvalidInput("image data holds " + std::to_string(msg.data.size()) + " bytes but " +
                             std::to_string(msg.height) + " rows of " + std::to_string(msg.step) +
                             " are declared (it must be exactly step x height)");
  }
  // A narrow image with a huge step is as large as a wide one.
  if (declared > limits.max_image_pixels * pixel_bytes) {
    throw mild::InvalidInput("image data of " + std::to_string(declared) + " bytes (step " + std::to_string(msg.step) +
                             ") is more than ~max_image_pixels (" + std::to_string(limits.max_image_pixels) +
                             ") pixels of " + msg.encoding + " hold");
  }
  return checkedOverhead(msg, msg.data.size(), "image");
}

size_t checkedInputBytes(const sensor_msgs::CompressedImage& msg, const InputLimits& limits) {
  if (msg.data.empty()) throw mild::InvalidInput("empty compressed image");
  const uint64_t max_bytes = kMaxCompressedBytesPerPixel * limits.max_image_pixels;
  if (msg.data.size() > max_bytes) {
    throw mild::InvalidInput("compressed image of " + std::to_string(msg.data.size()) + " bytes is larger than " +
                             std::to_string(max_bytes) + " (" + std::to_string(kMaxCompressedBytesPerPixel) +
                             " bytes per pixel of ~max_image_pixels)");
  }
  // The header's size, before a decoder allocates for it: 500 bytes may claim 20000 x 20000
  // pixels. Only formats whose header is read here are decoded at all (a TIFF or WebP decoder
  // allocates for its header's size before anything could judge it).
  const auto size = compressedImageSize(msg.data);
  if (!size) {
    throw mild::InvalidInput("compressed image (format '" + msg.format +
                             "') is not a JPEG or PNG whose header gives its size: only those are decoded");
  }
  if (size->width <= 0 || size->height <= 0) throw mild::InvalidInput("compressed image declares no pixels");
  refuseLargerThan(static_cast<uint64_t>(size->width), static_cast<uint64_t>(size->height), limits.max_image_pixels,
                   "compressed image");
  return checkedOverhead(msg, msg.data.size(), "compressed image");
}

size_t checkedInputBytes(const mild_lcd::Keyframe& msg, const InputLimits& limits) {
  const size_t n = limits.max_keyframe_features;
  if (msg.keypoints.size() > n || msg.descriptors.size() > n * mild::kMaxDescriptorBytes || msg.depths.size() > n) {
    throw mild::InvalidInput("keyframe has " + std::to_string(msg.keypoints.size()) + " keypoints, " +
                             std::to_string(msg.descriptors.size()) + " descriptor bytes and " +
                             std::to_string(msg.depths.size()) + " depths: more than ~max_keyframe_features (" +
                             std::to_string(n) + ") allows");
  }
  const size_t payload = msg.keypoints.size() * ros::serialization::serializationLength(mild_lcd::KeyPoint()) +
                         msg.descriptors.size() + msg.depths.size() * sizeof(float);
  return checkedOverhead(msg, payload, "keyframe");
}

DecodedImage imageFromMsg(const sensor_msgs::Image& msg, uint64_t max_pixels) {
  checkedInputBytes(msg, InputLimits{max_pixels, kDefaultMaxKeyframeFeatures});
  const Layout& layout = layoutOf(msg.encoding);
  if (layout.type != CV_16UC1) return DecodedImage{wrap(msg, layout.type), layout.format};
  if (msg.is_bigendian) throw mild::InvalidInput("big-endian mono16 images are not supported");
  DecodedImage out;
  wrap(msg, CV_16UC1).convertTo(out.image, CV_8UC1, 1.0 / 256.0);
  return out;
}

DecodedImage imageFromMsg(const sensor_msgs::CompressedImage& msg, uint64_t max_pixels) {
  checkedInputBytes(msg, InputLimits{max_pixels, kDefaultMaxKeyframeFeatures});
  cv::Mat decoded;
  try {
    decoded = cv::imdecode(msg.data, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    decoded.release();
  }
  if (decoded.empty()) throw mild::InvalidInput("compressed image (format '" + msg.format + "') cannot be decoded");
  refuseLargerThan(static_cast<uint64_t>(decoded.cols), static_cast<uint64_t>(decoded.rows), max_pixels,
                   "decoded image");
  if (decoded.depth() == CV_16U) decoded.convertTo(decoded, CV_8U, 1.0 / 256.0);
  if (const auto format = mild::decodedPixelFormat(decoded.channels())) return DecodedImage{decoded, *format};
  throw mild::InvalidInput("compressed image has " + std::to_string(decoded.channels()) + " channels");
}

std::vector<cv::KeyPoint> keypointsFromMsg(const std::vector<mild_lcd::KeyPoint>& msg) {
  std::vector<cv::KeyPoint> out;
  out.reserve(msg.size());
  for (const auto& k : msg) {
    if (!std::isfinite(k.x) || !std::isfinite(k.y)) throw mild::InvalidInput("keypoint with a non-finite position");
    out.emplace_back(k.x, k.y, k.size, k.angle, k.response, k.octave);
  }
  return out;
}

std::vector<mild_lcd::KeyPoint> keypointsToMsg(const std::vector<cv::KeyPoint>& keypoints) {
  std::vector<mild_lcd::KeyPoint> out(keypoints.size());
  for (size_t i = 0; i < keypoints.size(); ++i) {
    out[i].x = keypoints[i].pt.x;
    out[i].y = keypoints[i].pt.y;
    out[i].size = keypoints[i].size;
    out[i].angle = keypoints[i].angle;
    out[i].response = keypoints[i].response;
    out[i].octave = keypoints[i].octave;
  }
  return out;
}

ros::Time stampOf(double seconds) {
  // ros::Time holds unsigned 32-bit seconds; a stamp outside (a keyframe given time 0, or a file
  // from elsewhere) is clamped rather than thrown at the publisher.
  if (!(seconds > 0.0)) return ros::Time(0, 0);
  if (seconds >= 4294967295.0) return ros::Time(4294967295u, 0);
  return ros::Time(seconds);
}

int descriptorBytesOf(uint32_t field) {
  if (field == 0) return mild::kOrbDescriptorBytes;
  if (field > static_cast<uint32_t>(mild::kMaxDescriptorBytes)) {
    throw mild::InvalidInput("descriptor_bytes " + std::to_string(field) + " is not a supported width (8..64)");
  }
  return static_cast<int>(field);
}

mild::Features featuresFromMsg(const mild_lcd::Keyframe& msg) {
  mild::Features f;
  f.declared_bytes = descriptorBytesOf(msg.descriptor_bytes);  // 0 declares ORB's 32
  f.descriptors = mild::descriptorsFromBytes(msg.descriptors.data(), msg.descriptors.size(), f.declared_bytes,
                                             static_cast<long>(msg.keypoints.size()));
  f.keypoints = keypointsFromMsg(msg.keypoints);
  f.camera = intrinsicsFromMsg(msg.camera_info);
  f.depths = msg.depths;  // their count is checked by the detector (checkCameraAndDepths)
  return f;
}

mild::CameraIntrinsics intrinsicsFromMsg(const sensor_msgs::CameraInfo& msg) {
  const mild::CameraIntrinsics camera{msg.K[0], msg.K[4], msg.K[2], msg.K[5]};
  // Unknown when the entries read are zero, whatever the others hold: drivers without a
  // calibration commonly send K all zero but K[8] = 1.
  if (camera.fx == 0.0 && camera.fy == 0.0 && camera.cx == 0.0 && camera.cy == 0.0) return {};
  // Finite but absurd values (fx 1e12, 1e-300) would not fail loudly: every candidate would just
  // fail verification.
  const auto plausible = [](double focal) { return focal >= kMinFocalPixels && focal <= kMaxFocalPixels; };
  if (!camera.known() || !camera.wellFormed() || !plausible(camera.fx) || !plausible(camera.fy) ||
      std::abs(camera.cx) > kMaxFocalPixels || std::abs(camera.cy) > kMaxFocalPixels) {
    throw mild::InvalidInput(
        "camera_info K needs fx (K[0]) and fy (K[4]) within [1, 1e6] pixels and cx (K[2]), cy (K[5]) "
        "within +-1e6; got " +
        std::to_string(camera.fx) + ", " + std::to_string(camera.fy) + ", " + std::to_string(camera.cx) + ", " +
        std::to_string(camera.cy) + " (fx, fy, cx, cy all zero = unknown)");
  }
  return camera;
}

mild_lcd::LoopClosure loopClosureToMsg(const mild::DetectionResult& result, const std_msgs::Header& header,
                                       size_t database_size, bool correspondences,
                                       const std::vector<std::string>& robot_names) {
  const auto robotName = [&](uint32_t robot) { return robot < robot_names.size() ? robot_names[robot] : ""; };
  mild_lcd::LoopClosure msg;
  msg.header = header;
  msg.query_id = result.query_id;
  msg.query_session = result.query_session;
  msg.query_robot = robotName(result.query_robot);
  msg.features = static_cast<int32_t>(result.stats.features);
  msg.database_size = static_cast<int32_t>(database_size);
  msg.extract_ms = result.stats.extract_ms;
  msg.query_ms = result.stats.query_ms;
  msg.filter_ms = result.stats.filter_ms;
  msg.verify_ms = result.stats.verify_ms;
  msg.near_past_keyframes = static_cast<int32_t>(result.stats.near_past_keyframes);
  for (const mild::LoopCandidate& c : result.candidates) {
    mild_lcd::LoopCandidate m;
    m.id = c.id;
    m.session = c.session;
    m.robot = robotName(c.robot);
    m.stamp = stampOf(c.stamp);
    m.probability = c.probability;
    m.accepted = c.accepted;
    m.filter_probability = c.filter_probability;
    m.similarity = c.similarity;
    m.verified = c.verification.verified;
    m.inliers = c.verification.inliers;
    m.matches = c.verification.matches;
    m.inlier_ratio = c.verification.inlier_ratio;
    m.fit_skipped = c.verification.fit_skipped;
    m.coverage = c.verification.coverage;
    m.homography_share = c.verification.homography_share;
    const mild::RelativePose& pose = c.verification.pose;
    m.has_relative_pose = pose.valid;
    if (pose.valid) {
      Eigen::Matrix3d rotation;
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) rotation(r, c) = pose.rotation(r, c);
      const Eigen::Quaterniond q(rotation);
      m.relative_rotation.x = q.x();
      m.relative_rotation.y = q.y();
      m.relative_rotation.z = q.z();
      m.relative_rotation.w = q.w();
      m.relative_translation.x = pose.translation[0];
      m.relative_translation.y = pose.translation[1];
      m.relative_translation.z = pose.translation[2];
      m.metric_translation = pose.metric;
      m.pose_inliers = pose.inliers;
      m.reprojection_error = pose.reprojection_error;
    } else {
      m.relative_rotation.w = 1.0;  // identity, never an invalid all-zero quaternion
    }
    if (correspondences && c.verification.verified) {
      const mild::Verification& v = c.verification;
      for (const mild::FeatureMatch& match : v.inlier_matches) {
        m.inlier_query_indices.push_back(match.query);
        m.inlier_candidate_indices.push_back(match.train);
      }
      for (size_t i = 0; i < v.inlier_query_points.size() && i < v.inlier_candidate_points.size(); ++i) {
        m.inlier_query_pixels.insert(m.inlier_query_pixels.end(),
                                     {v.inlier_query_points[i].x, v.inlier_query_points[i].y});
        m.inlier_candidate_pixels.insert(m.inlier_candidate_pixels.end(),
                                         {v.inlier_candidate_points[i].x, v.inlier_candidate_points[i].y});
      }
    }
    msg.candidates.push_back(m);
  }
  return msg;
}

namespace {

mild::Features requestSide(const std::vector<uint8_t>& descriptors, const std::vector<mild_lcd::KeyPoint>& keypoints,
                           int bytes, const char* side, size_t max_features) {
  if (descriptors.empty()) throw mild::InvalidInput(std::string(side) + "_descriptors is empty");
  const size_t rows = descriptors.size() / static_cast<size_t>(bytes);
  if (rows > max_features || keypoints.size() > max_features) {
    throw mild::CapacityError(std::string(side) + " side has " + std::to_string(std::max(rows, keypoints.size())) +
                              " features, more than ~max_match_features (" + std::to_string(max_features) + ")");
  }
  mild::Features f;
  try {
    f.descriptors = mild::descriptorsFromBytes(descriptors.data(), descriptors.size(), bytes,
                                               keypoints.empty() ? -1 : static_cast<long>(keypoints.size()));
  } catch (const mild::InvalidInput& e) {
    throw mild::InvalidInput(std::string(side) + ": " + e.what());
  }
  f.keypoints = keypointsFromMsg(keypoints);
  return f;
}

}  // namespace

mild_lcd::SparseMatch::Response sparseMatch(const mild_lcd::SparseMatch::Request& request, const StoredFeatures& stored,
                                            const mild::GeometricVerifier& verifier, size_t max_features) {
  mild_lcd::SparseMatch::Response response;
  try {
    mild::Features query, train;
    if (request.use_descriptors) {
      const int bytes = descriptorBytesOf(request.descriptor_bytes);
      query = requestSide(request.query_descriptors, request.query_keypoints, bytes, "query", max_features);
      train = requestSide(request.train_descriptors, request.train_keypoints, bytes, "train", max_features);
    } else {
      if (!request.query_descriptors.empty() || !request.train_descriptors.empty()) {
        throw mild::InvalidInput(
            "descriptors were given but use_descriptors is false: set it to match them, "
            "or leave them empty to match stored keyframes by id");
      }
      auto q = stored(request.query_id);
      if (!q) throw mild::InvalidInput("unknown query_id " + std::to_string(request.query_id));
      auto t = stored(request.train_id);
      if (!t) throw mild::InvalidInput("unknown train_id " + std::to_string(request.train_id));
      // Stored keyframes are bounded like requests: a map loaded from a file may hold keyframes of
      // any size, and matching two of 100,000 features held the service thread for a minute.
      const auto refuseIfOver = [max_features](const char* side, uint64_t id, const mild::Features& f) {
        if (f.descriptors.size() <= max_features) return;
        throw mild::CapacityError(std::string(side) + " keyframe " + std::to_string(id) + " has " +
                                  std::to_string(f.descriptors.size()) + " features, more than ~max_match_features (" +
                                  std::to_string(max_features) + ")");
      };
      refuseIfOver("query", request.query_id, *q);
      refuseIfOver("train", request.train_id, *t);
      query = std::move(*q);
      train = std::move(*t);
    }
    const bool with_geometry = !query.keypoints.empty() && !train.keypoints.empty();
    mild::GeometricCheck check;
    if (with_geometry) {
      check = verifier.check(query, train);
    } else {
      mild::SparseMatcher matcher(verifier.params().matching);
      check.matches = matcher.match(query.descriptors, train.descriptors);
    }
    for (const auto& m : check.matches) {
      mild_lcd::FeatureMatch fm;
      fm.query = m.query;
      fm.train = m.train;
      fm.distance = m.distance;
      response.matches.push_back(fm);
    }
    response.model_fitted = !check.model.empty();
    response.inlier_mask = check.inlier_mask;
    response.inliers = check.verification.inliers;
    response.verified = check.verification.verified;
    if (response.model_fitted) {
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) response.model.push_back(check.model.at<double>(r, c));
      }
    }
    response.success = true;
    response.message = std::to_string(response.matches.size()) + " matches" +
                       (with_geometry ? ", " + std::to_string(response.inliers) + " inliers" +
                                            (response.verified ? " (verified)" : " (not verified)")
                                      : " (no keypoints: no geometric check)");
  } catch (const mild::Error& e) {
    response = mild_lcd::SparseMatch::Response();
    response.success = false;
    response.message = e.what();
  }
  return response;
}

}  // namespace mild_lcd
