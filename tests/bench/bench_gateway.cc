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
#include "tests/indexer/signature_testing.h"
#include "tests/service/indexer_testing.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::gateway {
namespace {

using indexer::BatchWriter;
using indexer::CoreOptions;
using indexer::IndexerCore;
using indexer::IndexerService;
using indexer::testing::ToWire;

constexpr int kShards = 4;

std::vector<tpr::v1::UpsertRequest> Requests(int n, uint64_t seed, const std::string& prefix) {
  tpr::index::testing::SignatureGeneratorOptions o;
  o.seed = seed;
  o.classes = 20;
  tpr::index::testing::SignatureGenerator gen(o);
  std::vector<tpr::v1::UpsertRequest> out(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    tpr::v1::Model* m = out[static_cast<size_t>(i)].mutable_model();
    m->set_id(absl::StrCat(prefix, i));
    m->set_label(absl::StrCat("class", i % 20));
    *m->mutable_signature() = ToWire(gen.Next());
  }
  return out;
}

// Directories made by this process, removed at exit (the cached k-NN
// set-ups live until then).
std::vector<std::string>* MadeDirs() {
  static std::vector<std::string>* dirs = [] {
    auto* d = new std::vector<std::string>;
    std::atexit([] {
      for (const std::string& dir : *MadeDirs()) {
        std::error_code ec;
        std::filesystem::remove_all(dir, ec);
      }
    });
    return d;
  }();
  return dirs;
}

std::string FreshDir(const std::string& tag) {
  std::string pattern =
      (std::filesystem::temp_directory_path() / ("tpr-bench-gw-" + tag + ".XXXXXX")).string();
  if (mkdtemp(pattern.data()) == nullptr) std::abort();
  MadeDirs()->push_back(pattern);
  return pattern;
}

// One served indexer (IndexerCore + IndexerService on a loopback port).
struct Indexer {
  std::string dir;
  std::unique_ptr<IndexerCore> core;
  std::unique_ptr<IndexerService> service;
  tpr::common::ServerOptions server_options;
  tpr::common::StartedServer server;

  ~Indexer() {
    if (server.server) tpr::common::ShutdownGracefully(server, server_options);
    server.server.reset();
    core.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
  std::string address() const { return absl::StrCat("127.0.0.1:", server.port); }
};

std::unique_ptr<Indexer> StartIndexer(bool durable) {
  auto x = std::make_unique<Indexer>();
  x->dir = FreshDir("indexer");
  CoreOptions options;
  options.data_dir = x->dir;
  options.persist_interval_ms = 0;
  options.storage.sync_writes = durable;
  absl::StatusOr<std::unique_ptr<IndexerCore>> core = IndexerCore::Open(options);
  if (!core.ok()) std::abort();
  x->core = std::move(*core);
  x->service = std::make_unique<IndexerService>(x->core.get(), indexer::ServiceOptions{});
  x->server_options.shutdown_grace_ms = 1000;
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(x->server_options, {x->service.get()});
  if (!started.ok()) std::abort();
  x->server = std::move(*started);
  return x;
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

std::unique_ptr<tpr::v1::Indexer::Stub> StubTo(const Indexer& x) {
  return tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(x.address(), grpc::InsecureChannelCredentials()));
}

// The k-NN set-up, built once per N: one indexer and 4 shards holding the
// same N models (written in process, not durable: set-up only), settled
// trees, a gateway over the shards.
struct KnnSetup {
  std::unique_ptr<Indexer> single;
  std::unique_ptr<tpr::v1::Indexer::Stub> single_stub;
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
    for (tpr::v1::UpsertRequest& r : Requests(n, 7, "m")) {
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
  s.single_stub = StubTo(*s.single);
  s.gateway = StartGateway(s.shards);
  for (tpr::v1::UpsertRequest& r : Requests(64, 99, "q")) {
    tpr::v1::SearchRequest q;
    *q.mutable_signature() = r.model().signature();
    q.set_k(10);
    s.queries.push_back(std::move(q));
  }
  return slot.get();
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * static_cast<double>(v.size() - 1))];
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
    single_ms.push_back(TimedSearch(s->single_stub.get(), q, &a, state));
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

// One durable streamed BatchUpsert of N models through `stub`.
void Ingest(tpr::v1::Indexer::Stub* stub, const std::vector<tpr::v1::UpsertRequest>& requests,
            benchmark::State& state) {
  grpc::ClientContext context;
  tpr::v1::BatchUpsertResponse response;
  auto writer = stub->BatchUpsert(&context, &response);
  for (const tpr::v1::UpsertRequest& r : requests) writer->Write(r);
  writer->WritesDone();
  if (!writer->Finish().ok() || response.written() != static_cast<int64_t>(requests.size())) {
    state.SkipWithError("ingest failed");
  }
}

void BM_IngestSingle(benchmark::State& state) {
  const std::vector<tpr::v1::UpsertRequest> requests =
      Requests(static_cast<int>(state.range(0)), 11, "b");
  for (auto _ : state) {
    state.PauseTiming();
    auto single = StartIndexer(/*durable=*/true);
    auto stub = StubTo(*single);
    state.ResumeTiming();
    Ingest(stub.get(), requests, state);
    state.PauseTiming();
    stub.reset();
    single.reset();
    state.ResumeTiming();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_IngestSingle)->Arg(2000)->Arg(10000)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_IngestGateway(benchmark::State& state) {
  const std::vector<tpr::v1::UpsertRequest> requests =
      Requests(static_cast<int>(state.range(0)), 11, "b");
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
