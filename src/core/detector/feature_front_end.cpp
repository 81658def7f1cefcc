#include "mild_lcd/detector/feature_front_end.hpp"

#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stopwatch.hpp"

namespace mild {

FeatureFrontEnd::FeatureFrontEnd(const FeatureParams& features)
    : extractor_((features.validate(), makeFeatureExtractor(features))),
      descriptor_bytes_(features.descriptorBytes()) {}

Observation FeatureFrontEnd::extract(Observation observation) const {
  if (!observation.image) return observation;
  if (extractor_->descriptorBytes() != descriptor_bytes_) {
    throw InvalidInput("this detector holds " + std::to_string(descriptor_bytes_) +
                       "-byte descriptors (features/descriptor_bytes) but features/type " + extractor_->name() +
                       " extracts " + std::to_string(extractor_->descriptorBytes()) +
                       "-byte ones: give it Keyframes with its descriptors, not images");
  }
  const auto start = Clock::now();
  Features features = extractor_->extract(observation.image->pixels, observation.image->format);
  observation.extract_ms = msSince(start);
  features.camera = std::move(observation.features.camera);
  observation.features = std::move(features);
  observation.image.reset();
  return observation;
}

}  // namespace mild
