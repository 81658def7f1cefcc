// mild_make_bag: writes an image sequence (bench layout) into a rosbag for replay through the
// nodelet: raw mono8 images, the original compressed bytes (the `compressed` transport), and
// Keyframe messages with features computed by mild_lcd's extractors (the `keyframe` input; ORB
// by default, --features brisk or akaze for other descriptor widths).
// Time stamps come from times.txt (or the frame rate) plus a start offset. With --camera, also
// camera_info beside the images and the intrinsics in each Keyframe.

#include <fstream>
#include <iostream>
#include <iterator>

#include <CLI/CLI.hpp>

#include <cv_bridge/cv_bridge.h>
#include <image_transport/camera_common.h>
#include <ros/time.h>
#include <rosbag/bag.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/image_encodings.h>
#include <opencv2/imgcodecs.hpp>
#include "common/tool_main.hpp"

#include "common/image_sequence.hpp"
#include "mild_lcd/Keyframe.h"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"
#include "mild_lcd/ros/conversions.hpp"

int main(int argc, char** argv) {
  CLI::App app{"Write an image sequence into a rosbag (raw, compressed and keyframe topics)."};
  app.name("mild_make_bag");
  std::string images, output, image_topic = "/camera/image", keyframe_topic = "/camera/keyframe", frame_id = "camera";
  double start = 1000.0, fps = 10.0;
  long id_offset = 0;
  std::vector<double> camera;
  std::string features = "orb";
  bool no_images = false;
  std::vector<size_t> range;
  app.add_option("--images", images, "sequence folder (frames, or an images/ subfolder)")->required();
  app.add_option("--output", output, "bag file to write")->required();
  app.add_option("--image-topic", image_topic, "raw images; compressed ones go to <topic>/compressed");
  app.add_flag("--no-images", no_images, "write no images, only Keyframes");
  app.add_option("--frames", range, "FIRST LAST: only frames FIRST..LAST-1 (ids and stamps stay the frames' own)")
      ->expected(2);
  app.add_option("--keyframe-topic", keyframe_topic, "mild_lcd/Keyframe messages");
  app.add_option("--keyframe-id-offset", id_offset, "Keyframe.id = frame index + this");
  app.add_option("--start", start, "time stamp of the first frame, seconds");
  app.add_option("--fps", fps, "frame rate when the sequence has no times.txt");
  app.add_option("--frame-id", frame_id, "header.frame_id");
  app.add_option("--camera", camera,
                 "fx fy cx cy: write sensor_msgs/CameraInfo beside the images (image_transport's camera_info) "
                 "and into each Keyframe")
      ->expected(4);
  app.add_option("--features", features, "extractor of the Keyframe messages: orb, brisk or akaze")
      ->capture_default_str();
  return mild::tools::toolMain(app, argc, argv, [&] {
    ros::Time::init();
    if (no_images) image_topic.clear();
    const mild::tools::ImageSequence seq = mild::tools::openImageSequence(images, fps);
    mild::FeatureParams feature_params;
    feature_params.type = features;
    const std::unique_ptr<mild::FeatureExtractor> extractor = mild::makeFeatureExtractor(feature_params);
    sensor_msgs::CameraInfo info;
    if (!camera.empty()) {
      info.K = {camera[0], 0.0, camera[2], 0.0, camera[1], camera[3], 0.0, 0.0, 1.0};
      info.P = {camera[0], 0.0, camera[2], 0.0, 0.0, camera[1], camera[3], 0.0, 0.0, 0.0, 1.0, 0.0};
      info.R = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
      info.distortion_model = "plumb_bob";
      info.D.assign(5, 0.0);
      mild_lcd::intrinsicsFromMsg(info);  // refuses what the node would refuse
    }
    rosbag::Bag bag(output, rosbag::bagmode::Write);
    const size_t first = range.empty() ? 0 : range[0];
    const size_t last = range.empty() ? seq.frames.size() : std::min(range[1], seq.frames.size());
    if (first >= last)
      throw mild::InvalidInput("--frames: no frame in " + std::to_string(first) + ".." + std::to_string(last));
    for (size_t i = first; i < last; ++i) {
      const cv::Mat image = cv::imread(seq.frames[i], cv::IMREAD_GRAYSCALE);
      if (image.empty()) throw mild::InvalidInput(seq.frames[i] + ": cannot read the image");
      std_msgs::Header header;
      header.seq = static_cast<uint32_t>(i);
      header.stamp = ros::Time(start + seq.stamps[i]);
      header.frame_id = frame_id;
      if (!image_topic.empty()) {
        if (!camera.empty()) {  // before its image, as a camera driver publishes them
          info.header = header;
          info.width = static_cast<uint32_t>(image.cols);
          info.height = static_cast<uint32_t>(image.rows);
          bag.write(image_transport::getCameraInfoTopic(image_topic), header.stamp, info);
        }
        bag.write(image_topic, header.stamp,
                  cv_bridge::CvImage(header, sensor_msgs::image_encodings::MONO8, image).toImageMsg());
        sensor_msgs::CompressedImage compressed;
        compressed.header = header;
        std::ifstream file(seq.frames[i], std::ios::binary);
        compressed.data.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
        const bool png = seq.frames[i].size() > 4 && seq.frames[i].substr(seq.frames[i].size() - 4) == ".png";
        compressed.format = png ? "mono8; png compressed mono8" : "mono8; jpeg compressed mono8";
        bag.write(image_topic + "/compressed", header.stamp, compressed);
      }
      if (!keyframe_topic.empty()) {
        const mild::Features f = extractor->extract(image, mild::PixelFormat::kGray);
        mild_lcd::Keyframe kf;
        kf.header = header;
        kf.has_id = true;
        kf.id = static_cast<uint64_t>(static_cast<long>(i) + id_offset);
        kf.keypoints = mild_lcd::keypointsToMsg(f.keypoints);
        const cv::Mat d = mild::descriptorsToMat(f.descriptors);
        kf.descriptors.assign(d.data, d.data + d.total());
        kf.descriptor_bytes = static_cast<uint32_t>(extractor->descriptorBytes());
        if (!camera.empty()) {
          kf.camera_info = info;
          kf.camera_info.header = header;
          kf.camera_info.width = static_cast<uint32_t>(image.cols);
          kf.camera_info.height = static_cast<uint32_t>(image.rows);
        }
        bag.write(keyframe_topic, header.stamp, kf);
      }
    }
    bag.close();
    std::cout << "wrote " << last - first << " frames to " << output << "\n";
    return 0;
  });
}
