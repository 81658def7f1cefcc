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

}  // namespace
}  // namespace mild
