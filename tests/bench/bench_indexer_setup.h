// Set-up shared by the served-indexer benchmarks (bench_service,
// bench_gateway): the same signatures, the same queries, scratch data
// directories removed at exit, a tpr-indexer served in process on a
// loopback port, a streamed ingest, percentiles.
//
//   std::unique_ptr<ServedIndexer> x = ServeIndexer({.durable = false});
//   Fill(x->core.get(), UpsertRequests(1000, 7, "m"));
//   for (const tpr::v1::SearchRequest& q : KnnQueries()) { ... x->stub->Search
//   ... }
#ifndef TPR_TESTS_BENCH_BENCH_INDEXER_SETUP_H_
#define TPR_TESTS_BENCH_BENCH_INDEXER_SETUP_H_

#include <benchmark/benchmark.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <stdlib.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/server_lifecycle.h"
#include "indexer/service/batch_writer.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/indexer_service.h"
#include "tests/indexer/signature_testing.h"
#include "tests/service/indexer_testing.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::bench {

// UpsertRequests returns n models "<prefix>0".."<prefix>n-1" with
// signatures of tests/indexer/signature_testing.h: 20 clustered classes
// (label "class<i mod 20>"), 30 features x 20 bands (the paper's average
// size). Deterministic in (n, seed).
inline std::vector<tpr::v1::UpsertRequest> UpsertRequests(
    int n, uint64_t seed, const std::string& prefix) {
  tpr::index::testing::SignatureGeneratorOptions o;
  o.seed = seed;
  o.classes = 20;
  tpr::index::testing::SignatureGenerator gen(o);
  std::vector<tpr::v1::UpsertRequest> out(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    tpr::v1::Model* m = out[static_cast<size_t>(i)].mutable_model();
    m->set_id(absl::StrCat(prefix, i));
    m->set_label(absl::StrCat("class", i % 20));
    *m->mutable_signature() = tpr::indexer::testing::ToWire(gen.Next());
  }
  return out;
}

// KnnQueries: the 64 query signatures every k-NN benchmark cycles through
// (seed 99, not stored), each a 10-NN search.
inline std::vector<tpr::v1::SearchRequest> KnnQueries() {
  std::vector<tpr::v1::SearchRequest> queries;
  for (tpr::v1::UpsertRequest& r : UpsertRequests(64, 99, "q")) {
    tpr::v1::SearchRequest q;
    *q.mutable_signature() = r.model().signature();
    q.set_k(10);
    queries.push_back(std::move(q));
  }
  return queries;
}

// InClassQueries: 64 10-NN queries drawn as the models of
// UpsertRequests(n, seed, ...) are (members of the same 20 classes, the
// draws that would follow model n-1) but not stored: the realistic case, a
// query shaped like a known kind of model. KnnQueries' signatures come from
// other prototypes (seed 99), far from every stored class, where the
// VP-tree prunes little: the worst case.
inline std::vector<tpr::v1::SearchRequest> InClassQueries(int n,
                                                          uint64_t seed) {
  tpr::index::testing::SignatureGeneratorOptions o;
  o.seed = seed;
  o.classes = 20;
  tpr::index::testing::SignatureGenerator gen(o);
  for (int i = 0; i < n; ++i) gen.Next();
  std::vector<tpr::v1::SearchRequest> queries(64);
  for (tpr::v1::SearchRequest& q : queries) {
    *q.mutable_signature() = tpr::indexer::testing::ToWire(gen.Next());
    q.set_k(10);
  }
  return queries;
}

// FreshDir makes a new directory under the system's temporary folder,
// removed when the process exits (set-ups cached for the whole run live
// until then). Aborts when it cannot.
inline std::string FreshDir(const std::string& tag) {
  static std::vector<std::string>* made = [] {
    static std::vector<std::string> dirs;
    std::atexit([] {
      for (const std::string& dir : dirs) {
        std::error_code ec;
        std::filesystem::remove_all(dir, ec);
      }
    });
    return &dirs;
  }();
  std::string pattern = (std::filesystem::temp_directory_path() /
                         ("tpr-bench-" + tag + ".XXXXXX"))
                            .string();
  if (mkdtemp(pattern.data()) == nullptr) std::abort();
  made->push_back(pattern);
  return pattern;
}

// Percentile returns the p-quantile (0..1, nearest rank below) of v; 0 for
// an empty v.
inline double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[static_cast<size_t>(p * static_cast<double>(v.size() - 1))];
}

// ServedIndexer: an IndexerCore on a fresh data directory and its
// IndexerService served on a loopback port, with a stub. Destroying it
// shuts the server down gracefully and removes the directory.
struct ServedIndexer {
  std::string dir;
  std::unique_ptr<tpr::indexer::IndexerCore> core;
  std::unique_ptr<tpr::indexer::IndexerService> service;
  tpr::common::ServerOptions server_options;
  tpr::common::StartedServer server;
  std::unique_ptr<tpr::v1::Indexer::Stub> stub;

  ~ServedIndexer() {
    stub.reset();
    if (server.server) tpr::common::ShutdownGracefully(server, server_options);
    server.server.reset();
    service.reset();
    core.reset();
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
  std::string address() const {
    return absl::StrCat("127.0.0.1:", server.port);
  }
};

// ServeIndexer starts a ServedIndexer: no background tree persistence,
// writes synced (durable group commits) when `durable`. Aborts on failure.
inline std::unique_ptr<ServedIndexer> ServeIndexer(bool durable) {
  auto x = std::make_unique<ServedIndexer>();
  x->dir = FreshDir("indexer");
  tpr::indexer::CoreOptions options;
  options.data_dir = x->dir;
  options.persist_interval_ms = 0;
  options.storage.sync_writes = durable;
  absl::StatusOr<std::unique_ptr<tpr::indexer::IndexerCore>> core =
      tpr::indexer::IndexerCore::Open(options);
  if (!core.ok()) std::abort();
  x->core = std::move(*core);
  x->service = std::make_unique<tpr::indexer::IndexerService>(
      x->core.get(), tpr::indexer::ServiceOptions{});
  x->server_options.shutdown_grace_ms = 1000;
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(x->server_options, {x->service.get()});
  if (!started.ok()) std::abort();
  x->server = std::move(*started);
  x->stub = tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(x->address(), grpc::InsecureChannelCredentials()));
  return x;
}

// Fill writes `requests` into `core` in process (one BatchWriter) and waits
// for the tree to settle. Set-up only: aborts on failure.
inline void Fill(tpr::indexer::IndexerCore* core,
                 std::vector<tpr::v1::UpsertRequest> requests) {
  tpr::indexer::BatchWriter batch(core);
  for (tpr::v1::UpsertRequest& r : requests) {
    if (!batch.Add(std::move(r)).ok()) std::abort();
  }
  if (!batch.Finish().ok()) std::abort();
  core->WaitForRebuild();
}

// Ingest streams `requests` through one BatchUpsert call on `stub`; marks
// the benchmark failed unless every model was written.
inline void Ingest(tpr::v1::Indexer::Stub* stub,
                   const std::vector<tpr::v1::UpsertRequest>& requests,
                   benchmark::State& state) {
  grpc::ClientContext context;
  tpr::v1::BatchUpsertResponse response;
  auto writer = stub->BatchUpsert(&context, &response);
  for (const tpr::v1::UpsertRequest& r : requests) writer->Write(r);
  writer->WritesDone();
  if (!writer->Finish().ok() ||
      response.written() != static_cast<int64_t>(requests.size())) {
    state.SkipWithError("ingest failed");
  }
}

}  // namespace tpr::bench

#endif  // TPR_TESTS_BENCH_BENCH_INDEXER_SETUP_H_
