#include <gtest/gtest.h>

#include <map>
#include <random>
#include <set>
#include <string>

#include "mild_lcd/common/errors.hpp"
#include "mild_lcd/index/mih_index.hpp"
#include "random_descriptors.hpp"

namespace mild {
namespace {

constexpr int kOrbBits = 256;

MihParams uncapped(int m, int r) {
  MihParams p;
  p.num_tables = m;
  p.radius = r;
  p.cap_buckets = false;
  p.max_candidates_per_feature = 0;  // the pigeonhole guarantee holds without the query budget
  return p;
}

std::set<FeatureId> visited(const MihIndex& index, const Descriptor& q, FeatureId limit = kAllKeyframes) {
  std::set<FeatureId> ids;
  ProbeCounters counters;
  index.probe(q, limit, counters, [&](FeatureId id, int) { ids.insert(id); });
  return ids;
}

// Pigeonhole: d differing bits spread over m substrings leave at least one substring with at most
// r of them whenever d < m (r + 1), so the pair must meet in some table.
TEST(MihIndex, FindsEveryFeatureWithinPigeonholeDistance) {
  std::mt19937_64 rng(42);
  const std::vector<std::pair<int, int>> settings = {{16, 0}, {8, 0},  {32, 0}, {15, 0}, {24, 0},
                                                     {16, 1}, {10, 1}, {8, 2},  {12, 2}, {16, 3}};
  for (auto [m, r] : settings) {
    MihIndex index(uncapped(m, r), kOrbBits);
    const int guaranteed = m * (r + 1);
    DescriptorList stored;
    const Descriptor base = test::randomDescriptor(rng);
    // Features at every distance from the query, plus unrelated ones; one keyframe each so that the
    // intra-image rule cannot hide any of them.
    for (int d = 0; d < guaranteed + 40 && d <= kOrbBits; ++d) stored.push_back(test::flipRandomBits(base, d, rng));
    for (int i = 0; i < 200; ++i) stored.push_back(test::randomDescriptor(rng));
    for (size_t i = 0; i < stored.size(); ++i) index.insertKeyframe(&stored[i], 1, static_cast<FeatureId>(i));

    const std::set<FeatureId> found = visited(index, base);
    for (size_t i = 0; i < stored.size(); ++i) {
      const int d = hammingDistance(base, stored[i]);
      bool meets = false;
      for (int t = 0; t < m; ++t) meets |= index.meetsInTable(base, stored[i], t);
      if (d < guaranteed) {
        ASSERT_TRUE(meets) << "m=" << m << " r=" << r << " d=" << d;
      }
      // The probe finds exactly the features that meet in at least one table.
      ASSERT_EQ(found.count(static_cast<FeatureId>(i)) == 1, meets) << "m=" << m << " r=" << r << " d=" << d;
    }
  }
}

TEST(MihIndex, ProbesEveryBucketWithinTheRadius) {
  for (int r = 0; r <= 3; ++r) {
    MihIndex index(uncapped(16, r), kOrbBits);
    ProbeCounters counters;
    index.probe(Descriptor{}, kAllKeyframes, counters, [](FeatureId, int) {});
    uint64_t per_table = 0;
    uint64_t binomial = 1;
    for (int k = 0; k <= r; ++k) {
      per_table += binomial;
      binomial = binomial * (16 - k) / (k + 1);
    }
    EXPECT_EQ(counters.buckets_probed, 16 * per_table) << "r=" << r;
  }
}

TEST(MihIndex, KeepsOneEntryPerKeyframePerBucket) {
  std::mt19937_64 rng(1);
  MihIndex index(uncapped(16, 0), kOrbBits);
  const Descriptor d = test::randomDescriptor(rng);
  const DescriptorList copies(200, d);
  index.insertKeyframe(copies.data(), copies.size(), 0);
  EXPECT_EQ(index.entryCount(), 16u);
  EXPECT_EQ(visited(index, d), (std::set<FeatureId>{0}));
  // A second keyframe with the same descriptor gets its own entries.
  index.insertKeyframe(copies.data(), 1, 200);
  EXPECT_EQ(index.entryCount(), 32u);
  EXPECT_EQ(visited(index, d), (std::set<FeatureId>{0, 200}));
}

TEST(MihIndex, DiscardsBucketsOverTheirCapAndStopsGrowingThem) {
  std::mt19937_64 rng(3);
  MihParams p;
  p.num_tables = 16;
  p.min_bucket_cap = 5;
  p.bucket_cap_factor = 1e-9;  // the floor decides
  MihIndex index(p, kOrbBits);
  const Descriptor common = test::randomDescriptor(rng);
  for (FeatureId k = 0; k < 5; ++k) index.insertKeyframe(&common, 1, k);
  EXPECT_EQ(index.discardedBuckets(), 0u);
  EXPECT_EQ(visited(index, common).size(), 5u);
  index.insertKeyframe(&common, 1, 5);  // the sixth entry would exceed the cap of 5
  EXPECT_EQ(index.discardedBuckets(), 16u);
  EXPECT_EQ(index.entryCount(), 0u);
  EXPECT_TRUE(visited(index, common).empty());
  index.insertKeyframe(&common, 1, 6);
  EXPECT_EQ(index.entryCount(), 0u);
  EXPECT_EQ(index.discardedBuckets(), 16u);
  // Other buckets are unaffected.
  const Descriptor other = test::randomDescriptor(rng);
  index.insertKeyframe(&other, 1, 7);
  EXPECT_EQ(visited(index, other), (std::set<FeatureId>{7}));
}

// A factor meant as "no cap" (beyond size_t's range once multiplied) once converted to 0 and left
// every bucket at the floor: now it caps nothing a map can hold.
TEST(MihIndex, AHugeCapFactorCapsNothing) {
  MihParams p;
  p.num_tables = 16;
  p.min_bucket_cap = 5;
  p.bucket_cap_factor = 1e300;
  p.max_bucket_entries = 0;
  MihIndex index(p, kOrbBits);
  Descriptor common;
  for (FeatureId k = 0; k < 50; ++k) index.insertKeyframe(&common, 1, k);
  EXPECT_EQ(index.discardedBuckets(), 0u);
  EXPECT_EQ(visited(index, common).size(), 50u);
}

TEST(MihIndex, DefaultCapFollowsThePaperFormula) {
  // N_buckets = 50 * N_features / 2^16 with N_features = 1.31M gives 1000 entries.
  MihParams p;
  p.expected_features = 1310720;
  p.max_bucket_entries = 0;  // a bounded bucket is trimmed at 256 entries, never discarded
  MihIndex index(p, kOrbBits);
  Descriptor common;
  for (FeatureId k = 0; k < 1000; ++k) index.insertKeyframe(&common, 1, k);
  EXPECT_EQ(index.discardedBuckets(), 0u);
  index.insertKeyframe(&common, 1, 1000);
  EXPECT_EQ(index.discardedBuckets(), 16u);
}

TEST(MihIndex, BoundedBucketsKeepTheirNewestEntries) {
  std::mt19937_64 rng(9);
  MihParams p = uncapped(16, 0);
  p.max_bucket_entries = 4;
  MihIndex index(p, kOrbBits);
  const Descriptor d = test::randomDescriptor(rng);
  for (FeatureId k = 0; k < 10; ++k) index.insertKeyframe(&d, 1, k);
  index.deferMerges(false);  // merge now: over-the-bound recent entries are dropped there
  EXPECT_EQ(visited(index, d), (std::set<FeatureId>{6, 7, 8, 9}));
  EXPECT_EQ(index.entryCount(), 16u * 4u);
  for (FeatureId k = 10; k < 13; ++k) index.insertKeyframe(&d, 1, k);  // settled ones give way at once
  EXPECT_EQ(visited(index, d), (std::set<FeatureId>{9, 10, 11, 12}));
  EXPECT_EQ(index.entryCount(), 16u * 4u);
  EXPECT_EQ(index.evictedEntries(), 16u * 9u);
  // Other buckets are untouched, and the bound does not discard.
  const Descriptor other = test::randomDescriptor(rng);
  index.insertKeyframe(&other, 1, 13);
  EXPECT_EQ(visited(index, other), (std::set<FeatureId>{13}));
  EXPECT_EQ(index.discardedBuckets(), 0u);
  index.clear();  // an emptied index has evicted nothing (its counters describe what it holds)
  EXPECT_EQ(index.evictedEntries(), 0u);
  EXPECT_EQ(index.entryCount(), 0u);
}

// Live insertion, as a detector does it: new entries land in the room a merge left after their
// run, then in chains, and merges move everything into place; at every point in between a probe
// must see exactly the entries a plain model of the tables holds. Substrings drawn from a small
// alphabet make buckets long and shared, so that rooms fill, chains form and merges happen.
// m = 16: directly addressed tables; m = 8: 32-bit substrings, slots handed out on first use.
TEST(MihIndex, LiveInsertionFindsExactlyTheBucketMembersThroughRoomsChainsAndMerges) {
  for (const int m : {16, 8}) {
    SCOPED_TRACE("m = " + std::to_string(m));
    std::mt19937_64 rng(77);
    MihParams p = uncapped(m, 0);
    p.max_bucket_entries = 0;  // every entry stays (BoundedBuckets... tests the bound)
    MihIndex index(p, kOrbBits);
    const SubstringLayout& layout = index.layout();
    const auto draw = [&rng] {
      Descriptor d(kOrbDescriptorBytes);
      for (auto& w : d.words) {
        w = 0;
        // 48 values per 16 bits, in 6 of the 16 shards of a 16-bit table
        for (int part = 0; part < 4; ++part) w |= ((rng() % 6) << 13 | rng() % 8) << (16 * part);
      }
      return d;
    };
    std::vector<std::map<uint64_t, std::set<FeatureId>>> model(m);  // table -> key -> ids
    FeatureId next = 0;
    for (int k = 0; k < 600; ++k) {
      DescriptorList kf(25);
      for (auto& d : kf) d = draw();
      for (int t = 0; t < m; ++t) {
        std::set<uint64_t> seen;  // one entry per keyframe per bucket
        for (size_t i = 0; i < kf.size(); ++i) {
          if (seen.insert(layout.key(kf[i], t)).second) model[t][layout.key(kf[i], t)].insert(next + i);
        }
      }
      index.insertKeyframe(kf.data(), kf.size(), next);
      next += static_cast<FeatureId>(kf.size());
      if (k % 37 == 0 || k == 599) {
        for (int q = 0; q < 20; ++q) {
          const Descriptor query = draw();
          std::set<FeatureId> expected;
          for (int t = 0; t < m; ++t) {
            const auto it = model[t].find(layout.key(query, t));
            if (it != model[t].end()) expected.insert(it->second.begin(), it->second.end());
          }
          ASSERT_EQ(visited(index, query), expected) << "after keyframe " << k;
          const FeatureId limit = next / 2;
          std::set<FeatureId> below;
          for (FeatureId id : expected) {
            if (id < limit) below.insert(id);
          }
          ASSERT_EQ(visited(index, query, limit), below) << "after keyframe " << k;
        }
      }
    }
    size_t stored = 0;
    for (const auto& table : model) {
      for (const auto& [key, ids] : table) stored += ids.size();
    }
    EXPECT_EQ(index.entryCount(), stored);
  }
}

// Live insertion merges as it goes, a few shards per insert: however the map grows, chains (a
// dependent read per entry at query time) stay a small part of it. Fails if queued merges never run
// or fall behind for good.
TEST(MihIndex, ChainsStayASmallPartOfTheEntriesAsTheMapGrows) {
  std::mt19937_64 rng(5);
  MihParams p = uncapped(16, 0);
  p.max_bucket_entries = 0;
  MihIndex index(p, kOrbBits);
  DescriptorList kf(300);
  FeatureId next = 0;
  for (int k = 0; k < 1500; ++k) {
    for (auto& d : kf) d = test::randomDescriptor(rng);
    index.insertKeyframe(kf.data(), kf.size(), next);
    next += static_cast<FeatureId>(kf.size());
    if (k >= 500 && k % 100 == 0) {
      EXPECT_LT(index.chainedEntries() * 10, index.entryCount()) << "after keyframe " << k;
    }
  }
  index.deferMerges(false);  // merges every chain
  EXPECT_EQ(index.chainedEntries(), 0u);
}

// A query budget reads the shortest buckets first and the newest entries of the last one it
// reaches: a feature met in one rare bucket is found even when the common buckets alone would use
// the budget many times over.
TEST(MihIndex, QueryBudgetReadsShortestBucketsFirstAndNewestEntries) {
  std::mt19937_64 rng(33);
  for (bool inline_prefixes : {false, true}) {
    MihParams p = uncapped(16, 0);
    p.max_bucket_entries = 0;
    p.max_candidates_per_feature = 50;
    p.inline_prefixes = inline_prefixes;
    MihIndex index(p, kOrbBits);
    const Descriptor q = test::randomDescriptor(rng);
    Descriptor rare = q;  // meets q in table 0 only
    for (int t = 1; t < 16; ++t) rare.flip(16 * t);
    Descriptor common = q;  // meets q in tables 1..15
    common.flip(0);
    index.insertKeyframe(&rare, 1, 0);
    for (FeatureId k = 1; k <= 60; ++k) index.insertKeyframe(&common, 1, k);
    index.deferMerges(false);  // 60 settled, the next 40 recent
    for (FeatureId k = 61; k <= 100; ++k) index.insertKeyframe(&common, 1, k);

    std::set<FeatureId> expected = {0};
    for (FeatureId k = 52; k <= 100; ++k) expected.insert(k);  // the newest 49 of the common ones
    ProbeCounters counters;
    std::set<FeatureId> found;
    if (inline_prefixes) {
      index.probeWithPrefixes(q, kAllKeyframes, counters, [&](FeatureId id, uint64_t prefix) {
        found.insert(id);
        EXPECT_EQ(prefix, id == 0 ? rare.words[0] : common.words[0]);
      });
    } else {
      index.probe(q, kAllKeyframes, counters, [&](FeatureId id, int) { found.insert(id); });
    }
    EXPECT_EQ(found, expected) << inline_prefixes;
    EXPECT_EQ(counters.entries_visited, 50u);

    // Entries at or past the limit neither count against the budget nor show.
    std::set<FeatureId> below_limit = {0};
    for (FeatureId k = 42; k <= 90; ++k) below_limit.insert(k);
    EXPECT_EQ(visited(index, q, 91), below_limit) << inline_prefixes;

    // Without the budget every entry of every bucket is read.
    MihParams unlimited = p;
    unlimited.max_candidates_per_feature = 0;
    MihIndex all(unlimited, kOrbBits);
    all.insertKeyframe(&rare, 1, 0);
    for (FeatureId k = 1; k <= 100; ++k) all.insertKeyframe(&common, 1, k);
    ProbeCounters all_counters;
    all.probe(q, kAllKeyframes, all_counters, [](FeatureId, int) {});
    EXPECT_EQ(all_counters.entries_visited, 1u + 15u * 100u);
  }
}

// Reading ahead (locate several features, prepare the next, read this one: what a database query
// does) gives every feature the ids gather() gives, in the same order, with the same counts; over
// settled runs, rooms, chains, bounded buckets and a budget that some features exhaust.
TEST(MihIndex, PlannedReadsGiveWhatProbingGives) {
  std::mt19937_64 rng(35);
  MihParams p = uncapped(16, 0);
  p.max_bucket_entries = 8;
  p.max_candidates_per_feature = 24;
  MihIndex index(p, kOrbBits);
  // A few hundred keyframes of near-copies of 40 places, so that buckets fill, get trimmed, merge.
  std::vector<Descriptor> places;
  for (int i = 0; i < 40; ++i) places.push_back(test::randomDescriptor(rng));
  FeatureId next = 0;
  for (int k = 0; k < 300; ++k) {
    std::vector<Descriptor> keyframe;
    for (int i = 0; i < 20; ++i) {
      Descriptor d = places[(k + i) % places.size()];
      for (int f = 0; f < 6; ++f) d.flip(static_cast<int>(rng() % kOrbBits));
      keyframe.push_back(d);
    }
    index.insertKeyframe(keyframe.data(), keyframe.size(), next);
    next += static_cast<FeatureId>(keyframe.size());
  }
  ASSERT_TRUE(index.hasQueryBudget());
  std::vector<Descriptor> queries;
  for (int i = 0; i < 40; ++i) {
    Descriptor d = places[static_cast<size_t>(i)];
    d.flip(static_cast<int>(rng() % kOrbBits));
    queries.push_back(d);
  }
  const FeatureId limit = next - 100;  // the newest entries are past the limit
  MihIndex::ProbePlan plans[3];
  ProbeCounters located, planned_counters;
  index.locate(queries[0], located, plans[0]);
  index.locate(queries[1], located, plans[1]);
  index.prepare(plans[0]);
  size_t exhausted = 0;
  for (size_t i = 0; i < queries.size(); ++i) {
    if (i + 2 < queries.size()) index.locate(queries[i + 2], located, plans[(i + 2) % 3]);
    if (i + 1 < queries.size()) index.prepare(plans[(i + 1) % 3]);
    std::vector<FeatureId> probed, planned;
    ProbeCounters probe_counters;
    index.gather(queries[i], limit, probe_counters, probed);
    const uint64_t before = planned_counters.entries_visited;
    index.gatherPlanned(plans[i % 3], limit, planned_counters, planned);
    ASSERT_EQ(planned, probed) << "query feature " << i;
    EXPECT_EQ(planned_counters.entries_visited - before, probe_counters.entries_visited);
    exhausted += probed.size() == 24;
  }
  EXPECT_EQ(located.buckets_probed, 16u * queries.size());
  EXPECT_GT(exhausted, 0u) << "no query feature reached the budget";
  EXPECT_GT(index.evictedEntries(), 0u);
}

// Ids read besides the budget (the near-past band's exclusion window, IdRange) are read only in the
// buckets the budget reaches: the window's matched counts and the eligible keyframes' then come from
// the same buckets. Read in every bucket, the window's counts stood above the eligible keyframes'
// wherever the budget ran out (BRISK's 32 tables sooner than ORB's 16), and the band ended at the
// window's edge (docs/accuracy.md, "The near-past band and BRISK").
TEST(MihIndex, IdsBesidesTheBudgetAreReadOnlyInTheBucketsItReaches) {
  std::mt19937_64 rng(35);
  for (bool inline_prefixes : {false, true}) {
    const Descriptor q = test::randomDescriptor(rng);
    Descriptor rare = q;  // meets q in table 0 only
    for (int t = 1; t < 16; ++t) rare.flip(16 * t);
    Descriptor common = q;  // meets q in tables 1..15
    common.flip(0);
    const auto read = [&](uint32_t budget, std::set<FeatureId>& found) {
      MihParams p = uncapped(16, 0);
      p.max_bucket_entries = 0;
      p.max_candidates_per_feature = budget;
      p.inline_prefixes = inline_prefixes;
      MihIndex index(p, kOrbBits);
      for (FeatureId k = 0; k < 50; ++k) index.insertKeyframe(&rare, 1, k);      // q's bucket of table 0: 50 ids
      for (FeatureId k = 50; k < 110; ++k) index.insertKeyframe(&common, 1, k);  // of tables 1..15: 60 each
      index.deferMerges(false);
      const IdRange ids(110, 100);  // 100..109 read besides the budget
      ProbeCounters counters;
      if (inline_prefixes) {
        index.probeWithPrefixes(q, ids, counters, [&](FeatureId id, uint64_t) { found.insert(id); });
      } else {
        index.probe(q, ids, counters, [&](FeatureId id, int) { found.insert(id); });
      }
      return counters.entries_visited;
    };
    // A budget of 50 is spent in table 0's bucket, the shortest: the window is read in none of the
    // others.
    std::set<FeatureId> found, expected;
    for (FeatureId k = 0; k < 50; ++k) expected.insert(k);
    EXPECT_EQ(read(50, found), 50u) << inline_prefixes;
    EXPECT_EQ(found, expected) << inline_prefixes;
    // A budget of 80 reaches table 1's bucket too: the window there, besides the budget, then its 30
    // newest eligible ids; tables 2..15 are not read, the window's ids in them neither.
    found.clear();
    for (FeatureId k = 70; k < 110; ++k) expected.insert(k);
    EXPECT_EQ(read(80, found), 50u + 10u + 30u) << inline_prefixes;
    EXPECT_EQ(found, expected) << inline_prefixes;
  }
}

// The budget is per 16 tables: BRISK's 32 tables read twice as many entries as ORB's 16.
TEST(MihIndex, QueryBudgetScalesWithTheTableCount) {
  std::mt19937_64 rng(34);
  for (int bytes : {32, 64}) {
    MihParams p = uncapped(0, 0);
    p.max_bucket_entries = 0;
    p.max_candidates_per_feature = 20;
    MihIndex index(p, bytes * 8);
    const Descriptor d = test::randomDescriptor(rng, bytes);
    for (FeatureId k = 0; k < 100; ++k) index.insertKeyframe(&d, 1, k);
    ProbeCounters counters;
    index.probe(d, kAllKeyframes, counters, [](FeatureId, int) {});
    EXPECT_EQ(counters.entries_visited, 20u * static_cast<uint64_t>(index.layout().count()) / 16u) << bytes;
  }
}

// Two neighbouring buckets (substring values 2j and 2j + 1 in every table) both over the bound in
// the same merge: each keeps its own newest entries (a merge once shifted the second bucket's
// evicted entries into the first one's run).
TEST(MihIndex, NeighbouringBucketsOverTheBoundEachKeepTheirOwnNewest) {
  std::mt19937_64 rng(21);
  for (bool inline_prefixes : {false, true}) {
    MihParams p = uncapped(16, 0);
    p.max_bucket_entries = 3;
    p.inline_prefixes = inline_prefixes;
    MihIndex index(p, kOrbBits);
    Descriptor a = test::randomDescriptor(rng);
    for (int t = 0; t < 16; ++t) {
      if (a.bit(16 * t)) a.flip(16 * t);  // every substring even ...
    }
    Descriptor b = a;
    for (int t = 0; t < 16; ++t) b.flip(16 * t);  // ... and b's the next bucket in every table
    for (FeatureId round = 0; round < 3; ++round) {
      for (FeatureId k = 5u * round; k < 5u * round + 5u; ++k) {
        const DescriptorList pair = {a, b};
        index.insertKeyframe(pair.data(), 2, 2 * k);  // a is feature 2k, b 2k + 1
      }
      index.deferMerges(false);  // merge now
      const FeatureId last = 5 * round + 4;
      EXPECT_EQ(visited(index, a), (std::set<FeatureId>{2 * last - 4, 2 * last - 2, 2 * last})) << round;
      EXPECT_EQ(visited(index, b), (std::set<FeatureId>{2 * last - 3, 2 * last - 1, 2 * last + 1})) << round;
    }
    EXPECT_EQ(index.entryCount(), 16u * 6u);
  }
}

TEST(MihIndex, IgnoresIdsAtOrBeyondTheLimit) {
  std::mt19937_64 rng(5);
  MihIndex index(uncapped(16, 0), kOrbBits);
  const Descriptor d = test::randomDescriptor(rng);
  for (FeatureId k = 0; k < 10; ++k) index.insertKeyframe(&d, 1, k);
  EXPECT_EQ(visited(index, d, 4), (std::set<FeatureId>{0, 1, 2, 3}));
}

// BRISK's 512 bits: the automatic table count keeps 16-bit substrings (32 tables), and the
// pigeonhole guarantee holds at the wider width as at 256 bits.
TEST(MihIndex, WideDescriptorsGetSixteenBitTablesAndTheSameGuarantee) {
  std::mt19937_64 rng(12);
  MihParams p;
  p.cap_buckets = false;
  p.max_candidates_per_feature = 0;  // the pigeonhole guarantee holds without the query budget
  ASSERT_EQ(p.num_tables, 0);        // automatic
  MihIndex index(p, 512);
  ASSERT_EQ(index.layout().count(), 32);
  for (int t = 0; t < 32; ++t) EXPECT_EQ(index.layout().length(t), 16);
  const Descriptor base = test::randomDescriptor(rng, 64);
  DescriptorList stored;
  for (int d = 0; d < 32 + 40; ++d) stored.push_back(test::flipRandomBits(base, d, rng));
  for (size_t i = 0; i < stored.size(); ++i) index.insertKeyframe(&stored[i], 1, static_cast<FeatureId>(i));
  const std::set<FeatureId> found = visited(index, base);
  for (size_t i = 0; i < stored.size(); ++i) {
    bool meets = false;
    for (int t = 0; t < 32; ++t) meets |= index.meetsInTable(base, stored[i], t);
    if (hammingDistance(base, stored[i]) < 32) {
      ASSERT_TRUE(meets) << i;
    }
    ASSERT_EQ(found.count(static_cast<FeatureId>(i)) == 1, meets) << i;
  }
  // The bits past 256 take part: flipping only them still separates the descriptors.
  Descriptor high = base;
  for (int b = 256; b < 512; b += 2) high.flip(b);
  EXPECT_EQ(hammingDistance(base, high), 128);
  EXPECT_EQ(MihIndex(p, 256).layout().count(), 16);  // and ORB keeps the paper's 16
  EXPECT_EQ(MihIndex(p, 488).layout().count(), 31);  // AKAZE's 61 bytes
}

TEST(MihIndex, RejectsInvalidParameters) {
  {
    MihParams wide;
    wide.num_tables = 4;  // 128-bit substrings of a 512-bit descriptor: longer than a word
    EXPECT_THROW((MihIndex{wide, 512}), InvalidInput);
    wide.num_tables = 8;
    EXPECT_NO_THROW((MihIndex{wide, 512}));
  }
  MihParams p;
  p.num_tables = 2;
  EXPECT_THROW((MihIndex{p, kOrbBits}), InvalidInput);
  p = MihParams{};
  p.radius = 4;
  EXPECT_THROW((MihIndex{p, kOrbBits}), InvalidInput);
  p = MihParams{};
  p.radius = -1;
  EXPECT_THROW((MihIndex{p, kOrbBits}), InvalidInput);
  p = MihParams{};
  p.bucket_cap_factor = 0;
  EXPECT_THROW((MihIndex{p, kOrbBits}), InvalidInput);
  p = MihParams{};
  p.max_bucket_entries = 1;
  EXPECT_THROW((MihIndex{p, kOrbBits}), InvalidInput);
}

}  // namespace
}  // namespace mild
