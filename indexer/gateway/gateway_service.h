// GatewayService: tpr-gateway's tpr.v1.Indexer service. Stateless: it holds
// no models, only the shard map (shard_map.h) and a gRPC channel per shard
// address, and serves the unchanged Indexer API over S indexer shards:
//
//   client ──> tpr-gateway ──> shard 0 (primary, replicas...)
//                          ──> shard 1 ...
//
// Routing:
// - Upsert, Get, GetThumbnail, GetPreview and Delete go to the owning
//   shard, ShardOf(id, S). Writes go to its primary; reads to any serving
//   address of the shard. GetPreview reads the shard's whole stream (at
//   most a preview's 2 MiB) before relaying it, so that a failover to
//   another address never sends a chunk twice.
// - BatchUpsert splits the stream by shard (one BatchUpsert stream per shard
//   primary) and answers OK only when every shard acknowledged its part; the
//   counts are the sums. On an error the call fails naming the shard; what
//   other shards acknowledged is durable, as are the failing shard's models
//   before its failing one.
// - List merges the shards' pages in id order; the page token carries every
//   shard's position (EncodeListToken). A page ends before 2 MiB of models,
//   as one indexer's.
// - Stats sums the shards and lists each (StatsResponse.shards: counts and
//   sizes; the labels only in the sums, the 1000 most populous as one
//   indexer reports them).
// - Search is exact k-NN: every shard gets the full k, radius and label
//   filter; the shards' ascending streams are merged lazily in (distance, id)
//   order, as one indexer orders them (RanksBefore), ranks renumbered; once k
//   neighbours are sent the remaining shard streams are cancelled. A search by
//   id reads the signature from the owning shard and sends it to all;
//   exclude_self drops the id at the gateway (the owner is asked for k + 1).
//   Statistics are the sums over the shards whose streams ran to their end
//   (a stream cancelled early reports nothing); milliseconds is the
//   gateway's own time for the whole search.
//
// Failures: a shard none of whose addresses serves fails the call with
// UNAVAILABLE naming the shard and every address tried; the gateway never
// answers from fewer shards. Reads fail over to the shard's next serving
// address on UNAVAILABLE (a search only before that shard sent anything);
// writes are never retried. Errors the caller caused (INVALID_ARGUMENT,
// NOT_FOUND, ALREADY_EXISTS, RESOURCE_EXHAUSTED) pass through unchanged;
// other shard errors are prefixed with the shard. Each shard call is made
// with grpc::ClientContext::FromServerContext, so the caller's deadline and
// cancellation propagate to the shards, and carries the call's request id
// (x-request-id, common/call_interceptor.h) into the shards' logs.
//
// Security and observation: the shard channels use the
// credentials in GatewayOptions (TLS, optionally a client certificate for
// shards that demand mutual TLS) and send shard_api_key as `authorization:
// Bearer` with every call; every shard call ends in on_shard_call (latency
// and code per shard; ShardCallMetrics turns it into Prometheus families).
//
// Health: a background thread asks every address's grpc.health.v1 service
// for the readiness of "tpr.v1.Indexer" (common/health.h) every
// health_interval_ms; a read goes only to addresses whose last answer
// was SERVING (a call failing with UNAVAILABLE marks its address down until
// the next check), or, when none is, to the primary as a last try. Primaries
// start as serving, replicas as not serving until their first check (a
// follower that has not caught up reports NOT_SERVING, and is never read
// from until it reports SERVING).
#ifndef TPR_INDEXER_GATEWAY_GATEWAY_SERVICE_H_
#define TPR_INDEXER_GATEWAY_GATEWAY_SERVICE_H_

#include <grpcpp/channel.h>
#include <grpcpp/security/credentials.h>

#include <atomic>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/status.h"
#include "indexer/gateway/shard_map.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::common {
class Metrics;
}  // namespace tpr::common

namespace tpr::gateway {

// ShardCall: one finished call of the gateway to a shard address.
struct ShardCall {
  int shard = 0;
  // Full method name, e.g. "/tpr.v1.Indexer/Search" (health checks
  // "/grpc.health.v1.Health/Check").
  std::string method;
  grpc::StatusCode code = grpc::StatusCode::OK;
  // From the call's creation to its status, in seconds.
  double seconds = 0;
};

// GatewayOptions: the shard map and how the gateway talks to the shards.
struct GatewayOptions {
  // The shards, in shard order. Required: at least one.
  ShardMap shards;
  // How often every shard address is health-checked, in milliseconds; 0
  // disables the checker (addresses then stay as they start, marked down
  // only by failing calls). Default 1000.
  int health_interval_ms = 1000;
  // Deadline of one health check, in milliseconds. Default 500.
  int health_timeout_ms = 500;
  // Largest message sent to or received from a shard, in bytes. Default
  // 64 MiB (as tpr-indexer's server limits).
  int max_message_bytes = 64 << 20;
  // Receives one line per notable event (an address going up or down, a
  // failed call that is not the caller's fault). Default: none.
  std::function<void(const std::string&)> log;
  // Credentials of the shard channels: TLS (tpr::client::MakeChannelCredentials
  // builds them from the --shard-tls* flags); nullptr: plaintext. Default
  // nullptr.
  std::shared_ptr<grpc::ChannelCredentials> shard_credentials;
  // Name the shards' certificates carry when it differs from the host in
  // their addresses. Default empty (the address's host).
  std::string shard_tls_server_name;
  // API key sent to the shards with every call (`authorization: Bearer`);
  // needs role write for writes. Empty: none. Default empty.
  std::string shard_api_key;
  // Called when each call to a shard ends (health checks included), on the
  // thread that ends it; must be thread-safe and quick. Default none.
  std::function<void(const ShardCall&)> on_shard_call;
  // Where reads (Get, List, Stats, Search) go: false, any serving copy of
  // the shard (a follower may not yet have applied the latest acknowledged
  // write: it tails the primary's log asynchronously); true, the primary
  // only (every acknowledged write is seen; the replicas serve no reads and
  // a stopped primary fails reads too). tpr-gateway --reads=primary|any.
  // Default false (any).
  bool reads_from_primary = false;
};

// ShardCallMetrics returns an on_shard_call that records into `metrics`
// (which must outlive every call):
//   tpr_gateway_shard_duration_seconds{shard,method}   histogram
//   tpr_gateway_shard_errors_total{shard,method,code}  counter
// Calls that end CANCELLED are neither timed nor errors: the gateway
// cancels the shard streams a search no longer needs, and a caller's own
// cancellation is not a shard's fault. Labels are bounded by the shard map
// (shard index) and the API (method, code). Thread-safe.
std::function<void(const ShardCall&)> ShardCallMetrics(
    tpr::common::Metrics& metrics);

// Shards: the channels to every shard address and their health. Thread-safe.
class Shards {
 public:
  // One address of a shard.
  struct Endpoint {
    int shard = 0;
    std::string address;
    bool primary = false;
    std::shared_ptr<grpc::Channel> channel;
    std::unique_ptr<tpr::v1::Indexer::Stub> stub;
    // Last health verdict (or a failed call's).
    std::atomic<bool> serving{false};
  };

  // Creates the channels (connections are made lazily) and starts the
  // health checker. Precondition: options.shards has at least one shard.
  explicit Shards(const GatewayOptions& options);
  // Stops the health checker.
  ~Shards();
  Shards(const Shards&) = delete;
  Shards& operator=(const Shards&) = delete;

  int count() const { return static_cast<int>(primaries_.size()); }
  // primary returns the endpoint of shard `shard`'s primary.
  Endpoint& primary(int shard) {
    return *primaries_[static_cast<size_t>(shard)];
  }
  // ReadOrder returns the serving addresses of `shard`, rotated round-robin
  // so that reads spread over them; when none serves, the primary alone
  // (tried anyway: it may be back before its next check). With
  // reads_from_primary, the primary alone, always.
  std::vector<Endpoint*> ReadOrder(int shard);
  // MarkDown records that `endpoint` failed a call (until its next health
  // check says otherwise).
  void MarkDown(Endpoint* endpoint, const std::string& reason);
  // CheckNow health-checks every address once, now (tests use it to see a
  // stopped process without waiting for the interval).
  void CheckNow();

 private:
  void Check(Endpoint* endpoint);
  void Loop();
  void Log(const std::string& line) const;

  const GatewayOptions options_;
  std::vector<std::unique_ptr<Endpoint>> endpoints_;
  std::vector<Endpoint*> primaries_;
  std::vector<std::vector<Endpoint*>> by_shard_;
  std::atomic<uint64_t> round_robin_{0};
  std::mutex mu_;
  std::condition_variable wake_;
  bool stop_ = false;
  std::thread checker_;
};

// GatewayService: see the file comment. Thread-safe.
class GatewayService final : public tpr::v1::Indexer::Service {
 public:
  // Precondition: options.shards has at least one shard (main.cc checks).
  explicit GatewayService(GatewayOptions options);

  grpc::Status Upsert(grpc::ServerContext* context,
                      const tpr::v1::UpsertRequest* request,
                      tpr::v1::UpsertResponse* response) override;
  // BatchUpsert reads its stream as raw bytes (common/stream_messages.h;
  // installed by the constructor in place of the generated handler): a
  // message that does not parse fails the call with INVALID_ARGUMENT after
  // the shards' streams for the models before it are finished.
  grpc::Status BatchUpsertRaw(grpc::ServerContext* context,
                              grpc::ServerReader<grpc::ByteBuffer>* reader,
                              tpr::v1::BatchUpsertResponse* response);
  grpc::Status Delete(grpc::ServerContext* context,
                      const tpr::v1::DeleteRequest* request,
                      tpr::v1::DeleteResponse* response) override;
  grpc::Status Get(grpc::ServerContext* context,
                   const tpr::v1::GetRequest* request,
                   tpr::v1::Model* response) override;
  grpc::Status List(grpc::ServerContext* context,
                    const tpr::v1::ListRequest* request,
                    tpr::v1::ListResponse* response) override;
  grpc::Status Stats(grpc::ServerContext* context,
                     const tpr::v1::StatsRequest* request,
                     tpr::v1::StatsResponse* response) override;
  grpc::Status Search(
      grpc::ServerContext* context, const tpr::v1::SearchRequest* request,
      grpc::ServerWriter<tpr::v1::SearchResponse>* writer) override;
  grpc::Status GetThumbnail(grpc::ServerContext* context,
                            const tpr::v1::GetThumbnailRequest* request,
                            tpr::v1::Thumbnail* response) override;
  grpc::Status GetPreview(
      grpc::ServerContext* context, const tpr::v1::GetPreviewRequest* request,
      grpc::ServerWriter<tpr::v1::PreviewChunk>* writer) override;

  // shards gives tests access to the health state (CheckNow).
  Shards& shards() { return shards_; }

 private:
  // Runs `call` against the serving addresses of `shard` in turn until one
  // answers with something other than UNAVAILABLE. Returns UNAVAILABLE
  // naming the shard when none does, else the call's status.
  absl::Status Read(grpc::ServerContext* context, int shard,
                    const std::function<grpc::Status(
                        Shards::Endpoint&, grpc::ClientContext*)>& call);
  // Maps a shard's failure to the gateway's answer (see the file comment).
  absl::Status FromShard(int shard, const std::string& address,
                         const grpc::Status& status) const;
  grpc::Status Finish(const char* method, const absl::Status& status) const;

  const GatewayOptions options_;
  Shards shards_;
};

}  // namespace tpr::gateway

#endif  // TPR_INDEXER_GATEWAY_GATEWAY_SERVICE_H_
