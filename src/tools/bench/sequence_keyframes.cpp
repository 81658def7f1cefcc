#include "bench/sequence_keyframes.hpp"

#include <opencv2/imgcodecs.hpp>

#include "common/image_sequence.hpp"
#include "mild_lcd/common/errors.hpp"

namespace mild::tools {

SequenceKeyframes::SequenceKeyframes(const std::string& dir, const FeatureExtractor& extractor, int queries) {
  std::vector<DescriptorList> frames;
  for (const auto& path : openImageSequence(dir).frames) {
    const cv::Mat image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (!image.empty()) frames.push_back(extractor.extract(image, PixelFormat::kGray).descriptors);
  }
  if (queries < 1 || frames.size() < static_cast<size_t>(queries) + 1) {
    throw InvalidInput("--sequence " + dir + ": " + std::to_string(frames.size()) +
                       " readable frames, need more than the " + std::to_string(queries) + " queries");
  }
  // Query q is frame (q + 0.5) * frames / queries: spread over the walk, never the first or last.
  const size_t stride = frames.size() / static_cast<size_t>(queries);
  for (size_t i = 0; i < frames.size(); ++i) {
    const bool is_query = i % stride == stride / 2 && queries_.size() < static_cast<size_t>(queries);
    (is_query ? queries_ : stored_).push_back(std::move(frames[i]));
  }
}

}  // namespace mild::tools
