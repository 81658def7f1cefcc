#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "mild_lcd/detector/loop_detector.hpp"

namespace mild {

// Where parameter values come from: a YAML file (YamlParameterSource) or the ROS parameter server
// (the nodelet's own source). Names are slash-separated paths such as "orb/num_features".
class ParameterSource {
 public:
  virtual ~ParameterSource() = default;
  // Each returns nullopt when the parameter is absent and throws InvalidInput when it is present
  // with a value of the wrong type.
  virtual std::optional<double> getDouble(const std::string& name) const = 0;
  virtual std::optional<int64_t> getInt(const std::string& name) const = 0;
  virtual std::optional<bool> getBool(const std::string& name) const = 0;
  virtual std::optional<std::string> getString(const std::string& name) const = 0;
  virtual std::optional<std::vector<double>> getDoubleList(const std::string& name) const = 0;
  // Every parameter name the source holds (leaves only).
  virtual std::vector<std::string> names() const = 0;
};

// Calls visit(name, field) for every tunable of DetectorParams, fields being int, double, bool,
// uint32_t, uint64_t, std::string, SearchMode or std::vector<double>. This list is the single definition of the
// parameter names.
template <class Visit>
void visitParameters(DetectorParams& p, Visit&& visit);

// Reads every parameter the source has (absent ones keep their defaults), rejects unknown names in
// the detector's namespaces, and validates the result. Throws InvalidInput naming the parameter.
DetectorParams loadDetectorParams(const ParameterSource& source, const DetectorParams& defaults = {});

// The namespaces that belong to the detector (a source may hold other names outside them).
const std::vector<std::string>& detectorParameterNamespaces();

// The parameters a running detector may change (LoopDetector::retune, the node's dynamic_reconfigure):
// how candidates are chosen, checked and reported. The others shape the stored map (features,
// index, similarity) or the filter's state and are fixed at start-up.
const std::vector<std::string>& runtimeParameterNames();

// Flattened "name: value" lines of every parameter, for logs and --print-config.
std::vector<std::pair<std::string, std::string>> describeParameters(const DetectorParams& p);

// A YAML file of nested maps (see config/default.yaml). Throws InvalidInput naming the file when it
// cannot be read or parsed.
class YamlParameterSource : public ParameterSource {
 public:
  static YamlParameterSource fromFile(const std::string& path);
  static YamlParameterSource fromString(const std::string& yaml, const std::string& origin = "<string>");

  std::optional<double> getDouble(const std::string& name) const override;
  std::optional<int64_t> getInt(const std::string& name) const override;
  std::optional<bool> getBool(const std::string& name) const override;
  std::optional<std::string> getString(const std::string& name) const override;
  std::optional<std::vector<double>> getDoubleList(const std::string& name) const override;
  std::vector<std::string> names() const override;

 private:
  struct Value {
    bool is_list = false;
    std::vector<std::string> items;
  };
  YamlParameterSource() = default;
  std::optional<std::string> scalar(const std::string& name) const;
  const Value* find(const std::string& name) const;

  std::string origin_;
  std::vector<std::pair<std::string, Value>> values_;
};

// ---------------------------------------------------------------------------------------------

inline std::string searchModeName(SearchMode m) { return m == SearchMode::kExact ? "exact" : "index"; }

template <class Visit>
void visitParameters(DetectorParams& p, Visit&& visit) {
  visit("orb/num_features", p.orb.num_features);
  visit("orb/scale_factor", p.orb.scale_factor);
  visit("orb/num_levels", p.orb.num_levels);
  visit("orb/fast_threshold", p.orb.fast_threshold);
  visit("orb/edge_threshold", p.orb.edge_threshold);

  visit("index/num_tables", p.database.index.num_tables);
  visit("index/radius", p.database.index.radius);
  visit("index/cap_buckets", p.database.index.cap_buckets);
  visit("index/bucket_cap_factor", p.database.index.bucket_cap_factor);
  visit("index/expected_features", p.database.index.expected_features);
  visit("index/inline_prefixes", p.database.index.inline_prefixes);
  visit("index/min_bucket_cap", p.database.index.min_bucket_cap);
  visit("index/max_bucket_entries", p.database.index.max_bucket_entries);

  visit("similarity/max_distance", p.database.similarity.max_distance);
  visit("similarity/sigma2", p.database.similarity.sigma2);
  visit("similarity/idf_weighting", p.database.similarity.idf_weighting);
  visit("similarity/vote_normalization", p.database.similarity.vote_normalization);
  visit("similarity/burstiness_regularizer", p.database.similarity.burstiness_regularizer);
  visit("similarity/normalize_by_feature_counts", p.database.similarity.normalize_by_feature_counts);
  visit("similarity/early_termination_threshold", p.database.similarity.early_termination_threshold);
  visit("similarity/search", p.search);

  visit("filter/type", p.filter.type);
  visit("filter/loop_persistence", p.filter.loop_persistence);
  visit("filter/loop_onset", p.filter.loop_onset);
  visit("filter/motion_kernel", p.filter.motion_kernel);
  visit("filter/no_loop_likelihood", p.filter.no_loop_likelihood);
  visit("filter/candidate_window", p.filter.candidate_window);

  visit("detector/exclusion_frames", p.candidates.exclusion_frames);
  visit("detector/exclusion_seconds", p.candidates.exclusion_seconds);
  visit("detector/near_past", p.candidates.near_past);
  visit("detector/near_past_kappa", p.candidates.near_past_kappa);
  visit("detector/near_past_tolerance", p.candidates.near_past_tolerance);
  visit("detector/near_past_min_background", p.candidates.near_past_min_background);
  visit("detector/max_candidates", p.candidates.max_candidates);
  visit("detector/suppression_radius", p.candidates.suppression_radius);
  visit("detector/min_probability", p.candidates.min_probability);

  visit("verification/enabled", p.verification.enabled);
  visit("verification/num_tables", p.verification.matching.num_tables);
  visit("verification/radius", p.verification.matching.radius);
  visit("verification/max_distance", p.verification.matching.max_distance);
  visit("verification/ratio", p.verification.matching.ratio);
  visit("verification/cross_check", p.verification.matching.cross_check);
  visit("verification/ransac_threshold", p.verification.ransac_threshold);
  visit("verification/confidence", p.verification.confidence);
  visit("verification/max_iterations", p.verification.max_iterations);
  visit("verification/min_inliers", p.verification.min_inliers);
  visit("verification/fx", p.verification.fx);
  visit("verification/fy", p.verification.fy);
  visit("verification/cx", p.verification.cx);
  visit("verification/cy", p.verification.cy);
  visit("verification/pnp_threshold", p.verification.pnp_threshold);

  visit("scoring/enabled", p.scoring.enabled);
  visit("scoring/weights", p.scoring.weights);
  visit("scoring/bias", p.scoring.bias);
  visit("scoring/decision_probability", p.scoring.decision_probability);
}

}  // namespace mild
