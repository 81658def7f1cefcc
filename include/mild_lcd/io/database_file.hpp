#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include "mild_lcd/io/database_directory.hpp"
#include "mild_lcd/place/keyframe_map.hpp"

namespace mild {

// A keyframe map in one file, for map reuse across runs.
//
// Layout (little-endian). Header, 32 bytes: magic "MILDLCD" + '\0', format version (u32), flags
// (u32, 0), payload size (u64), CRC-32 of the payload (u32), CRC-32 of the 28 bytes before it
// (u32). Payload (version 5): the saving detector's parameters as "name: value" lines, the
// descriptor width in bits, next id, session start, the keyframes (id, stamp, session, camera
// intrinsics fx fy cx cy as doubles, 0 = unknown, detection scale as a float, 1 to 64: how much the
// frame was shrunk before its keypoints were found, features/max_pixels; the id of the keyframe
// whose place it was found to show when it was stored as a u64, all ones = none; keypoints,
// descriptors), the temporal filter's name and its state. Version 4 files (no place: none),
// version 3 files (no detection scale: 1), version 2
// files (no intrinsics) and version 1 files (no width, no sessions, the exclusive-hypothesis
// filter's posterior) are read too. The MIH index is not
// stored: it is rebuilt from the descriptors on load, with the loading detector's parameters, so a
// file written with other index parameters cannot be mixed with this index.
//
// A file holds one robot's map. A RobotTeam's pair filters (robot A's keyframes against robot B's
// map) are not stored: each describes two maps at once, and a file is saved and loaded per robot.
// Any load, merge or reset of either map makes its hypotheses stale (RobotTeam::mapChanged restarts
// it from "no loop"), so a stored pair state could only ever be read back when every robot's file
// is loaded together, exactly as saved. What its loss costs: after a restart, the first few
// inter-robot keyframes of a revisit, while the filter's belief builds up again.
//
// Saving is crash-safe (ConfinedFile::replace, io/database_directory.hpp): the file is written in
// full under a temporary name beside it, flushed to disk, then renamed over the target, so a crash
// at any moment leaves either the previous file or the new one, both complete.
constexpr uint32_t kDatabaseFormatVersion = 5;
// Default bound on the size of a file to load (the node's ~max_database_mb).
constexpr unsigned long long kDefaultMaxDatabaseBytes = 16ull << 30;

// Throws IoError when the file cannot be written, InvalidInput when something other than a regular
// file sits at the target; the previous file is kept either way.
void saveMap(const KeyframeMap& map, const ConfinedFile& file);
void saveMap(const KeyframeMap& map, const std::string& path);

// Reads and checks a file: a regular file only (never a link, FIFO, device or folder); the header
// (magic, version, payload size against the file's size) before anything else is read or
// allocated; a file over max_bytes refused (CapacityError) unread; then checksums and every count
// against the bytes that remain. Throws InvalidInput naming the file and the problem, IoError when
// it cannot be read, CapacityError when it does not fit (max_bytes, memory); touches no map.
MapState readMapFile(const ConfinedFile& file, unsigned long long max_bytes = kDefaultMaxDatabaseBytes);
MapState readMapFile(const std::string& path, unsigned long long max_bytes = kDefaultMaxDatabaseBytes);
// The same on bytes in memory; `origin` names them in errors.
MapState parseMapState(const uint8_t* data, size_t size, const std::string& origin);

struct LoadReport {
  size_t keyframes = 0;
  size_t features = 0;
  double seconds = 0.0;
  std::string message;  // one line, e.g. for a service reply; says which index parameters differed
};

// readMapFile, then KeyframeMap::restore. On any error the map is left as it was.
LoadReport loadMap(KeyframeMap& map, const ConfinedFile& file, bool continue_session,
                   unsigned long long max_bytes = kDefaultMaxDatabaseBytes);
LoadReport loadMap(KeyframeMap& map, const std::string& path, bool continue_session);

// The same in two steps, for callers that must not hold a lock on the map for the reading and the
// index rebuild: prepareLoad touches nothing shared (only the map's parameters, which never change),
// commitLoad swaps the prepared state in and cannot fail.
struct PreparedLoad {
  MapContents restore;
  LoadReport report;
};
PreparedLoad prepareLoad(const KeyframeMap& map, const ConfinedFile& file, bool continue_session,
                         unsigned long long max_bytes = kDefaultMaxDatabaseBytes);
// The same from a state already read (readMapFile since `started`; `origin` names it), for callers
// that decide something from the file (its width: RobotTeam::takeWidth) before preparing.
PreparedLoad prepareLoad(const KeyframeMap& map, MapState state, const std::string& origin, bool continue_session,
                         std::chrono::steady_clock::time_point started = std::chrono::steady_clock::now());
void commitLoad(KeyframeMap& map, PreparedLoad&& prepared);

// KeyframeMap::merge of a state read from a file (`origin` names it in errors and the report).
// The caller holds whatever lock guards the map: merging reads it and rebuilds its index.
LoadReport mergeState(KeyframeMap& map, MapState state, const std::string& origin);
// readMapFile, then mergeState. On any error the map is left as it was.
LoadReport mergeMap(KeyframeMap& map, const ConfinedFile& file,
                    unsigned long long max_bytes = kDefaultMaxDatabaseBytes);
LoadReport mergeMap(KeyframeMap& map, const std::string& path);

}  // namespace mild
