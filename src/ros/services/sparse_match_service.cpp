#include "mild_lcd/ros/services/sparse_match_service.hpp"

#include <algorithm>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/ros/messages/message_conversions.hpp"

namespace mild_lcd {

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
