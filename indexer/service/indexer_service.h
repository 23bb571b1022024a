// IndexerService: the tpr.v1.Indexer gRPC service (indexer.proto), a thin
// shell over IndexerCore. Each handler checks the call's cancellation and
// deadline, hands the request to the core and maps its absl::Status with
// tpr::common::ToGrpcStatus (common/grpc_status.h); no logic lives here. A
// call from tpr-gateway names the shard's place in the gateway's map, which
// must match the place stored with the data (shard_place.h).
//
//   auto core = IndexerCore::Open(options);
//   IndexerService service(core->get(), ServiceOptions{});
//   auto server = tpr::common::StartServer(server_options, {&service});
//
// Uses gRPC's synchronous API: a search is CPU-bound (EMDs), so it runs on a
// thread of the server's pool (bounded by ServerOptions::max_threads) rather
// than on the callback executor that also moves bytes.
#ifndef TPR_INDEXER_SERVICE_INDEXER_SERVICE_H_
#define TPR_INDEXER_SERVICE_INDEXER_SERVICE_H_

#include <atomic>
#include <cstdint>
#include <string>

#include "common/metrics.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/search_metrics.h"
#include "indexer/service/shard_place.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::indexer {

// ServiceOptions: limits applied by the wire layer.
struct ServiceOptions {
  // Searches running at once; one more gets RESOURCE_EXHAUSTED at once
  // rather than queueing behind CPU-bound work. Default 16.
  int max_concurrent_searches = 16;
  // Receives one line per notable event (failed calls). Default: none.
  std::function<void(const std::string&)> log;
};

// IndexerService: see the file comment. Thread-safe. `core` must outlive it.
class IndexerService final : public tpr::v1::Indexer::Service,
                             public common::CallMetricsSource {
 public:
  IndexerService(IndexerCore* core, ServiceOptions options);

  grpc::Status Upsert(grpc::ServerContext* context,
                      const tpr::v1::UpsertRequest* request,
                      tpr::v1::UpsertResponse* response) override;
  // BatchUpsert reads its stream as raw bytes (common/stream_messages.h):
  // the constructor registers this handler in place of the generated typed
  // one, so that a message that does not parse is INVALID_ARGUMENT naming
  // it, not taken for the end of the stream.
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
  // GetPreview writes the preview in chunks of kPreviewChunkBytes, checking
  // between chunks whether the client is still there.
  grpc::Status GetPreview(
      grpc::ServerContext* context, const tpr::v1::GetPreviewRequest* request,
      grpc::ServerWriter<tpr::v1::PreviewChunk>* writer) override;

  // kPreviewChunkBytes: the size of every GetPreview chunk but the last.
  static constexpr size_t kPreviewChunkBytes = 64 << 10;

  // SearchCounters: the work of the searches this service ran, for health
  // and metrics. Read at any time from any thread.
  struct SearchCounters {
    // Searches running now.
    int running = 0;
    // EMDs computed by searches that have ended (completed, cancelled or
    // past their deadline).
    int64_t emd_computations = 0;
  };
  SearchCounters search_counters() const {
    return {searches_.load(), emd_computations_.load()};
  }

  // AddCallMetrics adds the searches' metrics (search_metrics.h).
  void AddCallMetrics(common::Metrics& metrics) override {
    AddSearchMetrics(metrics);
  }

 private:
  // The checks before every call: its cancellation, then the shard place a
  // gateway's call claims (shard_place.h).
  absl::Status Admit(grpc::ServerContext* context);
  // Logs failures that are the server's fault (not the caller's input).
  grpc::Status Finish(const char* method, const absl::Status& status) const;
  // Streams `session`'s neighbours and then its stats.
  grpc::Status Stream(grpc::ServerContext* context, SearchSession& session,
                      grpc::ServerWriter<tpr::v1::SearchResponse>* writer);

  IndexerCore* core_;
  const ServiceOptions options_;
  ShardPlace place_;
  std::atomic<int> searches_{0};
  std::atomic<int64_t> emd_computations_{0};
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_INDEXER_SERVICE_H_
