// Matching benchmarks (Tam & Lau 2007, section 6): one EMD between two
// realistic signatures, ours against LEMON's network simplex in the same
// binary so that the ratio holds on a busy machine.
//
//   bench_match --benchmark_filter=BM_Emd --benchmark_repetitions=5
//               --benchmark_report_aggregates_only=true
//
// Signatures come from tests/indexer/signature_testing.h: clustered
// classes, exactly N features per side (the paper averages 30), 20 bands.
// Each iteration compares the next pair of a fixed pool of 64 signatures
// (8 classes), so same-class and cross-class pairs are both timed.
#include <benchmark/benchmark.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <ctime>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "eval/lib/tpr_descriptor.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh.h"
#include "extractor/synth/synth.h"
#include "indexer/lib/brute_force_index.h"
#include "indexer/lib/centroid_table.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/internal/simd.h"
#include "indexer/lib/metric.h"
#include "indexer/lib/signature_arena.h"
#include "indexer/lib/signature_index.h"
#include "indexer/lib/vp_tree.h"
#include "tests/indexer/emd_oracle.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::index {
namespace {

std::vector<PreparedSignature> Pool(int features) {
  testing::SignatureGeneratorOptions o;
  o.seed = 42 + static_cast<uint64_t>(features);
  o.features = features;
  o.classes = 8;
  o.feature_change = 0.0;  // exactly `features` per side
  testing::SignatureGenerator gen(o);
  std::vector<PreparedSignature> pool;
  for (int k = 0; k < 64; ++k) {
    pool.push_back(*Prepare(gen.Next(), GroundDistanceOptions{}));
  }
  return pool;
}

void BM_Emd(benchmark::State& state) {
  const std::vector<PreparedSignature> pool =
      Pool(static_cast<int>(state.range(0)));
  EmdSolver solver;
  size_t k = 0;
  int64_t pivots = 0;
  for (auto _ : state) {
    const PreparedSignature& a = pool[k % pool.size()];
    const PreparedSignature& b = pool[(k * 7 + 3) % pool.size()];
    benchmark::DoNotOptimize(solver.Distance(a, b));
    pivots += solver.Stats().pivots;
    ++k;
  }
  state.counters["pivots"] =
      benchmark::Counter(static_cast<double>(pivots) / static_cast<double>(k));
}
BENCHMARK(BM_Emd)->Arg(10)->Arg(30)->Arg(60);

// The peer: LEMON NetworkSimplex (block search) on the same ground
// distances, graph and solver built once per size (only costs and supplies
// change per pair), so its time is the solve plus filling its maps.
void BM_EmdLemon(benchmark::State& state) {
  const std::vector<PreparedSignature> pool =
      Pool(static_cast<int>(state.range(0)));
  testing::LemonEmd lemon;
  size_t k = 0;
  for (auto _ : state) {
    const PreparedSignature& a = pool[k % pool.size()];
    const PreparedSignature& b = pool[(k * 7 + 3) % pool.size()];
    benchmark::DoNotOptimize(lemon.Distance(a, b));
    ++k;
  }
}
BENCHMARK(BM_EmdLemon)->Arg(10)->Arg(30)->Arg(60);

// The ground-distance matrix alone (part of every BM_Emd iteration).
void BM_GroundDistanceMatrix(benchmark::State& state) {
  const std::vector<PreparedSignature> pool =
      Pool(static_cast<int>(state.range(0)));
  std::vector<double> out(static_cast<size_t>(pool[0].size()) *
                          pool[0].stride());
  size_t k = 0;
  for (auto _ : state) {
    GroundDistanceMatrix(pool[k % pool.size()], pool[(k * 7 + 3) % pool.size()],
                         out.data(), pool[0].stride());
    benchmark::DoNotOptimize(out.data());
    ++k;
  }
}
BENCHMARK(BM_GroundDistanceMatrix)->Arg(10)->Arg(30)->Arg(60);

// The centroid lower bound that lets the index skip EMDs.
void BM_EmdLowerBound(benchmark::State& state) {
  const std::vector<PreparedSignature> pool =
      Pool(static_cast<int>(state.range(0)));
  size_t k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        EmdLowerBound(pool[k % pool.size()], pool[(k * 7 + 3) % pool.size()]));
    ++k;
  }
}
BENCHMARK(BM_EmdLowerBound)->Arg(30);

// ---------------------------------------------------------------------------
// k-NN (section 6.2): the VP-tree against brute force on the same data, in
// the same run. Databases are realistic signatures (about 30 features, 20
// bands) drawn from class prototypes (SignatureGenerator); queries are new
// members of the same classes. Counters per query: emds (full EMDs),
// emd_share (emds / database size), lbs (lower bounds, all levels; lbs1
// and lbs2 those of levels 1 and 2 in the tree benchmarks), nodes; build_s
// and build_cpu_s are the one-off tree build time of that database (wall
// and CPU; on a shared machine CPU is the figure to compare). Databases are
// built once per process and kept in memory (nothing is cached on disk).
namespace knn {

using tpr::index::BruteForceIndex;
using tpr::index::ConstrainedTransportBound;
using tpr::index::Distance;
using tpr::index::Emd;
using tpr::index::GroundDistanceOptions;
using tpr::index::HeatDistance;
using tpr::index::Intent;
using tpr::index::IntentWeights;
using tpr::index::ItemNeighbor;
using tpr::index::PreparedSignature;
using tpr::index::QuerySpec;
using tpr::index::RelaxedTransportBound;
using tpr::index::SearchStats;
using tpr::index::SpectralDistance;
using tpr::index::TermWeights;
using tpr::index::VpTree;
using tpr::index::VpTreeOptions;
using tpr::index::testing::SignatureGenerator;
using tpr::index::testing::SignatureGeneratorOptions;

// Database shape. classes == 0 means unclustered: every signature is its
// own random prototype (the highest intrinsic dimension we can make).
struct DbKey {
  int64_t n;
  int classes;
  int jitter_permille;
  size_t leaf_size = VpTreeOptions{}.leaf_size;
  // Prototypes are signatures extracted from generated shapes (the
  // foundation's synthetic classes) rather than drawn ones.
  bool extracted = false;
  // > 0: signatures carry 50-value spectra (SignatureGenerator) and the
  // distance is metric.h's EMD + w_s x spectral term with w_s =
  // spectral_permille / 1000 (the default transform and count); -1:
  // spectra present, w_s = 0
  // (the same data searched with the paper's distance).
  int spectral_permille = 0;
  // true: signatures carry 50-value spectra and the tree is built under
  // IntentWeights(Intent::kBalanced), as SignatureIndex builds it
  // (spectral_permille is then ignored).
  bool balanced = false;
  bool operator<(const DbKey& o) const {
    return std::tie(n, classes, jitter_permille, leaf_size, extracted,
                    spectral_permille, balanced) <
           std::tie(o.n, o.classes, o.jitter_permille, o.leaf_size, o.extracted,
                    o.spectral_permille, o.balanced);
  }
  // BuildWeights returns the weighting the tree is built (and by default
  // searched) under.
  TermWeights BuildWeights() const {
    if (balanced) return IntentWeights(Intent::kBalanced);
    return {1.0, spectral_permille > 0 ? spectral_permille / 1000.0 : 0.0, 0.0};
  }
};

struct Db {
  // One heap block per signature, in generation order.
  std::vector<PreparedSignature> items;
  std::vector<PreparedSignature> queries;
  // The same signatures as SignatureIndex keeps them: one huge-page arena
  // in tree order (SignatureArena); built on first use (Arena below).
  tpr::index::SignatureArena arena;
  double arena_cpu_seconds = 0.0;  // building `arena`, one thread
  // The items' centroids in one flat array, as SignatureIndex keeps them for
  // its lower bound.
  tpr::index::CentroidTable centroids;
  VpTree tree;
  TermWeights build;               // the tree's build weighting
  double build_seconds = 0.0;      // wall clock
  double build_cpu_seconds = 0.0;  // one thread
};

// Default data: 100 classes of models, 5% jitter (SignatureGenerator's
// default), so that a 100k database holds about 1000 poses per class.
constexpr int kClasses = 100;
constexpr int kJitterPermille = 50;

// ExtractedPrototypes returns `count` signatures extracted (ExtractSignature,
// default options) from generated shapes: every synthetic class in turn, a
// new pose each round, 3000 vertices. Each (class, pose) is one prototype;
// the generator then perturbs it like any other.
std::vector<tpr::index::Signature> ExtractedPrototypes(int count) {
  const std::vector<std::string> classes = tpr::synth::ClassNames();
  tpr::synth::ShapeOptions shape;
  shape.target_vertices = 3000;
  std::vector<tpr::index::Signature> out;
  for (int i = 0; static_cast<int>(out.size()) < count; ++i) {
    const std::string& cls = classes[i % classes.size()];
    absl::StatusOr<tpr::extract::Mesh> mesh = tpr::synth::GenerateShape(
        cls, i / static_cast<int>(classes.size()), shape);
    if (!mesh.ok()) continue;
    absl::StatusOr<tpr::extract::ExtractResult> r =
        tpr::extract::ExtractSignature(*mesh,
                                       tpr::extract::ComputeMeshStats(*mesh),
                                       tpr::extract::Options{});
    if (!r.ok()) continue;
    out.push_back(tpr::eval::ToIndexSignature(r->signature));
  }
  return out;
}

// Generate draws the raw signatures of a database (then 64 queries); the
// same key always gives the same data.
void Generate(const DbKey& key,
              const std::function<void(tpr::index::Signature)>& sink) {
  SignatureGeneratorOptions gopt;
  gopt.seed = 20071;
  gopt.classes = std::max(key.classes, 1);
  gopt.jitter = key.jitter_permille / 1000.0;
  if (key.spectral_permille != 0 || key.balanced) gopt.spectrum = 50;
  SignatureGenerator gen =
      key.extracted ? SignatureGenerator(gopt, ExtractedPrototypes(key.classes))
                    : SignatureGenerator(gopt);
  for (int64_t i = 0; i < key.n + 64; ++i) {
    sink(key.classes == 0 ? gen.Random(30) : gen.Next());
  }
}

Db& GetDb(const DbKey& key) {
  static std::map<DbKey, std::unique_ptr<Db>>* cache =
      new std::map<DbKey, std::unique_ptr<Db>>();
  std::unique_ptr<Db>& slot = (*cache)[key];
  if (slot) return *slot;
  slot = std::make_unique<Db>();
  GroundDistanceOptions ground;
  slot->items.reserve(static_cast<size_t>(key.n));
  Generate(key, [&](tpr::index::Signature s) {
    std::vector<PreparedSignature>& to =
        static_cast<int64_t>(slot->items.size()) < key.n ? slot->items
                                                         : slot->queries;
    to.push_back(*Prepare(s, ground));
  });
  const std::vector<PreparedSignature>& items = slot->items;
  slot->centroids = tpr::index::CentroidTable::Build(
      items.size(), [&items](uint32_t i) { return &items[i]; });
  const auto start = std::chrono::steady_clock::now();
  const std::clock_t cpu_start = std::clock();
  VpTreeOptions tree_options;
  tree_options.leaf_size = key.leaf_size;
  // Three terms, as SignatureIndex stores them (EMD, spectral, heat).
  const TermWeights b = key.BuildWeights();
  slot->build = b;
  slot->tree = *VpTree::Build(
      items.size(), 3,
      [&items](uint32_t i, uint32_t j, double* out) {
        out[0] = Emd(items[i], items[j]);
        out[1] = SpectralDistance(items[i], items[j]);
        out[2] = HeatDistance(items[i], items[j]);
      },
      {b.emd, b.spectral, b.heat}, tree_options);
  slot->build_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start)
          .count();
  slot->build_cpu_seconds =
      static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  return *slot;
}

// Arena returns db's signatures in a SignatureArena laid out in its tree's
// order, as SignatureIndex stores them, building it on first use (a second
// copy of the signatures beside `items`, so that both storages can run in
// one process).
const tpr::index::SignatureArena& Arena(Db& db) {
  if (db.arena.size() != db.items.size()) {
    const std::clock_t cpu_start = std::clock();
    db.arena = tpr::index::SignatureArena::Build(
        db.items.size(), db.tree.ItemsInTreeOrder(),
        [&db](uint32_t i) { return &db.items[i]; });
    db.arena_cpu_seconds =
        static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  }
  return db.arena;
}

// Where a search reads the items' signatures.
enum class Storage {
  kHeap,   // Db::items: a heap block each (the former layout)
  kArena,  // Arena(db): as SignatureIndex keeps them
};

// The bound cascade of a query (QuerySpec::lower_bounds) before the EMD.
enum class Cascade {
  kCentroid,       // the centroid bound alone
  kRelaxed,        // then the relaxed transport bound (RWMD)
  kConstrained,    // then the relaxed bound with capacities (ICT)
  kConstrained32,  // the same on a float32 matrix
                   // (ConstrainedTransportBound32): the index's
};

// When a search prefetches an item's signature (QuerySpec::prefetch).
enum class Prefetch {
  kNone,             // never
  kAdaptive,         // as SignatureIndex does: at level 0 only while
                     // PrefetchSignatureEarly, at levels >= 1 always
  kAdaptiveVantage,  // the same, and vantage points' signatures when their
                     // node is queued (QuerySpec::prefetch_vantage_points)
  kEarly,            // at level 0 always (the centroid row too)
  kLate,             // at levels >= 1 only (level 0: the centroid row alone)
};

// Level-1 and level-2 bound evaluations since the last reset (the `lbs1`
// and `lbs2` counters; `lbs` = lbs1 + lbs2).
std::atomic<int64_t> level1_bounds{0};
std::atomic<int64_t> level2_bounds{0};

// Spec is the query as SignatureIndex builds it: the cascade of lower
// bounds before the EMD. Distance is metric.h's (the EMD alone when the
// spectral weight is 0); level 1 adds the table's bound of the spectral
// term and level 2 the exact term, as SignatureIndex does
// (`table_spectral` false: level 1 reads the exact term from the
// signature instead, as before the table kept the embeddings).
// `items` (Db::items or Arena(db)) must outlive the search.
template <typename Items>
QuerySpec Spec(const Db& db, const Items& items, const PreparedSignature& q,
               Cascade cascade = Cascade::kConstrained32,
               Prefetch prefetch = Prefetch::kAdaptive,
               bool table_spectral = true,
               std::optional<TermWeights> weights = std::nullopt) {
  const TermWeights w = weights ? *weights : db.build;
  QuerySpec spec;
  spec.weights = {w.emd, w.spectral, w.heat};
  spec.distance = [&items, &q, w](uint32_t i, double* out) {
    if (w.emd > 0.0) out[0] = Emd(q, items[i]);
    if (w.spectral > 0.0) out[1] = SpectralDistance(q, items[i]);
    if (w.heat > 0.0) out[2] = HeatDistance(q, items[i]);
  };
  // The weighted embedding terms, exact.
  auto embeddings = [&items, &q, w](uint32_t i) {
    double sum = 0.0;
    if (w.spectral > 0.0) sum += w.spectral * SpectralDistance(q, items[i]);
    if (w.heat > 0.0) sum += w.heat * HeatDistance(q, items[i]);
    return sum;
  };
  // This query's bound counts, for the adaptive policy (as the index's
  // cursor keeps them).
  struct Counts {
    std::atomic<int64_t> level1{0};
    std::atomic<int64_t> level2{0};
  };
  auto counts = std::make_shared<Counts>();
  if (prefetch != Prefetch::kNone) {
    spec.prefetch = [&db, &items, prefetch, counts, w](uint32_t i,
                                                       size_t level) {
      if (level == 0) {
        db.centroids.Prefetch(i);
        if (w.heat > 0.0) db.centroids.PrefetchHeat(i);
        if (prefetch == Prefetch::kLate ||
            ((prefetch == Prefetch::kAdaptive ||
              prefetch == Prefetch::kAdaptiveVantage) &&
             !tpr::index::PrefetchSignatureEarly(counts->level1.load(),
                                                 counts->level2.load()))) {
          return;
        }
      }
      tpr::index::PrefetchSignature(items[i]);
    };
    spec.prefetch_vantage_points = prefetch == Prefetch::kAdaptiveVantage;
  }
  // The query's centroid, computed once per query as the index does.
  auto qc =
      std::make_shared<const std::vector<double>>(tpr::index::Centroid(q));
  if (table_spectral) {
    spec.lower_bounds.push_back([&db, &q, qc, counts, w](uint32_t i) {
      level1_bounds.fetch_add(1, std::memory_order_relaxed);
      counts->level1.fetch_add(1, std::memory_order_relaxed);
      double sum = w.emd > 0.0 ? w.emd * db.centroids.LowerBound(qc->data(),
                                                                 q.bands(), i)
                               : 0.0;
      if (w.spectral > 0.0) {
        sum += w.spectral * db.centroids.SpectralLowerBound(
                                q.spectral(), q.spectral_size(), i);
      }
      if (w.heat > 0.0) {
        sum += w.heat * db.centroids.HeatLowerBound(q.heat(), q.heat_size(), i);
      }
      return sum;
    });
  } else {
    spec.lower_bounds.push_back([&db, &q, qc, counts, w,
                                 embeddings](uint32_t i) {
      level1_bounds.fetch_add(1, std::memory_order_relaxed);
      counts->level1.fetch_add(1, std::memory_order_relaxed);
      return (w.emd > 0.0
                  ? w.emd * db.centroids.LowerBound(qc->data(), q.bands(), i)
                  : 0.0) +
             embeddings(i);
    });
  }
  if (w.emd == 0.0) return spec;  // no EMD: nothing for level 2 to bound
  auto level2 = [&items, &q, counts, w, embeddings](double (*bound)(
                    const PreparedSignature&, const PreparedSignature&)) {
    return [&items, &q, counts, w, embeddings, bound](uint32_t i) {
      level2_bounds.fetch_add(1, std::memory_order_relaxed);
      counts->level2.fetch_add(1, std::memory_order_relaxed);
      return w.emd * bound(q, items[i]) + embeddings(i);
    };
  };
  if (cascade == Cascade::kRelaxed) {
    spec.lower_bounds.push_back(level2(&RelaxedTransportBound));
  } else if (cascade == Cascade::kConstrained) {
    spec.lower_bounds.push_back(level2(&ConstrainedTransportBound));
  } else if (cascade == Cascade::kConstrained32) {
    spec.lower_bounds.push_back(
        level2(&tpr::index::ConstrainedTransportBound32));
  }
  return spec;
}

// PeakRssMiB returns the process's peak resident set (VmHWM) in MiB, or 0
// where /proc is not available. Databases are cached per process, so it is
// the peak over every database built so far: run one size per process
// (--benchmark_filter) to read it per size.
double PeakRssMiB() {
  std::ifstream status("/proc/self/status");
  std::string key;
  while (status >> key) {
    if (key == "VmHWM:") {
      double kib = 0.0;
      status >> kib;
      return kib / 1024.0;
    }
    status.ignore(1 << 20, '\n');
  }
  return 0.0;
}

void Report(benchmark::State& state, const Db& db, const SearchStats& total,
            int64_t queries, Storage storage = Storage::kHeap) {
  const double per = queries > 0 ? 1.0 / static_cast<double>(queries) : 0.0;
  const double n = static_cast<double>(db.items.size());
  state.counters["emds"] = static_cast<double>(total.emd_computations) * per;
  state.counters["emd_share"] =
      static_cast<double>(total.emd_computations) * per / n;
  state.counters["lbs"] = static_cast<double>(total.lower_bounds) * per;
  state.counters["lbs1"] = static_cast<double>(level1_bounds.load()) * per;
  state.counters["lbs2"] = static_cast<double>(level2_bounds.load()) * per;
  state.counters["nodes"] = static_cast<double>(total.nodes_visited) * per;
  state.counters["build_s"] = db.build_seconds;
  state.counters["build_cpu_s"] = db.build_cpu_seconds;
  state.counters["peak_rss_mib"] = PeakRssMiB();
  size_t bytes = db.tree.MemoryBytes() + db.centroids.MemoryBytes();
  if (storage == Storage::kArena) {
    bytes += db.arena.MemoryBytes();
    state.counters["arena_cpu_s"] = db.arena_cpu_seconds;
  } else {
    for (const PreparedSignature& p : db.items)
      bytes += sizeof(PreparedSignature) + p.MemoryBytes();
  }
  state.counters["bytes_per_model"] = static_cast<double>(bytes) / n;
}

// RunTree times k-NN searches of the tree over `key`'s database, reading
// the signatures from `storage` (by default as SignatureIndex does).
void RunTree(benchmark::State& state, const DbKey& key, size_t k,
             Cascade cascade = Cascade::kConstrained32, int threads = 1,
             Prefetch prefetch = Prefetch::kAdaptive,
             bool table_spectral = true, Storage storage = Storage::kArena,
             std::optional<TermWeights> weights = std::nullopt) {
  Db& db = GetDb(key);
  const tpr::index::SignatureArena* signatures =
      storage == Storage::kArena ? &Arena(db) : nullptr;
  SearchStats total;
  int64_t queries = 0;
  level1_bounds = 0;
  level2_bounds = 0;
  tbb::task_arena arena(std::max(threads, 1));
  for (auto _ : state) {
    SearchStats stats;
    const PreparedSignature& q = db.queries[queries % db.queries.size()];
    QuerySpec spec =
        signatures != nullptr
            ? Spec(db, *signatures, q, cascade, prefetch, table_spectral,
                   weights)
            : Spec(db, db.items, q, cascade, prefetch, table_spectral, weights);
    if (threads > 1) {
      // As SignatureIndex does with IndexOptions::search_threads.
      spec.parallel_batch = 2 * static_cast<size_t>(threads);
      spec.parallel_for = [&arena](size_t n,
                                   const std::function<void(size_t)>& body) {
        arena.execute([&] {
          tbb::parallel_for(size_t{0}, n, [&](size_t i) { body(i); });
        });
      };
    }
    std::vector<ItemNeighbor> result = db.tree.Knn(std::move(spec), k, &stats);
    benchmark::DoNotOptimize(result);
    total.emd_computations += stats.emd_computations;
    total.lower_bounds += stats.lower_bounds;
    total.nodes_visited += stats.nodes_visited;
    ++queries;
  }
  Report(state, db, total, queries, storage);
}

// BM_KnnVpTree/<n>/<k>: default clustered data.
void BM_KnnVpTree(benchmark::State& state) {
  RunTree(state, {state.range(0), kClasses, kJitterPermille},
          static_cast<size_t>(state.range(1)));
}
BENCHMARK(BM_KnnVpTree)
    ->Args({600, 1})
    ->Args({1000, 1})
    ->Args({1000, 10})
    ->Args({10000, 1})
    ->Args({10000, 10})
    ->Args({100000, 1})
    ->Args({100000, 10})
    ->Unit(benchmark::kMillisecond);

// ExtractedKey is the database of the BM_KnnVpTreeExtracted* benchmarks
// below: <n> = state.range(0) models from extracted prototypes.
DbKey ExtractedKey(const benchmark::State& state) {
  DbKey key{state.range(0), kClasses, kJitterPermille};
  key.extracted = true;
  return key;
}

// BM_KnnVpTreeExtracted/<n>/<k>: prototypes extracted from generated shapes
// (10 synthetic classes x 10 poses = 100 prototypes, each perturbed by 5%
// jitter), the realistic data the matching issue asks for.
void BM_KnnVpTreeExtracted(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  RunTree(state, key, static_cast<size_t>(state.range(1)));
}
// The 1M rows are for runs outside CI (docs/search-cost.md says how): the
// database takes about 10 GB and minutes to build.
BENCHMARK(BM_KnnVpTreeExtracted)
    ->Args({1000, 10})
    ->Args({10000, 10})
    ->Args({100000, 1})
    ->Args({100000, 10})
    ->Args({1000000, 1})
    ->Args({1000000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedSpectral/<n>/<k>: the same data and queries with the
// default metric (metric.h: EMD + spectral term, w_s = 1, by_index, n = 20;
// the extracted prototypes carry their 50-value spectra, which every member
// jitters by 1%): the million-model figure with the spectral term.
void BM_KnnVpTreeExtractedSpectral(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  key.spectral_permille = 1000;
  RunTree(state, key, static_cast<size_t>(state.range(1)));
}
BENCHMARK(BM_KnnVpTreeExtractedSpectral)
    ->Args({10000, 10})
    ->Args({100000, 1})
    ->Args({100000, 10})
    ->Args({1000000, 1})
    ->Args({1000000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedRelaxed/<n>/<k>: BM_KnnVpTreeExtracted with the
// relaxed transport bound without capacities (RWMD) at level 2, the
// cascade before the capacity-constrained bound, for a side-by-side run.
void BM_KnnVpTreeExtractedRelaxed(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  RunTree(state, key, static_cast<size_t>(state.range(1)), Cascade::kRelaxed);
}
BENCHMARK(BM_KnnVpTreeExtractedRelaxed)
    ->Args({10000, 10})
    ->Args({100000, 10})
    ->Args({1000000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedNoPrefetch/<n>/<k>: BM_KnnVpTreeExtracted without
// QuerySpec::prefetch, for a side-by-side run.
void BM_KnnVpTreeExtractedNoPrefetch(benchmark::State& state) {
  RunTree(state, ExtractedKey(state), static_cast<size_t>(state.range(1)),
          Cascade::kConstrained32, /*threads=*/1, Prefetch::kNone);
}
BENCHMARK(BM_KnnVpTreeExtractedNoPrefetch)
    ->Args({100000, 10})
    ->Args({1000000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedSpectralPolicy/<n>/<k>/<policy>: the default metric
// (BM_KnnVpTreeExtractedSpectral's data) under other prefetch policies and
// level-1 forms, side by side: policy 0 = as SignatureIndex (adaptive,
// spectral bound from the table), 1 = signature prefetched at level 0
// always, 2 = at levels >= 1 only, 3 = adaptive with level 1 reading the
// exact spectral term from the signature, 4 = policy 1 with level 1 from
// the signature (the search before the table kept the embeddings).
void BM_KnnVpTreeExtractedSpectralPolicy(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  key.spectral_permille = 1000;
  const int policy = static_cast<int>(state.range(2));
  const Prefetch prefetch[] = {Prefetch::kAdaptive, Prefetch::kEarly,
                               Prefetch::kLate, Prefetch::kAdaptive,
                               Prefetch::kEarly};
  RunTree(state, key, static_cast<size_t>(state.range(1)),
          Cascade::kConstrained32, /*threads=*/1, prefetch[policy],
          /*table_spectral=*/policy < 3);
}
BENCHMARK(BM_KnnVpTreeExtractedSpectralPolicy)
    ->ArgsProduct({{10000, 100000, 1000000}, {10}, {0, 1, 2, 3, 4}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedLevel2/<n>/<k>/<spectral>/<level 2>: the level-2
// bound on the double matrix (0: ConstrainedTransportBound, before) or on
// the float32 one (1: ConstrainedTransportBound32, the index's), with Eq. 7
// alone (spectral 0) or the default metric (1), side by side.
void BM_KnnVpTreeExtractedLevel2(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  if (state.range(2) != 0) key.spectral_permille = 1000;
  RunTree(
      state, key, static_cast<size_t>(state.range(1)),
      state.range(3) == 0 ? Cascade::kConstrained : Cascade::kConstrained32);
}
BENCHMARK(BM_KnnVpTreeExtractedLevel2)
    ->ArgsProduct({{10000, 100000, 1000000}, {1, 10}, {0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedStorage/<n>/<k>/<spectral>/<arena>: the index's
// search (as BM_KnnVpTreeExtractedLevel2/<n>/<k>/<spectral>/1) with the
// signatures read from one heap block each in generation order (arena 0,
// the former layout) or from the SignatureArena in tree order
// (1, the index's), side by side on one database and tree. Both rows
// build the arena (a second copy of the signatures), so peak_rss_mib
// counts both; bytes_per_model is each storage's.
void BM_KnnVpTreeExtractedStorage(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  if (state.range(2) != 0) key.spectral_permille = 1000;
  Arena(GetDb(key));
  RunTree(state, key, static_cast<size_t>(state.range(1)),
          Cascade::kConstrained32, /*threads=*/1, Prefetch::kAdaptive,
          /*table_spectral=*/true,
          state.range(3) != 0 ? Storage::kArena : Storage::kHeap);
}
BENCHMARK(BM_KnnVpTreeExtractedStorage)
    ->ArgsProduct({{10000, 100000, 1000000}, {1, 10}, {0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnIntentExtracted/<n>/<k>/<intent>: the index's search (the arena,
// the cascade, the adaptive prefetch) over one tree built under
// IntentWeights(Intent::kBalanced), as SignatureIndex builds it, searched
// under intent 0 balanced (the default, the build weighting), 1 identity,
// 2 kind, 3 the paper's distance {1, 0, 0}: the per-term bounds let every
// weighting use the one tree. Run the four side by side (one process, one
// database) for their ratios.
void BM_KnnIntentExtracted(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  key.balanced = true;
  const TermWeights weightings[] = {IntentWeights(Intent::kBalanced),
                                    IntentWeights(Intent::kIdentity),
                                    IntentWeights(Intent::kKind),
                                    {1.0, 0.0, 0.0}};
  RunTree(state, key, static_cast<size_t>(state.range(1)),
          Cascade::kConstrained32, /*threads=*/1, Prefetch::kAdaptive,
          /*table_spectral=*/true, Storage::kArena, weightings[state.range(2)]);
}
BENCHMARK(BM_KnnIntentExtracted)
    ->ArgsProduct({{10000, 100000, 1000000}, {10}, {0, 1, 2, 3}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedBefore/<n>/<k>/<spectral>: the search as it was
// before its last changes (level 1 reads the spectral term from
// the signature, the signature prefetched with the centroid row always,
// level 2 on the double matrix), on the data of BM_KnnVpTreeExtractedLevel2
// (same <spectral> meaning), to run beside it: `Level2/<n>/<k>/<s>/1` is
// the search now.
void BM_KnnVpTreeExtractedBefore(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  if (state.range(2) != 0) key.spectral_permille = 1000;
  RunTree(state, key, static_cast<size_t>(state.range(1)),
          Cascade::kConstrained, /*threads=*/1, Prefetch::kEarly,
          /*table_spectral=*/false);
}
BENCHMARK(BM_KnnVpTreeExtractedBefore)
    ->ArgsProduct({{10000, 100000, 1000000}, {1, 10}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedPrefetch/<n>/<k>/<spectral>/<prefetch>: the
// search with the vantage points' signatures prefetched when their node is
// queued (prefetch 1, QuerySpec::prefetch_vantage_points) beside the
// index's search (0), on the data of BM_KnnVpTreeExtractedLevel2 (same
// <spectral> meaning).
void BM_KnnVpTreeExtractedPrefetch(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  if (state.range(2) != 0) key.spectral_permille = 1000;
  RunTree(
      state, key, static_cast<size_t>(state.range(1)), Cascade::kConstrained32,
      /*threads=*/1,
      state.range(3) != 0 ? Prefetch::kAdaptiveVantage : Prefetch::kAdaptive);
}
BENCHMARK(BM_KnnVpTreeExtractedPrefetch)
    ->ArgsProduct({{10000, 100000, 1000000}, {1, 10}, {0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedPolicy/<n>/<k>/<policy>: the same for Eq. 7 alone
// (BM_KnnVpTreeExtracted's data), policies 0 to 2.
void BM_KnnVpTreeExtractedPolicy(benchmark::State& state) {
  const int policy = static_cast<int>(state.range(2));
  const Prefetch prefetch[] = {Prefetch::kAdaptive, Prefetch::kEarly,
                               Prefetch::kLate};
  RunTree(state, ExtractedKey(state), static_cast<size_t>(state.range(1)),
          Cascade::kConstrained32, /*threads=*/1, prefetch[policy]);
}
BENCHMARK(BM_KnnVpTreeExtractedPolicy)
    ->ArgsProduct({{10000, 100000, 1000000}, {10}, {0, 1, 2}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedThreads/<n>/<k>/<threads>: intra-query parallelism
// (QuerySpec::parallel_for over a oneTBB arena, batches of 2 x threads),
// wall time.
void BM_KnnVpTreeExtractedThreads(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  RunTree(state, key, static_cast<size_t>(state.range(1)),
          Cascade::kConstrained32, static_cast<int>(state.range(2)));
}
BENCHMARK(BM_KnnVpTreeExtractedThreads)
    ->Args({10000, 10, 1})
    ->Args({10000, 10, 2})
    ->Args({100000, 10, 1})
    ->Args({100000, 10, 2})
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedCentroid/<n>/<k>: the same with the centroid bound
// alone (no relaxed transport bound), to measure what the cascade saves.
void BM_KnnVpTreeExtractedCentroid(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  RunTree(state, key, static_cast<size_t>(state.range(1)), Cascade::kCentroid);
}
BENCHMARK(BM_KnnVpTreeExtractedCentroid)
    ->Args({1000, 10})
    ->Args({10000, 10})
    ->Args({100000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeSpectral/<n>/<k>/<w_s permille>: the default clustered data
// with 50-value spectra, searched with the combined distance of metric.h
// (w_s = permille / 1000) and, for permille 0, with the paper's distance
// (w_s = 0) on the same signatures: the issue's "k-NN over 100k grows by
// at most 10%" side by side in one run.
void BM_KnnVpTreeSpectral(benchmark::State& state) {
  DbKey key{state.range(0), kClasses, kJitterPermille};
  key.spectral_permille =
      state.range(2) == 0 ? -1 : static_cast<int>(state.range(2));
  RunTree(state, key, static_cast<size_t>(state.range(1)));
}
BENCHMARK(BM_KnnVpTreeSpectral)
    ->Args({10000, 10, 0})
    ->Args({10000, 10, 200})
    ->Args({100000, 10, 0})
    ->Args({100000, 10, 200})
    ->Args({100000, 10, 1000})  // the default w_s (spectral.h)
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeCentroid/<n>/<k>: BM_KnnVpTree with the centroid bound alone.
void BM_KnnVpTreeCentroid(benchmark::State& state) {
  RunTree(state, {state.range(0), kClasses, kJitterPermille},
          static_cast<size_t>(state.range(1)), Cascade::kCentroid);
}
BENCHMARK(BM_KnnVpTreeCentroid)
    ->Args({10000, 10})
    ->Args({100000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeLeaf/<n>/<k>/<leaf_size>: as BM_KnnVpTree with another bucket
// size (VpTreeOptions.leaf_size), to tune it. Each leaf size builds its own
// tree (about a minute at 100k).
void BM_KnnVpTreeLeaf(benchmark::State& state) {
  DbKey key{state.range(0), kClasses, kJitterPermille};
  key.leaf_size = static_cast<size_t>(state.range(2));
  RunTree(state, key, static_cast<size_t>(state.range(1)));
}
BENCHMARK(BM_KnnVpTreeLeaf)
    ->ArgsProduct({{600, 10000, 100000}, {10}, {64, 128, 192, 256, 512, 1024}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnVpTreeExtractedLeaf/<n>/<k>/<leaf_size>: BM_KnnVpTreeExtracted with
// another bucket size, to choose the default on realistic data.
void BM_KnnVpTreeExtractedLeaf(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  key.leaf_size = static_cast<size_t>(state.range(2));
  RunTree(state, key, static_cast<size_t>(state.range(1)));
}
BENCHMARK(BM_KnnVpTreeExtractedLeaf)
    ->ArgsProduct({{100000}, {10}, {32, 64, 128, 256, 512}})
    ->Unit(benchmark::kMillisecond);

// BM_KnnBruteForce/<n>/<k>: every EMD, same data and queries.
void BM_KnnBruteForce(benchmark::State& state) {
  Db& db = GetDb({state.range(0), kClasses, kJitterPermille});
  const BruteForceIndex oracle(db.items.size());
  SearchStats total;
  int64_t queries = 0;
  for (auto _ : state) {
    QuerySpec spec =
        Spec(db, db.items, db.queries[queries % db.queries.size()]);
    spec.lower_bounds.clear();
    SearchStats stats;
    std::vector<ItemNeighbor> result = oracle.Knn(
        std::move(spec), static_cast<size_t>(state.range(1)), &stats);
    benchmark::DoNotOptimize(result);
    total.emd_computations += stats.emd_computations;
    ++queries;
  }
  Report(state, db, total, queries);
}
BENCHMARK(BM_KnnBruteForce)
    ->Args({600, 1})
    ->Args({1000, 1})
    ->Args({1000, 10})
    ->Args({10000, 10})
    ->Args({100000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnIndex/<n>/<k>: the service-facing SignatureIndex (string ids,
// snapshots, buffer merge) on the same data as BM_KnnVpTree.
void RunIndex(benchmark::State& state, const DbKey& key) {
  std::vector<std::pair<std::string, tpr::index::Signature>> items;
  std::vector<tpr::index::Signature> queries;
  double features = 0.0;
  Generate(key, [&](tpr::index::Signature s) {
    if (static_cast<int64_t>(items.size()) < key.n) {
      features += static_cast<double>(s.features.size());
      items.emplace_back("model-" + std::to_string(items.size()), std::move(s));
    } else {
      queries.push_back(std::move(s));
    }
  });
  tpr::index::IndexOptions options;
  options.background_rebuild = false;
  tpr::index::SignatureIndex index(options);
  if (!index.UpsertBatch(items).ok()) {
    state.SkipWithError("UpsertBatch failed");
    return;
  }
  items.clear();
  index.Rebuild();
  SearchStats total;
  int64_t n_queries = 0;
  for (auto _ : state) {
    SearchStats stats;
    std::vector<tpr::index::Neighbor> result =
        index.Knn(queries[n_queries % queries.size()],
                  static_cast<size_t>(state.range(1)), &stats);
    benchmark::DoNotOptimize(result);
    total.emd_computations += stats.emd_computations;
    total.lower_bounds += stats.lower_bounds;
    total.nodes_visited += stats.nodes_visited;
    ++n_queries;
  }
  const double per = 1.0 / static_cast<double>(std::max<int64_t>(n_queries, 1));
  state.counters["bytes_per_model"] = static_cast<double>(index.MemoryBytes()) /
                                      static_cast<double>(index.size());
  state.counters["features_per_model"] = features / static_cast<double>(key.n);
  state.counters["emds"] = static_cast<double>(total.emd_computations) * per;
  state.counters["emd_share"] = static_cast<double>(total.emd_computations) *
                                per / static_cast<double>(key.n);
}
void BM_KnnIndex(benchmark::State& state) {
  RunIndex(state, {state.range(0), kClasses, kJitterPermille});
}
BENCHMARK(BM_KnnIndex)
    ->Args({1000, 10})
    ->Args({10000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnIndexExtracted/<n>/<k>: SignatureIndex over the extracted-prototype
// data of BM_KnnVpTreeExtracted; its bytes_per_model counter is the memory
// figure of the matching issue (index plus tree, 20 bands).
void BM_KnnIndexExtracted(benchmark::State& state) {
  DbKey key = ExtractedKey(state);
  RunIndex(state, key);
}
BENCHMARK(BM_KnnIndexExtracted)
    ->Args({10000, 10})
    ->Args({100000, 10})
    ->Unit(benchmark::kMillisecond);

// BM_KnnSpread/<n>/<jitter per mille>/<classes>, k = 10: what the data's
// intrinsic dimension does. classes = 0 is unclustered data.
void BM_KnnSpread(benchmark::State& state) {
  RunTree(state,
          {state.range(0), static_cast<int>(state.range(2)),
           static_cast<int>(state.range(1))},
          10);
}
BENCHMARK(BM_KnnSpread)
    ->Args({10000, 50, 10})
    ->Args({10000, 20, 100})
    ->Args({10000, 50, 100})
    ->Args({10000, 100, 100})
    ->Args({10000, 200, 100})
    ->Args({10000, 50, 1000})
    ->Args({10000, 50, 0})
    ->Args({100000, 50, 1000})
    ->Unit(benchmark::kMillisecond);

}  // namespace knn

}  // namespace
}  // namespace tpr::index

// The benchmark main, which also prints the kernel variant that runs
// (indexer/lib/internal/simd.h; TPR_SIMD=avx2 or scalar forces a lower
// one) in the context header: "tpr_simd: avx512".
int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::AddCustomContext("tpr_simd",
                              tpr::index::internal::SimdLevelName(
                                  tpr::index::internal::ChosenSimdLevel()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
