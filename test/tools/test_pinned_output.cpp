// mild_offline's output on the embedded sample (sample/corridor, the shipped configuration), pinned to
// a checked-in file: a refactor shows that it changed nothing, and a change that does change what
// the detector finds must update the file on purpose, in the same commit, saying why.
//
// The pin is what mild_offline prints (but the candidates file's path) and its --details CSV: every
// candidate of every keyframe with its probability, filter probability, similarity, matches,
// inliers, verdict and the scorer's inputs. Timings are not in it.
//
// To regenerate it after an intended change:
//   MILD_UPDATE_PINNED_OUTPUT=1 .build/devel/lib/mild_lcd/test_pinned_output
// then look at `git diff test/data/pinned/` and say in the commit what changed and why.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "../common/run_command.hpp"
#include "../common/scratch_folder.hpp"

namespace {

const std::string kSource = MILD_SOURCE_DIR;
const std::string kPinned = kSource + "/test/data/pinned/mild_offline_sample_corridor.txt";

std::string readFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<std::string> linesOf(const std::string& text) {
  std::vector<std::string> lines;
  std::stringstream s(text);
  for (std::string line; std::getline(s, line);) lines.push_back(line);
  return lines;
}

class PinnedOutput : public mild::test::ScratchFolderTest {};

TEST_F(PinnedOutput, MildOfflineOnTheSampleIsThePinnedFile) {
  // stdout to a file; what the command prints on stderr (the progress bar, errors) stays in run.output.
  const mild::test::CommandResult run = mild::test::runCommand(
      std::string(MILD_OFFLINE_BIN) + " --images " + kSource + "/sample/corridor --config " + kSource +
      "/config/default.yaml --gt " + kSource + "/sample/corridor/gt_loops.txt --output " + path("c.csv") +
      " --details " + path("d.csv") + " > " + path("stdout.txt"));
  ASSERT_EQ(run.status, 0) << run.output << readFile(path("stdout.txt"));

  std::string actual;
  for (const std::string& line : linesOf(readFile(path("stdout.txt")))) {
    if (line.rfind("candidates: ", 0) == 0) continue;  // the scratch folder's path
    actual += line + "\n";
  }
  actual += "--- details (mild_offline --details)\n" + readFile(path("d.csv"));

  if (const char* update = std::getenv("MILD_UPDATE_PINNED_OUTPUT"); update != nullptr && std::string(update) == "1") {
    std::ofstream(kPinned) << actual;
    GTEST_SKIP() << "wrote " << kPinned << ": check `git diff` and commit it with the change that made it";
  }

  const std::string pinned = readFile(kPinned);
  ASSERT_FALSE(pinned.empty()) << kPinned << " is missing or empty";
  if (actual == pinned) return;
  const std::vector<std::string> want = linesOf(pinned), got = linesOf(actual);
  size_t first = 0, differing = 0;
  const size_t n = std::max(want.size(), got.size());
  for (size_t k = n; k-- > 0;) {
    const std::string w = k < want.size() ? want[k] : "(none)", g = k < got.size() ? got[k] : "(none)";
    if (w != g) {
      ++differing;
      first = k;
    }
  }
  ADD_FAILURE() << "mild_offline's output on the sample differs from " << kPinned << " in " << differing
                << " line(s) (pinned " << want.size() << " lines, now " << got.size() << "); first at line "
                << first + 1 << ":\n  pinned: " << (first < want.size() ? want[first] : "(none)")
                << "\n  now:    " << (first < got.size() ? got[first] : "(none)")
                << "\nIf the change is intended, regenerate the file (see test/tools/test_pinned_output.cpp).";
}

}  // namespace
