// test_ros_parts: message admission and conversion (ros/input/input_admission.hpp,
// ros/input/image_decoding.hpp, ros/messages/message_conversions.hpp,
// ros/services/sparse_match_service.hpp): compressed-image headers, input bounds,
// sparse_match requests, LoopClosure fields.

#include <limits>

#include "ros_parts_support.hpp"

namespace mild_lcd {
namespace {

using namespace ros_parts_test;  // NOLINT(google-build-using-namespace): the shared helpers

// A few hundred bytes of JPEG whose header claims 20000 x 20000 pixels are refused on the header.
TEST(CompressedImages, AreJudgedByTheirHeaderBeforeDecoding) {
  std::vector<uint8_t> jpeg;
  cv::imencode(".jpg", cv::Mat(8, 8, CV_8UC1, cv::Scalar(100)), jpeg);
  ASSERT_EQ(compressedImageSize(jpeg), cv::Size(8, 8));
  for (size_t i = 2; i + 9 < jpeg.size(); ++i) {  // rewrite the frame header's size
    if (jpeg[i] == 0xFF && jpeg[i + 1] == 0xC0) {
      jpeg[i + 5] = 20000 >> 8, jpeg[i + 6] = 20000 & 0xFF, jpeg[i + 7] = 20000 >> 8, jpeg[i + 8] = 20000 & 0xFF;
    }
  }
  ASSERT_EQ(compressedImageSize(jpeg), cv::Size(20000, 20000));
  sensor_msgs::CompressedImage msg;
  msg.format = "jpeg";
  msg.data = jpeg;
  const std::string error = errorOf([&] { imageFromMsg(msg, 4096u * 4096u); });
  EXPECT_NE(error.find("20000 x 20000"), std::string::npos) << error;

  std::vector<uint8_t> png;
  cv::imencode(".png", cv::Mat(30, 50, CV_8UC1, cv::Scalar(1)), png);
  EXPECT_EQ(compressedImageSize(png), cv::Size(50, 30));
  msg.data = png;
  EXPECT_EQ(imageFromMsg(msg, 50 * 30).image.size(), cv::Size(50, 30));
  EXPECT_THROW(imageFromMsg(msg, 50 * 30 - 1), mild::InvalidInput);
}

// Formats whose header this node does not read are refused before any decoder sees them: OpenCV's
// TIFF and WebP decoders allocate for the size their header claims (593 bytes of TIFF may claim
// 20000 x 20000 pixels).
TEST(CompressedImages, OnlyJpegAndPngAreDecoded) {
  const cv::Mat small(8, 8, CV_8UC3, cv::Scalar(10, 20, 30));
  sensor_msgs::CompressedImage msg;
  for (const std::string ext : {".tiff", ".webp", ".bmp", ".ppm"}) {
    if (!cv::haveImageWriter(ext)) continue;
    ASSERT_TRUE(cv::imencode(ext, small, msg.data)) << ext;
    msg.format = ext.substr(1);
    const std::string error = errorOf([&] { imageFromMsg(msg); });
    EXPECT_NE(error.find("not a JPEG or PNG"), std::string::npos) << ext << ": " << error;
    EXPECT_NE(errorOf([&] { checkedInputBytes(msg, InputLimits{}); }), "") << ext;
  }
  ASSERT_TRUE(cv::imencode(".jpg", small, msg.data));
  EXPECT_EQ(imageFromMsg(msg).image.size(), small.size());
  // And at most 4 bytes per pixel of ~max_image_pixels, whatever the header says.
  msg.data.resize(4 * 1000 + 1, 0);
  EXPECT_NE(errorOf([&] { imageFromMsg(msg, 1000); }).find("larger than 4000"), std::string::npos);
}

// A raw image's data is exactly step x height, and its step cannot make it larger than
// ~max_image_pixels pixels of its encoding: eight 320 x 240 images carrying 250 MB each took the
// node from 79 MB to 2.3 GB.
TEST(InputBounds, AnImagesDataIsExactlyStepTimesHeightAndBoundedInBytes) {
  auto msg = image(320, 240, 1.0);
  const InputLimits limits{640 * 480, 10000};
  EXPECT_GE(checkedInputBytes(*msg, limits), 320u * 240u);
  EXPECT_EQ(imageFromMsg(*msg, limits.max_image_pixels).image.size(), cv::Size(320, 240));
  msg->data.resize(320 * 240 + 1);  // one byte more than declared
  EXPECT_NE(errorOf([&] { imageFromMsg(*msg, limits.max_image_pixels); }).find("exactly step x height"),
            std::string::npos);
  EXPECT_NE(errorOf([&] { checkedInputBytes(*msg, limits); }), "");
  msg->step = 320 * 1000;  // a step a thousand rows wide, and data to match: 76.8 MB
  msg->data.assign(static_cast<size_t>(msg->step) * msg->height, 0);
  EXPECT_NE(errorOf([&] { checkedInputBytes(*msg, limits); }).find("more than ~max_image_pixels"), std::string::npos);
  msg = image(320, 240, 2.0);
  msg->header.frame_id.assign(100 * 1024, 'x');  // everything besides the pixels is small
  EXPECT_NE(errorOf([&] { checkedInputBytes(*msg, limits); }).find("besides its payload"), std::string::npos);
}

TEST(InputBounds, AKeyframeHasAtMostMaxKeyframeFeaturesAndSmallExtras) {
  const InputLimits limits{kDefaultMaxImagePixels, 100};
  mild_lcd::Keyframe kf;
  kf.keypoints.resize(100);
  kf.descriptors.assign(100 * 32, 1);
  kf.depths.assign(100, 1.0f);
  EXPECT_GE(checkedInputBytes(kf, limits), 100u * (24 + 32 + 4));
  kf.keypoints.resize(101);
  kf.descriptors.assign(101 * 32, 1);
  EXPECT_NE(errorOf([&] { checkedInputBytes(kf, limits); }).find("~max_keyframe_features (100)"), std::string::npos);
  kf.keypoints.resize(1);
  kf.descriptors.assign(101 * 64 + 1, 1);  // descriptors of no keypoints
  EXPECT_NE(errorOf([&] { checkedInputBytes(kf, limits); }), "");
  kf.descriptors.assign(32, 1);
  kf.depths.clear();
  kf.camera_info.D.assign(1000000, 0.0);  // 8 MB of "distortion"
  EXPECT_NE(errorOf([&] { checkedInputBytes(kf, limits); }).find("besides its payload"), std::string::npos);
}

// sparse_match by id bounds the stored keyframes as it bounds a request's descriptors: a map loaded
// from a file may hold keyframes of any size (two of 20,000 and 100,000 features held the service
// thread for 17 and 68 s).
TEST(SparseMatchRequests, StoredKeyframesAreBoundedByMaxMatchFeaturesToo) {
  const auto keyframe = [](size_t n) {
    mild::Features f;
    cv::RNG rng(static_cast<uint64_t>(n));
    for (size_t i = 0; i < n; ++i) {
      mild::Descriptor d;
      for (int w = 0; w < d.numWords(); ++w) d.words[w] = (static_cast<uint64_t>(rng.next()) << 32) | rng.next();
      f.descriptors.push_back(d);
      f.keypoints.emplace_back(static_cast<float>(rng.uniform(0, 640)), static_cast<float>(rng.uniform(0, 480)), 7.0f);
    }
    return f;
  };
  const StoredFeatures stored = [&](uint64_t id) -> std::optional<mild::Features> { return keyframe(id); };
  const mild::GeometricVerifier verifier(mild::VerificationParams{});
  mild_lcd::SparseMatch::Request request;
  request.query_id = 20000;  // the stand-in's id is its feature count
  request.train_id = 300;
  auto response = sparseMatch(request, stored, verifier, 10000);
  EXPECT_FALSE(response.success);
  EXPECT_NE(response.message.find("query keyframe 20000 has 20000 features, more than ~max_match_features (10000)"),
            std::string::npos)
      << response.message;
  std::swap(request.query_id, request.train_id);
  response = sparseMatch(request, stored, verifier, 10000);
  EXPECT_FALSE(response.success);
  EXPECT_NE(response.message.find("train keyframe 20000"), std::string::npos) << response.message;
  request.query_id = 200;
  request.train_id = 300;
  response = sparseMatch(request, stored, verifier, 300);
  EXPECT_TRUE(response.success) << response.message;
}

// A Keyframe message's descriptor_bytes reaches the detector even with no keypoints.
TEST(Conversions, AnEmptyKeyframeCarriesItsDeclaredWidth) {
  mild_lcd::Keyframe kf;
  kf.descriptor_bytes = 64;
  EXPECT_EQ(featuresFromMsg(kf).declared_bytes, 64);
  kf.descriptor_bytes = 0;
  EXPECT_EQ(featuresFromMsg(kf).declared_bytes, 32) << "0 means 32";
  kf.descriptor_bytes = 64;
  mild::LoopDetector orb;
  EXPECT_THROW(orb.process(mild::Observation::ofFeatures(featuresFromMsg(kf), 1.0)), mild::InvalidInput);
  EXPECT_EQ(orb.map().size(), 0u);
}

// A team peer's pulled keyframe keeps how much its frame was shrunk (features/max_pixels), so the
// station that verifies it widens its tolerances as the peer would; what cannot be a scale is
// refused like a torn keyframe.
TEST(Conversions, APulledKeyframeKeepsItsDetectionScale) {
  mild::Features stored;
  stored.keypoints = {cv::KeyPoint(10.f, 20.f, 31.f)};
  stored.descriptors = {mild::Descriptor(32)};
  stored.detection_scale = 2.5f;
  mild_lcd::TeamFeatures reply;
  setTeamReplyFeatures(stored, 32, reply);
  EXPECT_FLOAT_EQ(reply.detection_scale, 2.5f);
  const mild::Features pulled = featuresFromTeamReply(reply);
  EXPECT_FLOAT_EQ(pulled.detection_scale, 2.5f);
  EXPECT_EQ(pulled.keypoints.size(), 1u);
  stored.detection_scale = 1000.0f;  // a shrink beyond what verification follows is sent as the widest
  setTeamReplyFeatures(stored, 32, reply);
  EXPECT_FLOAT_EQ(reply.detection_scale, mild::kMaxDetectionScale);
  reply.detection_scale = 0.0f;  // a peer that sends none
  EXPECT_FLOAT_EQ(featuresFromTeamReply(reply).detection_scale, 1.0f);
  for (const float bad :
       {std::numeric_limits<float>::quiet_NaN(), 0.5f, -1.0f, 65.0f, std::numeric_limits<float>::infinity()}) {
    reply.detection_scale = bad;
    EXPECT_THROW(featuresFromTeamReply(reply), mild::InvalidInput) << bad;
  }
}

TEST(Conversions, StampsOutsideRosTimeAreClamped) {
  EXPECT_EQ(stampOf(-5.0), ros::Time(0, 0));
  EXPECT_EQ(stampOf(1e12), ros::Time(4294967295u, 999999999u)) << "the latest ros::Time";
  EXPECT_EQ(stampOf(12.5), ros::Time(12.5));
  // Issue 49 item 5: the last second of ros::Time is inside it, not clamped to its start.
  EXPECT_EQ(stampOf(4294967295.5), ros::Time(4294967295u, 500000000u));
  EXPECT_EQ(stampOf(4294967294.75), ros::Time(4294967294u, 750000000u));
  EXPECT_EQ(stampOf(std::nextafter(4294967296.0, 0.0)).sec, 4294967295u) << "rounding never wraps the seconds";
}

TEST(Conversions, AStepThatSplitsASampleIsRefusedNotThrownByOpenCv) {
  // Found by fuzz_keyframe_message: mono16 rows of an odd number of bytes made cv::Mat throw.
  sensor_msgs::Image msg;
  msg.encoding = "mono16";
  msg.width = 4;
  msg.height = 2;
  msg.step = 9;
  msg.data.assign(18, 0);
  try {
    imageFromMsg(msg, 1u << 24);
    FAIL() << "an odd mono16 step was accepted";
  } catch (const mild::InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("multiple of the 2-byte sample"), std::string::npos) << e.what();
  }
  msg.step = 10;
  msg.data.assign(20, 0);
  EXPECT_EQ(imageFromMsg(msg, 1u << 24).image.rows, 2) << "an even padded step is fine";
}

TEST(Conversions, TheRelativePoseIsPublishedAsAUnitQuaternionAndDirection) {
  mild::DetectionResult result;
  mild::LoopCandidate posed, plain;
  const double a = 30.0 * M_PI / 180.0;  // about the optical y axis
  posed.verification.pose.valid = true;
  posed.verification.pose.rotation = cv::Matx33d(std::cos(a), 0, std::sin(a), 0, 1, 0, -std::sin(a), 0, std::cos(a));
  posed.verification.pose.translation = cv::Vec3d(0.6, 0.0, 0.8);
  posed.verification.pose.inliers = 42;
  plain.verification.fit_skipped = true;
  plain.verification.matches = 17;
  result.candidates = {posed, plain};
  const LoopClosure msg = loopClosureToMsg(result, std_msgs::Header(), 10);
  ASSERT_EQ(msg.candidates.size(), 2u);
  EXPECT_FALSE(msg.candidates[0].fit_skipped);
  EXPECT_TRUE(msg.candidates[1].fit_skipped) << "a candidate not fitted says so, not only 'not verified'";
  EXPECT_EQ(msg.candidates[1].matches, 17);
  const auto& q = msg.candidates[0].relative_rotation;
  EXPECT_TRUE(msg.candidates[0].has_relative_pose);
  EXPECT_NEAR(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w, 1.0, 1e-12);
  EXPECT_NEAR(q.y, std::sin(a / 2), 1e-12);
  EXPECT_NEAR(q.w, std::cos(a / 2), 1e-12);
  EXPECT_DOUBLE_EQ(msg.candidates[0].relative_translation.x, 0.6);
  EXPECT_DOUBLE_EQ(msg.candidates[0].relative_translation.z, 0.8);
  EXPECT_EQ(msg.candidates[0].pose_inliers, 42);
  EXPECT_FALSE(msg.candidates[1].has_relative_pose);
  EXPECT_EQ(msg.candidates[1].relative_rotation.w, 1.0) << "identity, not an invalid zero quaternion";
}

TEST(Conversions, AKeyframesCameraInfoAndDepthsReachTheCore) {
  mild_lcd::Keyframe msg;
  msg.keypoints.resize(2);
  msg.descriptors.assign(2 * mild::kOrbDescriptorBytes, 0x5A);
  msg.camera_info.K = {256.0, 0.0, 159.5, 0.0, 250.0, 119.5, 0.0, 0.0, 1.0};
  msg.depths = {1.5f, std::nanf("")};
  const mild::Features f = featuresFromMsg(msg);
  EXPECT_EQ(f.camera, (mild::CameraIntrinsics{256.0, 250.0, 159.5, 119.5}));
  ASSERT_EQ(f.depths.size(), 2u);
  EXPECT_EQ(f.depths[0], 1.5f);

  msg.depths.push_back(2.0f);  // three depths for two keypoints: refused by the detector, unchanged
  mild::LoopDetector detector;
  EXPECT_THROW(detector.process(mild::Observation::ofFeatures(featuresFromMsg(msg), 1.0)), mild::InvalidInput);
  EXPECT_EQ(detector.map().size(), 0u);
  msg.depths.clear();
  msg.camera_info.K = {};  // all zero: unknown, not an error
  EXPECT_FALSE(featuresFromMsg(msg).camera.known());
  msg.camera_info.K = {0.0, 0.0, 159.5, 0.0, 250.0, 119.5, 0.0, 0.0, 1.0};  // fx missing
  EXPECT_THROW(featuresFromMsg(msg), mild::InvalidInput);
  sensor_msgs::CameraInfo info;
  info.K = {256.0, 0.0, std::numeric_limits<double>::infinity(), 0.0, 256.0, 119.5, 0.0, 0.0, 1.0};
  EXPECT_THROW(intrinsicsFromMsg(info), mild::InvalidInput);
}

// K all zero but K[8] = 1 (a common driver pattern) means "no calibration", as all zero does; finite
// but absurd focal lengths are refused rather than silently failing every verification.
TEST(Conversions, UncalibratedAndAbsurdIntrinsics) {
  sensor_msgs::CameraInfo info;
  info.K = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0};
  EXPECT_FALSE(intrinsicsFromMsg(info).known()) << "unknown, not an error";
  for (const double fx : {1e12, 1e-300, 0.5, 2e6}) {
    info.K = {fx, 0.0, 159.5, 0.0, 256.0, 119.5, 0.0, 0.0, 1.0};
    const std::string error = errorOf([&] { intrinsicsFromMsg(info); });
    EXPECT_NE(error.find("[1, 1e6]"), std::string::npos) << fx << ": " << error;
    info.K = {256.0, 0.0, 159.5, 0.0, fx, 119.5, 0.0, 0.0, 1.0};
    EXPECT_THROW(intrinsicsFromMsg(info), mild::InvalidInput) << "fy " << fx;
  }
  info.K = {256.0, 0.0, 1e12, 0.0, 256.0, 119.5, 0.0, 0.0, 1.0};
  EXPECT_THROW(intrinsicsFromMsg(info), mild::InvalidInput) << "cx 1e12";
  info.K = {1.0, 0.0, -5.0, 0.0, 1e6, 1e6, 0.0, 0.0, 1.0};
  EXPECT_TRUE(intrinsicsFromMsg(info).known()) << "the bounds themselves are accepted";
}

TEST(Conversions, MetricPosesAndCorrespondencesArePublishedWhenAskedFor) {
  mild::DetectionResult result;
  mild::LoopCandidate c;
  c.verification.verified = true;
  c.verification.inliers = 2;
  c.verification.inlier_matches = {{3, 7, 10}, {4, 9, 12}};
  c.verification.inlier_query_points = {{1.0f, 2.0f}, {3.0f, 4.0f}};
  c.verification.inlier_candidate_points = {{5.0f, 6.0f}, {7.0f, 8.0f}};
  c.verification.pose.valid = true;
  c.verification.pose.metric = true;
  c.verification.pose.translation = cv::Vec3d(0.5, 0.0, 1.25);
  c.verification.pose.reprojection_error = 0.75;
  result.candidates = {c};
  const LoopClosure plain = loopClosureToMsg(result, std_msgs::Header(), 10);
  EXPECT_TRUE(plain.candidates[0].inlier_query_indices.empty()) << "only with ~publish_correspondences";
  EXPECT_TRUE(plain.candidates[0].metric_translation);
  EXPECT_DOUBLE_EQ(plain.candidates[0].relative_translation.z, 1.25);
  EXPECT_DOUBLE_EQ(plain.candidates[0].reprojection_error, 0.75);
  const LoopClosure full = loopClosureToMsg(result, std_msgs::Header(), 10, true);
  const auto& m = full.candidates[0];
  EXPECT_EQ(m.inlier_query_indices, (std::vector<int32_t>{3, 4}));
  EXPECT_EQ(m.inlier_candidate_indices, (std::vector<int32_t>{7, 9}));
  EXPECT_EQ(m.inlier_query_pixels, (std::vector<float>{1, 2, 3, 4}));
  EXPECT_EQ(m.inlier_candidate_pixels, (std::vector<float>{5, 6, 7, 8}));
}

}  // namespace
}  // namespace mild_lcd
