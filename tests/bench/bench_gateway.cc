// tpr-gateway benchmarks, one indexer against S = 4 shards behind the
// gateway, measured side by side in one run (all servers in this process,
// on loopback gRPC, sharing the machine's cores):
//  * BM_Knn10SingleVsGateway/N/Q: a 10-NN query over N models (the same
//    query, alternately) to one tpr-indexer and to the gateway over 4 shards
//    holding the same N models; Q = 0: queries of the stored classes (not
//    stored themselves), Q = 1: queries of other prototypes (worst case).
//    Counters: p50 latency of each (ms, wall), their ratio (target <= 1.5 on a
//    2-core machine), EMDs per query of the single indexer, and per shard (each
//    shard's full 10-NN on its part, run in process for the same queries: the
//    most a shard does for one query; the gateway cancels shards early once 10
//    are sent).
//  * BM_IngestSingle/N and BM_IngestGateway/N: a streamed BatchUpsert of N
//    models into fresh data directories, durable (synced group commits), to
//    one indexer or through the gateway to 4 shards; items/s.
//  * BM_FollowerLag/B/P: a primary and its follower (tpr-indexer --follow's
//    Follower over loopback gRPC); durable writes of B models every P ms
//    for 4 s; how long until the follower has applied each write (ms) and
//    how many keys it was behind when sampled.
//
//   bench_gateway --benchmark_filter=
//   'BM_Knn10SingleVsGateway/100000/0|BM_Ingest.*/10000|BM_FollowerLag'
//
// Signatures: tests/indexer/signature_testing.h, 20 clustered classes, 30
// features x 20 bands (the paper's average size), as bench_service.
#include <benchmark/benchmark.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <stdlib.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/server_lifecycle.h"
#include "indexer/gateway/gateway_service.h"
#include "indexer/gateway/shard_map.h"
#include "indexer/service/admin_service.h"
#include "indexer/service/batch_writer.h"
#include "indexer/service/follower.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/indexer_service.h"
#include "indexer/service/replication.h"
#include "tests/bench/bench_indexer_setup.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::gateway {
namespace {

using bench::Ingest;
using bench::Percentile;
using bench::UpsertRequests;
using indexer::BatchWriter;
using indexer::IndexerCore;

constexpr int kShards = 4;

using Indexer = bench::ServedIndexer;

std::unique_ptr<Indexer> StartIndexer(bool durable) {
  return bench::ServeIndexer(durable);
}

// A gateway over `shards`, served on a loopback port.
struct Gateway {
  std::unique_ptr<GatewayService> service;
  tpr::common::ServerOptions server_options;
  tpr::common::StartedServer server;
  std::unique_ptr<tpr::v1::Indexer::Stub> stub;
  ~Gateway() {
    if (server.server) tpr::common::ShutdownGracefully(server, server_options);
  }
};

std::unique_ptr<Gateway> StartGateway(
    const std::vector<std::unique_ptr<Indexer>>& shards) {
  auto g = std::make_unique<Gateway>();
  GatewayOptions options;
  for (const auto& s : shards)
    options.shards.shards.push_back({s->address(), {}});
  g->service = std::make_unique<GatewayService>(options);
  g->server_options.shutdown_grace_ms = 1000;
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(g->server_options, {g->service.get()});
  if (!started.ok()) std::abort();
  g->server = std::move(*started);
  g->stub = tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(absl::StrCat("127.0.0.1:", g->server.port),
                          grpc::InsecureChannelCredentials()));
  return g;
}

// The k-NN set-up, built once per N: one indexer and 4 shards holding the
// same N models (written in process, not durable: set-up only), settled
// trees, a gateway over the shards.
struct KnnSetup {
  std::unique_ptr<Indexer> single;
  std::vector<std::unique_ptr<Indexer>> shards;
  std::unique_ptr<Gateway> gateway;
  // [0]: in-class queries (InClassQueries), [1]: foreign ones (KnnQueries).
  std::vector<tpr::v1::SearchRequest> queries[2];
};

KnnSetup* KnnWith(int n) {
  static std::map<int, std::unique_ptr<KnnSetup>>* cache =
      new std::map<int, std::unique_ptr<KnnSetup>>;
  std::unique_ptr<KnnSetup>& slot = (*cache)[n];
  if (slot) return slot.get();
  slot = std::make_unique<KnnSetup>();
  KnnSetup& s = *slot;
  s.single = StartIndexer(/*durable=*/false);
  for (int i = 0; i < kShards; ++i) s.shards.push_back(StartIndexer(false));
  {
    BatchWriter single(s.single->core.get());
    std::vector<std::unique_ptr<BatchWriter>> parts;
    for (const auto& shard : s.shards)
      parts.push_back(std::make_unique<BatchWriter>(shard->core.get()));
    for (tpr::v1::UpsertRequest& r : UpsertRequests(n, 7, "m")) {
      const int owner = ShardOf(r.model().id(), kShards);
      if (!parts[static_cast<size_t>(owner)]->Add(r).ok()) std::abort();
      if (!single.Add(std::move(r)).ok()) std::abort();
    }
    if (!single.Finish().ok()) std::abort();
    for (auto& part : parts) {
      if (!part->Finish().ok()) std::abort();
    }
  }
  s.single->core->WaitForRebuild();
  for (auto& shard : s.shards) shard->core->WaitForRebuild();
  s.gateway = StartGateway(s.shards);
  s.queries[0] = bench::InClassQueries(n, 7);
  s.queries[1] = bench::KnnQueries();
  return slot.get();
}

// Runs one streamed search; returns its wall time in ms and the neighbours.
double TimedSearch(tpr::v1::Indexer::Stub* stub,
                   const tpr::v1::SearchRequest& q, int* neighbours,
                   benchmark::State& state) {
  const auto start = std::chrono::steady_clock::now();
  grpc::ClientContext context;
  auto reader = stub->Search(&context, q);
  tpr::v1::SearchResponse response;
  *neighbours = 0;
  while (reader->Read(&response))
    *neighbours += response.has_neighbor() ? 1 : 0;
  if (!reader->Finish().ok()) state.SkipWithError("search failed");
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now() - start)
      .count();
}

void BM_Knn10SingleVsGateway(benchmark::State& state) {
  KnnSetup* s = KnnWith(static_cast<int>(state.range(0)));
  const std::vector<tpr::v1::SearchRequest>& queries =
      s->queries[state.range(1) == 0 ? 0 : 1];
  std::vector<double> single_ms, gateway_ms;
  // Work per query: the single indexer's, and each shard's full 10-NN on
  // its part (measured once per distinct query, outside the timing).
  std::vector<double> single_emds, shard_emds_max, shard_emds_mean;
  size_t i = 0;
  for (auto _ : state) {
    const size_t qi = i++ % queries.size();
    const tpr::v1::SearchRequest& q = queries[qi];
    int a = 0, b = 0;
    single_ms.push_back(TimedSearch(s->single->stub.get(), q, &a, state));
    gateway_ms.push_back(TimedSearch(s->gateway->stub.get(), q, &b, state));
    if (a != 10 || b != 10) state.SkipWithError("fewer than 10 neighbours");
    if (i <= queries.size()) {
      state.PauseTiming();
      auto run = [&](IndexerCore* core) {
        auto session = core->StartSearch(q, nullptr);
        while ((*session)->Next()) {
        }
        return static_cast<double>((*session)->Stats().emd_computations());
      };
      single_emds.push_back(run(s->single->core.get()));
      double max = 0, sum = 0;
      for (auto& shard : s->shards) {
        const double e = run(shard->core.get());
        max = std::max(max, e);
        sum += e;
      }
      shard_emds_max.push_back(max);
      shard_emds_mean.push_back(sum / kShards);
      state.ResumeTiming();
    }
  }
  const double single_p50 = Percentile(single_ms, 0.5);
  const double gateway_p50 = Percentile(gateway_ms, 0.5);
  state.counters["single_p50_ms"] = single_p50;
  state.counters["gateway_p50_ms"] = gateway_p50;
  state.counters["gateway_p90_ms"] = Percentile(gateway_ms, 0.9);
  state.counters["ratio_p50"] = single_p50 > 0 ? gateway_p50 / single_p50 : 0;
  state.counters["single_emds"] = Percentile(single_emds, 0.5);
  state.counters["shard_emds_max"] = Percentile(shard_emds_max, 0.5);
  state.counters["shard_emds_mean"] = Percentile(shard_emds_mean, 0.5);
}
// Args (N, queries): 0 in-class queries (a known kind of shape, the
// realistic case), 1 foreign ones (far from every class: little pruning,
// the worst case; each costs seconds at 100k). 16 iterations: 16 distinct
// queries per repetition, the same 16 each time.
BENCHMARK(BM_Knn10SingleVsGateway)
    ->Args({2000, 0})
    ->Args({20000, 0})
    ->Args({100000, 0})
    ->Args({2000, 1})
    ->Args({100000, 1})
    ->Iterations(16)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_IngestSingle(benchmark::State& state) {
  const std::vector<tpr::v1::UpsertRequest> requests =
      UpsertRequests(static_cast<int>(state.range(0)), 11, "b");
  for (auto _ : state) {
    state.PauseTiming();
    auto single = StartIndexer(/*durable=*/true);
    state.ResumeTiming();
    Ingest(single->stub.get(), requests, state);
    state.PauseTiming();
    single.reset();
    state.ResumeTiming();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_IngestSingle)
    ->Arg(2000)
    ->Arg(10000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_IngestGateway(benchmark::State& state) {
  const std::vector<tpr::v1::UpsertRequest> requests =
      UpsertRequests(static_cast<int>(state.range(0)), 11, "b");
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<std::unique_ptr<Indexer>> shards;
    for (int i = 0; i < kShards; ++i)
      shards.push_back(StartIndexer(/*durable=*/true));
    auto gateway = StartGateway(shards);
    state.ResumeTiming();
    Ingest(gateway->stub.get(), requests, state);
    state.PauseTiming();
    gateway.reset();
    shards.clear();
    state.ResumeTiming();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_IngestGateway)
    ->Arg(2000)
    ->Arg(10000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// A primary or follower with the IndexerAdmin service (replication), served
// on a loopback port; a follower of `primary` (copied and tailing on
// return) when it is not empty.
struct ReplicaNode {
  std::string dir;
  std::unique_ptr<IndexerCore> core;
  std::unique_ptr<indexer::IndexerService> service;
  std::unique_ptr<indexer::Follower> follower;
  std::unique_ptr<indexer::IndexerAdminService> admin;
  tpr::common::ServerOptions server_options;
  tpr::common::StartedServer server;
  ~ReplicaNode() {
    admin->Stop();
    if (follower) follower->Stop();
    tpr::common::ShutdownGracefully(server, server_options);
    server.server.reset();
    follower.reset();
    core.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
  std::string address() const {
    return absl::StrCat("127.0.0.1:", server.port);
  }
};

std::unique_ptr<ReplicaNode> StartReplicaNode(const std::string& primary) {
  auto x = std::make_unique<ReplicaNode>();
  x->dir = bench::FreshDir("replica");
  indexer::FollowerOptions follower_options;
  follower_options.primary = primary;
  follower_options.data_dir = x->dir;
  if (!primary.empty() && !indexer::PrepareFollowerDir(follower_options).ok())
    std::abort();
  indexer::CoreOptions options;
  options.data_dir = x->dir;
  options.persist_interval_ms = 0;
  options.follow = primary;
  absl::StatusOr<std::unique_ptr<IndexerCore>> core =
      IndexerCore::Open(options);
  if (!core.ok()) std::abort();
  x->core = std::move(*core);
  x->service = std::make_unique<indexer::IndexerService>(
      x->core.get(), indexer::ServiceOptions{});
  if (!primary.empty()) {
    x->follower =
        std::make_unique<indexer::Follower>(x->core.get(), follower_options);
  }
  x->admin = std::make_unique<indexer::IndexerAdminService>(
      x->core.get(), x->follower.get(), indexer::AdminOptions{});
  x->server_options.shutdown_grace_ms = 1000;
  absl::StatusOr<tpr::common::StartedServer> started = tpr::common::StartServer(
      x->server_options, {x->service.get(), x->admin.get()});
  if (!started.ok()) std::abort();
  x->server = std::move(*started);
  if (x->follower) x->follower->Start(nullptr);
  return x;
}

// Follower lag under steady ingest: a primary and its follower (tpr-indexer
// --follow's Follower and IndexerAdmin services, in this process, over
// loopback gRPC), durable group writes of `batch` models every `period`
// ms for 4 s. Lag of each write: from the primary's acknowledgement to the
// follower having applied it (its store and index), in ms; and how many
// RocksDB sequence numbers (keys) the follower was behind when sampled.
void BM_FollowerLag(benchmark::State& state) {
  const int batch = static_cast<int>(state.range(0));
  const int period_ms = static_cast<int>(state.range(1));
  std::vector<double> lag_ms, behind;
  int64_t written = 0;
  for (auto _ : state) {
    state.PauseTiming();
    auto primary = StartReplicaNode("");
    auto follower = StartReplicaNode(primary->address());
    // Made before the clock starts, so the writes keep their pace.
    std::vector<tpr::v1::UpsertRequest> all =
        UpsertRequests(batch * (4000 / period_ms + 2), 5, "lag");
    state.ResumeTiming();
    const auto start = std::chrono::steady_clock::now();
    const auto end = start + std::chrono::seconds(4);
    std::atomic<bool> done{false};
    std::atomic<bool> stuck{false};
    std::mutex mu;
    std::deque<std::pair<std::chrono::steady_clock::time_point, uint64_t>>
        pending;
    std::thread watcher([&] {
      while (true) {
        const uint64_t latest =
            indexer::LatestSequence(primary->core->storage());
        const uint64_t applied =
            follower->follower->Status().applied_sequence();
        const auto now = std::chrono::steady_clock::now();
        {
          std::lock_guard<std::mutex> lock(mu);
          behind.push_back(
              static_cast<double>(latest > applied ? latest - applied : 0));
          while (!pending.empty() && pending.front().second <= applied) {
            lag_ms.push_back(std::chrono::duration<double, std::milli>(
                                 now - pending.front().first)
                                 .count());
            pending.pop_front();
          }
          if (done && pending.empty()) return;
          if (now >
              end + std::chrono::seconds(20)) {  // bounded: report, then stop
            stuck = true;
            return;
          }
        }
        std::this_thread::sleep_for(std::chrono::microseconds(500));
      }
    });
    size_t next = 0;
    for (auto t = start; t < end && next + batch <= all.size();
         t += std::chrono::milliseconds(period_ms)) {
      std::this_thread::sleep_until(t);
      std::vector<tpr::v1::UpsertRequest> group(all.begin() + next,
                                                all.begin() + next + batch);
      next += batch;
      std::vector<tpr::index::Signature> sigs(group.size());
      for (size_t i = 0; i < group.size(); ++i) {
        if (!primary->core->CheckModel(group[i].model(), &sigs[i]).ok())
          std::abort();
      }
      if (!primary->core->WriteGroup(group, sigs).ok()) std::abort();
      std::lock_guard<std::mutex> lock(mu);
      pending.emplace_back(std::chrono::steady_clock::now(),
                           indexer::LatestSequence(primary->core->storage()));
      written += batch;
    }
    done = true;
    watcher.join();
    if (stuck) state.SkipWithError("the follower did not catch up within 20 s");
    state.PauseTiming();
    follower.reset();
    primary.reset();
    state.ResumeTiming();
  }
  state.counters["lag_p50_ms"] = Percentile(lag_ms, 0.5);
  state.counters["lag_p99_ms"] = Percentile(lag_ms, 0.99);
  state.counters["lag_max_ms"] = Percentile(lag_ms, 1.0);
  state.counters["behind_p50_keys"] = Percentile(behind, 0.5);
  state.counters["behind_max_keys"] = Percentile(behind, 1.0);
  state.counters["models_per_s"] = benchmark::Counter(
      static_cast<double>(written), benchmark::Counter::kIsRate);
}
// (batch, period ms): 16 models every 50 ms (320/s), 64 (1280/s), 256
// (5120/s, beyond what one durable primary takes on this machine).
BENCHMARK(BM_FollowerLag)
    ->Args({16, 50})
    ->Args({64, 50})
    ->Args({256, 50})
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace tpr::gateway

BENCHMARK_MAIN();
