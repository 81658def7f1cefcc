// ~database_dir: names that ROS clients send to save_database / load_database resolve inside the
// folder or are refused, whatever they try.

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/io/database_directory.hpp"

namespace fs = std::filesystem;

namespace mild {
namespace {

class Confinement : public ::testing::Test {
 protected:
  void SetUp() override {
    base_ = fs::temp_directory_path() / ("mild_confine_" + std::to_string(::getpid()));
    fs::remove_all(base_);
    fs::create_directories(base_ / "outside");
    root_ = (base_ / "maps").string();
  }
  void TearDown() override { fs::remove_all(base_); }

  void expectRefused(const DatabaseDirectory& dir, const std::string& name, const std::string& words) {
    try {
      dir.resolve(name, true);
      ADD_FAILURE() << "accepted '" << name << "'";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << name << ": " << e.what();
    }
  }
  fs::path base_;
  std::string root_;
};

TEST_F(Confinement, TheFolderIsCreatedAndMustBeAbsolute) {
  const DatabaseDirectory dir(root_);
  EXPECT_TRUE(fs::is_directory(root_));
  EXPECT_EQ(dir.root(), root_);
  EXPECT_THROW(DatabaseDirectory("relative/maps"), InvalidInput);
}

TEST_F(Confinement, NamesInsideResolveThere) {
  const DatabaseDirectory dir(root_);
  EXPECT_EQ(dir.resolve("map.db").display(), root_ + "/map.db");
  EXPECT_EQ(dir.resolve(root_ + "/map.db").display(), root_ + "/map.db") << "absolute, inside";
  EXPECT_EQ(dir.resolve("site_a/map.db", true).display(), root_ + "/site_a/map.db");
  EXPECT_TRUE(fs::is_directory(root_ + "/site_a")) << "sub-folders are made for saving";
}

TEST_F(Confinement, EscapesAreRefused) {
  const DatabaseDirectory dir(root_);
  expectRefused(dir, "../outside/victim.txt", "'..'");
  expectRefused(dir, "site/../../outside/x", "'..'");
  expectRefused(dir, root_ + "/../outside/x.db", "must not contain '..'");  // absolute: named as such
  expectRefused(dir, root_ + "/site/..", "must not contain '..'");
  expectRefused(dir, (base_ / "outside" / "x.db").string(), "outside the database folder");
  expectRefused(dir, root_ + "_evil/x.db", "outside the database folder");
  expectRefused(dir, "/etc/passwd", "outside the database folder");
  expectRefused(dir, root_, "outside the database folder");
  expectRefused(dir, "", "empty");
  expectRefused(dir, "a//b", "empty or '.'");
  expectRefused(dir, "./map.db", "empty or '.'");
  expectRefused(dir, std::string("map\0.db", 7), "NUL");
  expectRefused(dir, std::string(300, 'x'), "255 bytes");
  expectRefused(dir, std::string(5000, 'x'), "4096");
  // A team station's ledger and its temporary file, as a file or a folder on the way.
  expectRefused(dir, "alpha.team_ledger.json", "team station");
  expectRefused(dir, "alpha.team_ledger.json.writing/x", "team station");
  expectRefused(dir, "site/beta.team_ledger.json.writing", "team station");
  EXPECT_FALSE(fs::exists(fs::path(root_) / "alpha.team_ledger.json.writing")) << "no folder made";
  EXPECT_FALSE(fs::exists(base_ / "outside" / "x")) << "nothing is created outside";
}

TEST_F(Confinement, SymbolicLinksBelowTheFolderAreNotFollowed) {
  const DatabaseDirectory dir(root_);
  fs::create_directory_symlink(base_ / "outside", root_ + "/escape");
  expectRefused(dir, "escape/x.db", "not a folder");
  std::ofstream(root_ + "/plain") << "a file";
  expectRefused(dir, "plain/x.db", "not a folder");
  // A link as the file itself resolves (the name is inside), but is refused when opened.
  fs::create_symlink(base_ / "outside" / "victim", root_ + "/link.db");
  const ConfinedFile file = dir.resolve("link.db");
  unsigned long long size = 0;
  EXPECT_THROW(file.openForReading(size), InvalidInput);
  EXPECT_THROW(file.refuseIfNotRegular(), InvalidInput);
}

TEST_F(Confinement, TheFolderItselfMayBeALink) {
  fs::create_directories(base_ / "real_maps");
  fs::create_directory_symlink(base_ / "real_maps", root_);
  const DatabaseDirectory dir(root_);
  EXPECT_EQ(dir.resolve("map.db").display(), root_ + "/map.db");
}

// A hard link planted in the folder is a second name of a file anywhere on the same file system:
// it is refused when opened, and the file it names is not read.
TEST_F(Confinement, HardLinksAreRefusedWhenOpened) {
  const DatabaseDirectory dir(root_);
  std::ofstream(base_ / "outside" / "secret") << "not for clients";
  ASSERT_EQ(::link((base_ / "outside" / "secret").c_str(), (root_ + "/planted.db").c_str()), 0);
  unsigned long long size = 0;
  try {
    dir.resolve("planted.db").openForReading(size);
    ADD_FAILURE() << "a hard link to a file outside was opened";
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("hard links"), std::string::npos) << e.what();
  }
  std::ofstream(root_ + "/own.db") << "a map";
  const int fd = dir.resolve("own.db").openForReading(size);
  EXPECT_GE(fd, 0) << "a file of its own opens";
  EXPECT_EQ(size, 5u);
  ::close(fd);
}

// Saves may not build unbounded trees or fill the disk: names are at most max_depth folders deep,
// and a save that adds a file or folder is refused once the folder holds max_entries of them or its
// files hold max_bytes; replacing a file is always allowed.
TEST_F(Confinement, SavesAreBoundedInDepthEntriesAndBytes) {
  const DatabaseDirectory dir(root_, DirectoryLimits{3, 6, 1000});
  expectRefused(dir, "a/b/c/d/map.db", "4 folders deep; at most 3");
  std::string deep;
  for (int i = 0; i < 2000; ++i) deep += "d/";
  expectRefused(dir, deep + "map.db", "folders deep");
  EXPECT_FALSE(fs::exists(root_ + "/a")) << "a refused save makes no folder";
  EXPECT_NO_THROW(dir.resolve("a/b/c/map.db", true)) << "3 deep is fine";  // 3 folders: 3 entries
  std::ofstream(root_ + "/a/b/c/map.db") << "x";                           // 4
  std::ofstream(root_ + "/one.db") << "x";                                 // 5
  EXPECT_NO_THROW(dir.resolve("two.db", true));                            // the 6th entry fits
  std::ofstream(root_ + "/two.db") << "x";
  expectRefused(dir, "three.db", "~max_database_files");
  expectRefused(dir, "e/f.db", "~max_database_files");
  EXPECT_NO_THROW(dir.resolve("one.db", true)) << "replacing adds nothing";
  EXPECT_NO_THROW(dir.resolve("three.db", false)) << "loading is not saving";

  const DatabaseDirectory small(root_, DirectoryLimits{3, 100, 1000});
  std::ofstream(root_ + "/big.db") << std::string(1000, 'x');
  expectRefused(small, "new.db", "~max_database_dir_mb");
  EXPECT_NO_THROW(small.resolve("big.db", true)) << "the file replaced does not count";
}

}  // namespace
}  // namespace mild
