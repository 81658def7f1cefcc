#pragma once

#include <cstdint>
#include <string>

#include "mild_lcd/loop_detector.hpp"

namespace mild {

// The detector's state in one file, for map reuse across runs.
//
// Layout (little-endian). Header, 32 bytes: magic "MILDLCD" + '\0', format version (u32), flags
// (u32, 0), payload size (u64), CRC-32 of the payload (u32), CRC-32 of the 28 bytes before it
// (u32). Payload: the saving detector's parameters as "name: value" lines, next id, session start,
// the keyframes (id, stamp, keypoints, descriptors) and the filter's state. The MIH index is not
// stored: it is rebuilt from the descriptors on load, with the loading detector's parameters, so a
// file written with other index parameters cannot be mixed with this index.
//
// Saving is crash-safe: the file is written under a temporary name in the same folder, flushed to
// disk (fsync), then renamed over the target, so a crash at any moment leaves either the previous
// file or the new one, both complete.
constexpr uint32_t kDatabaseFormatVersion = 1;

// Throws InvalidInput naming the path when the file cannot be written; the previous file is kept.
void saveDetector(const LoopDetector& detector, const std::string& path);

// Reads and checks a file (magic, version, sizes, checksums, every count against the bytes that
// remain). Throws InvalidInput naming the file and the problem; touches no detector.
DetectorState readDetectorFile(const std::string& path);
// The same on bytes in memory; `origin` names them in errors.
DetectorState parseDetectorState(const uint8_t* data, size_t size, const std::string& origin);

struct LoadReport {
  size_t keyframes = 0;
  size_t features = 0;
  double seconds = 0.0;
  std::string message;  // one line, e.g. for a service reply; says which index parameters differed
};

// readDetectorFile, then LoopDetector::restore. On any error the detector is left as it was.
LoadReport loadDetector(LoopDetector& detector, const std::string& path, bool continue_session);

}  // namespace mild
