#pragma once

// What one station tells the others about each keyframe it stores: a few of its descriptors, not
// its image or all its features. The MIH index votes per descriptor, so a keyframe's strongest
// descriptors find the same place in another station's maps as all of them (docs/multi_robot.md
// measures how many are needed); the keypoints, the camera and the other descriptors travel only
// when a peer asks for them to verify a candidate (a pull).

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "mild_lcd/features/features.hpp"

namespace mild {

struct PlaceSummary {
  std::string station;                   // the station that stores the keyframe
  uint64_t seq = 0;                      // its number among that station's summaries: 0, 1, 2, ... in the order stored
  uint64_t epoch = 0;                    // the station's run (StationLedger::beginRun): a peer keys what it took by it
  uint64_t epoch_start = 0;              // the first number of that run
  std::string robot;                     // the robot that saw it (a name of that station's ~robots)
  uint64_t id = 0;                       // its id in that robot's map
  uint32_t session = 0;                  // its session there
  double stamp = 0.0;                    // on its station's clock: never compared with another station's
  uint32_t features = 0;                 // how many features the whole keyframe has
  uint32_t descriptor_bytes = 0;         // the width of each descriptor below
  std::vector<uint8_t> descriptor_data;  // the strongest descriptors, row after row (at most the summary's size)
  // For each other station: how many of its summaries this station held (contiguously from 0)
  // when it stored this keyframe. Which keyframes of two stations came first is decided by this
  // (StationLedger::eligiblePrefix), never by their clocks.
  std::vector<std::pair<std::string, uint64_t>> known;
  // The stations it had not heard from for a while when it stored this keyframe (an outage): to
  // them, a loop of this keyframe is found late.
  std::vector<std::string> unreachable;
  std::vector<std::string> looped_by;  // stations whose loop for it its station holds: not decided again
  bool well_formed = true;             // received: false when the wire's lists did not pair up
  uint64_t wire_bytes = 0;             // received: its serialised size
};

// The descriptors a summary carries: the `count` of the strongest keypoints (by detector response;
// the first ones on ties), in the keyframe's order. All of them when there are no more.
DescriptorList strongestDescriptors(const Features& features, size_t count);

// The default budget of a summary's descriptors (~team/summary_bytes): 243 ORB descriptors, a
// message under 8 KB. On the embedded sample two stations then find every loop between them that
// one node serving both robots finds; 100 descriptors find 90 % of them (test_stations).
constexpr size_t kDefaultSummaryBytes = 7776;

// How many descriptors of `bytes` bytes fit in `budget_bytes` of descriptor data, at least 1.
size_t descriptorsWithin(size_t budget_bytes, int bytes);

}  // namespace mild
