#include "tpr/client.h"

#include <grpc/grpc.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <random>
#include <sstream>
#include <thread>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "common/grpc_status.h"

namespace tpr::client {
namespace {

std::chrono::system_clock::time_point DeadlineFor(const CallOptions& call) {
  if (call.timeout == absl::InfiniteDuration()) {
    return std::chrono::system_clock::time_point::max();
  }
  return std::chrono::system_clock::now() +
         std::chrono::microseconds(absl::ToInt64Microseconds(call.timeout));
}

// Waits up to `wait` before the next attempt, returning early once the
// channel is connected. Plain sleeping is not enough: while round_robin has
// no ready backend, gRPC fails calls at once and a connection attempt begun
// for a failed call is abandoned with it, so a restarted server could be
// missed by every retry. WaitForConnected drives the connection itself.
void BackoffWait(grpc::Channel* channel, std::chrono::microseconds wait) {
  channel->WaitForConnected(std::chrono::system_clock::now() + wait);
}

// Runs `attempt(context)` until it succeeds, fails with a code other than
// UNAVAILABLE, attempts run out, or the next backoff would pass the
// deadline. Every attempt gets a fresh context with the call's deadline.
// Backoff is hand-written rather than gRPC's service-config retry policy so
// that the rule "retry only idempotent calls" lives next to each call and
// the jitter does not depend on channel configuration.
template <typename Attempt>
grpc::Status WithRetries(grpc::Channel* channel, const CallOptions& call,
                         bool idempotent, Attempt&& attempt) {
  const auto deadline = DeadlineFor(call);
  const int attempts = idempotent ? std::max(1, call.max_attempts) : 1;
  absl::Duration backoff = call.initial_backoff;
  thread_local std::mt19937 rng(std::random_device{}());
  grpc::Status status;
  for (int i = 0; i < attempts; ++i) {
    grpc::ClientContext context;
    context.set_deadline(deadline);
    status = attempt(&context);
    if (status.error_code() != grpc::StatusCode::UNAVAILABLE ||
        i + 1 == attempts)
      break;
    std::uniform_real_distribution<double> jitter(0.8, 1.2);
    const auto wait = std::chrono::microseconds(static_cast<int64_t>(
        absl::ToDoubleMicroseconds(backoff) * jitter(rng)));
    if (std::chrono::system_clock::now() + wait >= deadline) break;
    BackoffWait(channel, wait);
    backoff = std::min(call.max_backoff, backoff * call.backoff_multiplier);
  }
  return status;
}

}  // namespace

// --- ExtractorClient ---------------------------------------------------------

ExtractorClient::ExtractorClient(std::shared_ptr<grpc::Channel> channel,
                                 CallOptions defaults)
    : channel_(std::move(channel)),
      stub_(v1::Extractor::NewStub(channel_)),
      defaults_(defaults) {}

absl::StatusOr<ExtractorClient> ExtractorClient::Connect(
    absl::string_view addresses, CallOptions defaults) {
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
      MakeChannel(addresses);
  if (!channel.ok()) return channel.status();
  return ExtractorClient(*std::move(channel), defaults);
}

namespace {

// A restartable sequence of upload chunks: Next stores the next chunk (at
// most kChunkBytes) in *chunk and returns true, false at the end, or an
// error when the source cannot be read. Restart rewinds it for a retry.
class ChunkSource {
 public:
  virtual ~ChunkSource() = default;
  virtual absl::Status Restart() = 0;
  virtual absl::StatusOr<bool> Next(std::string* chunk) = 0;
};

class BytesSource final : public ChunkSource {
 public:
  explicit BytesSource(absl::string_view bytes) : bytes_(bytes) {}
  absl::Status Restart() override {
    offset_ = 0;
    return absl::OkStatus();
  }
  absl::StatusOr<bool> Next(std::string* chunk) override {
    if (offset_ >= bytes_.size()) return false;
    const size_t n = std::min(kChunkBytes, bytes_.size() - offset_);
    chunk->assign(bytes_.data() + offset_, n);
    offset_ += n;
    return true;
  }

 private:
  absl::string_view bytes_;
  size_t offset_ = 0;
};

// Reads the file kChunkBytes at a time: the whole mesh is never in memory.
class FileSource final : public ChunkSource {
 public:
  explicit FileSource(std::string path) : path_(std::move(path)) {}
  absl::Status Restart() override {
    in_.close();
    in_.clear();
    in_.open(path_, std::ios::binary);
    if (!in_)
      return absl::NotFoundError(absl::StrCat("cannot open mesh file ", path_));
    return absl::OkStatus();
  }
  absl::StatusOr<bool> Next(std::string* chunk) override {
    chunk->resize(kChunkBytes);
    in_.read(chunk->data(), static_cast<std::streamsize>(kChunkBytes));
    if (in_.bad())
      return absl::DataLossError(absl::StrCat("cannot read mesh file ", path_));
    chunk->resize(static_cast<size_t>(in_.gcount()));
    return !chunk->empty();
  }

 private:
  std::string path_;
  std::ifstream in_;
};

// One Extract call streaming `source`, retried on UNAVAILABLE.
absl::StatusOr<v1::ExtractResponse> ExtractFrom(
    grpc::Channel* channel, v1::Extractor::Stub* stub, ChunkSource& source,
    absl::string_view file_name, const v1::ExtractOptions& options,
    const v1::MediaOptions* media, v1::MeshFormat format,
    const CallOptions& call) {
  v1::ExtractResponse response;
  absl::Status local =
      absl::OkStatus();  // a failure of the source, not the call
  grpc::Status status = WithRetries(
      channel, call, /*idempotent=*/true, [&](grpc::ClientContext* context) {
        response.Clear();
        local = source.Restart();
        if (!local.ok())
          return grpc::Status(grpc::StatusCode::CANCELLED, "source");
        std::unique_ptr<grpc::ClientWriter<v1::ExtractRequest>> writer =
            stub->Extract(context, &response);
        // The first message always goes out, even for an empty source, so
        // that the server sees the header (and reports "no mesh data").
        bool first = true;
        while (true) {
          v1::ExtractRequest request;
          absl::StatusOr<bool> more = source.Next(request.mutable_data());
          if (!more.ok()) {
            local = more.status();
            context->TryCancel();
            writer->Finish();
            return grpc::Status(grpc::StatusCode::CANCELLED, "source");
          }
          if (!*more && !first) break;
          if (first) {
            request.set_format(format);
            request.set_file_name(std::string(file_name));
            *request.mutable_options() = options;
            if (media != nullptr) *request.mutable_media() = *media;
          }
          first = false;
          // A failed write means the server already ended the call (for
          // example RESOURCE_EXHAUSTED at its byte limit): Finish says why.
          if (!writer->Write(request) || !*more) break;
        }
        writer->WritesDone();
        return writer->Finish();
      });
  if (!local.ok()) return local;
  if (!status.ok()) return common::FromGrpcStatus(status);
  return response;
}

}  // namespace

absl::StatusOr<v1::ExtractResponse> ExtractorClient::ExtractFile(
    const std::string& path, const v1::ExtractOptions& options,
    const CallOptions* call) const {
  const size_t slash = path.find_last_of('/');
  const std::string name =
      slash == std::string::npos ? path : path.substr(slash + 1);
  FileSource source(path);
  return ExtractFrom(channel_.get(), stub_.get(), source, name, options,
                     nullptr, v1::MESH_FORMAT_UNSPECIFIED,
                     call ? *call : defaults_);
}

absl::StatusOr<v1::ExtractResponse> ExtractorClient::ExtractBytes(
    absl::string_view bytes, absl::string_view file_name,
    const v1::ExtractOptions& options, v1::MeshFormat format,
    const CallOptions* call) const {
  BytesSource source(bytes);
  return ExtractFrom(channel_.get(), stub_.get(), source, file_name, options,
                     nullptr, format, call ? *call : defaults_);
}

absl::StatusOr<v1::ExtractResponse> ExtractorClient::ExtractFile(
    const std::string& path, const v1::ExtractOptions& options,
    const v1::MediaOptions& media, const CallOptions* call) const {
  const size_t slash = path.find_last_of('/');
  const std::string name =
      slash == std::string::npos ? path : path.substr(slash + 1);
  FileSource source(path);
  return ExtractFrom(channel_.get(), stub_.get(), source, name, options, &media,
                     v1::MESH_FORMAT_UNSPECIFIED, call ? *call : defaults_);
}

absl::StatusOr<v1::ExtractResponse> ExtractorClient::ExtractBytes(
    absl::string_view bytes, absl::string_view file_name,
    const v1::ExtractOptions& options, const v1::MediaOptions& media,
    v1::MeshFormat format, const CallOptions* call) const {
  BytesSource source(bytes);
  return ExtractFrom(channel_.get(), stub_.get(), source, file_name, options,
                     &media, format, call ? *call : defaults_);
}

// --- IndexerClient
// -------------------------------------------------------------

namespace {

class GrpcBatchUpsertWriter final : public BatchUpsertWriter {
 public:
  GrpcBatchUpsertWriter(std::shared_ptr<v1::Indexer::Stub> stub,
                        const CallOptions& call)
      : stub_(std::move(stub)) {
    context_.set_deadline(DeadlineFor(call));
    writer_ = stub_->BatchUpsert(&context_, &response_);
  }
  ~GrpcBatchUpsertWriter() override {
    if (!finished_) {
      context_.TryCancel();
      writer_->Finish();
    }
  }
  bool Write(const v1::Model& model, bool overwrite) override {
    v1::UpsertRequest request;
    *request.mutable_model() = model;
    request.set_overwrite(overwrite);
    return writer_->Write(request);
  }
  absl::StatusOr<v1::BatchUpsertResponse> Finish() override {
    finished_ = true;
    writer_->WritesDone();
    grpc::Status status = writer_->Finish();
    if (!status.ok()) return common::FromGrpcStatus(status);
    return response_;
  }

 private:
  // Shared so that the writer may outlive the client that made it.
  std::shared_ptr<v1::Indexer::Stub> stub_;
  grpc::ClientContext context_;
  v1::BatchUpsertResponse response_;
  std::unique_ptr<grpc::ClientWriter<v1::UpsertRequest>> writer_;
  bool finished_ = false;
};

class GrpcSearchStream final : public SearchStream {
 public:
  GrpcSearchStream(std::shared_ptr<grpc::Channel> channel,
                   std::shared_ptr<v1::Indexer::Stub> stub,
                   v1::SearchRequest request, const CallOptions& call)
      : channel_(std::move(channel)),
        stub_(std::move(stub)),
        request_(std::move(request)),
        call_(call),
        deadline_(DeadlineFor(call)) {
    Start();
  }
  ~GrpcSearchStream() override {
    if (!done_) {
      context_->TryCancel();
      reader_->Finish();
    }
  }

  bool Next(v1::Neighbor* neighbor) override {
    while (!done_) {
      v1::SearchResponse response;
      if (reader_->Read(&response)) {
        if (response.has_neighbor()) {
          ++delivered_;
          *neighbor = response.neighbor();
          return true;
        }
        if (response.has_stats()) {
          stats_ = response.stats();
          has_stats_ = true;
        }
        continue;
      }
      grpc::Status status = reader_->Finish();
      // Nothing delivered yet: the search may be repeated elsewhere.
      if (status.error_code() == grpc::StatusCode::UNAVAILABLE &&
          delivered_ == 0 && attempt_ < std::max(1, call_.max_attempts) &&
          Backoff()) {
        Start();
        continue;
      }
      done_ = true;
      status_ = cancelled_ ? absl::OkStatus() : common::FromGrpcStatus(status);
      if (!status_.ok()) has_stats_ = false;
    }
    return false;
  }

  void Cancel() override {
    if (done_) return;
    cancelled_ = true;
    context_->TryCancel();
  }

  absl::Status Finish() override {
    v1::Neighbor ignored;
    while (Next(&ignored)) {
    }
    return status_;
  }

  const v1::SearchStats* Stats() const override {
    return done_ && has_stats_ ? &stats_ : nullptr;
  }

 private:
  void Start() {
    ++attempt_;
    context_ = std::make_unique<grpc::ClientContext>();
    context_->set_deadline(deadline_);
    reader_ = stub_->Search(context_.get(), request_);
  }
  // Sleeps before the next attempt; false when that would pass the deadline.
  bool Backoff() {
    absl::Duration wait = call_.initial_backoff;
    for (int i = 1; i < attempt_; ++i)
      wait = std::min(call_.max_backoff, wait * call_.backoff_multiplier);
    const auto w = std::chrono::microseconds(absl::ToInt64Microseconds(wait));
    if (std::chrono::system_clock::now() + w >= deadline_) return false;
    BackoffWait(channel_.get(), w);
    return true;
  }

  std::shared_ptr<grpc::Channel> channel_;
  std::shared_ptr<v1::Indexer::Stub> stub_;
  const v1::SearchRequest request_;
  const CallOptions call_;
  const std::chrono::system_clock::time_point deadline_;
  std::unique_ptr<grpc::ClientContext> context_;
  std::unique_ptr<grpc::ClientReader<v1::SearchResponse>> reader_;
  int attempt_ = 0;
  int64_t delivered_ = 0;
  bool done_ = false;
  bool cancelled_ = false;
  absl::Status status_;
  v1::SearchStats stats_;
  bool has_stats_ = false;
};

}  // namespace

IndexerClient::IndexerClient(std::shared_ptr<grpc::Channel> channel,
                             CallOptions defaults)
    : channel_(std::move(channel)),
      stub_(v1::Indexer::NewStub(channel_)),
      defaults_(defaults) {}

absl::StatusOr<IndexerClient> IndexerClient::Connect(
    absl::string_view addresses, CallOptions defaults) {
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
      MakeChannel(addresses);
  if (!channel.ok()) return channel.status();
  return IndexerClient(*std::move(channel), defaults);
}

absl::StatusOr<bool> IndexerClient::Upsert(const v1::Model& model,
                                           bool overwrite,
                                           const CallOptions* call) const {
  v1::UpsertRequest request;
  *request.mutable_model() = model;
  request.set_overwrite(overwrite);
  v1::UpsertResponse response;
  grpc::Status status =
      WithRetries(channel_.get(), call ? *call : defaults_,
                  /*idempotent=*/overwrite, [&](grpc::ClientContext* context) {
                    return stub_->Upsert(context, request, &response);
                  });
  if (!status.ok()) return common::FromGrpcStatus(status);
  return response.created();
}

std::unique_ptr<BatchUpsertWriter> IndexerClient::BatchUpsert(
    const CallOptions* call) const {
  return std::make_unique<GrpcBatchUpsertWriter>(stub_,
                                                 call ? *call : defaults_);
}

absl::Status IndexerClient::Delete(const std::string& id,
                                   const CallOptions* call) const {
  v1::DeleteRequest request;
  request.set_id(id);
  v1::DeleteResponse response;
  return common::FromGrpcStatus(
      WithRetries(channel_.get(), call ? *call : defaults_,
                  /*idempotent=*/false, [&](grpc::ClientContext* context) {
                    return stub_->Delete(context, request, &response);
                  }));
}

absl::StatusOr<v1::Model> IndexerClient::Get(const std::string& id,
                                             const CallOptions* call) const {
  v1::GetRequest request;
  request.set_id(id);
  v1::Model response;
  grpc::Status status =
      WithRetries(channel_.get(), call ? *call : defaults_, /*idempotent=*/true,
                  [&](grpc::ClientContext* context) {
                    return stub_->Get(context, request, &response);
                  });
  if (!status.ok()) return common::FromGrpcStatus(status);
  return response;
}

absl::StatusOr<std::string> IndexerClient::GetThumbnail(
    const std::string& id, const CallOptions* call) const {
  v1::GetThumbnailRequest request;
  request.set_id(id);
  v1::Thumbnail response;
  grpc::Status status =
      WithRetries(channel_.get(), call ? *call : defaults_, /*idempotent=*/true,
                  [&](grpc::ClientContext* context) {
                    return stub_->GetThumbnail(context, request, &response);
                  });
  if (!status.ok()) return common::FromGrpcStatus(status);
  return std::move(*response.mutable_png());
}

absl::StatusOr<std::string> IndexerClient::GetPreview(
    const std::string& id, const CallOptions* call) const {
  v1::GetPreviewRequest request;
  request.set_id(id);
  std::string ply;
  int64_t announced = -1;
  grpc::Status status = WithRetries(
      channel_.get(), call ? *call : defaults_, /*idempotent=*/true,
      [&](grpc::ClientContext* context) {
        ply.clear();
        announced = -1;
        std::unique_ptr<grpc::ClientReader<v1::PreviewChunk>> reader =
            stub_->GetPreview(context, request);
        v1::PreviewChunk chunk;
        while (reader->Read(&chunk)) {
          if (announced < 0) announced = chunk.total_bytes();
          ply.append(chunk.data());
        }
        return reader->Finish();
      });
  if (!status.ok()) return common::FromGrpcStatus(status);
  if (announced != static_cast<int64_t>(ply.size())) {
    return absl::DataLossError(absl::StrCat("preview of '", id, "': received ",
                                            ply.size(), " bytes of ", announced,
                                            " announced"));
  }
  return ply;
}

absl::StatusOr<v1::ListResponse> IndexerClient::List(
    const v1::ListRequest& request, const CallOptions* call) const {
  v1::ListResponse response;
  grpc::Status status =
      WithRetries(channel_.get(), call ? *call : defaults_, /*idempotent=*/true,
                  [&](grpc::ClientContext* context) {
                    return stub_->List(context, request, &response);
                  });
  if (!status.ok()) return common::FromGrpcStatus(status);
  return response;
}

absl::StatusOr<std::vector<v1::Model>> IndexerClient::ListAll(
    const std::string& label, const CallOptions* call) const {
  std::vector<v1::Model> models;
  v1::ListRequest request;
  request.set_page_size(1000);
  request.set_label(label);
  while (true) {
    absl::StatusOr<v1::ListResponse> page = List(request, call);
    if (!page.ok()) return page.status();
    for (v1::Model& m : *page->mutable_models()) models.push_back(std::move(m));
    if (page->next_page_token().empty()) break;
    request.set_page_token(page->next_page_token());
  }
  return models;
}

std::unique_ptr<SearchStream> IndexerClient::Search(
    const v1::SearchRequest& request, const CallOptions* call) const {
  return std::make_unique<GrpcSearchStream>(channel_, stub_, request,
                                            call ? *call : defaults_);
}

absl::StatusOr<v1::StatsResponse> IndexerClient::Stats(
    const CallOptions* call) const {
  v1::StatsRequest request;
  v1::StatsResponse response;
  grpc::Status status =
      WithRetries(channel_.get(), call ? *call : defaults_, /*idempotent=*/true,
                  [&](grpc::ClientContext* context) {
                    return stub_->Stats(context, request, &response);
                  });
  if (!status.ok()) return common::FromGrpcStatus(status);
  return response;
}

// --- Connect with TLS and API key --------------------------------------------

absl::StatusOr<ExtractorClient> ExtractorClient::Connect(
    absl::string_view addresses, const ConnectionOptions& connection,
    CallOptions defaults) {
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
      MakeChannel(addresses, connection);
  if (!channel.ok()) return channel.status();
  return ExtractorClient(*std::move(channel), defaults);
}

absl::StatusOr<IndexerClient> IndexerClient::Connect(
    absl::string_view addresses, const ConnectionOptions& connection,
    CallOptions defaults) {
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
      MakeChannel(addresses, connection);
  if (!channel.ok()) return channel.status();
  return IndexerClient(*std::move(channel), defaults);
}

}  // namespace tpr::client
