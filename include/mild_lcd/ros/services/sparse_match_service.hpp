#pragma once

// The sparse_match service's work, without ROS plumbing: a request's two sides (given or stored)
// matched by the MIH-based sparse matcher and, when asked, checked geometrically.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>

#include "mild_lcd/SparseMatch.h"
#include "mild_lcd/features/features.hpp"
#include "mild_lcd/verification/geometric_verifier.hpp"

namespace mild_lcd {

// Serves a SparseMatch request. `stored` returns a copy of the features of a keyframe in the
// database (none for an unknown id), so that the matching itself needs no lock on it. A side with
// more than max_features descriptors, given in the request or stored, is refused. Failures come back as success = false
// with a message, never as exceptions.
using StoredFeatures = std::function<std::optional<mild::Features>(uint64_t id)>;
constexpr size_t kDefaultMaxMatchFeatures = 10000;
mild_lcd::SparseMatch::Response sparseMatch(const mild_lcd::SparseMatch::Request& request, const StoredFeatures& stored,
                                            const mild::GeometricVerifier& verifier,
                                            size_t max_features = kDefaultMaxMatchFeatures);

}  // namespace mild_lcd
