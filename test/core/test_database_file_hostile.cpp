// Database files against hostile file systems: what a ROS client (or an unlucky disk) can put where
// a map is expected, and saves that race each other. Every case fails without its fix.

#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <thread>

#include <opencv2/imgcodecs.hpp>

#include "../common/scratch_folder.hpp"
#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/loop_detector.hpp"
#include "mild_lcd/io/database_directory.hpp"
#include "mild_lcd/io/database_file.hpp"
#include "random_descriptors.hpp"

namespace fs = std::filesystem;

namespace mild {
namespace {

// A detector holding `keyframes` keyframes of random features, ids from `first_id`.
std::unique_ptr<LoopDetector> detectorWith(size_t keyframes, uint64_t first_id = 0, uint32_t seed = 1) {
  DetectorParams p;
  p.verification.enabled = false;
  auto d = std::make_unique<LoopDetector>(p);
  std::mt19937_64 rng(seed);
  for (size_t k = 0; k < keyframes; ++k) {
    Features f;
    for (int i = 0; i < 50; ++i) {
      f.descriptors.push_back(test::randomDescriptor(rng));
      f.keypoints.emplace_back(static_cast<float>(i), static_cast<float>(k), 7.0f);
    }
    d->process(Observation::ofFeatures(std::move(f), static_cast<double>(k), first_id + k));
  }
  return d;
}

// Runs `body` in a child process and waits at most `seconds`: true when it exited 0 in time. A
// child that hangs is killed (a FIFO opened for reading blocks until a writer comes).
bool inChildWithin(double seconds, const std::function<int()>& body) {
  const pid_t pid = fork();
  if (pid == 0) _exit(body());
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  int status = 0;
  while (std::chrono::steady_clock::now() < end) {
    if (waitpid(pid, &status, WNOHANG) == pid) return WIFEXITED(status) && WEXITSTATUS(status) == 0;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(pid, SIGKILL);
  waitpid(pid, &status, 0);
  return false;
}

class HostileFiles : public mild::test::ScratchFolderTest {
 protected:
  static std::string contents(const std::string& file) {
    std::ifstream in(file, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }
  // Sets a file's (or link's) modification time `seconds` into the past.
  static void age(const std::string& file, int seconds) {
    struct timespec times[2];
    clock_gettime(CLOCK_REALTIME, &times[0]);
    times[0].tv_sec -= seconds;
    times[1] = times[0];
    ASSERT_EQ(utimensat(AT_FDCWD, file.c_str(), times, AT_SYMLINK_NOFOLLOW), 0) << std::strerror(errno);
  }
  size_t temporaries(const std::string& target) const {
    size_t n = 0;
    for (const auto& e : fs::directory_iterator(dir_)) {
      n += e.path().filename().string().rfind(temporaryPrefix(target), 0) == 0 ? 1 : 0;
    }
    return n;
  }
  // The name a save to `target` gives its temporary files, less their 16 hex digits.
  static std::string temporaryPrefix(const std::string& target) {
    return "." + fs::path(target).filename().string() + ".mild-lcd-save.";
  }
  // What a killed save leaves: the magic, then part of a map.
  static void halfASave(const std::string& file) {
    std::ofstream(file, std::ios::binary) << std::string("MILDLCD\0", 8) << "half a database";
  }
};

TEST_F(HostileFiles, AFifoIsRefusedWithoutBlocking) {
  ASSERT_EQ(mkfifo(path("map.mild").c_str(), 0600), 0);
  const std::string fifo = path("map.mild");
  EXPECT_TRUE(inChildWithin(10.0, [&] {
    try {
      readMapFile(fifo);
    } catch (const InvalidInput& e) {
      return std::string(e.what()).find("a FIFO") != std::string::npos ? 0 : 1;
    } catch (...) {
    }
    return 2;
  })) << "reading a FIFO must fail at once, naming it";
}

TEST_F(HostileFiles, AFolderIsRefusedAsInput) {
  fs::create_directories(path("map.mild"));
  try {
    readMapFile(path("map.mild"));
    FAIL() << "read a folder";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("a folder"), std::string::npos) << e.what();
  }
}

TEST_F(HostileFiles, ASymbolicLinkIsNeitherReadNorWrittenThrough) {
  auto detector = detectorWith(3);
  saveMap(detector->map(), path("real.mild"));
  std::ofstream(path("victim.txt")) << "precious";
  fs::create_symlink(path("real.mild"), path("link.mild"));
  EXPECT_THROW(readMapFile(path("link.mild")), InvalidInput);
  fs::create_symlink(path("victim.txt"), path("to_victim.mild"));
  EXPECT_THROW(saveMap(detector->map(), path("to_victim.mild")), InvalidInput);
  EXPECT_EQ(contents(path("victim.txt")), "precious");
  EXPECT_TRUE(fs::is_symlink(path("to_victim.mild"))) << "the link itself is left alone too";
}

TEST_F(HostileFiles, AFolderOrDeviceAtTheTargetIsNotReplaced) {
  auto detector = detectorWith(3);
  fs::create_directories(path("folder.mild"));
  EXPECT_THROW(saveMap(detector->map(), path("folder.mild")), InvalidInput);
  EXPECT_TRUE(fs::is_directory(path("folder.mild")));
  if (mknod(path("null.mild").c_str(), S_IFCHR | 0600, makedev(1, 3)) == 0) {  // /dev/null's numbers (needs root)
    EXPECT_THROW(saveMap(detector->map(), path("null.mild")), InvalidInput);
    EXPECT_TRUE(fs::is_character_file(path("null.mild")));
  }
}

// A sparse 2 GB file: refused on its 32-byte header, in a child whose address space could not even
// hold the file (reading it whole first would throw std::bad_alloc instead).
TEST_F(HostileFiles, AHugeFileIsJudgedByItsHeaderNotReadWhole) {
  const std::string huge = path("huge.mild");
  { std::ofstream(huge) << "X"; }
  fs::resize_file(huge, 2ull << 30);
  EXPECT_TRUE(inChildWithin(30.0, [&] {
#if !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
    const rlimit limit{512ull << 20, 512ull << 20};  // sanitizers reserve terabytes of shadow: no limit there
    setrlimit(RLIMIT_AS, &limit);
#endif
    try {
      readMapFile(huge);
    } catch (const InvalidInput& e) {
      return std::string(e.what()).find("not a mild_lcd database") != std::string::npos ? 0 : 1;
    } catch (...) {
    }
    return 2;
  }));
}

// A real database over the size bound is refused unread, as a capacity problem.
TEST_F(HostileFiles, AFileOverTheSizeBoundIsRefusedUnread) {
  auto detector = detectorWith(40);
  saveMap(detector->map(), path("map.mild"));
  const auto size = fs::file_size(path("map.mild"));
  ASSERT_GT(size, 64u << 10);
  try {
    readMapFile(path("map.mild"), 64u << 10);
    FAIL() << "read a file over the bound";
  } catch (const CapacityError& e) {
    EXPECT_NE(std::string(e.what()).find("allowed"), std::string::npos) << e.what();
  }
  EXPECT_EQ(readMapFile(path("map.mild"), size).records.size(), 40u) << "at the bound it loads";
}

// Two detectors (as two nodelets in one manager) saving to one path at once, 20 times: every save
// leaves a complete file of one of them, never a mix, and no temporary file stays behind.
TEST_F(HostileFiles, ConcurrentSavesToOnePathNeverCorruptEachOther) {
  auto small = detectorWith(5, 0, 1);
  auto large = detectorWith(60, 1000, 2);
  const std::string target = path("shared.mild");
  for (int round = 0; round < 20; ++round) {
    std::atomic<int> failures{0};
    std::thread a([&] {
      try {
        saveMap(small->map(), target);
      } catch (...) {
        ++failures;
      }
    });
    std::thread b([&] {
      try {
        saveMap(large->map(), target);
      } catch (...) {
        ++failures;
      }
    });
    a.join();
    b.join();
    EXPECT_EQ(failures.load(), 0) << "round " << round;
    const MapState state = readMapFile(target);
    const size_t n = state.records.size();
    ASSERT_TRUE(n == 5 || n == 60) << "round " << round << ": " << n << " keyframes";
    EXPECT_EQ(state.records.front().id, n == 5 ? 0u : 1000u) << "one detector's file, whole";
  }
  EXPECT_EQ(temporaries(target), 0u);
}

TEST_F(HostileFiles, TemporaryFilesOfKilledSavesAreRemovedByTheNextSave) {
  auto detector = detectorWith(3);
  const std::string target = path("map.mild");
  const std::string prefix = path(temporaryPrefix(target));
  const std::string stale = prefix + "000000000badf00d", fresh = prefix + "000000000000beef",
                    locked = prefix + "00000000000c0ffe", empty = prefix + "00000000deadbeef";
  for (const auto& f : {stale, fresh, locked}) halfASave(f);
  std::ofstream{empty};  // killed between creating the file and writing to it
  age(stale, 3600);
  age(empty, 3600);
  age(locked, 3600);
  const int held = open(locked.c_str(), O_RDONLY);
  ASSERT_EQ(flock(held, LOCK_EX), 0);  // a save in progress elsewhere holds its lock
  saveMap(detector->map(), target);
  EXPECT_FALSE(fs::exists(stale)) << "abandoned an hour ago, unlocked: removed";
  EXPECT_FALSE(fs::exists(empty)) << "and the empty one";
  EXPECT_TRUE(fs::exists(fresh)) << "seconds old: may belong to a save that has not locked it yet";
  EXPECT_TRUE(fs::exists(locked)) << "locked: a save in progress";
  close(held);
  EXPECT_EQ(readMapFile(target).records.size(), 3u);
}

// Issue 49 item 2: a user's files named like the temporary files of earlier versions
// ("<name>.tmp.<8 characters>"), hours old and unlocked, are the user's: a save never removes them.
TEST_F(HostileFiles, AUsersFilesNamedLikeTemporariesAreNeverRemoved) {
  auto detector = detectorWith(3);
  const std::vector<std::pair<std::string, std::string>> kept = {{"snap.mild", "snap.mild.tmp.20261205"},
                                                                 {"site.mild", "site.mild.tmp.backup01"},
                                                                 {"site.mild", "site.mild.tmp.0badf00d"}};
  for (const auto& [target, user_file] : kept) {
    saveMap(detectorWith(2, 100)->map(), path(user_file));  // a map the user saved under that name
    age(path(user_file), 3600);
  }
  for (const auto& [target, user_file] : kept) saveMap(detector->map(), path(target));
  for (const auto& [target, user_file] : kept) {
    ASSERT_TRUE(fs::exists(path(user_file))) << user_file << " was removed by a save to " << target;
    EXPECT_EQ(readMapFile(path(user_file)).records.size(), 2u) << user_file;
  }

  // Under a temporary's own name, only what is provably a killed save's goes: not a file of other
  // content, not one with a second name, not one of another pattern (15 or 17 digits, capitals).
  const std::string prefix = path(temporaryPrefix("snap.mild"));
  const std::string other_content = prefix + "0123456789abcdef", linked = prefix + "00000000000000aa",
                    short_name = prefix + "0123456789abcde", long_name = prefix + "0123456789abcdef0",
                    capitals = prefix + "0123456789ABCDEF";
  std::ofstream(other_content) << "a user's notes";
  halfASave(path("second_name"));
  fs::create_hard_link(path("second_name"), linked);
  for (const auto& f : {short_name, long_name, capitals}) halfASave(f);
  for (const auto& f : {other_content, linked, short_name, long_name, capitals}) age(f, 3600);
  saveMap(detector->map(), path("snap.mild"));
  for (const auto& f : {other_content, linked, short_name, long_name, capitals}) {
    EXPECT_TRUE(fs::exists(f)) << f << " is not provably a killed save's, and was removed";
  }
  EXPECT_EQ(contents(other_content), "a user's notes");

  // Nor can a client make such a file: the name is refused for saving and loading.
  const DatabaseDirectory folder(dir_.string());
  for (const bool saving : {true, false}) {
    try {
      folder.resolve(fs::path(prefix).filename().string() + "0123456789abcdef", saving);
      FAIL() << "a temporary file's name was accepted as a map's";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("reserved"), std::string::npos) << e.what();
    }
  }
  EXPECT_NO_THROW(folder.resolve("snap.mild.tmp.20261205", true)) << "a user's name is a user's name";
  // A saved file's name leaves room for its temporary's (32 bytes more, at most 255 in all).
  EXPECT_NO_THROW(saveMap(detector->map(), folder.resolve(std::string(223, 'a'), true)));
  EXPECT_THROW(folder.resolve(std::string(224, 'a'), true), InvalidInput);
  EXPECT_NO_THROW(folder.resolve(std::string(255, 'a'), false)) << "reading has no temporary";
}

// A link planted under a temporary name (a guess at the next one, or an old one's) is not followed:
// neither by the save nor by the clean-up.
TEST_F(HostileFiles, LinksPlantedAtTemporaryNamesAreNotFollowed) {
  auto detector = detectorWith(3);
  const std::string target = path("map.mild");
  std::ofstream(path("victim.txt")) << "precious";
  const std::string planted = path(temporaryPrefix(target)) + "0000000012345678";
  fs::create_symlink(path("victim.txt"), planted);
  age(planted, 3600);
  for (int i = 0; i < 5; ++i) saveMap(detector->map(), target);
  EXPECT_EQ(contents(path("victim.txt")), "precious");
  EXPECT_TRUE(fs::is_symlink(planted));
  EXPECT_EQ(readMapFile(target).records.size(), 3u);
}

}  // namespace
}  // namespace mild
