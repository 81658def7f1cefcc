#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "mild_lcd/detector/detector_params.hpp"
#include "mild_lcd/params/parameter_source.hpp"

namespace mild {

// Calls visit(name, field, bounds, doc) for every parameter of DetectorParams (const or not),
// section by section: fields are int, double, bool, uint32_t, uint64_t, std::string, SearchMode or
// std::vector<double>. The names, bounds and docs are each struct's declare(); this is their order.
template <class P, class Visit>
void visitParameters(P& p, Visit&& visit);

// The sections in their order, each with what it is about (config/default.yaml's section comments):
// each section struct's kDoc, the extension points' from their tables.
struct ParameterSection {
  std::string name;
  std::string doc;
};
const std::vector<ParameterSection>& parameterSections();

// Every parameter with its value, bounds and meaning as a YAML file, generated from the
// declarations: of DetectorParams{} it is config/default.yaml (a test keeps the file equal);
// mild_offline --print-config prints the effective ones.
std::string parameterYaml(const DetectorParams& params = {});
// docs/parameters.md's table of the detector's parameters (parameter, default, range, runtime, meaning).
std::string parameterMarkdown();

// Reads every parameter the source has (absent ones keep their defaults), rejects unknown names in
// the detector's namespaces, and validates the result. Throws InvalidInput naming the parameter.
// The filters' parameters are also read by their names of earlier versions, filter/<name>, which
// set <name> in every filter's section that has it (legacyParameterName).
DetectorParams loadDetectorParams(const ParameterSource& source, const DetectorParams& defaults = {});

// The earlier name of a parameter that is still read ("filter/loop_onset" for
// "exclusive_hypotheses/loop_onset"), or "" when it has none.
std::string legacyParameterName(const std::string& name);

// The namespaces that belong to the detector (a source may hold other names outside them).
const std::vector<std::string>& detectorParameterNamespaces();

// The parameters a running detector may change (LoopDetector::retune, the node's dynamic_reconfigure):
// how candidates are chosen, checked and reported; declared with Bounds::runtime(). The others
// shape the stored map (features, index, similarity) or the filter's state and are fixed at start-up.
const std::vector<std::string>& runtimeParameterNames();

// Sets every runtime parameter of `into` to its value in `from`, and only those: what
// LoopDetector::retune applies, so a parameter declared runtime() is retuned without a list to
// keep in step.
void copyRuntimeParameters(const DetectorParams& from, DetectorParams& into);

// Flattened "name: value" lines of every parameter, for logs and --print-config. With a section
// name, that section's only.
std::vector<std::pair<std::string, std::string>> describeParameters(const DetectorParams& p,
                                                                    const std::string& section = "");

// ---------------------------------------------------------------------------------------------

inline std::string searchModeName(SearchMode m) { return m == SearchMode::kExact ? "exact" : "index"; }

template <class P, class Visit>
void visitParameters(P& p, Visit&& visit) {
  visitSection(p.features, visit);
  forEachSection(p.features.extractors, [&](auto& section) { visitSection(section, visit); });
  visitSection(p.database.index, visit);
  visitSection(p.database.similarity, visit);
  visit(std::string("similarity/search"), p.search, Bounds::oneOf({"index", "exact"}),
        "How a query searches the stored features, index (multi-index hashing) or exact (brute force over every "
        "stored feature, for evaluation only).");
  visitSection(p.filter, visit);
  forEachSection(p.filter.filters, [&](auto& section) { visitSection(section, visit); });
  visitSection(p.candidates, visit);
  visitSection(p.verification, visit);
  visitSection(p.scoring, visit);
}

}  // namespace mild
