#include "mild_lcd/detector/observation.hpp"

#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/common/stopwatch.hpp"

namespace mild {

Observation extractFeatures(Observation observation, const FeatureExtractor& extractor, int descriptor_bytes) {
  if (!observation.image) return observation;
  if (extractor.descriptorBytes() != descriptor_bytes) {
    throw InvalidInput("this detector holds " + std::to_string(descriptor_bytes) +
                       "-byte descriptors (features/descriptor_bytes) but features/type " + extractor.name() +
                       " extracts " + std::to_string(extractor.descriptorBytes()) +
                       "-byte ones: give it Keyframes with its descriptors, not images");
  }
  const auto start = Clock::now();
  Features features = extractor.extract(observation.image->pixels, observation.image->format);
  observation.extract_ms = msSince(start);
  features.camera = std::move(observation.features.camera);
  observation.features = std::move(features);
  observation.image.reset();
  return observation;
}

}  // namespace mild
