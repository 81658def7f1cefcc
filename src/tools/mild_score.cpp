// mild_score: scores a candidates CSV (query,candidate,score) against ground truth with the rules of
// ../shared/bench/EVALUATION.md, as mild_offline --gt does.

#include <cstdio>
#include <iostream>

#include <CLI/CLI.hpp>

#include <nlohmann/json.hpp>
#include "common/tool_main.hpp"

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/offline/evaluation.hpp"

int main(int argc, char** argv) {
  CLI::App app{"Score loop-closure candidates against ground truth (recall@100%P, AP, max F1)."};
  app.name("mild_score");
  std::string gt, candidates;
  int min_gap = 40;
  bool json = false;
  app.add_option("gt", gt, "gt_loops.txt")->required();
  app.add_option("candidates", candidates, "CSV rows query,candidate,score")->required();
  app.add_option("--min-gap", min_gap, "pairs closer than this many frames are ignored")->check(CLI::NonNegativeNumber);
  app.add_flag("--json", json, "print one JSON object");
  return mild::tools::toolMain(app, argc, argv, [&] {
    const mild::GroundTruth truth = mild::loadGroundTruth(gt);
    const std::vector<mild::ScoredPair> scored = mild::loadCandidates(candidates);
    const mild::Metrics m = mild::evaluate(truth, scored, min_gap);
    const mild::Decision half = mild::decideAt(truth, scored, 0.5, min_gap);
    if (json) {
      std::cout << nlohmann::json{{"loop_queries", m.loop_queries},
                                  {"scored_queries", m.scored_queries},
                                  {"true_positives", m.true_positives},
                                  {"false_positives", m.false_positives},
                                  {"recall_at_100_precision", m.recall_at_100_precision},
                                  {"average_precision", m.average_precision},
                                  {"max_f1", m.max_f1},
                                  {"precision_at_half", half.precision},
                                  {"recall_at_half", half.recall},
                                  {"right_at_half", half.right},
                                  {"wrong_at_half", half.wrong}}
                       .dump()
                << "\n";
    } else {
      std::printf("recall@100%%P: %.4f\naverage precision: %.4f\nmax F1: %.4f\n", m.recall_at_100_precision,
                  m.average_precision, m.max_f1);
      std::printf("loop queries: %zu, scored queries: %zu, true positives: %zu, false positives: %zu\n", m.loop_queries,
                  m.scored_queries, m.true_positives, m.false_positives);
      std::printf("at probability >= 0.5: precision %.4f, recall %.4f (%zu right, %zu wrong)\n", half.precision,
                  half.recall, half.right, half.wrong);
    }
    return 0;
  });
}
