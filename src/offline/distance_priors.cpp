#include "mild_lcd/offline/distance_priors.hpp"

#include <random>

#include <opencv2/features2d.hpp>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace mild {
namespace {

void checkView(const Features* f) {
  if (f == nullptr) throw InvalidInput("a feature pair is missing a view");
  if (f->keypoints.size() != f->descriptors.size()) {
    throw InvalidInput("a view has " + std::to_string(f->keypoints.size()) + " keypoints but " +
                       std::to_string(f->descriptors.size()) + " descriptors");
  }
}

// Exhaustive nearest neighbours of a's descriptors among b's, kept by Lowe's ratio test.
std::vector<FeatureMatch> exactRatioMatches(const Features& a, const Features& b, double ratio) {
  std::vector<FeatureMatch> out;
  if (a.descriptors.empty() || b.descriptors.size() < 2) return out;
  std::vector<std::vector<cv::DMatch>> knn;
  cv::BFMatcher(cv::NORM_HAMMING).knnMatch(descriptorsToMat(a.descriptors), descriptorsToMat(b.descriptors), knn, 2);
  for (const auto& pair : knn) {
    if (pair.size() == 2 && pair[0].distance < ratio * pair[1].distance) {
      out.push_back({pair[0].queryIdx, pair[0].trainIdx, static_cast<int>(pair[0].distance)});
    }
  }
  return out;
}

}  // namespace

MeasuredPriors measureDistancePriors(const std::vector<FeaturePair>& overlapping,
                                     const std::vector<FeaturePair>& disjoint, const PriorMeasurementParams& params) {
  MeasuredPriors out;
  int bytes = 0;
  for (const auto* pairs : {&overlapping, &disjoint}) {
    for (const FeaturePair& pair : *pairs) {
      for (const Features* view : {pair.a, pair.b}) {
        checkView(view);
        if (bytes == 0 && !view->descriptors.empty()) bytes = view->descriptors.front().bytes;
        checkDescriptorWidth(view->descriptors, bytes, "a view");
      }
    }
  }
  out.bits = bytes == 0 ? kOrbDescriptorBytes * 8 : bytes * 8;
  out.inlier_counts.assign(static_cast<size_t>(out.bits) + 1, 0.0);
  out.outlier_counts.assign(static_cast<size_t>(out.bits) + 1, 0.0);

  VerificationParams geometry;
  geometry.ransac_threshold = params.ransac_threshold;
  geometry.min_inliers = std::max(8, params.min_inliers);
  const GeometricVerifier verifier(geometry);
  for (const FeaturePair& pair : overlapping) {
    checkView(pair.a);
    checkView(pair.b);
    const GeometricCheck check =
        verifier.fit(pair.a->keypoints, pair.b->keypoints, exactRatioMatches(*pair.a, *pair.b, params.ratio));
    if (!check.verification.verified) continue;
    ++out.overlapping_pairs_used;
    for (size_t i = 0; i < check.matches.size(); ++i) {
      if (!check.inlier_mask[i]) continue;
      const FeatureMatch& m = check.matches[i];
      out.inlier_counts[m.distance] += 1.0;
      out.inlier_descriptors.emplace_back(pair.a->descriptors[m.query], pair.b->descriptors[m.train]);
    }
  }

  std::mt19937_64 rng(params.seed);
  for (const FeaturePair& pair : disjoint) {
    checkView(pair.a);
    checkView(pair.b);
    if (pair.b->descriptors.empty()) continue;
    std::uniform_int_distribution<size_t> pick(0, pair.b->descriptors.size() - 1);
    for (const Descriptor& d : pair.a->descriptors)
      out.outlier_counts[hammingDistance(d, pair.b->descriptors[pick(rng)])] += 1.0;
  }
  return out;
}

double indexRecall(const std::vector<std::pair<Descriptor, Descriptor>>& correspondences, MihParams params) {
  if (correspondences.empty()) throw InvalidInput("no correspondences to look up");
  params.cap_buckets = false;  // every stored descriptor must stay findable
  params.max_candidates_per_feature = 0;
  MihIndex index(params, correspondences.front().first.bits());
  const FeatureId n = static_cast<FeatureId>(correspondences.size());
  for (FeatureId k = 0; k < n; ++k) index.insertKeyframe(&correspondences[k].second, 1, k);
  size_t found = 0;
  for (FeatureId k = 0; k < n; ++k) {
    bool hit = false;
    ProbeCounters counters;
    index.probe(correspondences[k].first, n, counters, [&](FeatureId id, int) { hit |= id == k; });
    found += hit ? 1 : 0;
  }
  return static_cast<double>(found) / n;
}

}  // namespace mild
