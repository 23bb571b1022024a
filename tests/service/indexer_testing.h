// Helpers for the tpr-indexer tests: an in-process indexer (IndexerCore +
// IndexerService on a loopback port, restartable on the same data dir),
// wire conversion of generated signatures, a streaming search call, and the
// brute-force oracle: every EMD computed directly (indexer/lib/emd.h), sorted
// by (distance, id), independent of the VP-tree.
//
//   InProcessIndexer server(dir.path());
//   ASSERT_TRUE(server.Start().ok());
//   SearchResult r = RunSearch(server.stub(), request);
#ifndef TPR_TESTS_SERVICE_INDEXER_TESTING_H_
#define TPR_TESTS_SERVICE_INDEXER_TESTING_H_

#include <grpcpp/client_context.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/impl/codegen/client_unary_call.h>
#include <grpcpp/impl/codegen/rpc_method.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/sync_stream.h>

#include <algorithm>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/call_interceptor.h"
#include "common/grpc_status.h"
#include "common/server_lifecycle.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/intent.h"
#include "indexer/lib/metric.h"
#include "indexer/service/convert.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/indexer_service.h"
#include "tests/indexer/signature_testing.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::indexer::testing {

// ToWire returns `s` as the extractor would send it (the first half of the
// features points, the rest rings; the kind is not matched), through the
// indexer's own converter (indexer/service/convert.h).
inline tpr::v1::Signature ToWire(const tpr::index::Signature& s) {
  return ToWireSignature(s, static_cast<int>(s.features.size() + 1) / 2);
}

// A generated model: id, label and signature.
struct TestModel {
  std::string id;
  std::string label;
  tpr::index::Signature signature;
};

// Generates `n` models of `classes` classes (label "class<c>"), small
// signatures (12 features x 8 bands) so that tests stay quick.
inline std::vector<TestModel> MakeModels(int n, int classes, uint64_t seed,
                                         const std::string& prefix = "m",
                                         int spectrum = 0) {
  tpr::index::testing::SignatureGeneratorOptions options;
  options.spectrum = spectrum;
  options.seed = seed;
  options.features = 12;
  options.bands = 8;
  options.classes = classes;
  tpr::index::testing::SignatureGenerator gen(options);
  std::vector<TestModel> out;
  for (int i = 0; i < n; ++i) {
    const int c = i % classes;
    char id[64];
    std::snprintf(id, sizeof(id), "%s%05d", prefix.c_str(), i);
    out.push_back({id, absl::StrCat("class", c), gen.Member(c)});
  }
  return out;
}

inline tpr::v1::UpsertRequest ToRequest(const TestModel& m,
                                        bool overwrite = false) {
  tpr::v1::UpsertRequest r;
  r.mutable_model()->set_id(m.id);
  r.mutable_model()->set_label(m.label);
  (*r.mutable_model()->mutable_metadata())["source"] =
      absl::StrCat("gen/", m.id);
  *r.mutable_model()->mutable_signature() = ToWire(m.signature);
  r.set_overwrite(overwrite);
  return r;
}

// One expected or received neighbour.
struct Hit {
  std::string id;
  double distance = 0;
};

// WeightsOf returns the weighting `request` asks for, read from the
// library's IntentWeights (an oracle of the service's conversion): the
// ranking's weights when set, else its intent's (unset: balanced).
inline tpr::index::TermWeights WeightsOf(const tpr::v1::SearchRequest& r) {
  if (r.has_ranking()) {
    return {r.ranking().emd_weight(), r.ranking().spectral_weight(),
            r.ranking().heat_weight()};
  }
  switch (r.intent()) {
    case tpr::v1::INTENT_IDENTITY:
      return tpr::index::IntentWeights(tpr::index::Intent::kIdentity);
    case tpr::v1::INTENT_KIND:
      return tpr::index::IntentWeights(tpr::index::Intent::kKind);
    default:
      return tpr::index::IntentWeights(tpr::index::Intent::kBalanced);
  }
}

// BruteForce returns the exact ranking: d_w (default the EMD alone) to every
// model accepted by `label` (empty: all) and `exclude`, within `radius`
// (<= 0: all), sorted by (distance, id), first k.
inline std::vector<Hit> BruteForce(
    const tpr::index::Signature& query, const std::vector<TestModel>& models,
    int k, double radius = 0, const std::string& label = "",
    const std::string& exclude = "",
    const tpr::index::TermWeights& w = {1, 0, 0}) {
  const tpr::index::GroundDistanceOptions ground;
  const tpr::index::PreparedSignature q = *tpr::index::Prepare(query, ground);
  std::vector<Hit> hits;
  for (const TestModel& m : models) {
    if (!label.empty() && m.label != label) continue;
    if (m.id == exclude) continue;
    // Each weighed term in the order emd, spectral, heat, as the index sums.
    const tpr::index::PreparedSignature p =
        *tpr::index::Prepare(m.signature, ground);
    double d = 0.0;
    if (w.emd > 0.0) d += w.emd * tpr::index::Emd(q, p);
    if (w.spectral > 0.0) d += w.spectral * tpr::index::SpectralDistance(q, p);
    if (w.heat > 0.0) d += w.heat * tpr::index::HeatDistance(q, p);
    if (radius > 0 && d > radius) continue;
    hits.push_back({m.id, d});
  }
  std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.id < b.id;
  });
  if (hits.size() > static_cast<size_t>(k)) hits.resize(static_cast<size_t>(k));
  return hits;
}

// What a Search call returned.
struct SearchResult {
  grpc::Status status;
  std::vector<tpr::v1::Neighbor> neighbors;
  bool got_stats = false;
  tpr::v1::SearchStats stats;
};

// RunSearch runs one search to its end (60 s deadline). `progress` asks for
// each neighbour's cumulative statistics (tpr.v1.Neighbor.progress).
inline SearchResult RunSearch(tpr::v1::Indexer::Stub* stub,
                              const tpr::v1::SearchRequest& request,
                              bool progress = false) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(60));
  if (progress) context.AddMetadata(tpr::common::kSearchProgressHeader, "1");
  SearchResult result;
  auto reader = stub->Search(&context, request);
  tpr::v1::SearchResponse response;
  while (reader->Read(&response)) {
    if (response.has_neighbor())
      result.neighbors.push_back(response.neighbor());
    if (response.has_stats()) {
      result.got_stats = true;
      result.stats = response.stats();
    }
  }
  result.status = reader->Finish();
  return result;
}

// ReflectedServices asks the v1alpha reflection service for the server's
// service list with raw bytes (no generated reflection client in Debian's
// gRPC): the request sets list_services (field 7, string) to "", i.e. bytes
// 0x3a 0x00. Returns the answer's bytes, in which the service names appear
// verbatim.
inline absl::StatusOr<std::string> ReflectedServices(
    const std::shared_ptr<grpc::Channel>& channel) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(10));
  const grpc::internal::RpcMethod method(
      "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
      grpc::internal::RpcMethod::BIDI_STREAMING);
  std::unique_ptr<grpc::ClientReaderWriter<grpc::ByteBuffer, grpc::ByteBuffer>>
      stream(grpc::internal::ClientReaderWriterFactory<
             grpc::ByteBuffer, grpc::ByteBuffer>::Create(channel.get(), method,
                                                         &context));
  const char request_bytes[] = {0x3a, 0x00};
  grpc::Slice slice(request_bytes, sizeof(request_bytes));
  grpc::ByteBuffer request(&slice, 1);
  stream->Write(request);
  stream->WritesDone();
  std::string bytes;
  grpc::ByteBuffer response;
  while (stream->Read(&response)) {
    std::vector<grpc::Slice> slices;
    if (!response.Dump(&slices).ok())
      return absl::InternalError("cannot read the answer");
    for (const grpc::Slice& s : slices) {
      bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
    }
  }
  grpc::Status status = stream->Finish();
  if (!status.ok()) return tpr::common::FromGrpcStatus(status);
  return bytes;
}

// An IndexerCore and IndexerService served on a free loopback port. Stop()
// shuts the server down and closes the core (persisting the tree); Start()
// again reopens the same data directory.
class InProcessIndexer {
 public:
  explicit InProcessIndexer(std::string data_dir, CoreOptions core = {})
      : core_options_(std::move(core)) {
    core_options_.data_dir = std::move(data_dir);
  }
  ~InProcessIndexer() { Stop(); }

  absl::Status Start(ServiceOptions service_options = {}) {
    absl::StatusOr<std::unique_ptr<IndexerCore>> core =
        IndexerCore::Open(core_options_);
    if (!core.ok()) return core.status();
    core_ = std::move(*core);
    service_ = std::make_unique<IndexerService>(core_.get(), service_options);
    server_options_.shutdown_grace_ms = 2000;
    // Readiness as in indexer/service/main.cc, polled faster for tests.
    server_options_.readiness_service = "tpr.v1.Indexer";
    server_options_.readiness_check = [c = core_.get()] {
      return c->WriteReadiness();
    };
    server_options_.readiness_poll_ms = 100;
    absl::StatusOr<tpr::common::StartedServer> started =
        tpr::common::StartServer(server_options_, {service_.get()});
    if (!started.ok()) return started.status();
    readiness_ = std::move(started->readiness);
    server_ = std::move(started->server);
    port_ = started->port;
    channel_ = grpc::CreateChannel(absl::StrCat("127.0.0.1:", port_),
                                   grpc::InsecureChannelCredentials());
    stub_ = tpr::v1::Indexer::NewStub(channel_);
    return absl::OkStatus();
  }

  void Stop() {
    readiness_.reset();  // before the server it watches
    if (server_) tpr::common::ShutdownGracefully(*server_, server_options_);
    stub_.reset();
    channel_.reset();
    server_.reset();
    service_.reset();
    core_.reset();  // Close(): persists the tree
  }

  tpr::v1::Indexer::Stub* stub() { return stub_.get(); }
  std::shared_ptr<grpc::Channel> channel() { return channel_; }
  std::string address() const { return absl::StrCat("127.0.0.1:", port_); }
  IndexerCore* core() { return core_.get(); }
  IndexerService* service() { return service_.get(); }
  CoreOptions& core_options() { return core_options_; }

 private:
  CoreOptions core_options_;
  tpr::common::ServerOptions server_options_;
  std::unique_ptr<IndexerCore> core_;
  std::unique_ptr<IndexerService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<tpr::common::ReadinessMonitor> readiness_;
  int port_ = 0;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<tpr::v1::Indexer::Stub> stub_;
};

// ExpectSameRanking compares a received ranking with the oracle's: same ids
// in the same order, distances equal to rounding, ranks 1..n.
#define TPR_EXPECT_SAME_RANKING(received, expected)           \
  do {                                                        \
    const auto& r_ = (received);                              \
    const auto& e_ = (expected);                              \
    ASSERT_EQ(r_.size(), e_.size());                          \
    for (size_t i_ = 0; i_ < e_.size(); ++i_) {               \
      EXPECT_EQ(r_[i_].id(), e_[i_].id) << "rank " << i_ + 1; \
      EXPECT_NEAR(r_[i_].distance(), e_[i_].distance, 1e-9)   \
          << "rank " << i_ + 1;                               \
      EXPECT_EQ(r_[i_].rank(), static_cast<int>(i_ + 1));     \
    }                                                         \
  } while (false)

}  // namespace tpr::indexer::testing

#endif  // TPR_TESTS_SERVICE_INDEXER_TESTING_H_
