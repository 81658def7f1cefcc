#include "mild_lcd/place/keyframe_map.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/features/feature_source.hpp"

namespace mild {

namespace {

uint32_t largestSession(const std::vector<KeyframeRecord>& records) {
  uint32_t largest = 0;
  for (const KeyframeRecord& r : records) largest = std::max(largest, r.session);
  return largest;
}

}  // namespace

double SessionClock::next(double stamp) const {
  if (times_.empty()) return stamp;
  const double stepped_back = stepped_back_ + (stamp < last_stamp_ ? last_stamp_ - stamp : 0.0);
  return std::max(times_.back(), stamp + stepped_back);  // never below the last (rounding)
}

void SessionClock::add(double stamp) {
  const double time = next(stamp);
  if (stepsBack(stamp)) stepped_back_ += last_stamp_ - stamp;
  times_.push_back(time);
  last_stamp_ = stamp;
}

KeyframeMap::KeyframeMap(const DatabaseParams& database, const FilterParams& filter, std::string descriptor_name)
    : database_params_(database),
      filter_params_(filter),
      descriptor_name_(std::move(descriptor_name)),
      contents_{KeyframeDatabase(database), makeTemporalFilter(filter), {}, {}, 0, 0, 0, SessionClock()} {}

KeyframeMap KeyframeMap::emptyLike() const {
  KeyframeMap map(database_params_, filter_params_, descriptor_name_);
  map.setBuilderParameters(builder_parameters_);
  return map;
}

std::optional<KeyframeIndex> KeyframeMap::find(uint64_t id) const {
  auto it = contents_.index_of_id.find(id);
  if (it == contents_.index_of_id.end()) return std::nullopt;
  return it->second;
}

Features KeyframeMap::features(KeyframeIndex k) const {
  Features out{contents_.records[k].keypoints, contents_.database.descriptors(k), contents_.records[k].camera, {}};
  out.detection_scale = contents_.records[k].detection_scale;
  return out;
}

size_t KeyframeMap::memoryBytes() const {
  size_t bytes = contents_.database.memoryBytes() + contents_.records.capacity() * sizeof(KeyframeRecord) +
                 contents_.clock.times().capacity() * sizeof(double) + contents_.filter->memoryBytes();
  for (const auto& r : contents_.records) bytes += r.keypoints.capacity() * sizeof(cv::KeyPoint);
  return bytes + contents_.index_of_id.size() * (sizeof(uint64_t) + sizeof(KeyframeIndex) + 2 * sizeof(void*));
}

KeyframeIndex KeyframeMap::eligibleCount(double stamp, int exclusion_frames, double exclusion_seconds) const {
  // The query will be keyframe n; keyframe j may be a candidate when n - j >= exclusion_frames.
  const size_t n = contents_.records.size();
  const size_t frames = static_cast<size_t>(exclusion_frames);
  size_t limit = frames == 0 ? n : (n + 1 > frames ? n + 1 - frames : 0);
  if (limit <= contents_.session_start) return contents_.session_start;  // earlier sessions are never "a moment ago"
  if (exclusion_seconds > 0.0) {
    // Within the running session only, on its clock, whose times never decrease: the eligible
    // keyframes are a prefix of it. (Another session's stamps come from another run's clock: one
    // stamped later than this run hid every keyframe of it.)
    const std::vector<double>& times = contents_.clock.times();
    const double newest_allowed = contents_.clock.next(stamp) - exclusion_seconds;
    const auto end = times.begin() + static_cast<long>(limit - contents_.session_start);
    limit = contents_.session_start +
            static_cast<size_t>(std::upper_bound(times.begin(), end, newest_allowed) - times.begin());
  }
  return static_cast<KeyframeIndex>(limit);
}

void KeyframeMap::checkId(std::optional<uint64_t> id) const {
  if (id) {
    if (*id > kMaxKeyframeId) {
      throw InvalidInput("keyframe id " + std::to_string(*id) + " is too large (ids must be below 2^64 - 1)");
    }
    if (contents_.index_of_id.count(*id))
      throw InvalidInput("keyframe id " + std::to_string(*id) + " is already in the database");
  } else if (contents_.next_id > kMaxKeyframeId) {
    throw CapacityError("no keyframe id left to assign (the largest id in use is 2^64 - 2): give ids explicitly");
  }
}

KeyframeIndex KeyframeMap::add(uint64_t id, double stamp, std::vector<cv::KeyPoint> keypoints,
                               const DescriptorList& descriptors, const CameraIntrinsics& camera,
                               float detection_scale) {
  contents_.database.insert(descriptors);
  const auto index = static_cast<KeyframeIndex>(contents_.records.size());
  contents_.records.push_back(
      KeyframeRecord{id, stamp, contents_.session, std::move(keypoints), camera, detection_scale, std::nullopt});
  contents_.index_of_id.emplace(id, index);
  contents_.next_id = std::max(contents_.next_id, id + 1);
  contents_.clock.add(stamp);
  return index;
}

void KeyframeMap::reset() {
  contents_.database.clear();
  contents_.filter->reset();
  contents_.records.clear();
  contents_.index_of_id.clear();
  contents_.next_id = 0;
  contents_.session_start = 0;
  contents_.session = 0;
  contents_.clock = SessionClock();
}

void KeyframeMap::restore(MapState state, bool continue_session) {
  commitRestore(prepareRestore(std::move(state), continue_session));
}

MapContents KeyframeMap::prepareRestore(MapState state, bool continue_session) const {
  const size_t n = state.records.size();
  if (state.session_start > n) throw InvalidInput("state's session start lies beyond its keyframes");
  // Resuming: the saved run's session (that of its newest keyframe, unless it had just begun a new
  // one). A new session: a number above every stored one.
  const uint32_t next_session = n == 0 ? 0 : largestSession(state.records) + 1;
  if (n > 0 && next_session == 0) throw InvalidInput("state uses the largest session number; none is left");
  if (continue_session) {
    const uint32_t session = state.session_start < n ? state.records.back().session : next_session;
    const KeyframeIndex session_start = state.session_start;
    return build(std::move(state), session_start, session, true);
  }
  return build(std::move(state), static_cast<KeyframeIndex>(n), next_session, false);
}

void KeyframeMap::checkWidth(const MapState& state) const {
  if (state.descriptor_bytes != descriptorBytes()) {
    throw InvalidInput("the map holds " + std::to_string(state.descriptor_bytes) + "-byte descriptors, this detector " +
                       std::to_string(descriptorBytes()) + "-byte ones (" + descriptor_name_ +
                       "): a map is only loaded by a detector with the same descriptor; set " +
                       descriptorSetting(state.descriptor_bytes) + " to load it");
  }
}

MapContents KeyframeMap::prepareMerge(MapState state) const {
  checkWidth(state);
  const size_t added = state.records.size();
  for (const KeyframeRecord& r : state.records) {
    if (contents_.index_of_id.count(r.id)) {
      throw InvalidInput("keyframe id " + std::to_string(r.id) +
                         " is in both maps: merging needs distinct ids (give each robot or session's Keyframe ids a "
                         "range of their own)");
    }
  }
  if (state.descriptors.size() != added) {
    throw InvalidInput("state has " + std::to_string(added) + " keyframes but " +
                       std::to_string(state.descriptors.size()) + " descriptor lists");
  }
  // The merged map's sessions are renumbered above every number in use here.
  const uint64_t base = static_cast<uint64_t>(std::max(contents_.session, largestSession(contents_.records))) + 1;
  if (base + largestSession(state.records) > UINT32_MAX) throw InvalidInput("too many sessions to merge");
  MapState combined;
  combined.next_id = std::max(contents_.next_id, state.next_id);
  const size_t n = contents_.records.size();
  combined.records.reserve(n + added);
  combined.descriptors.reserve(n + added);
  // Earlier sessions first, then the merged map, then the running session: its keyframes stay last.
  for (KeyframeIndex k = 0; k < contents_.session_start; ++k) {
    combined.records.push_back(contents_.records[k]);
    combined.descriptors.push_back(contents_.database.descriptors(k));
  }
  for (size_t k = 0; k < added; ++k) {
    combined.records.push_back(std::move(state.records[k]));
    combined.records.back().session = static_cast<uint32_t>(base + combined.records.back().session);
    combined.descriptors.push_back(std::move(state.descriptors[k]));
  }
  for (KeyframeIndex k = contents_.session_start; k < n; ++k) {
    combined.records.push_back(contents_.records[k]);
    combined.descriptors.push_back(contents_.database.descriptors(k));
  }
  const auto session_start = static_cast<KeyframeIndex>(contents_.session_start + added);
  return build(std::move(combined), session_start, contents_.session, false);
}

void KeyframeMap::merge(MapState state) { commitRestore(prepareMerge(std::move(state))); }

MapContents KeyframeMap::build(MapState state, KeyframeIndex session_start, uint32_t session, bool load_filter) const {
  const size_t n = state.records.size();
  if (state.descriptors.size() != n)
    throw InvalidInput("state has " + std::to_string(n) + " keyframes but " + std::to_string(state.descriptors.size()) +
                       " descriptor lists");
  std::unordered_map<uint64_t, KeyframeIndex> index_of_id;
  uint64_t largest_id = 0;
  for (size_t k = 0; k < n; ++k) {
    const KeyframeRecord& r = state.records[k];
    if (r.keypoints.size() != state.descriptors[k].size()) {
      throw InvalidInput("keyframe " + std::to_string(r.id) + " has " + std::to_string(r.keypoints.size()) +
                         " keypoints but " + std::to_string(state.descriptors[k].size()) + " descriptors");
    }
    if (!std::isfinite(r.stamp)) throw InvalidInput("keyframe " + std::to_string(r.id) + " has a non-finite stamp");
    if (r.id > kMaxKeyframeId) throw InvalidInput("keyframe id " + std::to_string(r.id) + " is above the largest id");
    if (!r.camera.wellFormed()) throw InvalidInput("keyframe " + std::to_string(r.id) + " has malformed intrinsics");
    if (!index_of_id.emplace(r.id, static_cast<KeyframeIndex>(k)).second) {
      throw InvalidInput("keyframe id " + std::to_string(r.id) + " appears twice");
    }
    largest_id = std::max(largest_id, r.id);
  }
  if (n > 0 && state.next_id <= largest_id) throw InvalidInput("state's next id is not above its largest keyframe id");

  checkWidth(state);
  KeyframeDatabase database(database_params_);
  database.insertAll(state.descriptors);
  std::unique_ptr<TemporalFilter> filter = makeTemporalFilter(filter_params_);
  if (load_filter) {
    if (state.filter_name != filter->name()) {
      throw InvalidInput("the saved run used filter/type '" + state.filter_name + "', this detector runs '" +
                         filter->name() + "': load it as a new session (continue_session false), or run '" +
                         state.filter_name + "' to resume it");
    }
    filter->loadState(state.filter_state);
    if (filter->stateKeyframes() > n) throw InvalidInput("filter state covers more keyframes than the database holds");
  }
  // The running session's clock, as adding its keyframes one by one built it.
  SessionClock clock;
  for (size_t k = session_start; k < n; ++k) clock.add(state.records[k].stamp);
  return MapContents{
      std::move(database), std::move(filter), std::move(state.records), std::move(index_of_id), state.next_id,
      session_start,       session,           std::move(clock)};
}

void KeyframeMap::commitRestore(MapContents&& prepared) { contents_ = std::move(prepared); }

}  // namespace mild
