// The TPR Search C++ SDK: typed calls to tpr-extractor (mesh -> signature)
// and tpr-indexer (store signatures, k-NN search under EMD), with
// absl::Status errors, per-call deadlines, retries with exponential backoff
// on UNAVAILABLE for idempotent calls, a streaming k-NN iterator that can be
// stopped early, and channels over several addresses or a dns:/// name with
// round-robin load balancing. Messages are the tpr.v1 protobuf types.
//
//   auto extractor = tpr::client::ExtractorClient::Connect(
//       "127.0.0.1:7001,127.0.0.1:7011");
//   auto indexer = tpr::client::IndexerClient::Connect("127.0.0.1:7002");
//   absl::StatusOr<tpr::v1::ExtractResponse> r =
//       extractor->ExtractFile("dog.off");
//   tpr::v1::Model model;
//   model.set_id("dog.off");
//   *model.mutable_signature() = r->signature();
//   absl::Status s = indexer->Upsert(model, /*overwrite=*/true).status();
//   tpr::v1::SearchRequest q;  q.set_id("dog.off");  q.set_k(5);
//   std::unique_ptr<tpr::client::SearchStream> stream = indexer->Search(q);
//   for (tpr::v1::Neighbor n; stream->Next(&n);) {
//     Print(n.rank(), n.id(), n.distance());
//   }
//   absl::Status done = stream->Finish();   // OK, or why the stream broke
//
// Thread-safety: ExtractorClient and IndexerClient are thread-safe and cheap
// to copy (they share one channel). SearchStream and BatchUpsertWriter
// objects belong to one thread at a time.
#ifndef TPR_CLIENT_CLIENT_H_
#define TPR_CLIENT_CLIENT_H_

#include <grpcpp/channel.h>
#include <grpcpp/client_context.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/time/time.h"
#include "tpr/connection.h"
#include "tpr/v1/extractor.grpc.pb.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::client {

// CallOptions: deadline and retry policy of one call.
struct CallOptions {
  // Deadline for the whole call, retries included, measured from the call's
  // start. Default 60 s. absl::InfiniteDuration() for none.
  absl::Duration timeout = absl::Seconds(60);
  // Attempts for idempotent calls that fail with UNAVAILABLE (extract, get,
  // list, search before its first result, stats, upsert with overwrite);
  // 1 disables retries. Other calls and other codes are never retried.
  // Default 4.
  int max_attempts = 4;
  // Wait before the second attempt; each later wait is multiplied by
  // backoff_multiplier up to max_backoff, with +-20% jitter so that clients
  // do not retry in lockstep. Defaults 100 ms, 2.0, 2 s.
  absl::Duration initial_backoff = absl::Milliseconds(100);
  double backoff_multiplier = 2.0;
  absl::Duration max_backoff = absl::Seconds(2);
};

// ExtractorClient calls tpr.v1.Extractor.
class ExtractorClient {
 public:
  // Uses `channel` (see MakeChannel); `defaults` apply to calls that pass no
  // CallOptions.
  explicit ExtractorClient(std::shared_ptr<grpc::Channel> channel,
                           CallOptions defaults = {});

  // Connect returns a client over MakeChannel(addresses).
  static absl::StatusOr<ExtractorClient> Connect(absl::string_view addresses,
                                                 CallOptions defaults = {});
  // Connect over MakeChannel(addresses, connection): TLS and API key.
  static absl::StatusOr<ExtractorClient> Connect(
      absl::string_view addresses, const ConnectionOptions& connection,
      CallOptions defaults = {});

  // ExtractFile uploads the mesh file at `path` as ExtractBytes does (file
  // name: its base name), reading it kChunkBytes at a time as it streams, so
  // that memory stays at one chunk whatever the file's size (a retry reads
  // the file again). NOT_FOUND when the file cannot be opened, DATA_LOSS
  // when reading it fails midway (the call is cancelled); otherwise as
  // ExtractBytes. Cost: one read of the file plus the call.
  absl::StatusOr<v1::ExtractResponse> ExtractFile(
      const std::string& path, const v1::ExtractOptions& options = {},
      const CallOptions* call = nullptr) const;

  // ExtractBytes uploads `bytes` in kChunkBytes messages (the first carries
  // format, file_name and options) and returns the server's response.
  // Errors: the server's code and message (INVALID_ARGUMENT for a malformed
  // mesh, RESOURCE_EXHAUSTED above its limits or when it is busy,
  // DEADLINE_EXCEEDED, UNAVAILABLE after max_attempts). Retried on
  // UNAVAILABLE (extraction is a pure function of bytes and options).
  absl::StatusOr<v1::ExtractResponse> ExtractBytes(
      absl::string_view bytes, absl::string_view file_name,
      const v1::ExtractOptions& options = {},
      v1::MeshFormat format = v1::MESH_FORMAT_UNSPECIFIED,
      const CallOptions* call = nullptr) const;

  // ExtractFile and ExtractBytes asking for pictures too
  // (ExtractRequest.media): the response's `media` then holds those
  // `media` asks for. Errors as above.
  absl::StatusOr<v1::ExtractResponse> ExtractFile(
      const std::string& path, const v1::ExtractOptions& options,
      const v1::MediaOptions& media, const CallOptions* call = nullptr) const;
  absl::StatusOr<v1::ExtractResponse> ExtractBytes(
      absl::string_view bytes, absl::string_view file_name,
      const v1::ExtractOptions& options, const v1::MediaOptions& media,
      v1::MeshFormat format = v1::MESH_FORMAT_UNSPECIFIED,
      const CallOptions* call = nullptr) const;

 private:
  std::shared_ptr<grpc::Channel> channel_;
  std::shared_ptr<v1::Extractor::Stub> stub_;
  CallOptions defaults_;
};

// SearchStream iterates over the neighbours of one k-NN search as the server
// streams them, in ascending distance. Destroying it (or calling Cancel)
// before the end cancels the RPC, which stops the server's search.
class SearchStream {
 public:
  virtual ~SearchStream() = default;
  // Next stores the next neighbour in `*neighbor` and returns true, or
  // returns false at the end of the stream or on error (see Finish). Blocks
  // until the server sends the neighbour.
  virtual bool Next(v1::Neighbor* neighbor) = 0;
  // Cancel stops the search early; later Next calls return false and
  // Finish returns OK (a cancel asked for by the caller is not an error).
  virtual void Cancel() = 0;
  // Finish returns how the stream ended: OK after the last neighbour (or a
  // Cancel), otherwise the server's error (INVALID_ARGUMENT for k < 1 or a
  // negative radius, NOT_FOUND for an unknown query id, DEADLINE_EXCEEDED,
  // UNAVAILABLE). Drains and discards unread neighbours first.
  virtual absl::Status Finish() = 0;
  // Stats returns the server's search statistics once the stream ended
  // normally, else nullptr.
  virtual const v1::SearchStats* Stats() const = 0;
};

// BatchUpsertWriter streams models to one BatchUpsert call.
class BatchUpsertWriter {
 public:
  virtual ~BatchUpsertWriter() = default;
  // Write sends one model. Returns false when the stream is broken (the
  // server failed the call); Finish then says why. Blocks under flow control.
  virtual bool Write(const v1::Model& model, bool overwrite) = 0;
  // Finish closes the stream and returns the server's counts, or its error
  // (models before the failing one are kept). Call exactly once.
  virtual absl::StatusOr<v1::BatchUpsertResponse> Finish() = 0;
};

// IndexerClient calls tpr.v1.Indexer: one tpr-indexer, or a tpr-gateway in
// front of a sharded index (same API). Several addresses in one Connect are
// REPLICAS OF ONE INDEX: calls go to any of them in turn, so each must hold
// the same models. Never list independent indexers (or shards) here: every
// search would see only part of the data. Sharding is the gateway's job:
// connect to the gateway (or several gateways of one shard map), which
// routes ids to shards and merges their answers exactly. When the addresses
// are a primary and its followers (tpr-indexer --follow), writes that reach
// a follower fail with FAILED_PRECONDITION naming the primary, and reads
// may lag the primary by the replication delay: write through the gateway
// (writes to primaries, reads to any ready copy) or list only the primary.
class IndexerClient {
 public:
  explicit IndexerClient(std::shared_ptr<grpc::Channel> channel,
                         CallOptions defaults = {});
  static absl::StatusOr<IndexerClient> Connect(absl::string_view addresses,
                                               CallOptions defaults = {});
  // Connect over MakeChannel(addresses, connection): TLS and API key.
  static absl::StatusOr<IndexerClient> Connect(
      absl::string_view addresses, const ConnectionOptions& connection,
      CallOptions defaults = {});

  // Upsert stores `model`; returns true when the id was new. ALREADY_EXISTS
  // when the id exists and !overwrite; INVALID_ARGUMENT for a bad id or
  // signature. Retried on UNAVAILABLE only when overwrite (then repeating it
  // is harmless).
  absl::StatusOr<bool> Upsert(const v1::Model& model, bool overwrite,
                              const CallOptions* call = nullptr) const;

  // BatchUpsert starts a streaming batch upsert under one deadline. Never
  // retried (the stream is not replayable).
  std::unique_ptr<BatchUpsertWriter> BatchUpsert(
      const CallOptions* call = nullptr) const;

  // Delete removes `id`. NOT_FOUND when unknown. Not retried (a retry after
  // a lost reply would report NOT_FOUND for a delete that happened).
  absl::Status Delete(const std::string& id,
                      const CallOptions* call = nullptr) const;

  // Get returns the model `id` with its signature. NOT_FOUND when unknown.
  absl::StatusOr<v1::Model> Get(const std::string& id,
                                const CallOptions* call = nullptr) const;

  // GetThumbnail returns model `id`'s thumbnail PNG. NOT_FOUND when the id
  // is unknown or the model has no media (the message says which).
  // Retried on UNAVAILABLE.
  absl::StatusOr<std::string> GetThumbnail(
      const std::string& id, const CallOptions* call = nullptr) const;

  // GetPreview returns model `id`'s preview PLY, the chunks of the stream
  // joined. NOT_FOUND as GetThumbnail; DATA_LOSS when the bytes received
  // differ from the size the server announced. Retried on UNAVAILABLE
  // (from the start). Memory: the whole file (a few hundred KB at most).
  absl::StatusOr<std::string> GetPreview(
      const std::string& id, const CallOptions* call = nullptr) const;

  // List returns one page (see ListRequest). Retried on UNAVAILABLE.
  absl::StatusOr<v1::ListResponse> List(
      const v1::ListRequest& request, const CallOptions* call = nullptr) const;

  // ListAll pages through every model (with `label` if non-empty) and
  // returns them in id order, without signatures. Cost: one call per 1000.
  absl::StatusOr<std::vector<v1::Model>> ListAll(
      const std::string& label = "", const CallOptions* call = nullptr) const;

  // Search starts a k-NN search (see SearchRequest) and returns its stream.
  // Retried on UNAVAILABLE while no neighbour has been delivered yet. Errors
  // arrive through SearchStream::Finish.
  std::unique_ptr<SearchStream> Search(const v1::SearchRequest& request,
                                       const CallOptions* call = nullptr) const;

  // Stats returns the server's counts and sizes.
  absl::StatusOr<v1::StatsResponse> Stats(
      const CallOptions* call = nullptr) const;

 private:
  std::shared_ptr<grpc::Channel> channel_;
  std::shared_ptr<v1::Indexer::Stub> stub_;
  CallOptions defaults_;
};

}  // namespace tpr::client

#endif  // TPR_CLIENT_CLIENT_H_
