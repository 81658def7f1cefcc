#pragma once

// A keyframe database made from a real walk (e.g. ../shared/bench/generator/gen.py scale --frames
// 10000), for mild_bench_scale --sequence: the frames' own features in walk order, so that the
// map's buckets fill the way a robot's do (revisits, long stretches of new places), not the way
// replicated frames do. Query frames are spread evenly over the walk and held out of the stored
// keyframes, so each has its stored neighbours but is not itself in the map.

#include <string>
#include <vector>

#include "mild_lcd/features/descriptor.hpp"
#include "mild_lcd/features/feature_extractor.hpp"

namespace mild::tools {

class SequenceKeyframes {
 public:
  // Reads and extracts every frame of `dir` (a folder of frames or one with images/). Throws
  // InvalidInput when the folder holds fewer than queries + 1 readable frames.
  SequenceKeyframes(const std::string& dir, const FeatureExtractor& extractor, int queries);

  // Stored keyframe k (0-based, walk order without the query frames); k < size().
  const DescriptorList& keyframe(size_t k) const { return stored_.at(k); }
  const std::vector<DescriptorList>& queries() const { return queries_; }
  size_t size() const { return stored_.size(); }

 private:
  std::vector<DescriptorList> stored_;
  std::vector<DescriptorList> queries_;
};

}  // namespace mild::tools
