#pragma once

namespace mild {

// One descriptor correspondence: query index, train index, Hamming distance.
struct FeatureMatch {
  int query = 0;
  int train = 0;
  int distance = 0;
  bool operator==(const FeatureMatch& o) const {
    return query == o.query && train == o.train && distance == o.distance;
  }
};

}  // namespace mild
