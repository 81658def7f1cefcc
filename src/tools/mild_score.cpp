// mild_score: scores a candidates CSV (query,candidate,score) against ground truth with the rules of
// ../shared/bench/EVALUATION.md, as mild_offline --gt does, and reports the hard decision at the
// configuration's scoring/decision_probability.

#include <cstdio>
#include <iostream>

#include <CLI/CLI.hpp>

#include <nlohmann/json.hpp>
#include "common/decision_line.hpp"
#include "common/tool_main.hpp"

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/detector/detector_parameters.hpp"
#include "mild_lcd/offline/evaluation.hpp"

int main(int argc, char** argv) {
  CLI::App app{"Score loop-closure candidates against ground truth (recall@100%P, AP, max F1)."};
  app.name("mild_score");
  std::string gt, candidates, config;
  int min_gap = 40;
  bool json = false;
  app.add_option("gt", gt, "gt_loops.txt")->required();
  app.add_option("candidates", candidates, "CSV rows query,candidate,score")->required();
  app.add_option("--min-gap", min_gap, "pairs closer than this many frames are ignored")->check(CLI::NonNegativeNumber);
  app.add_option("--config", config,
                 "YAML parameter file whose scoring/decision_probability is the decision reported (default: the "
                 "built-in defaults, those of config/default.yaml)");
  app.add_flag("--json", json, "print one JSON object");
  return mild::tools::toolMain(app, argc, argv, [&] {
    const mild::GroundTruth truth = mild::loadGroundTruth(gt);
    const std::vector<mild::ScoredPair> scored = mild::loadCandidates(candidates);
    const mild::Metrics m = mild::evaluate(truth, scored, min_gap);
    mild::DetectorParams params;
    if (!config.empty()) params = mild::loadDetectorParams(mild::YamlParameterSource::fromFile(config));
    const double decision_probability = params.scoring.decision_probability;
    const mild::Decision decision = mild::decideAt(truth, scored, decision_probability, min_gap);
    if (json) {
      std::cout << nlohmann::json{{"loop_queries", m.loop_queries},
                                  {"scored_queries", m.scored_queries},
                                  {"true_positives", m.true_positives},
                                  {"false_positives", m.false_positives},
                                  {"recall_at_100_precision", m.recall_at_100_precision},
                                  {"average_precision", m.average_precision},
                                  {"max_f1", m.max_f1},
                                  {"decision_probability", decision_probability},
                                  {"precision_at_decision", decision.precision},
                                  {"recall_at_decision", decision.recall},
                                  {"right_at_decision", decision.right},
                                  {"wrong_at_decision", decision.wrong}}
                       .dump()
                << "\n";
    } else {
      std::printf("recall@100%%P: %.4f\naverage precision: %.4f\nmax F1: %.4f\n", m.recall_at_100_precision,
                  m.average_precision, m.max_f1);
      std::printf("loop queries: %zu, scored queries: %zu, true positives: %zu, false positives: %zu\n", m.loop_queries,
                  m.scored_queries, m.true_positives, m.false_positives);
      std::printf("%s\n", mild::tools::decisionLine(decision).c_str());
    }
    return 0;
  });
}
