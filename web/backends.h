// Backends: tpr-web's gRPC side. One channel to tpr-extractor and one to
// tpr-indexer (or tpr-gateway, same API), each call made with the HTTP
// request's id (`x-request-id`), its API key and a deadline; every failure
// comes back as the service's own code and message (absl::Status with the
// gRPC code), so the HTTP layer reports exactly what the service said.
//
//   BackendOptions options;  options.extractor = "127.0.0.1:7001";
//   options.indexer = "127.0.0.1:7002";
//   absl::StatusOr<std::unique_ptr<Backends>> backends =
//       Backends::Connect(options);
//   CallMeta meta{"4f2c9a...", "Bearer tpr_..."};
//   absl::StatusOr<v1::Model> model = (*backends)->Get("dog.off", meta);
#ifndef TPR_WEB_BACKENDS_H_
#define TPR_WEB_BACKENDS_H_

#include <grpcpp/channel.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "tpr/connection.h"
#include "tpr/v1/extractor.grpc.pb.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::web {

// BackendOptions: where the services are and how to reach them.
struct BackendOptions {
  // tpr-extractor address(es), HOST:PORT[,HOST:PORT] (tpr's --extractor).
  // Default 127.0.0.1:7001.
  std::string extractor = "127.0.0.1:7001";
  // tpr-indexer or tpr-gateway address(es) (tpr's --indexer). Default
  // 127.0.0.1:7002.
  std::string indexer = "127.0.0.1:7002";
  // TLS towards both services; api_key is tpr-web's own key. When api_key
  // is empty, each call carries the HTTP caller's own Authorization header
  // instead, so the services check the caller's role. Default: plaintext,
  // no key.
  client::ConnectionOptions connection;
  // Deadline of one call, in seconds. Default 60.
  double timeout_s = 60;
};

// CallMeta: what one HTTP request hands to the calls it makes.
struct CallMeta {
  // Request id sent as `x-request-id` (empty: none).
  std::string request_id;
  // The caller's Authorization header value ("Bearer tpr_..."), forwarded
  // when BackendOptions.connection.api_key is empty. Empty: none.
  std::string authorization;
};

// SearchResult: one finished search.
struct SearchResult {
  std::vector<v1::Neighbor> neighbors;  // Ascending distance.
  v1::SearchStats stats;                // The indexer's final statistics.
};

// Backends: the two services' stubs. Thread-safe; every method blocks for
// one call (at most the deadline).
class Backends {
 public:
  // Connect makes both channels (lazily connected). INVALID_ARGUMENT for a
  // malformed address list, NOT_FOUND / INVALID_ARGUMENT for TLS files (as
  // client::MakeChannel), naming --extractor or --indexer.
  static absl::StatusOr<std::unique_ptr<Backends>> Connect(
      const BackendOptions& options);

  // Extract uploads `bytes` (1 MiB messages) and returns the extractor's
  // answer. Errors: the extractor's (INVALID_ARGUMENT naming the element
  // at fault, RESOURCE_EXHAUSTED, UNAVAILABLE when it is down, ...).
  absl::StatusOr<v1::ExtractResponse> Extract(absl::string_view bytes,
                                              const std::string& file_name,
                                              v1::MeshFormat format,
                                              const v1::ExtractOptions& options,
                                              const v1::MediaOptions& media,
                                              const CallMeta& meta) const;

  // Search runs `request` to its end. Errors: the indexer's.
  absl::StatusOr<SearchResult> Search(const v1::SearchRequest& request,
                                      const CallMeta& meta) const;

  // Get, List, Stats, Upsert (returns created), Delete: one unary call each.
  absl::StatusOr<v1::Model> Get(const std::string& id,
                                const CallMeta& meta) const;
  absl::StatusOr<v1::ListResponse> List(const v1::ListRequest& request,
                                        const CallMeta& meta) const;
  absl::StatusOr<v1::StatsResponse> Stats(const CallMeta& meta) const;
  absl::StatusOr<bool> Upsert(const v1::Model& model, bool overwrite,
                              const CallMeta& meta) const;
  absl::Status Delete(const std::string& id, const CallMeta& meta) const;

  // Thumbnail returns the PNG bytes of `id`, Preview the PLY bytes (the
  // chunks of GetPreview joined). NOT_FOUND for an unknown id or a model
  // without media.
  absl::StatusOr<std::string> Thumbnail(const std::string& id,
                                        const CallMeta& meta) const;
  absl::StatusOr<std::string> Preview(const std::string& id,
                                      const CallMeta& meta) const;

  // ExtractorReadiness and IndexerReadiness ask the service's health
  // service whether it is ready (grpc.health.v1, service "tpr.v1.Extractor"
  // / "tpr.v1.Indexer", 2 s deadline): "" when SERVING, else the reason
  // ("not serving", "unreachable: ..."). Never need a key.
  std::string ExtractorReadiness() const;
  std::string IndexerReadiness() const;

  const BackendOptions& options() const { return options_; }

 private:
  Backends(BackendOptions options, std::shared_ptr<grpc::Channel> extractor,
           std::shared_ptr<grpc::Channel> indexer);
  void Prepare(grpc::ClientContext* context, const CallMeta& meta) const;
  // CallIndexer makes the unary Indexer call `rpc` with `meta` and returns
  // its response, or the call's status with `method` named when the
  // service sent no message.
  template <typename Request, typename Response>
  absl::StatusOr<Response> CallIndexer(
      grpc::Status (v1::Indexer::Stub::*rpc)(grpc::ClientContext*,
                                             const Request&, Response*),
      const Request& request, const char* method, const CallMeta& meta) const;

  BackendOptions options_;
  std::string authorization_;  // "Bearer <own key>", or "" to forward.
  std::shared_ptr<grpc::Channel> extractor_channel_;
  std::shared_ptr<grpc::Channel> indexer_channel_;
  std::unique_ptr<v1::Extractor::Stub> extractor_;
  std::unique_ptr<v1::Indexer::Stub> indexer_;
};

}  // namespace tpr::web

#endif  // TPR_WEB_BACKENDS_H_
