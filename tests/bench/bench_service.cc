// tpr-indexer service benchmarks:
//  * BM_KnnGrpcVsInProcess/N: a 10-NN query over N stored models, timed
//    side by side for the same query on the same IndexerCore: in-process
//    (IndexerCore::StartSearch, no wire) and through gRPC on loopback (a
//    streamed Search read to its end). Counters: p50 of each and p50 of the
//    per-query difference (the wire's added latency; target <= 1 ms). N = 10
//    makes the search itself cheap (10 EMDs), isolating the wire's cost.
//  * BM_ReopenDataDir/N: reopening a data dir of N models with a persisted
//    VP-tree (target: seconds for 100k, not a rebuild).
//  * BM_BatchUpsertIngest/N/durable: streaming BatchUpsert of N models into
//    a fresh data dir, durable (synced group commits) or not, items/s
//    (target >= 5,000 signatures/s durable).
//
//   bench_service --benchmark_filter='BM_KnnGrpcVsInProcess/10000'
//                 --benchmark_repetitions=3
//
// Signatures: tests/indexer/signature_testing.h, clustered classes, 30
// features x 20 bands (the paper's average size).
#include <benchmark/benchmark.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <stdlib.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/auth.h"
#include "common/metrics.h"
#include "common/server_lifecycle.h"
#include "common/tls.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/indexer_service.h"
#include "tests/bench/bench_indexer_setup.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::indexer {
namespace {

using bench::FreshDir;
using bench::Percentile;
using bench::UpsertRequests;

// The k-NN set-up, one served indexer holding N models with a settled
// tree, built once per N and kept for the process (building 10k trees costs
// seconds; 100k models take 1.5 GB).
struct Served {
  std::unique_ptr<bench::ServedIndexer> indexer;
  std::vector<tpr::v1::SearchRequest> queries;
};

Served* ServedWith(int n) {
  static std::map<int, std::unique_ptr<Served>>* cache =
      new std::map<int, std::unique_ptr<Served>>;
  auto& slot = (*cache)[n];
  if (slot) return slot.get();
  slot = std::make_unique<Served>();
  slot->indexer = bench::ServeIndexer(/*durable=*/false);
  bench::Fill(slot->indexer->core.get(), UpsertRequests(n, 7, "m"));
  slot->queries = bench::KnnQueries();
  return slot.get();
}

void BM_KnnGrpcVsInProcess(benchmark::State& state) {
  Served* s = ServedWith(static_cast<int>(state.range(0)));
  std::vector<double> local_us, grpc_us, added_us;
  size_t i = 0;
  int64_t neighbours = 0;
  int64_t emds = 0;
  for (auto _ : state) {
    const tpr::v1::SearchRequest& q = s->queries[i++ % s->queries.size()];
    auto t0 = std::chrono::steady_clock::now();
    auto session = s->indexer->core->StartSearch(q, nullptr);
    while (auto n = (*session)->Next()) benchmark::DoNotOptimize(n->distance());
    auto t1 = std::chrono::steady_clock::now();
    emds += (*session)->Stats().emd_computations();
    grpc::ClientContext context;
    auto reader = s->indexer->stub->Search(&context, q);
    tpr::v1::SearchResponse response;
    while (reader->Read(&response))
      neighbours += response.has_neighbor() ? 1 : 0;
    if (!reader->Finish().ok()) state.SkipWithError("search failed");
    auto t2 = std::chrono::steady_clock::now();
    const double a = std::chrono::duration<double, std::micro>(t1 - t0).count();
    const double b = std::chrono::duration<double, std::micro>(t2 - t1).count();
    local_us.push_back(a);
    grpc_us.push_back(b);
    added_us.push_back(b - a);
  }
  state.counters["inproc_p50_us"] = Percentile(local_us, 0.5);
  state.counters["grpc_p50_us"] = Percentile(grpc_us, 0.5);
  state.counters["added_p50_us"] = Percentile(added_us, 0.5);
  state.counters["added_p90_us"] = Percentile(added_us, 0.9);
  state.counters["emds_per_query"] = benchmark::Counter(
      static_cast<double>(emds), benchmark::Counter::kAvgIterations);
  state.counters["neighbours"] = benchmark::Counter(
      static_cast<double>(neighbours), benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_KnnGrpcVsInProcess)
    ->Arg(10)
    ->Arg(1000)
    ->Arg(10000)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

void BM_BatchUpsertIngest(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const bool durable = state.range(1) != 0;
  const std::vector<tpr::v1::UpsertRequest> requests =
      UpsertRequests(n, 11, "b");
  int64_t items = 0;
  for (auto _ : state) {
    state.PauseTiming();
    std::unique_ptr<bench::ServedIndexer> indexer =
        bench::ServeIndexer(durable);
    state.ResumeTiming();
    bench::Ingest(indexer->stub.get(), requests, state);
    items += n;
    state.PauseTiming();
    indexer.reset();
    state.ResumeTiming();
  }
  state.SetItemsProcessed(items);
}
BENCHMARK(BM_BatchUpsertIngest)
    ->Args({2000, 1})
    ->Args({2000, 0})
    ->Args({10000, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// A data dir holding N models and their persisted VP-tree, made once: the
// models are written straight to Storage, then the first IndexerCore::Open
// builds the tree once and persists it.
std::string DataDirWith(int n) {
  static std::map<int, std::string>* cache = new std::map<int, std::string>;
  std::string& dir = (*cache)[n];
  if (!dir.empty()) return dir;
  dir = FreshDir("reopen");
  {
    StorageOptions storage_options;
    storage_options.sync_writes = false;  // set-up only; not what is timed
    auto storage = std::move(*Storage::Open(dir, storage_options));
    constexpr int kChunk = 1000;
    for (int begin = 0; begin < n; begin += kChunk) {
      std::vector<tpr::v1::UpsertRequest> chunk = UpsertRequests(
          std::min(kChunk, n - begin), 1000 + static_cast<uint64_t>(begin),
          absl::StrCat("r", begin, "-"));
      std::vector<ModelWrite> writes;
      for (tpr::v1::UpsertRequest& r : chunk)
        writes.push_back({r.model().id(), &r.model()});
      if (!storage->Write(writes).ok()) std::abort();
    }
  }
  CoreOptions options;
  options.data_dir = dir;
  options.persist_interval_ms = 0;
  auto core = IndexerCore::Open(options);  // builds and persists the tree
  if (!core.ok()) std::abort();
  return dir;
}

// BM_ReopenDataDir/N: IndexerCore::Open of a data dir of N models with a
// persisted VP-tree (scan, parse, SignatureIndex::Load; no EMD), as
// tpr-indexer does at start. The target: seconds for 100k.
void BM_ReopenDataDir(benchmark::State& state) {
  const std::string dir = DataDirWith(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    CoreOptions options;
    options.data_dir = dir;
    options.persist_interval_ms = 0;
    auto core = IndexerCore::Open(options);
    if (!core.ok()) state.SkipWithError("open failed");
    state.PauseTiming();
    if (core.ok() &&
        (*core)->index().size() != static_cast<size_t>(state.range(0))) {
      state.SkipWithError("wrong model count");
    }
    if (core.ok())
      core->reset();  // Close: nothing changed, nothing re-persisted
    state.ResumeTiming();
  }
}
BENCHMARK(BM_ReopenDataDir)
    ->Arg(10000)
    ->Arg(100000)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(2);

// BM_SecurityAndMetricsOverhead/N: the same cheap 10-NN search (N = 10
// models: 10 EMDs) against three servers over one IndexerCore, timed side
// by side in each iteration (order rotating): plaintext; TLS + API key
// (ECDSA P-256 certificate made with openssl, `authorization: Bearer`
// checked in the auth filter: one SHA-256 per call); plaintext with
// Prometheus metrics recorded (common/metrics.h). Counters: p50 of each,
// p50 of the per-query differences (targets: TLS + key <= 300 us added at
// p50; metrics < 2% of search throughput, i.e. of the summed time).
// Connections are established before timing (TLS handshakes are per
// connection, not per call).
void BM_SecurityAndMetricsOverhead(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const std::string dir = FreshDir("security");
  const std::string certs = absl::StrCat(
      "cd ", dir,
      " && openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 "
      "-nodes "
      "-keyout ca.key -out ca.pem -days 2 -subj /CN=bench-ca 2>/dev/null && "
      "openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes "
      "-keyout server.key "
      "-out server.csr -subj /CN=localhost 2>/dev/null && "
      "printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\\n' > san.ext && "
      "openssl x509 -req -in server.csr -CA ca.pem -CAkey ca.key "
      "-CAcreateserial -days 2 "
      "-out server.pem -extfile san.ext 2>/dev/null");
  if (std::system(certs.c_str()) != 0) {
    state.SkipWithError("openssl failed");
    return;
  }
  const std::string key = *tpr::common::NewApiKey();
  {
    std::ofstream out(dir + "/keys");
    out << tpr::common::KeyFileLine(key, tpr::common::Role::kRead, "bench")
        << "\n";
  }
  CoreOptions core_options;
  core_options.data_dir = dir + "/data";
  core_options.persist_interval_ms = 0;
  auto core = std::move(*IndexerCore::Open(core_options));
  bench::Fill(core.get(), UpsertRequests(n, 7, "m"));

  // Three services over the one core (a service serves one server).
  std::vector<std::unique_ptr<IndexerService>> services;
  std::vector<tpr::common::StartedServer> servers;
  std::vector<std::unique_ptr<tpr::v1::Indexer::Stub>> stubs;
  auto metrics = std::make_shared<tpr::common::Metrics>();
  for (int config = 0; config < 3; ++config) {
    tpr::common::ServerOptions options;
    if (config == 1) {
      tpr::common::TlsServerOptions tls;
      tls.cert_file = dir + "/server.pem";
      tls.key_file = dir + "/server.key";
      options.credentials = *tpr::common::MakeTlsServerCredentials(tls);
      options.api_keys =
          *tpr::common::ApiKeyAuthenticator::Open(dir + "/keys", "bench", 0);
    }
    if (config == 2) options.metrics = metrics;
    services.push_back(
        std::make_unique<IndexerService>(core.get(), ServiceOptions{}));
    auto started = tpr::common::StartServer(options, {services.back().get()});
    if (!started.ok()) std::abort();
    const std::string address = absl::StrCat("127.0.0.1:", started->port);
    std::shared_ptr<grpc::ChannelCredentials> credentials =
        grpc::InsecureChannelCredentials();
    if (config == 1) {
      grpc::SslCredentialsOptions ssl;
      std::ifstream in(dir + "/ca.pem");
      std::stringstream pem;
      pem << in.rdbuf();
      ssl.pem_root_certs = pem.str();
      credentials = grpc::SslCredentials(ssl);
    }
    stubs.push_back(
        tpr::v1::Indexer::NewStub(grpc::CreateChannel(address, credentials)));
    servers.push_back(std::move(*started));
  }
  const std::vector<tpr::v1::SearchRequest> queries = bench::KnnQueries();
  auto search = [&](int config, const tpr::v1::SearchRequest& q) {
    grpc::ClientContext context;
    if (config == 1) context.AddMetadata("authorization", "Bearer " + key);
    auto reader = stubs[static_cast<size_t>(config)]->Search(&context, q);
    tpr::v1::SearchResponse response;
    while (reader->Read(&response)) benchmark::DoNotOptimize(response);
    return reader->Finish().ok();
  };
  for (int config = 0; config < 3; ++config) {  // Connect and warm up.
    for (int i = 0; i < 20; ++i) {
      if (!search(config, queries[0])) {
        state.SkipWithError("warm-up search failed");
        return;
      }
    }
  }
  std::vector<double> us[3];
  std::vector<double> secure_added, metrics_added;
  size_t i = 0;
  for (auto _ : state) {
    const tpr::v1::SearchRequest& q = queries[i % queries.size()];
    double t[3];
    for (int k = 0; k < 3; ++k) {
      const int config = static_cast<int>((i + static_cast<size_t>(k)) % 3);
      const auto t0 = std::chrono::steady_clock::now();
      if (!search(config, q)) state.SkipWithError("search failed");
      t[config] = std::chrono::duration<double, std::micro>(
                      std::chrono::steady_clock::now() - t0)
                      .count();
      us[config].push_back(t[config]);
    }
    secure_added.push_back(t[1] - t[0]);
    metrics_added.push_back(t[2] - t[0]);
    ++i;
  }
  auto sum = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return s;
  };
  state.counters["plain_p50_us"] = Percentile(us[0], 0.5);
  state.counters["tls_key_p50_us"] = Percentile(us[1], 0.5);
  state.counters["metrics_p50_us"] = Percentile(us[2], 0.5);
  state.counters["tls_key_added_p50_us"] = Percentile(secure_added, 0.5);
  state.counters["metrics_added_p50_us"] = Percentile(metrics_added, 0.5);
  state.counters["metrics_overhead_pct"] =
      100.0 * (sum(us[2]) - sum(us[0])) / sum(us[0]);
  for (tpr::common::StartedServer& s : servers) {
    s.server->Shutdown(std::chrono::system_clock::now());
    s.server->Wait();
  }
}
BENCHMARK(BM_SecurityAndMetricsOverhead)
    ->Arg(10)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

}  // namespace
}  // namespace tpr::indexer

BENCHMARK_MAIN();
