#pragma once

// The messages stations exchange, as the station protocol (team/station.hpp) reads and writes them:
// plain structs, without the wire's counter and MAC (the link's: ros/team/team_link.hpp converts,
// signs and checks them). Field meanings: msg/TeamStatus.msg, TeamRequest.msg, TeamFeatures.msg,
// TeamLoop.msg; the summary is PlaceSummary (place_summary.hpp).

#include <any>
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "mild_lcd/detector/detection_result.hpp"
#include "mild_lcd/features/features.hpp"
#include "mild_lcd/team/station_ledger.hpp"

namespace mild {

// A station's heartbeat (once a second): its run, its numbering and what it took of each peer.
struct TeamStatus {
  std::string station;
  uint64_t epoch = 0, epoch_start = 0;
  uint64_t summaries = 0;  // it has numbered
  uint32_t descriptor_bytes = 0;
  std::vector<std::string> peers;
  std::vector<uint64_t> received, loops_received, loops_from, loops_epoch;  // per peer (loops_*: may be shorter)
  uint64_t summaries_in = 0, summary_bytes_in = 0, features_in = 0, feature_bytes_in = 0;
  uint64_t loops_decided = 0, loops_found_late = 0, refused = 0;
};

struct TeamRequest {
  enum Kind : uint8_t { kSummaries = 1, kFeatures = 2 };
  std::string from;
  uint64_t request_id = 0;
  uint8_t kind = 0;
  uint64_t first = 0;  // kSummaries: the first number missed
  uint32_t count = 0;  // kSummaries: how many
  std::string robot;   // kFeatures: the keyframe's robot
  uint64_t id = 0;     // kFeatures: and its id
};

// A pull's answer: a keyframe's whole features (kOk).
struct TeamFeatures {
  enum Status : uint8_t { kOk = 0, kBusy = 1, kUnknown = 2, kMalformed = 3 };
  std::string from;
  uint64_t request_id = 0;
  uint8_t status = kOk;
  std::string reason;                // why, when not kOk
  std::optional<Features> features;  // kOk; received: none when the wire's could not be read
  uint64_t id = 0;                   // sent: the keyframe's id
  uint64_t wire_bytes = 0;           // received: its serialised size
};

// A loop this station decided for a peer's keyframe: sent to the query's station (resent until
// acknowledged) and published here on the robots' loop_closure. The link renders it as a
// LoopClosure (the decider's candidates, the query named as its station numbered it).
struct DecidedLoop {
  std::string peer;    // the query's station
  uint64_t epoch = 0;  // this station's run
  uint64_t seq = 0;    // per peer and run
  DetectionResult result;
  std::string query_robot;
  uint32_t query_session = 0;
  uint64_t query_id = 0;
  double query_stamp = 0.0;  // on the peer's clock
  uint32_t query_features = 0;
  size_t database_size = 0;    // of the first robot's map that accepted it
  std::vector<size_t> robots;  // this station's robots whose maps hold an accepted candidate
};

// A peer's loop for one of this station's keyframes, as received: its numbering, its query and
// candidates, the content the station checks before publishing it (team/peer_loop_check.hpp), and
// what the link publishes when it is taken (the message as it came; `accepted` is decided here).
struct PeerLoop {
  std::string decider;
  uint64_t epoch = 0, seq = 0;
  LoopKey query;  // its query as the decider names it (station, robot, session, id; decider)
  struct Candidate {
    std::string station, robot;
    uint32_t session = 0;
    uint64_t id = 0;
    double probability = 0, filter_probability = 0, similarity = 0;
    bool verified = false;
    int64_t inliers = 0, matches = 0, pose_inliers = 0;
    double inlier_ratio = 0, coverage = 0, homography_share = 0;
    std::array<double, 7> pose{0, 0, 0, 1, 0, 0, 0};  // rotation x, y, z, w; translation x, y, z
    double reprojection_error = 0;
    size_t query_indices = 0, candidate_indices = 0;  // its correspondences
    size_t query_pixels = 0, candidate_pixels = 0;    // their pixels' values (two each, or none)
    bool pixels_finite = true;
    bool accepted = false;  // decided here on arrival (Station::receive), whatever the peer sent
  };
  std::vector<Candidate> candidates;
  size_t frame_id_bytes = 0;
  std::array<double, 4> timings{};  // extraction, query, filter, verification (ms)
  std::any published;               // what the link publishes when it is taken (opaque here)
  // Set by Station::receive on arrival: what its content breaks ("" when nothing). A loop refused
  // so waits without its candidates and message: only its numbering is still read.
  std::string content_problem;
  uint64_t wire_bytes = 0;
};

}  // namespace mild
