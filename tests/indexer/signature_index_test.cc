// SignatureIndex against a brute-force oracle on realistic clustered
// signatures: k-NN, ranked and radius search under the index's own weighting,
// every intent and random weightings, ties, inserts and deletes with and
// without rebuilds, background rebuilds under concurrent use, and
// persistence (round trip, missing and changed items, corrupt bytes).
#include "indexer/lib/signature_index.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "indexer/lib/emd.h"
#include "indexer/lib/metric.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

using testing::SignatureGenerator;
using testing::SignatureGeneratorOptions;

// The index's own weighting (IndexOptions::build_weights by default).
TermWeights Own() { return IntentWeights(Intent::kBalanced); }

// The oracle's d_w, written out: each weighed term in the order emd,
// spectral, heat (the order the index sums them in, so equal bit for bit).
double OracleDistance(const PreparedSignature& q, const PreparedSignature& p,
                      const TermWeights& w) {
  double d = 0.0;
  if (w.emd > 0.0) d += w.emd * Emd(q, p);
  if (w.spectral > 0.0) d += w.spectral * SpectralDistance(q, p);
  if (w.heat > 0.0) d += w.heat * HeatDistance(q, p);
  return d;
}

// The oracle: every live signature, prepared independently, one distance
// each under the weighting asked for.
class Oracle {
 public:
  explicit Oracle(GroundDistanceOptions ground = {}, TermWeights w = Own())
      : ground_(ground), w_(w) {}

  void Upsert(const std::string& id, const Signature& s) {
    live_[id] = *Prepare(s, ground_);
  }
  void Remove(const std::string& id) { live_.erase(id); }
  size_t size() const { return live_.size(); }

  std::vector<Neighbor> Search(
      const Signature& query, size_t k, double radius = 0.0,
      const std::function<bool(const std::string&)>& filter = nullptr,
      const TermWeights* weights = nullptr) const {
    const PreparedSignature q = *Prepare(query, ground_);
    const TermWeights& w = weights != nullptr ? *weights : w_;
    std::vector<Neighbor> all;
    for (const auto& [id, p] : live_) {
      if (filter && !filter(id)) continue;
      const double d = OracleDistance(q, p, w);
      if (radius > 0.0 && d > radius) continue;
      all.push_back({id, d});
    }
    std::sort(all.begin(), all.end(), [](const Neighbor& a, const Neighbor& b) {
      return a.distance != b.distance ? a.distance < b.distance : a.id < b.id;
    });
    if (all.size() > k) all.resize(k);
    return all;
  }

 private:
  GroundDistanceOptions ground_;
  TermWeights w_;
  std::map<std::string, PreparedSignature> live_;
};

void ExpectSame(const std::vector<Neighbor>& got,
                const std::vector<Neighbor>& want, const std::string& ctx) {
  ASSERT_EQ(got.size(), want.size()) << ctx;
  for (size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].id, want[i].id) << ctx << " rank " << i;
    EXPECT_EQ(got[i].distance, want[i].distance) << ctx << " rank " << i;
  }
}

std::string Id(int i) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "m%05d", i);
  return buf;
}

IndexOptions ManualOptions() {
  IndexOptions options;
  options.background_rebuild = false;
  options.tree.leaf_size = 8;
  return options;
}

// Drain returns every neighbour a search yields, in order (under the
// index's own weighting unless `w` is given).
std::vector<Neighbor> Drain(
    const SignatureIndex& index, const Signature& query, double radius,
    std::function<bool(const std::string&)> filter = nullptr,
    std::optional<TermWeights> w = std::nullopt) {
  absl::StatusOr<std::unique_ptr<SignatureIndex::Cursor>> cursor = index.Search(
      query, w ? *w : index.build_weights(), radius, std::move(filter));
  EXPECT_TRUE(cursor.ok()) << cursor.status();
  std::vector<Neighbor> got;
  if (!cursor.ok()) return got;
  while (std::optional<Neighbor> n = (*cursor)->Next()) got.push_back(*n);
  return got;
}

// Queries: members of the classes (near data) and unclustered signatures.
std::vector<Signature> Queries(SignatureGenerator* gen, int count) {
  std::vector<Signature> out;
  for (int i = 0; i < count; ++i) {
    out.push_back(i % 4 == 3 ? gen->Random(20 + i % 20) : gen->Next());
  }
  return out;
}

// CheckKnn compares k-NN over `queries`; `stored` bounds the EMDs a search
// may compute (live entries plus tombstoned vantage points).
void CheckKnn(const SignatureIndex& index, const Oracle& oracle,
              const std::vector<Signature>& queries, const std::string& ctx,
              size_t stored = 0) {
  if (stored == 0) stored = index.size();
  const size_t ks[] = {1, 5, 10, oracle.size() + 3};
  for (size_t q = 0; q < queries.size(); ++q) {
    const size_t k = ks[q % 4];
    SearchStats stats;
    ExpectSame(index.Knn(queries[q], k, &stats), oracle.Search(queries[q], k),
               ctx + " query " + std::to_string(q) + " k " + std::to_string(k));
    EXPECT_LE(stats.emd_computations, static_cast<int64_t>(stored));
  }
}

TEST(SignatureIndexTest, EmptyIndex) {
  SignatureIndex index(ManualOptions());
  SignatureGenerator gen(SignatureGeneratorOptions{});
  const Signature q = gen.Next();
  EXPECT_EQ(index.size(), 0u);
  EXPECT_TRUE(index.Knn(q, 5).empty());
  absl::StatusOr<std::unique_ptr<SignatureIndex::Cursor>> cursor =
      index.Search(q, Own(), 0.0, nullptr);
  ASSERT_TRUE(cursor.ok()) << cursor.status();
  EXPECT_FALSE((*cursor)->Next().has_value());
  index.Rebuild();
  EXPECT_TRUE(index.Knn(q, 5).empty());
  absl::StatusOr<std::unique_ptr<SignatureIndex>> loaded =
      SignatureIndex::Load(index.SerializeTree(), {}, ManualOptions());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ((*loaded)->size(), 0u);
}

TEST(SignatureIndexTest, KnnMatchesBruteForceBeforeAndAfterRebuild) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 3;
  gopt.classes = 12;
  SignatureGenerator gen(gopt);
  SignatureIndex index(ManualOptions());
  Oracle oracle;
  for (int i = 0; i < 300; ++i) {
    const Signature s = gen.Next();
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
  }
  const std::vector<Signature> queries = Queries(&gen, 60);
  EXPECT_EQ(index.buffered(), 300u);
  CheckKnn(index, oracle, queries, "buffer only");
  index.Rebuild();
  EXPECT_EQ(index.buffered(), 0u);
  EXPECT_EQ(index.indexed(), 300u);
  CheckKnn(index, oracle, queries, "tree");
}

// A tree's signatures live in one arena per tree (signature_arena.h): a
// cursor opened on one tree must keep reading it, exactly, after rebuilds
// have replaced that tree (and its arena) and after the index is gone.
TEST(SignatureIndexTest, CursorKeepsItsArenaAcrossRebuildsAndTheIndexsEnd) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 11;
  gopt.classes = 6;
  SignatureGenerator gen(gopt);
  auto index = std::make_unique<SignatureIndex>(ManualOptions());
  Oracle oracle;
  for (int i = 0; i < 200; ++i) {
    const Signature s = gen.Next();
    ASSERT_TRUE(index->Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
  }
  index->Rebuild();
  const std::vector<Signature> queries = Queries(&gen, 8);
  std::vector<std::unique_ptr<SignatureIndex::Cursor>> cursors;
  std::vector<std::vector<Neighbor>> want;
  for (const Signature& q : queries) {
    absl::StatusOr<std::unique_ptr<SignatureIndex::Cursor>> c =
        index->Search(q, Own(), 0.0, nullptr);
    ASSERT_TRUE(c.ok()) << c.status();
    ASSERT_TRUE((*c)->Next().has_value());  // reads the arena once
    cursors.push_back(*std::move(c));
    want.push_back(oracle.Search(q, oracle.size()));
  }
  // Replace every signature and rebuild twice: two new arenas.
  for (int round = 0; round < 2; ++round) {
    for (int i = 0; i < 200; ++i) {
      ASSERT_TRUE(index->Upsert(Id(i), gen.Next()).ok());
    }
    index->Rebuild();
  }
  index.reset();
  for (size_t q = 0; q < cursors.size(); ++q) {
    std::vector<Neighbor> got;
    while (std::optional<Neighbor> n = cursors[q]->Next()) got.push_back(*n);
    want[q].erase(want[q].begin());  // taken before the rebuilds
    ExpectSame(got, want[q], "query " + std::to_string(q));
  }
}

// The bound cascade changes work, never answers: with and without the
// relaxed transport bound, both equal brute force, and the cascade computes
// no more EMDs.
TEST(SignatureIndexTest, RelaxedBoundKeepsAnswersAndSavesEmds) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 5;
  gopt.classes = 15;
  SignatureGenerator gen(gopt);
  IndexOptions with = ManualOptions();
  IndexOptions without = ManualOptions();
  without.relaxed_bound = false;
  SignatureIndex a(with);
  SignatureIndex b(without);
  Oracle oracle;
  for (int i = 0; i < 600; ++i) {
    const Signature s = gen.Next();
    ASSERT_TRUE(a.Upsert(Id(i), s).ok());
    ASSERT_TRUE(b.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
  }
  a.Rebuild();
  b.Rebuild();
  int64_t emds_with = 0;
  int64_t emds_without = 0;
  for (const Signature& q : Queries(&gen, 40)) {
    SearchStats sa;
    SearchStats sb;
    const std::vector<Neighbor> want = oracle.Search(q, 10);
    ExpectSame(a.Knn(q, 10, &sa), want, "with relaxed bound");
    ExpectSame(b.Knn(q, 10, &sb), want, "centroid bound only");
    emds_with += sa.emd_computations;
    emds_without += sb.emd_computations;
  }
  EXPECT_LE(emds_with, emds_without);
}

// Intra-query parallelism changes neither answers nor their order: k-NN,
// radius and filtered ranked searches with 2 threads (batches of 2, 3 and
// 8) equal brute force, ties included (duplicates are inserted).
TEST(SignatureIndexTest, ParallelSearchEqualsBruteForce) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 41;
  gopt.classes = 10;
  SignatureGenerator gen(gopt);
  std::vector<std::pair<std::string, Signature>> items;
  Oracle oracle;
  for (int i = 0; i < 700; ++i) {
    const Signature s = i % 50 == 7 ? items.back().second : gen.Next();
    items.emplace_back(Id(i), s);
    oracle.Upsert(Id(i), s);
  }
  const std::vector<Signature> queries = Queries(&gen, 30);
  for (size_t batch : {2u, 3u, 8u}) {
    IndexOptions options = ManualOptions();
    options.search_threads = 2;
    options.search_batch = batch;
    SignatureIndex index(options);
    ASSERT_TRUE(index.UpsertBatch(items).ok());
    index.Rebuild();
    // A few writes after the rebuild: the buffer and tombstones too.
    const Signature extra = gen.Next();
    ASSERT_TRUE(index.Upsert("extra", extra).ok());
    ASSERT_TRUE(index.Remove(Id(3)));
    Oracle o = oracle;
    o.Upsert("extra", extra);
    o.Remove(Id(3));
    const std::string ctx = "batch " + std::to_string(batch);
    for (size_t q = 0; q < queries.size(); ++q) {
      const size_t k = q % 3 == 0 ? 1 : (q % 3 == 1 ? 10 : 800);
      ExpectSame(index.Knn(queries[q], k), o.Search(queries[q], k),
                 ctx + " knn " + std::to_string(q));
    }
  }
}

// MemoryBytes counts at least every prepared signature's own bytes and
// grows linearly with the model count.
TEST(SignatureIndexTest, MemoryBytesCountsSignaturesAndGrowsLinearly) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  SignatureIndex index(ManualOptions());
  const size_t empty = index.MemoryBytes();
  size_t prepared = 0;
  for (int i = 0; i < 400; ++i) {
    const Signature s = gen.Next();
    prepared += Prepare(s, GroundDistanceOptions{})->MemoryBytes();
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    if (i == 199) {
      index.Rebuild();
      EXPECT_GT(index.MemoryBytes(), empty + prepared);
    }
  }
  index.Rebuild();
  const size_t full = index.MemoryBytes();
  EXPECT_GT(full, empty + prepared);
  EXPECT_LT(full, empty + 3 * prepared);  // overheads stay a fraction
}

TEST(SignatureIndexTest, DuplicateSignaturesTieByIdAndQueryHitsItself) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  SignatureIndex index(ManualOptions());
  Oracle oracle;
  std::vector<Signature> distinct;
  for (int i = 0; i < 40; ++i) distinct.push_back(gen.Next());
  for (int i = 0; i < 200; ++i) {
    // Ids inserted out of order, five copies of each signature.
    const int id = (i * 37) % 200;
    ASSERT_TRUE(index.Upsert(Id(id), distinct[id % 40]).ok());
    oracle.Upsert(Id(id), distinct[id % 40]);
  }
  index.Rebuild();
  for (int i = 0; i < 40; ++i) {
    const std::vector<Neighbor> got = index.Knn(distinct[i], 7);
    ExpectSame(got, oracle.Search(distinct[i], 7), "dup " + std::to_string(i));
    ASSERT_GE(got.size(), 5u);
    EXPECT_EQ(got[0].distance, 0.0);
    EXPECT_EQ(got[4].distance, 0.0);
    EXPECT_EQ(got[0].id, Id(i));  // smallest id of the five copies
  }
}

TEST(SignatureIndexTest, InsertsReplacementsAndDeletesStayExact) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 5;
  SignatureGenerator gen(gopt);
  SignatureIndex index(ManualOptions());
  Oracle oracle;
  for (int i = 0; i < 250; ++i) {
    const Signature s = gen.Next();
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
  }
  index.Rebuild();
  const std::vector<Signature> queries = Queries(&gen, 40);
  // New ids, replaced ids (tree entries move to the buffer), deletes from
  // the tree and from the buffer.
  for (int i = 250; i < 300; ++i) {
    const Signature s = gen.Next();
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
  }
  for (int i = 0; i < 60; i += 3) {
    const Signature s = gen.Next();
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
  }
  for (int i = 1; i < 300; i += 7) {
    EXPECT_TRUE(index.Remove(Id(i)));
    oracle.Remove(Id(i));
    EXPECT_FALSE(index.Contains(Id(i)));
    EXPECT_FALSE(index.Remove(Id(i)));
  }
  EXPECT_FALSE(index.Remove("never-there"));
  EXPECT_TRUE(index.Contains(Id(0)));
  EXPECT_EQ(index.size(), oracle.size());
  EXPECT_EQ(index.indexed() + index.buffered(), index.size());
  CheckKnn(index, oracle, queries, "with buffer and tombstones", 300 + 20);
  index.Rebuild();
  EXPECT_EQ(index.buffered(), 0u);
  EXPECT_EQ(index.size(), oracle.size());
  CheckKnn(index, oracle, queries, "rebuilt");
}

TEST(SignatureIndexTest, RankedRadiusAndFilteredSearchMatchBruteForce) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 9;
  SignatureGenerator gen(gopt);
  SignatureIndex index(ManualOptions());
  Oracle oracle;
  for (int i = 0; i < 300; ++i) {
    const Signature s = gen.Next();
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
  }
  index.Rebuild();
  for (int i = 300; i < 330; ++i) {  // some in the buffer too
    const Signature s = gen.Next();
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
  }
  const std::vector<Signature> queries = Queries(&gen, 30);
  for (size_t q = 0; q < queries.size(); ++q) {
    // Whole ranking.
    auto cursor = index.Search(queries[q], Own(), 0.0, nullptr);
    ASSERT_TRUE(cursor.ok());
    std::vector<Neighbor> got;
    while (std::optional<Neighbor> n = (*cursor)->Next()) got.push_back(*n);
    const std::vector<Neighbor> all = oracle.Search(queries[q], 10000);
    ExpectSame(got, all, "ranked " + std::to_string(q));
    // Radius at the 20th distance (inclusive), and a filter on the ids.
    const double radius = all[19].distance;
    auto filter = [](const std::string& id) { return id.back() % 2 == 0; };
    cursor = index.Search(queries[q], Own(), radius, filter);
    ASSERT_TRUE(cursor.ok());
    got.clear();
    while (std::optional<Neighbor> n = (*cursor)->Next()) got.push_back(*n);
    ExpectSame(got, oracle.Search(queries[q], 10000, radius, filter),
               "radius " + std::to_string(q));
    // Stopping early costs less than draining.
    cursor = index.Search(queries[q], Own(), 0.0, nullptr);
    (*cursor)->Next();
    EXPECT_LT((*cursor)->stats().emd_computations,
              static_cast<int64_t>(index.size()));
  }
}

TEST(SignatureIndexTest, CombinedMetricMatchesBruteForceIncludingTies) {
  // The distance with the spectral term on (metric.h): k-NN, whole
  // rankings and radius searches equal the oracle, tree and buffer, with
  // ties: copies of one signature (distance 0) and signatures equal but
  // for their spectra (distance = the spectral term alone).
  for (SpectralTransform t :
       {SpectralTransform::kByIndex, SpectralTransform::kLog}) {
    SignatureGeneratorOptions gopt;
    gopt.seed = 21;
    gopt.classes = 10;
    gopt.spectrum = 50;
    SignatureGenerator gen(gopt);
    IndexOptions options = ManualOptions();
    options.build_weights = {1.0, 0.6, 0.0};
    options.ground.spectral.transform = t;
    SignatureIndex index(options);
    Oracle oracle(options.ground, options.build_weights);
    std::vector<Signature> stored;
    for (int i = 0; i < 240; ++i) {
      Signature s = i % 6 == 5 ? stored[static_cast<size_t>(i - 5)]  // a copy
                    : i % 12 == 4
                        ? stored[static_cast<size_t>(i - 1)]  // see below
                        : gen.Next();
      if (i % 12 == 4)
        s.spectrum.back() *= 1.3;  // same features, other spectrum
      stored.push_back(s);
      ASSERT_TRUE(index.Upsert(Id(i), s).ok());
      oracle.Upsert(Id(i), s);
    }
    index.Rebuild();
    for (int i = 240; i < 270; ++i) {  // some in the buffer too
      const Signature s = gen.Next();
      ASSERT_TRUE(index.Upsert(Id(i), s).ok());
      oracle.Upsert(Id(i), s);
    }
    std::vector<Signature> queries = Queries(&gen, 24);
    for (int i = 0; i < 12; ++i)
      queries.push_back(stored[static_cast<size_t>(i * 17)]);
    CheckKnn(index, oracle, queries, SpectralTransformName(t));
    for (size_t q = 0; q < queries.size(); q += 3) {
      const std::vector<Neighbor> all = oracle.Search(queries[q], 10000);
      ExpectSame(Drain(index, queries[q], 0.0), all,
                 "ranked " + std::to_string(q));
      const double radius = all[15].distance;
      ExpectSame(Drain(index, queries[q], radius),
                 oracle.Search(queries[q], 10000, radius),
                 "radius " + std::to_string(q));
    }
  }
}

// Weightings: every intent, the paper's distance, each embedding alone,
// and random ones with some term at 0.
std::vector<TermWeights> Weightings(uint64_t seed) {
  std::vector<TermWeights> out = {IntentWeights(Intent::kBalanced),
                                  IntentWeights(Intent::kIdentity),
                                  IntentWeights(Intent::kKind),
                                  {1, 0, 0},
                                  {0, 1, 0},
                                  {0, 0, 1},
                                  {1, 1, 1}};
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 3.0);
  for (int r = 0; r < 4; ++r) {
    TermWeights w{u(rng), u(rng), u(rng)};
    if (r % 3 == 0) w.emd = 0.0;
    if (r % 3 == 1) w.spectral = 0.0;
    if (r % 3 == 2) w.heat = 0.0;
    out.push_back(w);
  }
  return out;
}

std::string Name(const TermWeights& w) {
  return std::to_string(w.emd) + "/" + std::to_string(w.spectral) + "/" +
         std::to_string(w.heat);
}

// One tree, built once under the index's own weighting, answers every
// intent and every weighting exactly: k-NN (k > n too), the whole ranked
// order, radius and label-filtered searches equal the oracle's order and
// distances bit for bit, over tree items, buffered items and tombstones,
// with ties (exact copies, at distance 0), and again after SerializeTree /
// Load.
TEST(SignatureIndexTest, EveryIntentAndWeightingMatchesBruteForce) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 33;
  gopt.classes = 8;
  gopt.spectrum = 50;
  SignatureGenerator gen(gopt);
  SignatureIndex index(ManualOptions());
  Oracle oracle;
  std::vector<std::pair<std::string, Signature>> items;
  std::vector<Signature> stored;
  for (int i = 0; i < 200; ++i) {
    const Signature s = i % 10 == 9 ? stored[static_cast<size_t>(i - 4)]
                                    : gen.Next();  // some exact copies
    stored.push_back(s);
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
    items.emplace_back(Id(i), s);
  }
  index.Rebuild();
  for (int i = 200; i < 225; ++i) {  // buffered entries
    const Signature s = gen.Next();
    ASSERT_TRUE(index.Upsert(Id(i), s).ok());
    oracle.Upsert(Id(i), s);
    items.emplace_back(Id(i), s);
  }
  for (int i : {7, 40, 210}) {  // tombstones and a buffer delete
    ASSERT_TRUE(index.Remove(Id(i)));
    oracle.Remove(Id(i));
    items.erase(std::find_if(items.begin(), items.end(),
                             [i](const auto& e) { return e.first == Id(i); }));
  }
  ASSERT_GT(index.indexed(), 0u);
  ASSERT_GT(index.buffered(), 0u);
  absl::StatusOr<std::unique_ptr<SignatureIndex>> loaded =
      SignatureIndex::Load(index.SerializeTree(), items, ManualOptions());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  std::vector<Signature> queries = Queries(&gen, 5);
  queries.push_back(stored[9]);  // has a copy at distance 0
  auto labels = [](const std::string& id) { return id.back() % 3 != 0; };
  for (const SignatureIndex* idx : {&index, loaded->get()}) {
    for (const TermWeights& w : Weightings(34)) {
      for (size_t q = 0; q < queries.size(); ++q) {
        const std::string ctx = Name(w) + " query " + std::to_string(q);
        const std::vector<Neighbor> all =
            oracle.Search(queries[q], 10000, 0.0, nullptr, &w);
        ASSERT_EQ(all.size(), oracle.size());
        const std::vector<Neighbor> got =
            Drain(*idx, queries[q], 0.0, nullptr, w);
        ExpectSame(got, all, ctx + " ranked");
        // k-NN through the cursor, with k > n.
        for (size_t k : {size_t{1}, size_t{10}, oracle.size() + 3}) {
          auto cursor = idx->Search(queries[q], w, 0.0, nullptr);
          ASSERT_TRUE(cursor.ok()) << cursor.status();
          std::vector<Neighbor> first;
          while (first.size() < k) {
            std::optional<Neighbor> n = (*cursor)->Next();
            if (!n) break;
            first.push_back(*n);
          }
          ExpectSame(first, oracle.Search(queries[q], k, 0.0, nullptr, &w),
                     ctx + " k " + std::to_string(k));
          if (k == 10 && w.emd > 0.0) {
            EXPECT_LT((*cursor)->stats().emd_computations,
                      static_cast<int64_t>(oracle.size()))
                << ctx;
          }
        }
        const double radius = all[20].distance;
        ExpectSame(Drain(*idx, queries[q], radius, labels, w),
                   oracle.Search(queries[q], 10000, radius, labels, &w),
                   ctx + " radius and filter");
      }
    }
  }
}

TEST(SignatureIndexTest, SearchRefusesBadWeightsAndStops) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 5;
  gopt.spectrum = 20;
  SignatureGenerator gen(gopt);
  SignatureIndex index(ManualOptions());
  for (int i = 0; i < 40; ++i)
    ASSERT_TRUE(index.Upsert(Id(i), gen.Next()).ok());
  index.Rebuild();
  const Signature q = gen.Next();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (const TermWeights& w : std::vector<TermWeights>{{-1, 0, 0},
                                                       {0, -0.5, 1},
                                                       {nan, 1, 0},
                                                       {1, inf, 0},
                                                       {0, 0, 0},
                                                       {1, 0, -2}}) {
    absl::StatusOr<std::unique_ptr<SignatureIndex::Cursor>> c =
        index.Search(q, w, 0.0, nullptr);
    EXPECT_EQ(c.status().code(), absl::StatusCode::kInvalidArgument) << Name(w);
  }
  // stop: polled before each step that may compute an EMD; once true,
  // nothing more is computed and the cursor ends.
  for (const TermWeights& w : Weightings(6)) {
    int polls = 0;
    absl::StatusOr<std::unique_ptr<SignatureIndex::Cursor>> stopped =
        index.Search(q, w, 0.0, nullptr, [&polls] { return ++polls > 3; });
    ASSERT_TRUE(stopped.ok());
    EXPECT_FALSE((*stopped)->Next().has_value());
    EXPECT_LE((*stopped)->stats().emd_computations, 3) << Name(w);
  }
  // An empty index has no neighbour under any weighting.
  SignatureIndex empty(ManualOptions());
  for (const TermWeights& w : Weightings(7)) {
    EXPECT_TRUE(Drain(empty, q, 0.0, nullptr, w).empty());
  }
  // Bad build weights are refused where options are checked.
  IndexOptions bad = ManualOptions();
  bad.build_weights = {0, 0, 0};
  EXPECT_EQ(ValidateIndexOptions(bad).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(
      SignatureIndex::Load(index.SerializeTree(), {}, bad).status().code(),
      absl::StatusCode::kInvalidArgument);
  // A tree built under other build weights is refused on load (rebuild).
  IndexOptions other = ManualOptions();
  other.build_weights = {1, 0, 0};
  EXPECT_EQ(
      SignatureIndex::Load(index.SerializeTree(), {}, other).status().code(),
      absl::StatusCode::kFailedPrecondition);
}

TEST(SignatureIndexTest, PrunesOnClusteredData) {
  // Work, not time: 1-NN over 600 clustered signatures must compute far
  // fewer EMDs than a scan (the paper's 7.4 setting is 600 models).
  SignatureGeneratorOptions gopt;
  gopt.seed = 13;
  gopt.classes = 13;
  SignatureGenerator gen(gopt);
  IndexOptions options = ManualOptions();
  SignatureIndex index(options);
  for (int i = 0; i < 600; ++i)
    ASSERT_TRUE(index.Upsert(Id(i), gen.Next()).ok());
  index.Rebuild();
  int64_t emds = 0;
  for (int q = 0; q < 50; ++q) {
    SearchStats stats;
    ASSERT_EQ(index.Knn(gen.Next(), 1, &stats).size(), 1u);
    emds += stats.emd_computations;
    EXPECT_GT(stats.lower_bounds, 0);
  }
  EXPECT_LT(emds / 50, 600 / 4);
}

TEST(SignatureIndexTest, UpsertBatchEqualsUpsertsAndIsAtomic) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 31;
  SignatureGenerator gen(gopt);
  SignatureIndex index(ManualOptions());
  Oracle oracle;
  std::vector<std::pair<std::string, Signature>> batch;
  for (int i = 0; i < 200; ++i) batch.emplace_back(Id(i), gen.Next());
  ASSERT_TRUE(index.UpsertBatch(batch).ok());
  for (const auto& [id, s] : batch) oracle.Upsert(id, s);
  index.Rebuild();
  // A second batch: replacements of tree entries, a repeated id (the later
  // wins), new ids.
  batch.clear();
  for (int i = 0; i < 200; i += 9) batch.emplace_back(Id(i), gen.Next());
  batch.emplace_back(Id(500), gen.Next());
  batch.emplace_back(Id(500), gen.Next());
  ASSERT_TRUE(index.UpsertBatch(batch).ok());
  for (const auto& [id, s] : batch) oracle.Upsert(id, s);
  EXPECT_EQ(index.size(), oracle.size());
  CheckKnn(index, oracle, Queries(&gen, 20), "batch", 201 + 23);
  // One bad entry: nothing applied.
  batch.clear();
  batch.emplace_back(Id(600), gen.Next());
  batch.emplace_back(Id(601), Signature{});
  EXPECT_EQ(index.UpsertBatch(batch).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(index.Contains(Id(600)));
  EXPECT_EQ(index.size(), oracle.size());
}

TEST(SignatureIndexTest, MalformedInputIsInvalidArgument) {
  SignatureIndex index(ManualOptions());
  SignatureGenerator gen(SignatureGeneratorOptions{});
  ASSERT_TRUE(index.Upsert("good", gen.Next()).ok());
  Signature bad = gen.Next();
  bad.features[0].weight = -1.0;
  EXPECT_EQ(index.Upsert("bad", bad).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(index.Upsert("", gen.Next()).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(index.Upsert("empty", Signature{}).code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_FALSE(index.Contains("bad"));
  EXPECT_EQ(index.size(), 1u);
  EXPECT_EQ(index.Search(bad, Own(), 0.0, nullptr).status().code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(index.Knn(bad, 3).empty());
}

TEST(SignatureIndexTest, BackgroundRebuildUnderConcurrentWritesAndReads) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 17;
  SignatureGenerator gen(gopt);
  IndexOptions options;
  options.rebuild_threshold = 40;
  options.tree.leaf_size = 8;
  SignatureIndex index(options);
  std::vector<Signature> data;
  for (int i = 0; i < 300; ++i) data.push_back(gen.Next());
  const std::vector<Signature> queries = Queries(&gen, 20);
  std::atomic<bool> done{false};
  std::atomic<int> searches{0};
  std::thread reader([&] {
    while (!done) {
      const std::vector<Neighbor> got = index.Knn(queries[searches % 20], 5);
      EXPECT_LE(got.size(), 5u);
      for (size_t i = 1; i < got.size(); ++i) {
        EXPECT_LE(got[i - 1].distance, got[i].distance);
      }
      ++searches;
    }
  });
  Oracle oracle;
  for (int i = 0; i < 300; ++i) {
    ASSERT_TRUE(index.Upsert(Id(i), data[i]).ok());
    oracle.Upsert(Id(i), data[i]);
    if (i % 5 == 4) {
      ASSERT_TRUE(index.Remove(Id(i - 2)));
      oracle.Remove(Id(i - 2));
    }
  }
  done = true;
  reader.join();
  index.WaitForRebuild();
  EXPECT_GT(searches.load(), 0);
  EXPECT_EQ(index.size(), oracle.size());
  EXPECT_GT(index.indexed(), 0u);  // at least one rebuild folded the buffer
  CheckKnn(index, oracle, queries, "after background rebuilds", 300);
  index.Rebuild();
  EXPECT_EQ(index.buffered(), 0u);
  CheckKnn(index, oracle, queries, "after final rebuild");
}

TEST(SignatureIndexTest, SerializeAndLoadRoundTrip) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 23;
  SignatureGenerator gen(gopt);
  SignatureIndex index(ManualOptions());
  Oracle oracle;
  std::map<std::string, Signature> live;
  for (int i = 0; i < 300; ++i) {
    live[Id(i)] = gen.Next();
    ASSERT_TRUE(index.Upsert(Id(i), live[Id(i)]).ok());
    oracle.Upsert(Id(i), live[Id(i)]);
  }
  index.Rebuild();
  const std::string bytes = index.SerializeTree();
  const std::vector<Signature> queries = Queries(&gen, 24);

  // Same items: everything in the tree, nothing buffered, same results and
  // the same work.
  std::vector<std::pair<std::string, Signature>> items(live.begin(),
                                                       live.end());
  absl::StatusOr<std::unique_ptr<SignatureIndex>> loaded =
      SignatureIndex::Load(bytes, items, ManualOptions());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ((*loaded)->buffered(), 0u);
  EXPECT_EQ((*loaded)->indexed(), 300u);
  EXPECT_EQ((*loaded)->SerializeTree(), bytes);
  CheckKnn(**loaded, oracle, queries, "reloaded");
  for (const Signature& q : queries) {
    SearchStats a, b;
    index.Knn(q, 10, &a);
    (*loaded)->Knn(q, 10, &b);
    EXPECT_EQ(a.emd_computations, b.emd_computations);
  }

  // Items changed since the tree was written: some missing (tombstoned),
  // some altered (buffered), some new (buffered).
  for (int i = 0; i < 300; i += 11) {
    live.erase(Id(i));
    oracle.Remove(Id(i));
  }
  for (int i = 5; i < 300; i += 13) {
    if (live.count(Id(i)) == 0) continue;
    live[Id(i)] = gen.Next();
    oracle.Upsert(Id(i), live[Id(i)]);
  }
  for (int i = 300; i < 320; ++i) {
    live[Id(i)] = gen.Next();
    oracle.Upsert(Id(i), live[Id(i)]);
  }
  items.assign(live.begin(), live.end());
  loaded = SignatureIndex::Load(bytes, items, ManualOptions());
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_EQ((*loaded)->size(), live.size());
  EXPECT_GT((*loaded)->buffered(), 20u);
  EXPECT_FALSE((*loaded)->Contains(Id(0)));
  EXPECT_TRUE((*loaded)->Contains(Id(319)));
  CheckKnn(**loaded, oracle, queries, "reloaded with changes", 320 + 20);
  (*loaded)->Rebuild();
  CheckKnn(**loaded, oracle, queries, "reloaded and rebuilt");

  // Other ground-distance options: the stored distances mean nothing.
  IndexOptions other = ManualOptions();
  other.ground.w1 = 0.4;  // All four set: valid (sum 1) whatever the defaults.
  other.ground.w2 = 0.1;
  other.ground.w3 = 0.25;
  other.ground.w4 = 0.25;
  EXPECT_EQ(SignatureIndex::Load(bytes, items, other).status().code(),
            absl::StatusCode::kFailedPrecondition);
  // A malformed item.
  items[0].second.features.clear();
  EXPECT_EQ(SignatureIndex::Load(bytes, items, ManualOptions()).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST(SignatureIndexTest, CorruptBytesAreErrors) {
  SignatureGenerator gen(SignatureGeneratorOptions{});
  SignatureIndex index(ManualOptions());
  std::vector<std::pair<std::string, Signature>> items;
  for (int i = 0; i < 40; ++i) {
    items.emplace_back(Id(i), gen.Next());
    ASSERT_TRUE(index.Upsert(items.back().first, items.back().second).ok());
  }
  index.Rebuild();
  const std::string bytes = index.SerializeTree();
  auto is_error = [](const absl::Status& s) {
    return s.code() == absl::StatusCode::kDataLoss ||
           s.code() == absl::StatusCode::kInvalidArgument;
  };
  for (size_t len = 0; len < bytes.size(); len += 1 + len / 16) {
    EXPECT_TRUE(is_error(
        SignatureIndex::Load(bytes.substr(0, len), items, ManualOptions())
            .status()))
        << len;
  }
  std::mt19937_64 rng(29);
  for (int trial = 0; trial < 300; ++trial) {
    std::string bad = bytes;
    const size_t pos = rng() % bad.size();
    bad[pos] = static_cast<char>(bad[pos] ^ (1 + rng() % 255));
    EXPECT_TRUE(
        is_error(SignatureIndex::Load(bad, items, ManualOptions()).status()))
        << pos;
  }
  EXPECT_EQ(
      SignatureIndex::Load("garbage", items, ManualOptions()).status().code(),
      absl::StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace tpr::index
