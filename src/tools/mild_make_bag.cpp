// mild_make_bag: writes an image sequence (bench layout) into a rosbag for replay through the
// nodelet: raw mono8 images, the original compressed bytes (the `compressed` transport), and
// Keyframe messages with features computed by mild_lcd's extractors (the `keyframe` input; ORB
// by default, --features brisk or akaze for other descriptor widths).
// Time stamps come from times.txt (or the frame rate) plus a start offset. With --camera, also
// camera_info beside the images and the intrinsics in each Keyframe. With --odometry-from POSES
// (the bench's poses.txt), also odometry with drift (backend/trajectory.hpp's model): nav_msgs/Odometry
// on /odom and tf odom -> base_link at each frame's stamp, and the camera's mounting as static tf
// base_link -> the images' frame (a forward-looking camera at the base's origin, as the bench's).

#include <fstream>
#include <iostream>
#include <iterator>

#include <CLI/CLI.hpp>

#include <cv_bridge/cv_bridge.h>
#include <image_transport/camera_common.h>
#include <nav_msgs/Odometry.h>
#include <ros/time.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/image_encodings.h>
#include <tf2_msgs/TFMessage.h>
#include <Eigen/Geometry>
#include <boost/make_shared.hpp>
#include <opencv2/imgcodecs.hpp>
#include "common/drift_options.hpp"
#include "common/ros_quaternion.hpp"
#include "common/tool_main.hpp"

#include "common/image_sequence.hpp"
#include "mild_lcd/Keyframe.h"
#include "mild_lcd/backend/pose_graph.hpp"
#include "mild_lcd/backend/trajectory.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/offline/pose_evaluation.hpp"
#include "mild_lcd/ros/messages/message_conversions.hpp"

namespace {

struct Options {
  std::string images, output, image_topic = "/camera/image", keyframe_topic = "/camera/keyframe", frame_id = "camera";
  double start = 1000.0, fps = 10.0;
  long id_offset = 0;
  std::vector<double> camera;
  std::string features = "orb";
  bool no_images = false;
  std::vector<size_t> range;
  bool no_keyframes = false;
  std::string odometry_from, odom_topic = "/odom";
  mild::backend::DriftModel drift;
  std::string odom_frame = "odom", base_frame = "base_link";  // fixed, no option sets them
};

void addOptions(CLI::App& app, Options& opt) {
  app.add_option("--images", opt.images, "sequence folder (frames, or an images/ subfolder)")->required();
  app.add_option("--output", opt.output, "bag file to write")->required();
  app.add_option("--image-topic", opt.image_topic, "raw images; compressed ones go to <topic>/compressed");
  app.add_flag("--no-images", opt.no_images, "write no images, only Keyframes");
  app.add_flag("--no-keyframes", opt.no_keyframes, "write no Keyframe messages");
  app.add_option("--frames", opt.range, "FIRST LAST: only frames FIRST..LAST-1 (ids and stamps stay the frames' own)")
      ->expected(2);
  app.add_option("--keyframe-topic", opt.keyframe_topic, "mild_lcd/Keyframe messages");
  app.add_option("--keyframe-id-offset", opt.id_offset, "Keyframe.id = frame index + this");
  app.add_option("--start", opt.start, "time stamp of the first frame, seconds");
  app.add_option("--fps", opt.fps, "frame rate when the sequence has no times.txt");
  app.add_option("--frame-id", opt.frame_id, "header.frame_id");
  app.add_option("--camera", opt.camera,
                 "fx fy cx cy: write sensor_msgs/CameraInfo beside the images (image_transport's camera_info) "
                 "and into each Keyframe")
      ->expected(4);
  app.add_option("--odometry-from", opt.odometry_from,
                 "poses.txt of the sequence (x y yaw per frame): write odometry with drift on --odom-topic, tf odom -> "
                 "base_link, and static tf base_link -> --frame-id");
  app.add_option("--odom-topic", opt.odom_topic, "nav_msgs/Odometry topic")->capture_default_str();
  mild::tools::addDriftOptions(app, opt.drift, "--drift-seed");
  app.add_option("--features", opt.features, "extractor of the Keyframe messages: orb, brisk or akaze")
      ->capture_default_str();
}

geometry_msgs::Quaternion yawQuaternion(double yaw) {
  return mild::tools::quaternion(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())));
}

// --camera's intrinsics as a CameraInfo; an empty one without --camera.
sensor_msgs::CameraInfo cameraInfoOf(const std::vector<double>& camera) {
  sensor_msgs::CameraInfo info;
  if (!camera.empty()) {
    info.K = {camera[0], 0.0, camera[2], 0.0, camera[1], camera[3], 0.0, 0.0, 1.0};
    info.P = {camera[0], 0.0, camera[2], 0.0, 0.0, camera[1], camera[3], 0.0, 0.0, 0.0, 1.0, 0.0};
    info.R = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
    info.distortion_model = "plumb_bob";
    info.D.assign(5, 0.0);
    mild_lcd::intrinsicsFromMsg(info);  // refuses what the node would refuse
  }
  return info;
}

// The frames to write, first..last-1.
struct FrameRange {
  size_t first, last;
};

FrameRange frameRangeOf(const std::vector<size_t>& range, size_t frames) {
  const size_t first = range.empty() ? 0 : range[0];
  const size_t last = range.empty() ? frames : std::min(range[1], frames);
  if (first >= last)
    throw mild::InvalidInput("--frames: no frame in " + std::to_string(first) + ".." + std::to_string(last));
  return {first, last};
}

std::vector<mild::backend::Pose2> driftedOdometryOf(const Options& opt, const mild::tools::ImageSequence& seq) {
  std::vector<mild::backend::Pose2> truth;
  for (const auto& p : mild::loadPlanarPoses(opt.odometry_from, static_cast<long>(seq.frames.size()))) {
    truth.push_back({p.x, p.y, p.yaw});
  }
  return mild::backend::driftedOdometry(truth, opt.drift);
}

// The camera's mounting, once, as a static transform.
void writeCameraMount(rosbag::Bag& bag, const Options& opt, const ros::Time& stamp) {
  const mild::backend::Extrinsics e = mild::backend::Extrinsics::forwardLooking();
  geometry_msgs::TransformStamped mount;
  mount.header.stamp = stamp;
  mount.header.frame_id = opt.base_frame;
  mount.child_frame_id = opt.frame_id;
  mount.transform.rotation = mild::tools::quaternion(Eigen::Quaterniond(e.rotation));
  tf2_msgs::TFMessage statics;
  statics.transforms.push_back(mount);
  // Latched, as tf2's static broadcaster publishes it: rosbag play then latches it too.
  auto latched = boost::make_shared<ros::M_string>();
  (*latched)["callerid"] = "/mild_make_bag";
  (*latched)["latching"] = "1";
  // A given connection header is written as it is: it must carry the type too.
  (*latched)["type"] = ros::message_traits::datatype<tf2_msgs::TFMessage>();
  (*latched)["md5sum"] = ros::message_traits::md5sum<tf2_msgs::TFMessage>();
  (*latched)["message_definition"] = ros::message_traits::definition<tf2_msgs::TFMessage>();
  bag.write("/tf_static", mount.header.stamp, statics, latched);
}

// Odometry on --odom-topic and tf odom -> base_link.
void writeOdometry(rosbag::Bag& bag, const Options& opt, const mild::tools::ImageSequence& seq, size_t i,
                   const mild::backend::Pose2& pose) {
  nav_msgs::Odometry odom;
  odom.header.stamp = ros::Time(opt.start + seq.stamps[i]);
  odom.header.seq = static_cast<uint32_t>(i);
  odom.header.frame_id = opt.odom_frame;
  odom.child_frame_id = opt.base_frame;
  odom.pose.pose.position.x = pose.x;
  odom.pose.pose.position.y = pose.y;
  odom.pose.pose.orientation = yawQuaternion(pose.yaw);
  bag.write(opt.odom_topic, odom.header.stamp, odom);
  geometry_msgs::TransformStamped t;
  t.header = odom.header;
  t.child_frame_id = opt.base_frame;
  t.transform.translation.x = pose.x;
  t.transform.translation.y = pose.y;
  t.transform.rotation = odom.pose.pose.orientation;
  tf2_msgs::TFMessage tf;
  tf.transforms.push_back(t);
  bag.write("/tf", odom.header.stamp, tf);
}

std_msgs::Header frameHeader(const Options& opt, const mild::tools::ImageSequence& seq, size_t i) {
  std_msgs::Header header;
  header.seq = static_cast<uint32_t>(i);
  header.stamp = ros::Time(opt.start + seq.stamps[i]);
  header.frame_id = opt.frame_id;
  return header;
}

// The image file's own bytes, as the `compressed` transport carries them.
void writeCompressedImage(rosbag::Bag& bag, const std::string& topic, const std_msgs::Header& header,
                          const std::string& path) {
  sensor_msgs::CompressedImage compressed;
  compressed.header = header;
  std::ifstream file(path, std::ios::binary);
  compressed.data.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
  const bool png = path.size() > 4 && path.substr(path.size() - 4) == ".png";
  compressed.format = png ? "mono8; png compressed mono8" : "mono8; jpeg compressed mono8";
  bag.write(topic, header.stamp, compressed);
}

// The camera_info (with --camera), the raw image and the compressed one.
void writeImages(rosbag::Bag& bag, const Options& opt, const std_msgs::Header& header, const cv::Mat& image,
                 const std::string& path, sensor_msgs::CameraInfo& info) {
  if (!opt.camera.empty()) {  // before its image, as a camera driver publishes them
    info.header = header;
    info.width = static_cast<uint32_t>(image.cols);
    info.height = static_cast<uint32_t>(image.rows);
    bag.write(image_transport::getCameraInfoTopic(opt.image_topic), header.stamp, info);
  }
  bag.write(opt.image_topic, header.stamp,
            cv_bridge::CvImage(header, sensor_msgs::image_encodings::MONO8, image).toImageMsg());
  writeCompressedImage(bag, opt.image_topic + "/compressed", header, path);
}

void writeKeyframe(rosbag::Bag& bag, const Options& opt, const std_msgs::Header& header, const cv::Mat& image, size_t i,
                   const mild::FeatureExtractor& extractor, const sensor_msgs::CameraInfo& info) {
  const mild::Features f = extractor.extract(image, mild::PixelFormat::kGray);
  mild_lcd::Keyframe kf;
  kf.header = header;
  kf.has_id = true;
  kf.id = static_cast<uint64_t>(static_cast<long>(i) + opt.id_offset);
  kf.keypoints = mild_lcd::keypointsToMsg(f.keypoints);
  const cv::Mat d = mild::descriptorsToMat(f.descriptors);
  kf.descriptors.assign(d.data, d.data + d.total());
  kf.descriptor_bytes = static_cast<uint32_t>(extractor.descriptorBytes());
  if (!opt.camera.empty()) {
    kf.camera_info = info;
    kf.camera_info.header = header;
    kf.camera_info.width = static_cast<uint32_t>(image.cols);
    kf.camera_info.height = static_cast<uint32_t>(image.rows);
  }
  bag.write(opt.keyframe_topic, header.stamp, kf);
}

void writeFrame(rosbag::Bag& bag, const Options& opt, const mild::tools::ImageSequence& seq, size_t i,
                const mild::FeatureExtractor& extractor, sensor_msgs::CameraInfo& info) {
  const cv::Mat image = cv::imread(seq.frames[i], cv::IMREAD_GRAYSCALE);
  if (image.empty()) throw mild::InvalidInput(seq.frames[i] + ": cannot read the image");
  const std_msgs::Header header = frameHeader(opt, seq, i);
  if (!opt.image_topic.empty()) writeImages(bag, opt, header, image, seq.frames[i], info);
  if (!opt.keyframe_topic.empty()) writeKeyframe(bag, opt, header, image, i, extractor, info);
}

int writeBag(Options& opt) {
  ros::Time::init();
  if (opt.no_images) opt.image_topic.clear();
  if (opt.no_keyframes) opt.keyframe_topic.clear();
  const mild::tools::ImageSequence seq = mild::tools::openImageSequence(opt.images, opt.fps);
  mild::FeatureParams feature_params;
  feature_params.type = opt.features;
  const std::unique_ptr<mild::FeatureExtractor> extractor = mild::makeFeatureExtractor(feature_params);
  sensor_msgs::CameraInfo info = cameraInfoOf(opt.camera);
  rosbag::Bag bag(opt.output, rosbag::bagmode::Write);
  const FrameRange frames = frameRangeOf(opt.range, seq.frames.size());
  std::vector<mild::backend::Pose2> odometry;
  if (!opt.odometry_from.empty()) {
    odometry = driftedOdometryOf(opt, seq);
    writeCameraMount(bag, opt, ros::Time(opt.start + seq.stamps[frames.first]));
  }
  for (size_t i = frames.first; i < frames.last; ++i) {
    // Before the frame, as a robot's odometry runs ahead of its keyframes.
    if (!odometry.empty()) writeOdometry(bag, opt, seq, i, odometry[i]);
    writeFrame(bag, opt, seq, i, *extractor, info);
  }
  bag.close();
  std::cout << "wrote " << frames.last - frames.first << " frames to " << opt.output << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Write an image sequence into a rosbag (raw, compressed and keyframe topics)."};
  app.name("mild_make_bag");
  Options opt;
  addOptions(app, opt);
  return mild::tools::toolMain(app, argc, argv, [&] { return writeBag(opt); });
}
