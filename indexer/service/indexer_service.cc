#include "indexer/service/indexer_service.h"

#include <chrono>
#include <memory>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/call_interceptor.h"
#include "common/grpc_status.h"
#include "common/stream_messages.h"

namespace tpr::indexer {
namespace {

absl::Status CancelledStatus(grpc::ServerContext* context) {
  // Past its deadline gRPC cancels the call; either way the client is gone.
  return context->IsCancelled()
             ? absl::CancelledError("call cancelled or deadline exceeded")
             : absl::OkStatus();
}

// The shard place a gateway's call claims (gateway::kShardPlaceHeader), "" when
// none.
absl::string_view ClaimedPlace(const grpc::ServerContext& context) {
  const auto& metadata = context.client_metadata();
  auto it = metadata.find(tpr::gateway::kShardPlaceHeader);
  if (it == metadata.end()) return "";
  return absl::string_view(it->second.data(), it->second.size());
}

}  // namespace

absl::Status IndexerService::Admit(grpc::ServerContext* context) {
  if (absl::Status c = CancelledStatus(context); !c.ok()) return c;
  const absl::string_view claimed = ClaimedPlace(*context);
  if (claimed.empty()) return absl::OkStatus();
  return place_.Check(claimed, /*may_store=*/core_->following().empty());
}

// The index of BatchUpsert among tpr.v1.Indexer's methods (their order in
// indexer.proto, as the generated code numbers them).
constexpr int kBatchUpsertMethod = 1;

IndexerService::IndexerService(IndexerCore* core, ServiceOptions options)
    : core_(core), options_(std::move(options)), place_(&core->storage()) {
  // The generated handler reads tpr.v1.UpsertRequest, and gRPC's typed
  // reader ends the stream on a message that does not parse; this one reads
  // raw bytes (common/stream_messages.h).
  MarkMethodStreamed(
      kBatchUpsertMethod,
      tpr::common::RawClientStreamHandler<tpr::v1::Indexer::Service,
                                          tpr::v1::UpsertRequest>(
          GetHandler(kBatchUpsertMethod), "BatchUpsert", this,
          &IndexerService::BatchUpsertRaw));
}

grpc::Status IndexerService::Finish(const char* method,
                                    const absl::Status& status) const {
  if (options_.log && !status.ok()) {
    switch (status.code()) {
      case absl::StatusCode::kInternal:
      case absl::StatusCode::kDataLoss:
      case absl::StatusCode::kUnavailable:
      case absl::StatusCode::kUnknown:
        options_.log(absl::StrCat(method, " failed: ", status.ToString()));
        break;
      default:
        break;
    }
  }
  return tpr::common::ToGrpcStatus(status);
}

grpc::Status IndexerService::Upsert(grpc::ServerContext* context,
                                    const tpr::v1::UpsertRequest* request,
                                    tpr::v1::UpsertResponse* response) {
  if (absl::Status c = Admit(context); !c.ok()) return Finish("Upsert", c);
  absl::StatusOr<bool> created = core_->Upsert(*request);
  if (created.ok()) response->set_created(*created);
  return Finish("Upsert", created.status());
}

grpc::Status IndexerService::BatchUpsertRaw(
    grpc::ServerContext* context, grpc::ServerReader<grpc::ByteBuffer>* reader,
    tpr::v1::BatchUpsertResponse* response) {
  if (absl::Status c = Admit(context); !c.ok()) return Finish("BatchUpsert", c);
  BatchWriter batch(core_);
  tpr::common::StreamParser<tpr::v1::UpsertRequest> parser("BatchUpsert");
  grpc::ByteBuffer raw;
  tpr::v1::UpsertRequest request;
  while (reader->Read(&raw)) {
    if (absl::Status bad = parser.Parse(&raw, &request); !bad.ok()) {
      // As for any other bad request in the stream: the models before it
      // are written (the proto's promise), then the call fails.
      absl::StatusOr<tpr::v1::BatchUpsertResponse> before = batch.Finish();
      return Finish("BatchUpsert", before.ok() ? bad : before.status());
    }
    absl::Status st = batch.Add(std::move(request));
    if (!st.ok()) return Finish("BatchUpsert", st);
    request.Clear();
  }
  // Read() also ends when the client cancels: then the models of the last
  // group are written anyway (keeping the "models before are kept" promise)
  // but the call reports the cancellation.
  absl::StatusOr<tpr::v1::BatchUpsertResponse> counts = batch.Finish();
  if (!counts.ok()) return Finish("BatchUpsert", counts.status());
  if (absl::Status c = CancelledStatus(context); !c.ok())
    return Finish("BatchUpsert", c);
  *response = std::move(*counts);
  return grpc::Status::OK;
}

grpc::Status IndexerService::Delete(grpc::ServerContext* context,
                                    const tpr::v1::DeleteRequest* request,
                                    tpr::v1::DeleteResponse*) {
  if (absl::Status c = Admit(context); !c.ok()) return Finish("Delete", c);
  return Finish("Delete", core_->Delete(request->id()));
}

grpc::Status IndexerService::Get(grpc::ServerContext* context,
                                 const tpr::v1::GetRequest* request,
                                 tpr::v1::Model* response) {
  if (absl::Status c = Admit(context); !c.ok()) return Finish("Get", c);
  absl::StatusOr<tpr::v1::Model> model = core_->Get(request->id());
  if (model.ok()) *response = std::move(*model);
  return Finish("Get", model.status());
}

grpc::Status IndexerService::List(grpc::ServerContext* context,
                                  const tpr::v1::ListRequest* request,
                                  tpr::v1::ListResponse* response) {
  if (absl::Status c = Admit(context); !c.ok()) return Finish("List", c);
  absl::StatusOr<tpr::v1::ListResponse> page = core_->List(*request);
  if (page.ok()) *response = std::move(*page);
  return Finish("List", page.status());
}

grpc::Status IndexerService::Stats(grpc::ServerContext* context,
                                   const tpr::v1::StatsRequest*,
                                   tpr::v1::StatsResponse* response) {
  if (absl::Status c = Admit(context); !c.ok()) return Finish("Stats", c);
  *response = core_->Stats();
  return grpc::Status::OK;
}

grpc::Status IndexerService::GetThumbnail(
    grpc::ServerContext* context, const tpr::v1::GetThumbnailRequest* request,
    tpr::v1::Thumbnail* response) {
  if (absl::Status c = Admit(context); !c.ok())
    return Finish("GetThumbnail", c);
  absl::StatusOr<std::string> png = core_->GetThumbnail(request->id());
  if (png.ok()) response->set_png(std::move(*png));
  return Finish("GetThumbnail", png.status());
}

grpc::Status IndexerService::GetPreview(
    grpc::ServerContext* context, const tpr::v1::GetPreviewRequest* request,
    grpc::ServerWriter<tpr::v1::PreviewChunk>* writer) {
  if (absl::Status c = Admit(context); !c.ok()) return Finish("GetPreview", c);
  absl::StatusOr<std::string> ply = core_->GetPreview(request->id());
  if (!ply.ok()) return Finish("GetPreview", ply.status());
  tpr::v1::PreviewChunk chunk;
  for (size_t at = 0; at < ply->size(); at += kPreviewChunkBytes) {
    if (absl::Status c = CancelledStatus(context); !c.ok())
      return Finish("GetPreview", c);
    chunk.set_data(ply->substr(at, kPreviewChunkBytes));
    chunk.set_total_bytes(at == 0 ? static_cast<int64_t>(ply->size()) : 0);
    if (!writer->Write(chunk)) {
      return Finish("GetPreview",
                    absl::CancelledError("client stopped reading the stream"));
    }
  }
  return grpc::Status::OK;
}

grpc::Status IndexerService::Search(
    grpc::ServerContext* context, const tpr::v1::SearchRequest* request,
    grpc::ServerWriter<tpr::v1::SearchResponse>* writer) {
  if (absl::Status c = Admit(context); !c.ok()) return Finish("Search", c);
  // Admission: a slot or RESOURCE_EXHAUSTED, never an unbounded queue.
  if (searches_.fetch_add(1) >= options_.max_concurrent_searches) {
    searches_.fetch_sub(1);
    return Finish("Search",
                  absl::ResourceExhaustedError(absl::StrCat(
                      "too many concurrent searches (limit ",
                      options_.max_concurrent_searches, "); retry later")));
  }
  struct Release {
    std::atomic<int>* n;
    ~Release() { n->fetch_sub(1); }
  } release{&searches_};

  // The core polls this between EMDs. On the sync API IsCancelled() polls
  // the call's completion queue (a system call), which per EMD cost more
  // than the search itself; so it is asked at most every 2 ms and the answer
  // cached in between (cancellation then stops work within ~2 ms plus one
  // EMD). The deadline is also compared directly, so the search stops at it
  // even before gRPC has processed the cancellation.
  struct Probe {
    grpc::ServerContext* context;
    std::chrono::system_clock::time_point deadline;
    std::chrono::steady_clock::time_point next;
    bool cancelled = false;
    bool operator()() {
      if (cancelled) return true;
      const auto now = std::chrono::steady_clock::now();
      if (now < next) return false;
      next = now + std::chrono::milliseconds(2);
      cancelled = context->IsCancelled() ||
                  std::chrono::system_clock::now() >= deadline;
      return cancelled;
    }
  };
  auto probe = std::make_shared<Probe>(
      Probe{context, context->deadline(), std::chrono::steady_clock::now()});
  absl::StatusOr<std::unique_ptr<SearchSession>> session =
      core_->StartSearch(*request, [probe] { return (*probe)(); });
  if (!session.ok()) return Finish("Search", session.status());
  const grpc::Status status = Stream(context, **session, writer);
  emd_computations_ += (*session)->Stats().emd_computations();
  return status;
}

grpc::Status IndexerService::Stream(
    grpc::ServerContext* context, SearchSession& session,
    grpc::ServerWriter<tpr::v1::SearchResponse>* writer) {
  tpr::v1::SearchResponse response;
  // Per-neighbour statistics only for callers that ask (tpr-gateway): see
  // tpr.v1.Neighbor.progress.
  const bool progress = tpr::common::WantsSearchProgress(*context);
  while (std::optional<tpr::v1::Neighbor> n = session.Next()) {
    *response.mutable_neighbor() = std::move(*n);
    if (progress)
      *response.mutable_neighbor()->mutable_progress() = session.Stats();
    // Write fails once the client has gone: stop working for it.
    if (!writer->Write(response)) {
      return Finish("Search",
                    absl::CancelledError("client stopped reading the stream"));
    }
  }
  // The probe compares the deadline itself, so the search may stop before
  // gRPC's own timer has ended the call: then the status sent is the
  // client's, DEADLINE_EXCEEDED (CANCELLED here reached clients under load).
  if (std::chrono::system_clock::now() >= context->deadline()) {
    return Finish("Search", absl::DeadlineExceededError(
                                "the search reached the call's deadline"));
  }
  if (context->IsCancelled()) {
    return Finish("Search", absl::CancelledError("call cancelled"));
  }
  *response.mutable_stats() = session.Stats();
  writer->Write(response);
  return grpc::Status::OK;
}

}  // namespace tpr::indexer
