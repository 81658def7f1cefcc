// mild_bench_ledger: what saving a station's ledger costs a robot. The ledger is written after
// each loop a station decides or takes (~save_on_shutdown); it is guarded by the detector lock, so
// a robot's keyframe waits for whatever part of the save happens under that lock. The station
// copies the ledger under the lock and makes its text after releasing it (Station::ledgerText):
// this measures both parts, in the same run, for ledgers holding more and more loops, and prints
// text / copy: how much longer the lock would be held if the text were made under it (these
// machines are noisy; the ratio is what carries over).

#include <algorithm>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "common/tool_main.hpp"
#include "mild_lcd/common/stopwatch.hpp"
#include "mild_lcd/team/station_ledger.hpp"

namespace {

struct Options {
  std::vector<size_t> loops = {1000, 10000, 100000};
  size_t own = 5000;         // this station's keyframes, numbered
  size_t announced = 20000;  // keyframes a peer announced
  int repeats = 5;
};

// A ledger of alpha (two robots) that took bravo's summaries and holds `loops` loops.
mild::StationLedger ledgerHolding(const Options& o, size_t loops) {
  mild::StationLedger ledger("alpha", 2);
  ledger.beginRun(mild::StationLedger::drawEpoch());
  for (uint64_t i = 0; i < o.own; ++i) ledger.recordOwn(i % 2, i, static_cast<mild::KeyframeIndex>(i / 2), {});
  for (uint64_t i = 0; i < o.announced; ++i) {
    ledger.took("bravo");
    ledger.announced("bravo", "robot3", 0, i);
  }
  for (uint64_t i = 0; i < loops; ++i) ledger.keepLoop(mild::LoopKey{"alpha", "robot1", 0, i, "bravo"});
  return ledger;
}

double medianOf(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"The cost of saving a station ledger: the copy under the detector lock, the text after it",
               "mild_bench_ledger"};
  Options o;
  app.add_option("--loops", o.loops, "loops held, one ledger per value")->delimiter(',')->check(CLI::Range(0, 100000));
  app.add_option("--own", o.own, "this station's keyframes")->check(CLI::Range(0, 1000000));
  app.add_option("--announced", o.announced, "keyframes a peer announced")->check(CLI::Range(0, 1000000));
  app.add_option("--repeats", o.repeats, "measurements per ledger (the median is printed)")->check(CLI::Range(1, 100));
  return mild::tools::toolMain(app, argc, argv, [&] {
    std::cout << "loops held | ledger bytes | copy under the lock, ms | text after it, ms | text / copy\n";
    for (const size_t loops : o.loops) {
      const mild::StationLedger ledger = ledgerHolding(o, loops);
      std::vector<double> copy_ms, text_ms;
      size_t bytes = 0;
      for (int r = 0; r < o.repeats; ++r) {
        const mild::Clock::time_point copying = mild::Clock::now();
        const mild::StationLedger copy = ledger;
        copy_ms.push_back(mild::msSince(copying));
        const mild::Clock::time_point writing = mild::Clock::now();
        bytes = copy.toText().size();
        text_ms.push_back(mild::msSince(writing));
      }
      const double copy = medianOf(copy_ms), text = medianOf(text_ms);
      std::cout << loops << " | " << bytes << " | " << copy << " | " << text << " | " << text / copy << "\n";
    }
    return 0;
  });
}
