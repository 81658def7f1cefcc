#include "mild_lcd/features/feature_source.hpp"

#include <string>
#include <utility>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/resolution_cap.hpp"

namespace mild {

const std::vector<std::string>& featureTypes() {
  static const std::vector<std::string> types = FeatureExtractors::names();
  return types;
}

int FeatureParams::extractorBytes() const {
  int bytes = 0;
  if (!FeatureExtractors::withName(type, [&](auto entry) { bytes = decltype(entry)::type::kDescriptorBytes; })) {
    throw InvalidInput("features/type '" + type + "' names no extractor");
  }
  return bytes;
}

int FeatureParams::descriptorBytes() const { return descriptor_bytes > 0 ? descriptor_bytes : extractorBytes(); }

std::string descriptorSetting(int bytes) {
  std::string setting;
  FeatureExtractors::forEach([&](auto entry) {
    using E = typename decltype(entry)::type;
    if (setting.empty() && E::kDescriptorBytes == bytes) setting = std::string("features/type ") + E::kName;
  });
  return setting.empty() ? "features/descriptor_bytes " + std::to_string(bytes) : setting;
}

void FeatureParams::validate() const {
  validateDeclared(*this);
  forEachSection(extractors, [](const auto& section) { section.validate(); });
}

std::unique_ptr<FeatureExtractor> makeFeatureExtractor(const FeatureParams& params) {
  params.validate();
  std::unique_ptr<FeatureExtractor> extractor;
  FeatureExtractors::withName(params.type, [&](auto entry) {
    using E = typename decltype(entry)::type;
    extractor = std::make_unique<E>(params.section<typename E::Params>(), params.reference_pixels);
  });
  if (params.max_pixels > 0.0) extractor = std::make_unique<ResolutionCap>(std::move(extractor), params.max_pixels);
  return extractor;
}

}  // namespace mild
