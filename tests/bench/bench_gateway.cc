// tpr-gateway benchmarks, one indexer against S = 4 shards behind the
// gateway, measured side by side in one run (all servers in this process,
// on loopback gRPC, sharing the machine's cores):
//  * BM_Knn10SingleVsGateway/N: a 10-NN query over N models (the same
//    query, alternately) to one tpr-indexer and to the gateway over 4 shards
//    holding the same N models. Counters: p50 latency of each (ms, wall),
//    their ratio (target <= 1.5 on a 2-core machine), EMDs per query of the
//    single indexer, and per shard (each shard's full 10-NN on its part, run
//    in process for the same queries: the most a shard does for one query;
//    the gateway cancels shards early once 10 are sent).
//  * BM_IngestSingle/N and BM_IngestGateway/N: a streamed BatchUpsert of N
//    models into fresh data directories, durable (synced group commits), to
//    one indexer or through the gateway to 4 shards; items/s.
//
//   bench_gateway --benchmark_filter='BM_Knn10SingleVsGateway/100000|BM_Ingest'
//
// Signatures: tests/indexer/signature_testing.h, 20 clustered classes, 30
// features x 20 bands (the paper's average size), as bench_service.
#include <benchmark/benchmark.h>
#include <stdlib.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>

#include "absl/strings/str_cat.h"
#include "common/server_lifecycle.h"
#include "indexer/gateway/gateway_service.h"
#include "indexer/gateway/shard_map.h"
#include "indexer/service/batch_writer.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/indexer_service.h"
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

std::unique_ptr<Indexer> StartIndexer(bool durable) { return bench::ServeIndexer(durable); }

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

std::unique_ptr<Gateway> StartGateway(const std::vector<std::unique_ptr<Indexer>>& shards) {
  auto g = std::make_unique<Gateway>();
  GatewayOptions options;
  for (const auto& s : shards) options.shards.shards.push_back({s->address(), {}});
  g->service = std::make_unique<GatewayService>(options);
  g->server_options.shutdown_grace_ms = 1000;
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(g->server_options, {g->service.get()});
  if (!started.ok()) std::abort();
  g->server = std::move(*started);
  g->stub = tpr::v1::Indexer::NewStub(grpc::CreateChannel(
      absl::StrCat("127.0.0.1:", g->server.port), grpc::InsecureChannelCredentials()));
  return g;
}

// The k-NN set-up, built once per N: one indexer and 4 shards holding the
// same N models (written in process, not durable: set-up only), settled
// trees, a gateway over the shards.
struct KnnSetup {
  std::unique_ptr<Indexer> single;
  std::vector<std::unique_ptr<Indexer>> shards;
  std::unique_ptr<Gateway> gateway;
  std::vector<tpr::v1::SearchRequest> queries;
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
    for (const auto& shard : s.shards) parts.push_back(std::make_unique<BatchWriter>(shard->core.get()));
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
  s.queries = bench::KnnQueries();
  return slot.get();
}

// Runs one streamed search; returns its wall time in ms and the neighbours.
double TimedSearch(tpr::v1::Indexer::Stub* stub, const tpr::v1::SearchRequest& q,
                   int* neighbours, benchmark::State& state) {
  const auto start = std::chrono::steady_clock::now();
  grpc::ClientContext context;
  auto reader = stub->Search(&context, q);
  tpr::v1::SearchResponse response;
  *neighbours = 0;
  while (reader->Read(&response)) *neighbours += response.has_neighbor() ? 1 : 0;
  if (!reader->Finish().ok()) state.SkipWithError("search failed");
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

void BM_Knn10SingleVsGateway(benchmark::State& state) {
  KnnSetup* s = KnnWith(static_cast<int>(state.range(0)));
  std::vector<double> single_ms, gateway_ms;
  // Work per query: the single indexer's, and each shard's full 10-NN on
  // its part (measured once per distinct query, outside the timing).
  std::vector<double> single_emds, shard_emds_max, shard_emds_mean;
  size_t i = 0;
  for (auto _ : state) {
    const size_t qi = i++ % s->queries.size();
    const tpr::v1::SearchRequest& q = s->queries[qi];
    int a = 0, b = 0;
    single_ms.push_back(TimedSearch(s->single->stub.get(), q, &a, state));
    gateway_ms.push_back(TimedSearch(s->gateway->stub.get(), q, &b, state));
    if (a != 10 || b != 10) state.SkipWithError("fewer than 10 neighbours");
    if (i <= s->queries.size()) {
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
// 16 iterations: 16 distinct queries per repetition, the same 16 each time.
BENCHMARK(BM_Knn10SingleVsGateway)
    ->Arg(2000)
    ->Arg(20000)
    ->Arg(100000)
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
BENCHMARK(BM_IngestSingle)->Arg(2000)->Arg(10000)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_IngestGateway(benchmark::State& state) {
  const std::vector<tpr::v1::UpsertRequest> requests =
      UpsertRequests(static_cast<int>(state.range(0)), 11, "b");
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<std::unique_ptr<Indexer>> shards;
    for (int i = 0; i < kShards; ++i) shards.push_back(StartIndexer(/*durable=*/true));
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
BENCHMARK(BM_IngestGateway)->Arg(2000)->Arg(10000)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace tpr::gateway

BENCHMARK_MAIN();
