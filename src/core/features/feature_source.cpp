#include "mild_lcd/features/feature_source.hpp"

#include <string>

#include "mild_lcd/common/errors.hpp"

namespace mild {

const std::vector<std::string>& featureTypes() {
  static const std::vector<std::string> types = {OrbExtractor::kName, BriskExtractor::kName, AkazeExtractor::kName};
  return types;
}

int FeatureParams::extractorBytes() const {
  if (type == BriskExtractor::kName) return BriskExtractor::kDescriptorBytes;
  if (type == AkazeExtractor::kName) return AkazeExtractor::kDescriptorBytes;
  return OrbExtractor::kDescriptorBytes;
}

int FeatureParams::descriptorBytes() const { return descriptor_bytes > 0 ? descriptor_bytes : extractorBytes(); }

void FeatureParams::validate() const {
  validateDeclared(*this);
  orb.validate();
  brisk.validate();
  akaze.validate();
}

std::unique_ptr<FeatureExtractor> makeFeatureExtractor(const FeatureParams& params) {
  params.validate();
  if (params.type == BriskExtractor::kName)
    return std::make_unique<BriskExtractor>(params.brisk, params.reference_pixels);
  if (params.type == AkazeExtractor::kName)
    return std::make_unique<AkazeExtractor>(params.akaze, params.reference_pixels);
  return std::make_unique<OrbExtractor>(params.orb, params.reference_pixels);
}

}  // namespace mild
