#include "mild_lcd/io/database_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <optional>
#include <sstream>
#include <string_view>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/filter/filter_state.hpp"
#include "mild_lcd/params/parameter_source.hpp"

namespace mild {
namespace {

// KeyframeRecord::same_place_as in a file (format version 5): this value for none.
constexpr uint64_t kNoSamePlace = UINT64_MAX;

constexpr char kMagic[8] = {'M', 'I', 'L', 'D', 'L', 'C', 'D', '\0'};
constexpr size_t kHeaderBytes = 32;
constexpr size_t kKeypointBytes = 6 * 4;

uint32_t crc(uint32_t running, const uint8_t* data, size_t size) {
  while (size > 0) {  // zlib takes 32-bit lengths
    const uInt chunk = static_cast<uInt>(std::min<size_t>(size, 1u << 30));
    running = static_cast<uint32_t>(crc32(running, data, chunk));
    data += chunk;
    size -= chunk;
  }
  return running;
}

template <class T>
void putRaw(std::vector<uint8_t>& out, const T& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  const auto* p = reinterpret_cast<const uint8_t*>(&v);
  out.insert(out.end(), p, p + sizeof(T));
}

std::string errnoText() { return std::strerror(errno); }

// Buffered writes to a file descriptor, with the payload's CRC kept along the way.
class PayloadWriter {
 public:
  PayloadWriter(int fd, const std::string& path) : fd_(fd), path_(path) { buffer_.reserve(kFlushAt + 4096); }

  template <class T>
  void put(const T& v) {
    putRaw(buffer_, v);
    maybeFlush();
  }
  void putBytes(const void* data, size_t size) {
    const auto* p = static_cast<const uint8_t*>(data);
    buffer_.insert(buffer_.end(), p, p + size);
    maybeFlush();
  }
  void flush() {
    crc_ = crc(crc_, buffer_.data(), buffer_.size());
    size_ += buffer_.size();
    size_t done = 0;
    while (done < buffer_.size()) {
      const ssize_t n = ::write(fd_, buffer_.data() + done, buffer_.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) throw IoError(path_ + ": cannot write (" + errnoText() + ")");
      done += static_cast<size_t>(n);
    }
    buffer_.clear();
  }
  uint64_t size() const { return size_; }
  uint32_t checksum() const { return crc_; }

 private:
  static constexpr size_t kFlushAt = 1 << 20;
  void maybeFlush() {
    if (buffer_.size() >= kFlushAt) flush();
  }
  int fd_;
  std::string path_;
  std::vector<uint8_t> buffer_;
  uint64_t size_ = 0;
  uint32_t crc_ = static_cast<uint32_t>(crc32(0, nullptr, 0));
};

void writePayload(const KeyframeMap& map, PayloadWriter& w) {
  const std::string& parameters = map.builderParameters();
  w.put(static_cast<uint32_t>(parameters.size()));
  w.putBytes(parameters.data(), parameters.size());
  const int bytes = map.descriptorBytes();
  w.put(static_cast<uint32_t>(bytes * 8));
  w.put(map.nextId());
  w.put(static_cast<uint32_t>(map.sessionStart()));
  w.put(static_cast<uint32_t>(map.size()));
  for (KeyframeIndex k = 0; k < map.size(); ++k) {
    const KeyframeRecord& r = map.record(k);
    w.put(r.id);
    w.put(r.stamp);
    w.put(r.session);
    w.put(r.camera.fx);
    w.put(r.camera.fy);
    w.put(r.camera.cx);
    w.put(r.camera.cy);
    w.put(boundedDetectionScale(r.detection_scale));
    w.put(r.same_place_as.value_or(kNoSamePlace));
    w.put(static_cast<uint32_t>(r.keypoints.size()));
    for (const cv::KeyPoint& p : r.keypoints) {
      w.put(p.pt.x);
      w.put(p.pt.y);
      w.put(p.size);
      w.put(p.angle);
      w.put(p.response);
      w.put(static_cast<int32_t>(p.octave));
    }
    for (const Descriptor& d : map.database().descriptors(k)) w.putBytes(d.words.data(), static_cast<size_t>(bytes));
  }
  const std::string filter = map.filter().name();
  w.put(static_cast<uint32_t>(filter.size()));
  w.putBytes(filter.data(), filter.size());
  const std::vector<uint8_t> filter_state = map.filter().saveState();
  w.put(static_cast<uint64_t>(filter_state.size()));
  w.putBytes(filter_state.data(), filter_state.size());
  w.flush();
}

// Reads fixed-size values from the payload, refusing to run past its end.
class Cursor {
 public:
  Cursor(const uint8_t* data, size_t size, const std::string& origin) : p_(data), end_(data + size), origin_(origin) {}

  template <class T>
  T get(const char* what) {
    need(sizeof(T), what);
    T v;
    std::memcpy(&v, p_, sizeof(T));
    p_ += sizeof(T);
    return v;
  }
  const uint8_t* take(size_t bytes, const char* what) {
    need(bytes, what);
    const uint8_t* start = p_;
    p_ += bytes;
    return start;
  }
  // A count of items of `item_bytes` each that must fit in what is left.
  size_t count(size_t item_bytes, const char* what) {
    const uint32_t n = get<uint32_t>(what);
    if (item_bytes > 0 && n > remaining() / item_bytes) {
      throw InvalidInput(origin_ + ": corrupt: " + what + " says " + std::to_string(n) + " but only " +
                         std::to_string(remaining()) + " bytes remain");
    }
    return n;
  }
  size_t remaining() const { return static_cast<size_t>(end_ - p_); }

 private:
  void need(size_t bytes, const char* what) const {
    if (bytes > remaining()) throw InvalidInput(origin_ + ": corrupt: ends inside " + std::string(what));
  }
  const uint8_t* p_;
  const uint8_t* end_;
  std::string origin_;
};

std::map<std::string, std::string> parameterLines(const std::string& text) {
  std::map<std::string, std::string> out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const auto colon = line.find(": ");
    if (colon != std::string::npos) out[line.substr(0, colon)] = line.substr(colon + 2);
  }
  return out;
}

}  // namespace

namespace {

void writeAll(int fd, const std::vector<uint8_t>& bytes, off_t offset, const std::string& display) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::pwrite(fd, bytes.data() + done, bytes.size() - done, offset + static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw IoError(display + ": cannot write (" + errnoText() + ")");
    done += static_cast<size_t>(n);
  }
}

}  // namespace

void saveMap(const KeyframeMap& map, const std::string& path) { saveMap(map, fileAtPath(path)); }

void saveMap(const KeyframeMap& map, const ConfinedFile& file) {
  // Written in full under a temporary name, then renamed over the file (ConfinedFile::replace): a
  // crash at any moment leaves the previous file or the new one, both complete. The magic is the
  // signature replace writes first: what marks a killed save's temporary file as one.
  const auto write = [&](int fd) {
    // The rest of the header is written once the payload's size and checksum are known.
    writeAll(fd, std::vector<uint8_t>(kHeaderBytes - sizeof(kMagic), 0), sizeof(kMagic), file.display());
    if (::lseek(fd, static_cast<off_t>(kHeaderBytes), SEEK_SET) < 0) throw IoError(file.display() + ": cannot seek");
    PayloadWriter writer(fd, file.display());
    writePayload(map, writer);

    std::vector<uint8_t> header(kMagic, kMagic + sizeof(kMagic));
    putRaw(header, kDatabaseFormatVersion);
    putRaw(header, uint32_t{0});
    putRaw(header, writer.size());
    putRaw(header, writer.checksum());
    putRaw(header, crc(static_cast<uint32_t>(crc32(0, nullptr, 0)), header.data(), header.size()));
    writeAll(fd, header, 0, file.display());
  };
  file.replace(write, std::string_view(kMagic, sizeof(kMagic)));
}

namespace {

// The payload a file's header announces, once the header, its checksums and the payload's size are
// checked; its format version beside it.
struct CheckedPayload {
  uint32_t version = 0;
  const uint8_t* data = nullptr;
  size_t size = 0;
};

CheckedPayload checkedPayload(const uint8_t* data, size_t size, const std::string& origin) {
  if (size == 0) throw InvalidInput(origin + ": empty file, not a mild_lcd database");
  if (size < kHeaderBytes || std::memcmp(data, kMagic, sizeof(kMagic)) != 0) {
    throw InvalidInput(origin + ": not a mild_lcd database (no MILDLCD header)");
  }
  Cursor header(data, kHeaderBytes, origin);
  header.take(sizeof(kMagic), "the magic");
  const uint32_t version = header.get<uint32_t>("the version");
  const uint32_t flags = header.get<uint32_t>("the flags");
  const uint64_t payload_size = header.get<uint64_t>("the payload size");
  const uint32_t payload_crc = header.get<uint32_t>("the payload checksum");
  const uint32_t header_crc = header.get<uint32_t>("the header checksum");
#ifndef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION  // the fuzzer must get past the checksums
  if (crc(static_cast<uint32_t>(crc32(0, nullptr, 0)), data, kHeaderBytes - 4) != header_crc) {
    throw InvalidInput(origin + ": corrupt header (checksum mismatch)");
  }
#else
  (void)header_crc;
  (void)payload_crc;
#endif
  if (version < 1 || version > kDatabaseFormatVersion) {
    throw InvalidInput(origin + ": database format version " + std::to_string(version) +
                       "; this mild_lcd reads versions 1 to " + std::to_string(kDatabaseFormatVersion));
  }
  if (flags != 0) throw InvalidInput(origin + ": unknown format flags " + std::to_string(flags));
  if (payload_size != size - kHeaderBytes) {
    throw InvalidInput(origin + ": truncated or padded: the header announces " + std::to_string(payload_size) +
                       " bytes of data, the file holds " + std::to_string(size - kHeaderBytes));
  }
  const uint8_t* payload = data + kHeaderBytes;
#ifndef FUZZING_BUILD_MODE_UNSAFE_FOR_PRODUCTION
  if (crc(static_cast<uint32_t>(crc32(0, nullptr, 0)), payload, payload_size) != payload_crc) {
    throw InvalidInput(origin + ": corrupt data (checksum mismatch)");
  }
#endif
  return {version, payload, static_cast<size_t>(payload_size)};
}

// Bytes of one keyframe record before its features, by format version.
size_t recordBytes(uint32_t version) {
  return 8 + 8 + 4 + (version >= 2 ? 4 : 0) + (version >= 3 ? 4 * 8 : 0) + (version >= 4 ? 4 : 0) +
         (version >= 5 ? 8 : 0);
}

void readKeyframe(Cursor& in, uint32_t version, int descriptor_width, const std::string& origin, KeyframeRecord& r,
                  DescriptorList& descriptors) {
  const size_t descriptor_bytes = static_cast<size_t>(descriptor_width);
  r.id = in.get<uint64_t>("a keyframe id");
  r.stamp = in.get<double>("a keyframe stamp");
  if (version >= 2) r.session = in.get<uint32_t>("a keyframe session");
  if (version >= 3) {
    r.camera.fx = in.get<double>("a keyframe's camera");
    r.camera.fy = in.get<double>("a keyframe's camera");
    r.camera.cx = in.get<double>("a keyframe's camera");
    r.camera.cy = in.get<double>("a keyframe's camera");
    if (!r.camera.wellFormed()) {
      throw InvalidInput(origin + ": corrupt: keyframe " + std::to_string(r.id) + " has malformed camera intrinsics");
    }
  }
  if (version >= 4) {
    r.detection_scale = in.get<float>("a keyframe's detection scale");
    if (!detectionScaleValid(r.detection_scale)) {
      throw InvalidInput(origin + ": corrupt: keyframe " + std::to_string(r.id) + " has detection scale " +
                         std::to_string(r.detection_scale) + " (1 to " +
                         std::to_string(static_cast<int>(kMaxDetectionScale)) + ")");
    }
  }
  if (version >= 5) {
    // The place the keyframe was found to show when it was stored: an id that names no keyframe of
    // the map is no link (LoopDetector looks it up and stops there).
    const auto same_place = in.get<uint64_t>("a keyframe's place");
    if (same_place != kNoSamePlace) r.same_place_as = same_place;
  }
  const size_t features = in.count(kKeypointBytes + descriptor_bytes, "a keyframe's feature count");
  r.keypoints.resize(features);
  for (cv::KeyPoint& p : r.keypoints) {
    p.pt.x = in.get<float>("a keypoint");
    p.pt.y = in.get<float>("a keypoint");
    p.size = in.get<float>("a keypoint");
    p.angle = in.get<float>("a keypoint");
    p.response = in.get<float>("a keypoint");
    p.octave = in.get<int32_t>("a keypoint");
  }
  const uint8_t* bytes = in.take(features * descriptor_bytes, "descriptors");
  descriptors = descriptorsFromBytes(bytes, features * descriptor_bytes, descriptor_width);
}

void readFilterState(Cursor& in, uint32_t version, const std::string& origin, MapState& state) {
  if (version == 1) {
    // Version 1 held the exclusive-hypothesis filter's posterior and no-loop probability, without
    // the count: that filter's state (filter_state.hpp) once the count is put in front.
    const size_t posterior = in.count(sizeof(double), "the filter state size");
    const uint8_t* beliefs = in.take(posterior * sizeof(double) + sizeof(double), "the filter state");
    std::vector<double> values(posterior);
    double no_loop = 0.0;
    if (posterior > 0) std::memcpy(values.data(), beliefs, posterior * sizeof(double));
    std::memcpy(&no_loop, beliefs + posterior * sizeof(double), sizeof(double));
    state.filter_name = "exclusive_hypotheses";
    state.filter_state = packFilterState(values, {no_loop});
    return;
  }
  const size_t name = in.count(1, "the filter name");
  const uint8_t* name_chars = in.take(name, "the filter name");
  state.filter_name.assign(reinterpret_cast<const char*>(name_chars), name);
  const uint64_t bytes = in.get<uint64_t>("the filter state size");
  if (bytes > in.remaining()) throw InvalidInput(origin + ": corrupt: the filter state runs past the end");
  const uint8_t* filter_state = in.take(static_cast<size_t>(bytes), "the filter state");
  state.filter_state.assign(filter_state, filter_state + bytes);
}

}  // namespace

MapState parseMapState(const uint8_t* data, size_t size, const std::string& origin) {
  const CheckedPayload payload = checkedPayload(data, size, origin);
  const uint32_t version = payload.version;
  Cursor in(payload.data, payload.size, origin);
  MapState state;
  const size_t text = in.count(1, "the parameters");
  const uint8_t* chars = in.take(text, "the parameters");
  state.parameters.assign(reinterpret_cast<const char*>(chars), text);
  if (version >= 2) {  // version 1 held ORB's 256 bits only
    const uint32_t bits = in.get<uint32_t>("the descriptor width");
    if (bits % 8 != 0 || bits / 8 < static_cast<uint32_t>(kMinDescriptorBytes) ||
        bits / 8 > static_cast<uint32_t>(kMaxDescriptorBytes)) {
      throw InvalidInput(origin + ": corrupt: descriptors of " + std::to_string(bits) + " bits");
    }
    state.descriptor_bytes = static_cast<int>(bits / 8);
  }
  state.next_id = in.get<uint64_t>("the next id");
  state.session_start = in.get<uint32_t>("the session start");
  const size_t keyframes = in.count(recordBytes(version), "the keyframe count");
  state.records.resize(keyframes);
  state.descriptors.resize(keyframes);
  for (size_t k = 0; k < keyframes; ++k) {
    readKeyframe(in, version, state.descriptor_bytes, origin, state.records[k], state.descriptors[k]);
  }
  readFilterState(in, version, origin, state);
  if (in.remaining() != 0) throw InvalidInput(origin + ": corrupt: " + std::to_string(in.remaining()) + " stray bytes");
  return state;
}

namespace {

void readExactly(int fd, uint8_t* data, size_t size, off_t offset, const std::string& display) {
  size_t done = 0;
  while (done < size) {
    const ssize_t n = ::pread(fd, data + done, size - done, offset + static_cast<off_t>(done));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) throw IoError(display + ": read error (" + errnoText() + ")");
    if (n == 0) throw InvalidInput(display + ": truncated while reading (the file shrank)");
    done += static_cast<size_t>(n);
  }
}

// Closes the descriptor on every path out.
struct FdCloser {
  int fd;
  ~FdCloser() { ::close(fd); }
};

}  // namespace

MapState readMapFile(const std::string& path, unsigned long long max_bytes) {
  return readMapFile(fileAtPath(path), max_bytes);
}

MapState readMapFile(const ConfinedFile& file, unsigned long long max_bytes) {
  unsigned long long size = 0;
  const FdCloser fd{file.openForReading(size)};
  const std::string& origin = file.display();
  if (size == 0) throw InvalidInput(origin + ": empty file, not a mild_lcd database");
  // The header first: a huge or sparse file that is not a database costs 32 bytes, not its size.
  std::vector<uint8_t> header(kHeaderBytes, 0);
  if (size < kHeaderBytes) throw InvalidInput(origin + ": not a mild_lcd database (no MILDLCD header)");
  readExactly(fd.fd, header.data(), kHeaderBytes, 0, origin);
  if (std::memcmp(header.data(), kMagic, sizeof(kMagic)) != 0) {
    throw InvalidInput(origin + ": not a mild_lcd database (no MILDLCD header)");
  }
  uint64_t payload_size = 0;
  std::memcpy(&payload_size, header.data() + 16, sizeof(payload_size));
  if (payload_size != size - kHeaderBytes) {
    throw InvalidInput(origin + ": truncated or padded: the header announces " + std::to_string(payload_size) +
                       " bytes of data, the file holds " + std::to_string(size - kHeaderBytes));
  }
  if (size > max_bytes) {
    throw CapacityError(origin + ": " + std::to_string(size >> 20) + " MB, over the " +
                        std::to_string(max_bytes >> 20) + " MB allowed (~max_database_mb)");
  }
  try {
    std::vector<uint8_t> bytes(static_cast<size_t>(size));
    std::memcpy(bytes.data(), header.data(), kHeaderBytes);
    readExactly(fd.fd, bytes.data() + kHeaderBytes, bytes.size() - kHeaderBytes, static_cast<off_t>(kHeaderBytes),
                origin);
    return parseMapState(bytes.data(), bytes.size(), origin);
  } catch (const std::bad_alloc&) {
    throw CapacityError(origin + ": not enough memory to load a database of " + std::to_string(size >> 20) + " MB");
  }
}

PreparedLoad prepareLoad(const KeyframeMap& map, MapState state, const std::string& origin, bool continue_session,
                         std::chrono::steady_clock::time_point start) {
  LoadReport report;
  report.keyframes = state.records.size();
  for (const auto& d : state.descriptors) report.features += d.size();

  // The index is rebuilt with this map's parameters; say so when the file's differ.
  const auto saved = parameterLines(state.parameters);
  std::string differing;
  visitSection(map.databaseParams().index, [&](const std::string& name, const auto& field, const Bounds&, const char*) {
    const std::string value = parameterText(field);
    auto it = saved.find(name);
    if (it != saved.end() && it->second != value) {
      differing += (differing.empty() ? "" : ", ") + name + " " + it->second + " -> " + value;
    }
  });
  std::optional<MapContents> restore;
  try {
    restore.emplace(map.prepareRestore(std::move(state), continue_session));
  } catch (const InvalidInput& e) {
    throw InvalidInput(origin + ": " + e.what());
  } catch (const std::bad_alloc&) {
    throw CapacityError(origin + ": not enough memory to rebuild the index of " + std::to_string(report.keyframes) +
                        " keyframes");
  }
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::ostringstream msg;
  msg.precision(3);
  msg << "loaded " << report.keyframes << " keyframes (" << report.features << " features) from " << origin << " in "
      << report.seconds << " s" << (continue_session ? ", continuing the saved session" : ", as a new session");
  if (!differing.empty()) msg << "; index rebuilt with this node's parameters (" << differing << ")";
  report.message = msg.str();
  return PreparedLoad{std::move(*restore), std::move(report)};
}

PreparedLoad prepareLoad(const KeyframeMap& map, const ConfinedFile& file, bool continue_session,
                         unsigned long long max_bytes) {
  const auto start = std::chrono::steady_clock::now();  // the report's time counts the reading
  return prepareLoad(map, readMapFile(file, max_bytes), file.display(), continue_session, start);
}

void commitLoad(KeyframeMap& map, PreparedLoad&& prepared) { map.commitRestore(std::move(prepared.restore)); }

LoadReport loadMap(KeyframeMap& map, const ConfinedFile& file, bool continue_session, unsigned long long max_bytes) {
  PreparedLoad prepared = prepareLoad(map, file, continue_session, max_bytes);
  LoadReport report = prepared.report;
  commitLoad(map, std::move(prepared));
  return report;
}

LoadReport loadMap(KeyframeMap& map, const std::string& path, bool continue_session) {
  return loadMap(map, fileAtPath(path), continue_session);
}

LoadReport mergeState(KeyframeMap& map, MapState state, const std::string& origin) {
  const auto start = std::chrono::steady_clock::now();
  LoadReport report;
  report.keyframes = state.records.size();
  for (const auto& d : state.descriptors) report.features += d.size();
  const size_t before = map.size();
  try {
    map.merge(std::move(state));
  } catch (const InvalidInput& e) {
    throw InvalidInput(origin + ": " + e.what());
  } catch (const std::bad_alloc&) {
    throw CapacityError(origin + ": not enough memory to merge " + std::to_string(report.keyframes) + " keyframes");
  }
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::ostringstream msg;
  msg.precision(3);
  msg << "merged " << report.keyframes << " keyframes (" << report.features << " features) from " << origin
      << " into the running map of " << before << " in " << report.seconds << " s; it now holds " << map.size()
      << " keyframes, new ones join session " << map.session();
  report.message = msg.str();
  return report;
}

LoadReport mergeMap(KeyframeMap& map, const ConfinedFile& file, unsigned long long max_bytes) {
  return mergeState(map, readMapFile(file, max_bytes), file.display());
}

LoadReport mergeMap(KeyframeMap& map, const std::string& path) { return mergeMap(map, fileAtPath(path)); }

}  // namespace mild
