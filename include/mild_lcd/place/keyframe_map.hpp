#pragma once

// The keyframe map: what a detector has learnt, apart from how it judges a query. It holds the
// MIH database of every stored keyframe's descriptors, the keyframes' records (id, stamp, session,
// keypoints, camera), the id lookup, the sessions, and the temporal filter's belief over these
// keyframes (a belief is about one map's entries: it is saved, restored and reset with them).
// Persistence (io/database_file.hpp) and a robot team's other maps (detector/robot_team.hpp)
// depend on the map alone; the pipeline that queries it, filters, verifies and scores
// (detector/loop_detector.hpp) runs over it, as DBoW2's detector runs over its database.

#include <algorithm>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <vector>

#include <opencv2/core.hpp>

#include "mild_lcd/features/features.hpp"
#include "mild_lcd/filter/filters.hpp"
#include "mild_lcd/place/keyframe_database.hpp"

namespace mild {

// A stored keyframe, as handed to verifiers and clients (e.g. the sparse-match service).
struct KeyframeRecord {
  uint64_t id = 0;
  double stamp = 0.0;
  uint32_t session = 0;
  std::vector<cv::KeyPoint> keypoints;
  CameraIntrinsics camera;  // unknown unless the keyframe brought them
  // Its Features::detection_scale, so that verifying against it widens the tolerance for it too
  // (a stored keyframe as a SparseMatch side, a pulled peer's query against it). Saved in a map
  // file (format version 4; a keyframe of an older file is 1) and sent to team peers.
  float detection_scale = 1.0f;
  // The id of the keyframe this one was found to show when it was stored (its best candidate of
  // this map, verified and more likely than not a loop), if any: two candidates chained by these
  // are one place seen twice, not a place that repeats (LoopDetector's another-place input). Saved
  // in a map file (format version 5; none in an older file), not sent to peers.
  std::optional<uint64_t> same_place_as;
};

// Everything a map holds, as plain data: what database_file.hpp saves and loads.
struct MapState {
  std::string parameters;                      // "name: value" lines of the detector that saved it
  int descriptor_bytes = kOrbDescriptorBytes;  // the width of every descriptor below
  uint64_t next_id = 0;
  KeyframeIndex session_start = 0;
  std::vector<KeyframeRecord> records;      // in database order
  std::vector<DescriptorList> descriptors;  // one list per record, one descriptor per keypoint
  std::string filter_name;                  // TemporalFilter::name() of the filter that saved it
  std::vector<uint8_t> filter_state;        // its saveState()
};

// The running session's clock, as the temporal exclusion reads it: its keyframes' stamps, except
// that a stamp below the previous keyframe's (a replay restarted, sim time reset, a clock set back)
// counts as no time passing since that keyframe. Its times never decrease, so the exclusion is a
// prefix of the session, and keyframes before a step back become eligible as time goes on after it,
// instead of staying "in the future" of every later stamp. Stamps that never decrease are their own
// times, exactly. Earlier sessions are never on it: their stamps come from another run's clock.
class SessionClock {
 public:
  // The time of a keyframe stamped `stamp`, if it were added next.
  double next(double stamp) const;
  // Whether `stamp` is below the previous keyframe's: the clock stepped back.
  bool stepsBack(double stamp) const { return !times_.empty() && stamp < last_stamp_; }
  void add(double stamp);
  // One time per keyframe of the running session, in its order.
  const std::vector<double>& times() const { return times_; }

 private:
  std::vector<double> times_;
  double stepped_back_ = 0.0;  // what the stamps stepped back in all, added to each later stamp
  double last_stamp_ = 0.0;
};

// What a map holds, ready: a map's own contents, and a checked state (prepareRestore,
// prepareMerge) waiting to replace them.
struct MapContents {
  KeyframeDatabase database;
  std::unique_ptr<TemporalFilter> filter;
  std::vector<KeyframeRecord> records;
  std::unordered_map<uint64_t, KeyframeIndex> index_of_id;
  uint64_t next_id = 0;
  KeyframeIndex session_start = 0;
  uint32_t session = 0;  // the session new keyframes join
  SessionClock clock;    // of keyframes [session_start, records.size())
};

// Largest keyframe id: ids are below 2^64 - 1 so that "largest + 1", the next free id, exists.
constexpr uint64_t kMaxKeyframeId = UINT64_MAX - 1;

class KeyframeMap {
 public:
  // `database` at the descriptors' width; `descriptor_name` says where that width came from in
  // errors ("features/type orb"). Throws InvalidInput for invalid parameters.
  KeyframeMap(const DatabaseParams& database, const FilterParams& filter, std::string descriptor_name);

  // --- Reading -----------------------------------------------------------------------------------
  size_t size() const { return contents_.records.size(); }
  // The width of the descriptors this map stores and accepts, in bytes.
  int descriptorBytes() const { return contents_.database.descriptorBytes(); }
  const std::string& descriptorSource() const { return descriptor_name_; }  // where that width came from
  // An empty map of the same parameters: what a load is prepared on (prepareRestore) without the
  // lock on this one, which a keyframe may meanwhile give another width (LoopDetector::takeWidth).
  KeyframeMap emptyLike() const;
  const DatabaseParams& databaseParams() const { return database_params_; }
  const KeyframeDatabase& database() const { return contents_.database; }
  const TemporalFilter& filter() const { return *contents_.filter; }
  const KeyframeRecord& record(KeyframeIndex k) const { return contents_.records[k]; }
  std::optional<KeyframeIndex> find(uint64_t id) const;
  Features features(KeyframeIndex k) const;
  uint64_t nextId() const { return contents_.next_id; }
  // Ids below `floor` are not given out (by store() without an id) from now on: they may have been
  // given out by a run whose keyframes this map does not hold (a crash before its save).
  void raiseNextId(uint64_t floor) { contents_.next_id = std::max(contents_.next_id, std::min(floor, kMaxKeyframeId)); }
  // Keyframes [0, sessionStart()) come from earlier sessions and are always eligible.
  KeyframeIndex sessionStart() const { return contents_.session_start; }
  // The session new keyframes join: 0 at first, above every stored one after a load or merge
  // (continue_session keeps the saved run's).
  uint32_t session() const { return contents_.session; }
  size_t memoryBytes() const;
  // The parameters of the detector that builds this map, as "name: value" lines: saved with it, so
  // that a load can say which of them differ.
  const std::string& builderParameters() const { return builder_parameters_; }
  void setBuilderParameters(std::string lines) { builder_parameters_ = std::move(lines); }

  // The keyframes [0, eligibleCount) a keyframe stamped `stamp`, about to be stored, may find as
  // candidates: those at least exclusion_frames keyframes (and, when exclusion_seconds > 0, that
  // many seconds on the running session's clock) older; earlier sessions always, whatever their
  // stamps.
  KeyframeIndex eligibleCount(double stamp, int exclusion_frames, double exclusion_seconds) const;
  const SessionClock& sessionClock() const { return contents_.clock; }

  // --- Growing -----------------------------------------------------------------------------------
  // Throws InvalidInput for an id in use or above kMaxKeyframeId; CapacityError when no id is given
  // and none is left to assign.
  void checkId(std::optional<uint64_t> id) const;
  // Throws CapacityError when `descriptors` would not fit the database.
  void checkRoomFor(const DescriptorList& descriptors) const { contents_.database.checkRoomFor(descriptors); }
  // The temporal filter the pipeline updates with each of this map's own keyframes.
  TemporalFilter& filter() { return *contents_.filter; }
  // Stores a keyframe whose id was checked (checkId) and whose descriptors fit (checkRoomFor);
  // returns its index. Cannot fail for a checked keyframe.
  // Records that keyframe k (of this map) shows the place of the keyframe with id `id`.
  void markSamePlace(KeyframeIndex k, uint64_t id) { contents_.records.at(k).same_place_as = id; }
  KeyframeIndex add(uint64_t id, double stamp, std::vector<cv::KeyPoint> keypoints, const DescriptorList& descriptors,
                    const CameraIntrinsics& camera, float detection_scale = 1.0f);

  // --- Replacing ---------------------------------------------------------------------------------
  void reset();
  // Replaces everything the map holds by `state` (the index is rebuilt from the descriptors with
  // this map's parameters). continue_session = true resumes exactly where the saved run stopped:
  // the same outputs as if it had never stopped (it needs the state of a filter of this map's
  // filter/type). false starts a new session on the stored map (e.g. yesterday's): the loaded
  // keyframes are exempt from the temporal exclusion, since they were not seen a moment ago, and
  // the filter starts from "no loop". Throws InvalidInput, changing nothing, when the state is
  // inconsistent.
  void restore(MapState state, bool continue_session);
  // restore() in two steps: prepareRestore reads only the map's parameters (fixed at
  // construction), so it may run without the caller's lock; commitRestore cannot fail.
  MapContents prepareRestore(MapState state, bool continue_session) const;
  void commitRestore(MapContents&& prepared);
  // Adds the keyframes of a saved map (yesterday's, another robot's) to this one, keeping both: they
  // become earlier sessions (their session numbers shifted above every number in use here), always
  // eligible as candidates, while the running session goes on. The index is rebuilt (the running
  // session's keyframes stay last, so the temporal exclusion still reads a prefix) and the filter
  // restarts from "no loop", as for a new session. Ids must be distinct across the two maps.
  // Throws InvalidInput, changing nothing, when the state is inconsistent or shares an id.
  void merge(MapState state);
  MapContents prepareMerge(MapState state) const;  // reads this map: hold its lock

 private:
  void checkWidth(const MapState& state) const;  // throws InvalidInput for another descriptor width
  // Checks `state` and builds its database; session_start and session as given, the filter fresh
  // or from the state.
  MapContents build(MapState state, KeyframeIndex session_start, uint32_t session, bool load_filter) const;

  DatabaseParams database_params_;
  FilterParams filter_params_;
  std::string descriptor_name_;
  std::string builder_parameters_;
  MapContents contents_;
};

}  // namespace mild
