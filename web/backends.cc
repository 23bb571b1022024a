#include "web/backends.h"

#include <grpcpp/client_context.h>

#include <algorithm>
#include <chrono>

#include "absl/strings/str_cat.h"
#include "common/grpc_status.h"
#include "common/logging.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace tpr::web {
namespace {

// Mesh bytes per upload message: the SDK's chunk size, well under gRPC's
// 4 MiB default message limit.
constexpr size_t kChunkBytes = client::kChunkBytes;

// Failed returns the service's status, with a message naming the method
// when the service sent none (gRPC's own UNIMPLEMENTED has none).
absl::Status Failed(const grpc::Status& status, const char* method) {
  absl::Status out = common::FromGrpcStatus(status);
  if (!status.error_message().empty()) return out;
  std::string hint;
  if (status.error_code() == grpc::StatusCode::UNIMPLEMENTED)
    hint = ": the service does not offer it";
  return absl::Status(
      out.code(),
      absl::StrCat(method, " answered ", absl::StatusCodeToString(out.code()),
                   " without a message", hint));
}

std::string Readiness(const std::shared_ptr<grpc::Channel>& channel,
                      const std::string& service) {
  std::unique_ptr<grpc::health::v1::Health::Stub> stub =
      grpc::health::v1::Health::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(2));
  grpc::health::v1::HealthCheckRequest request;
  request.set_service(service);
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status s = stub->Check(&context, request, &response);
  if (!s.ok()) {
    return absl::StrCat(
        "unreachable: ",
        absl::StatusCodeToString(static_cast<absl::StatusCode>(s.error_code())),
        s.error_message().empty() ? "" : ": ", s.error_message());
  }
  if (response.status() != grpc::health::v1::HealthCheckResponse::SERVING)
    return "not serving";
  return "";
}

}  // namespace

absl::StatusOr<std::unique_ptr<Backends>> Backends::Connect(
    const BackendOptions& options) {
  // The key travels as per-call metadata (Prepare), never as channel
  // credentials, so that a caller's own key can be forwarded instead.
  client::ConnectionOptions connection = options.connection;
  connection.api_key.clear();
  absl::StatusOr<std::shared_ptr<grpc::Channel>> extractor =
      client::MakeChannel(options.extractor, connection);
  if (!extractor.ok()) {
    return absl::Status(
        extractor.status().code(),
        absl::StrCat("--extractor: ", extractor.status().message()));
  }
  absl::StatusOr<std::shared_ptr<grpc::Channel>> indexer =
      client::MakeChannel(options.indexer, connection);
  if (!indexer.ok()) {
    return absl::Status(
        indexer.status().code(),
        absl::StrCat("--indexer: ", indexer.status().message()));
  }
  return std::unique_ptr<Backends>(
      new Backends(options, *std::move(extractor), *std::move(indexer)));
}

Backends::Backends(BackendOptions options,
                   std::shared_ptr<grpc::Channel> extractor,
                   std::shared_ptr<grpc::Channel> indexer)
    : options_(std::move(options)),
      extractor_channel_(std::move(extractor)),
      indexer_channel_(std::move(indexer)),
      extractor_(v1::Extractor::NewStub(extractor_channel_)),
      indexer_(v1::Indexer::NewStub(indexer_channel_)) {
  if (!options_.connection.api_key.empty())
    authorization_ = absl::StrCat("Bearer ", options_.connection.api_key);
}

void Backends::Prepare(grpc::ClientContext* context,
                       const CallMeta& meta) const {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(
                            static_cast<int64_t>(options_.timeout_s * 1000.0)));
  if (!meta.request_id.empty())
    context->AddMetadata(common::kRequestIdHeader, meta.request_id);
  const std::string& authorization =
      authorization_.empty() ? meta.authorization : authorization_;
  if (!authorization.empty())
    context->AddMetadata("authorization", authorization);
}

absl::StatusOr<v1::ExtractResponse> Backends::Extract(
    absl::string_view bytes, const std::string& file_name,
    v1::MeshFormat format, const v1::ExtractOptions& options,
    const v1::MediaOptions& media, const CallMeta& meta) const {
  grpc::ClientContext context;
  Prepare(&context, meta);
  v1::ExtractResponse response;
  std::unique_ptr<grpc::ClientWriter<v1::ExtractRequest>> writer =
      extractor_->Extract(&context, &response);
  size_t offset = 0;
  bool first = true;
  while (first || offset < bytes.size()) {
    v1::ExtractRequest request;
    const size_t n = std::min(kChunkBytes, bytes.size() - offset);
    request.set_data(std::string(bytes.substr(offset, n)));
    if (first) {
      request.set_file_name(file_name);
      request.set_format(format);
      *request.mutable_options() = options;
      *request.mutable_media() = media;
    }
    offset += n;
    first = false;
    // A refused write means the server ended the call; Finish says why.
    if (!writer->Write(request)) break;
  }
  writer->WritesDone();
  const grpc::Status s = writer->Finish();
  if (!s.ok()) return Failed(s, "/tpr.v1.Extractor/Extract");
  return response;
}

absl::StatusOr<SearchResult> Backends::Search(const v1::SearchRequest& request,
                                              const CallMeta& meta) const {
  grpc::ClientContext context;
  Prepare(&context, meta);
  std::unique_ptr<grpc::ClientReader<v1::SearchResponse>> reader =
      indexer_->Search(&context, request);
  SearchResult result;
  for (v1::SearchResponse item; reader->Read(&item);) {
    if (item.has_neighbor()) {
      result.neighbors.push_back(std::move(*item.mutable_neighbor()));
    } else if (item.has_stats()) {
      result.stats = item.stats();
    }
  }
  const grpc::Status s = reader->Finish();
  if (!s.ok()) return Failed(s, "/tpr.v1.Indexer/Search");
  return result;
}

template <typename Request, typename Response>
absl::StatusOr<Response> Backends::CallIndexer(
    grpc::Status (v1::Indexer::Stub::*rpc)(grpc::ClientContext*, const Request&,
                                           Response*),
    const Request& request, const char* method, const CallMeta& meta) const {
  grpc::ClientContext context;
  Prepare(&context, meta);
  Response response;
  const grpc::Status s = (indexer_.get()->*rpc)(&context, request, &response);
  if (!s.ok()) return Failed(s, method);
  return response;
}

absl::StatusOr<v1::Model> Backends::Get(const std::string& id,
                                        const CallMeta& meta) const {
  v1::GetRequest request;
  request.set_id(id);
  return CallIndexer(&v1::Indexer::Stub::Get, request, "/tpr.v1.Indexer/Get",
                     meta);
}

absl::StatusOr<v1::ListResponse> Backends::List(const v1::ListRequest& request,
                                                const CallMeta& meta) const {
  return CallIndexer(&v1::Indexer::Stub::List, request, "/tpr.v1.Indexer/List",
                     meta);
}

absl::StatusOr<v1::StatsResponse> Backends::Stats(const CallMeta& meta) const {
  return CallIndexer(&v1::Indexer::Stub::Stats, v1::StatsRequest(),
                     "/tpr.v1.Indexer/Stats", meta);
}

absl::StatusOr<bool> Backends::Upsert(const v1::Model& model, bool overwrite,
                                      const CallMeta& meta) const {
  v1::UpsertRequest request;
  *request.mutable_model() = model;
  request.set_overwrite(overwrite);
  absl::StatusOr<v1::UpsertResponse> response = CallIndexer(
      &v1::Indexer::Stub::Upsert, request, "/tpr.v1.Indexer/Upsert", meta);
  if (!response.ok()) return response.status();
  return response->created();
}

absl::Status Backends::Delete(const std::string& id,
                              const CallMeta& meta) const {
  v1::DeleteRequest request;
  request.set_id(id);
  return CallIndexer(&v1::Indexer::Stub::Delete, request,
                     "/tpr.v1.Indexer/Delete", meta)
      .status();
}

absl::StatusOr<std::string> Backends::Thumbnail(const std::string& id,
                                                const CallMeta& meta) const {
  v1::GetThumbnailRequest request;
  request.set_id(id);
  absl::StatusOr<v1::Thumbnail> response =
      CallIndexer(&v1::Indexer::Stub::GetThumbnail, request,
                  "/tpr.v1.Indexer/GetThumbnail", meta);
  if (!response.ok()) return response.status();
  return std::move(*response->mutable_png());
}

absl::StatusOr<std::string> Backends::Preview(const std::string& id,
                                              const CallMeta& meta) const {
  grpc::ClientContext context;
  Prepare(&context, meta);
  v1::GetPreviewRequest request;
  request.set_id(id);
  std::unique_ptr<grpc::ClientReader<v1::PreviewChunk>> reader =
      indexer_->GetPreview(&context, request);
  std::string bytes;
  for (v1::PreviewChunk chunk; reader->Read(&chunk);) {
    if (chunk.total_bytes() > 0 && bytes.empty())
      bytes.reserve(static_cast<size_t>(chunk.total_bytes()));
    bytes += chunk.data();
  }
  const grpc::Status s = reader->Finish();
  if (!s.ok()) return Failed(s, "/tpr.v1.Indexer/GetPreview");
  return bytes;
}

std::string Backends::ExtractorReadiness() const {
  return Readiness(extractor_channel_, "tpr.v1.Extractor");
}

std::string Backends::IndexerReadiness() const {
  return Readiness(indexer_channel_, "tpr.v1.Indexer");
}

}  // namespace tpr::web
