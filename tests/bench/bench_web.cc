// What tpr-web adds to a search: the same 10-NN search over a served
// tpr-indexer, through gRPC directly and through tpr-web's HTTP/JSON API
// (an in-process WebServer in front of the same indexer, over loopback,
// one keep-alive connection), alternated query by query in one run, so the
// paired difference holds on a noisy machine.
//
//   BM_KnnHttpVsGrpc/N/0   by id: GET /api/v1/search?id=ID&k=10 against
//                          SearchRequest{id, k: 10}
//   BM_KnnHttpVsGrpc/N/1   by signature: POST /api/v1/search with the
//                          SearchRequest as JSON (30 features x 20 bands)
//                          against the same request in binary
// Counters: grpc_p50_us, http_p50_us, and added_p50_us / added_p90_us (the
// per-query HTTP minus gRPC time). docs/benchmarks.md has the figures.
#include <benchmark/benchmark.h>
#include <google/protobuf/util/json_util.h>

#include <chrono>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tests/bench/bench_indexer_setup.h"
#include "web/api.h"
#include "web/backends.h"
#include "web/recent_searches.h"
#include "web/web_server.h"
// After Eigen (bench_indexer_setup.h): httplib.h pulls in <resolv.h>.
#include <httplib.h>

namespace tpr {
namespace {

using bench::Percentile;

struct Served {
  std::unique_ptr<bench::ServedIndexer> indexer;
  std::unique_ptr<web::Backends> backends;
  web::RecentSearches searches;
  std::unique_ptr<web::WebServer> web;
  std::vector<v1::SearchRequest> by_signature;
  std::vector<std::string> signature_json;
};

Served* ServedWith(int n) {
  static std::map<int, std::unique_ptr<Served>>* cache =
      new std::map<int, std::unique_ptr<Served>>;
  auto& slot = (*cache)[n];
  if (slot) return slot.get();
  slot = std::make_unique<Served>();
  Served& s = *slot;
  s.indexer = bench::ServeIndexer(/*durable=*/false);
  bench::Fill(s.indexer->core.get(), bench::UpsertRequests(n, 7, "m"));
  web::BackendOptions backend_options;
  backend_options.extractor = s.indexer->address();  // Unused here.
  backend_options.indexer = s.indexer->address();
  absl::StatusOr<std::unique_ptr<web::Backends>> backends =
      web::Backends::Connect(backend_options);
  if (!backends.ok()) std::abort();
  s.backends = std::move(*backends);
  web::WebServerOptions options;
  options.listen = "127.0.0.1:0";
  options.log_requests = false;
  absl::StatusOr<std::unique_ptr<web::WebServer>> server =
      web::WebServer::Start(options,
                            web::ApiRoutes(s.backends.get(), &s.searches),
                            s.backends.get());
  if (!server.ok()) std::abort();
  s.web = std::move(*server);
  s.by_signature = bench::InClassQueries(n, 7);
  for (const v1::SearchRequest& q : s.by_signature) {
    std::string json;
    if (!google::protobuf::util::MessageToJsonString(q, &json).ok())
      std::abort();
    s.signature_json.push_back(std::move(json));
  }
  return &s;
}

void BM_KnnHttpVsGrpc(benchmark::State& state) {
  Served* s = ServedWith(static_cast<int>(state.range(0)));
  const bool by_signature = state.range(1) == 1;
  httplib::Client http("127.0.0.1", s->web->port());
  http.set_keep_alive(true);
  http.set_tcp_nodelay(true);  // As browsers do.
  std::vector<double> grpc_us, http_us, added_us;
  size_t i = 0;
  for (auto _ : state) {
    const size_t which = i++ % s->by_signature.size();
    v1::SearchRequest q;
    std::string path = "/api/v1/search";
    if (by_signature) {
      q = s->by_signature[which];
    } else {
      const std::string id = absl::StrCat("m", which * 97 % state.range(0));
      q.set_id(id);
      q.set_k(10);
      absl::StrAppend(&path, "?k=10&id=", id);
    }
    const auto t0 = std::chrono::steady_clock::now();
    grpc::ClientContext context;
    auto reader = s->indexer->stub->Search(&context, q);
    int64_t neighbours = 0;
    for (v1::SearchResponse r; reader->Read(&r);)
      neighbours += r.has_neighbor() ? 1 : 0;
    if (!reader->Finish().ok() || neighbours != 10)
      state.SkipWithError("gRPC search failed");
    const auto t1 = std::chrono::steady_clock::now();
    httplib::Result r = by_signature ? http.Post(path, s->signature_json[which],
                                                 "application/json")
                                     : http.Get(path);
    if (!r || r->status != 200) state.SkipWithError("HTTP search failed");
    benchmark::DoNotOptimize(r->body.data());
    const auto t2 = std::chrono::steady_clock::now();
    const double g = std::chrono::duration<double, std::micro>(t1 - t0).count();
    const double h = std::chrono::duration<double, std::micro>(t2 - t1).count();
    grpc_us.push_back(g);
    http_us.push_back(h);
    added_us.push_back(h - g);
  }
  state.counters["grpc_p50_us"] = Percentile(grpc_us, 0.5);
  state.counters["http_p50_us"] = Percentile(http_us, 0.5);
  state.counters["added_p50_us"] = Percentile(added_us, 0.5);
  state.counters["added_p90_us"] = Percentile(added_us, 0.9);
}
BENCHMARK(BM_KnnHttpVsGrpc)
    ->Args({1000, 0})
    ->Args({10000, 0})
    ->Args({10000, 1})
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();

}  // namespace
}  // namespace tpr

BENCHMARK_MAIN();
