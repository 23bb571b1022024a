#include "indexer/gateway/gateway_service.h"

#include <grpcpp/client_context.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>
#include <grpcpp/support/client_interceptor.h>

#include <algorithm>
#include <chrono>
#include <climits>
#include <map>
#include <queue>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "common/call_interceptor.h"
#include "common/grpc_status.h"
#include "common/metrics.h"
#include "common/stream_messages.h"
#include "grpc/health/v1/health.grpc.pb.h"

namespace tpr::gateway {
namespace {

using Endpoint = Shards::Endpoint;

// Sends the gateway's own API key and the shard's place in the map ("I/N",
// kShardPlaceHeader: the shard refuses a place other than its stored one)
// to the shard and reports each call's end (GatewayOptions::on_shard_call).
class ShardCallInterceptor final : public grpc::experimental::Interceptor {
 public:
  ShardCallInterceptor(grpc::experimental::ClientRpcInfo* info, int shard,
                       const GatewayOptions* options)
      : shard_(shard),
        method_(info->method() != nullptr ? info->method() : ""),
        options_(options),
        start_(std::chrono::steady_clock::now()) {}

  void Intercept(
      grpc::experimental::InterceptorBatchMethods* methods) override {
    using grpc::experimental::InterceptionHookPoints;
    if (methods->QueryInterceptionHookPoint(
            InterceptionHookPoints::PRE_SEND_INITIAL_METADATA)) {
      auto* metadata = methods->GetSendInitialMetadata();
      if (!options_->shard_api_key.empty()) {
        metadata->emplace("authorization", "Bearer " + options_->shard_api_key);
      }
      metadata->emplace(
          kShardPlaceHeader,
          ShardPlaceOf(shard_,
                       static_cast<int>(options_->shards.shards.size())));
    }
    if (methods->QueryInterceptionHookPoint(
            InterceptionHookPoints::POST_RECV_STATUS) &&
        options_->on_shard_call) {
      ShardCall call;
      call.shard = shard_;
      call.method = method_;
      call.code = methods->GetRecvStatus()->error_code();
      call.seconds = std::chrono::duration<double>(
                         std::chrono::steady_clock::now() - start_)
                         .count();
      options_->on_shard_call(call);
    }
    methods->Proceed();
  }

 private:
  const int shard_;
  const std::string method_;
  const GatewayOptions* options_;
  const std::chrono::steady_clock::time_point start_;
};

class ShardCallInterceptorFactory final
    : public grpc::experimental::ClientInterceptorFactoryInterface {
 public:
  ShardCallInterceptorFactory(int shard, const GatewayOptions* options)
      : shard_(shard), options_(options) {}
  grpc::experimental::Interceptor* CreateClientInterceptor(
      grpc::experimental::ClientRpcInfo* info) override {
    return new ShardCallInterceptor(info, shard_, options_);
  }

 private:
  const int shard_;
  const GatewayOptions* options_;
};

// `options` must outlive the channel (Shards owns both).
std::shared_ptr<grpc::Channel> MakeShardChannel(const std::string& address,
                                                int shard,
                                                const GatewayOptions* options) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(options->max_message_bytes);
  args.SetMaxSendMessageSize(options->max_message_bytes);
  // gRPC's reconnect backoff starts at 1 s and grows to 120 s: a shard that
  // restarts would stay unreachable through this channel for minutes.
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 1000);
  if (!options->shard_tls_server_name.empty()) {
    args.SetSslTargetNameOverride(options->shard_tls_server_name);
  }
  std::vector<
      std::unique_ptr<grpc::experimental::ClientInterceptorFactoryInterface>>
      factories;
  factories.push_back(
      std::make_unique<ShardCallInterceptorFactory>(shard, options));
  return grpc::experimental::CreateCustomChannelWithInterceptors(
      address,
      options->shard_credentials != nullptr
          ? options->shard_credentials
          : grpc::InsecureChannelCredentials(),
      args, std::move(factories));
}

// Codes that describe the caller's request, not the shard's health: passed
// through unchanged so the gateway answers as one indexer would.
bool IsCallersFault(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::NOT_FOUND:
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
    case grpc::StatusCode::CANCELLED:
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return true;
    default:
      return false;
  }
}

absl::Status CancelledStatus(grpc::ServerContext* context) {
  return context->IsCancelled()
             ? absl::CancelledError("call cancelled or deadline exceeded")
             : absl::OkStatus();
}

// A shard context that inherits the caller's deadline and cancellation and
// carries its request id, so one call can be followed through every log.
std::unique_ptr<grpc::ClientContext> ShardContext(
    grpc::ServerContext* context) {
  std::unique_ptr<grpc::ClientContext> shard =
      grpc::ClientContext::FromServerContext(*context);
  const std::string request_id = tpr::common::RequestIdOf(*context);
  if (!request_id.empty()) shard->AddMetadata("x-request-id", request_id);
  return shard;
}

// Bounds that keep the gateway's answers as small as one indexer's, far
// below gRPC's default 4 MiB (indexer/service/indexer_core.h has the same).
constexpr size_t kMaxListPageBytes = 2 << 20;
constexpr size_t kMaxStatsLabels = 1000;

// AddStats adds the counts of `from` to `to` (not the milliseconds).
void AddStats(const tpr::v1::SearchStats& from, tpr::v1::SearchStats* to) {
  to->set_emd_computations(to->emd_computations() + from.emd_computations());
  to->set_lower_bounds(to->lower_bounds() + from.lower_bounds());
  to->set_nodes_visited(to->nodes_visited() + from.nodes_visited());
}

}  // namespace

std::function<void(const ShardCall&)> ShardCallMetrics(
    tpr::common::Metrics& metrics) {
  prometheus::Family<prometheus::Histogram>& duration =
      prometheus::BuildHistogram()
          .Name("tpr_gateway_shard_duration_seconds")
          .Help(
              "Calls of the gateway to its shards, by shard and method (not "
              "cancelled ones)")
          .Register(metrics.registry());
  prometheus::Family<prometheus::Counter>& errors =
      prometheus::BuildCounter()
          .Name("tpr_gateway_shard_errors_total")
          .Help(
              "Calls of the gateway to its shards that failed, by shard, "
              "method and code")
          .Register(metrics.registry());
  return [&duration, &errors](const ShardCall& call) {
    if (call.code == grpc::StatusCode::CANCELLED) return;
    const std::string shard = std::to_string(call.shard);
    duration
        .Add({{"shard", shard}, {"method", call.method}},
             tpr::common::SecondsBuckets())
        .Observe(call.seconds);
    if (call.code != grpc::StatusCode::OK) {
      errors
          .Add({{"shard", shard},
                {"method", call.method},
                {"code", absl::StatusCodeToString(
                             static_cast<absl::StatusCode>(call.code))}})
          .Increment();
    }
  };
}

// ---------------------------------------------------------------------------
// Shards.

Shards::Shards(const GatewayOptions& options) : options_(options) {
  by_shard_.resize(options_.shards.shards.size());
  for (size_t s = 0; s < options_.shards.shards.size(); ++s) {
    const ShardAddresses& shard = options_.shards.shards[s];
    std::vector<std::string> addresses = {shard.primary};
    addresses.insert(addresses.end(), shard.replicas.begin(),
                     shard.replicas.end());
    for (size_t i = 0; i < addresses.size(); ++i) {
      auto endpoint = std::make_unique<Endpoint>();
      endpoint->shard = static_cast<int>(s);
      endpoint->address = addresses[i];
      endpoint->primary = i == 0;
      endpoint->channel =
          MakeShardChannel(addresses[i], static_cast<int>(s), &options_);
      endpoint->stub = tpr::v1::Indexer::NewStub(endpoint->channel);
      endpoint->serving = endpoint->primary;
      if (endpoint->primary) primaries_.push_back(endpoint.get());
      by_shard_[s].push_back(endpoint.get());
      endpoints_.push_back(std::move(endpoint));
    }
  }
  if (options_.health_interval_ms > 0)
    checker_ = std::thread([this] { Loop(); });
}

Shards::~Shards() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  wake_.notify_all();
  if (checker_.joinable()) checker_.join();
}

void Shards::Log(const std::string& line) const {
  if (options_.log) options_.log(line);
}

std::vector<Endpoint*> Shards::ReadOrder(int shard) {
  if (options_.reads_from_primary)
    return {primaries_[static_cast<size_t>(shard)]};
  const std::vector<Endpoint*>& all = by_shard_[static_cast<size_t>(shard)];
  std::vector<Endpoint*> serving;
  const size_t start =
      static_cast<size_t>(round_robin_.fetch_add(1) % all.size());
  for (size_t i = 0; i < all.size(); ++i) {
    Endpoint* e = all[(start + i) % all.size()];
    if (e->serving.load()) serving.push_back(e);
  }
  // With every address marked down, the primary is still tried: it may have
  // restarted since its last check, and it is never stale (a follower might
  // be), so a read only fails once it fails too.
  if (serving.empty())
    serving.push_back(primaries_[static_cast<size_t>(shard)]);
  return serving;
}

void Shards::MarkDown(Endpoint* endpoint, const std::string& reason) {
  if (endpoint->serving.exchange(false)) {
    Log(absl::StrCat("shard ", endpoint->shard, " address ", endpoint->address,
                     " marked down: ", reason));
  }
}

void Shards::Check(Endpoint* endpoint) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::milliseconds(options_.health_timeout_ms));
  // Readiness, not liveness (common/health.h): a loading indexer or a
  // follower still catching up is alive but must not be read from.
  grpc::health::v1::HealthCheckRequest request;
  request.set_service("tpr.v1.Indexer");
  grpc::health::v1::HealthCheckResponse response;
  const grpc::Status status =
      grpc::health::v1::Health::NewStub(endpoint->channel)
          ->Check(&context, request, &response);
  const bool serving =
      status.ok() &&
      response.status() == grpc::health::v1::HealthCheckResponse::SERVING;
  if (endpoint->serving.exchange(serving) != serving) {
    Log(absl::StrCat(
        "shard ", endpoint->shard, " address ", endpoint->address,
        serving ? " serving" : " not serving",
        status.ok() ? "" : absl::StrCat(" (", status.error_message(), ")")));
  }
}

void Shards::CheckNow() {
  for (const auto& endpoint : endpoints_) Check(endpoint.get());
}

void Shards::Loop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!stop_) {
    lock.unlock();
    CheckNow();
    lock.lock();
    wake_.wait_for(lock, std::chrono::milliseconds(options_.health_interval_ms),
                   [this] { return stop_; });
  }
}

// ---------------------------------------------------------------------------
// GatewayService: plumbing.

GatewayService::GatewayService(GatewayOptions options)
    : options_(std::move(options)), shards_(options_) {
  constexpr int kBatchUpsertMethod = 1;  // its position in indexer.proto
  MarkMethodStreamed(
      kBatchUpsertMethod,
      tpr::common::RawClientStreamHandler<tpr::v1::Indexer::Service,
                                          tpr::v1::UpsertRequest>(
          GetHandler(kBatchUpsertMethod), "BatchUpsert", this,
          &GatewayService::BatchUpsertRaw));
}

absl::Status GatewayService::FromShard(int shard, const std::string& address,
                                       const grpc::Status& status) const {
  if (status.ok() || IsCallersFault(status.error_code()))
    return common::FromGrpcStatus(status);
  return common::FromGrpcStatus(grpc::Status(
      status.error_code(), absl::StrCat("shard ", shard, " (", address,
                                        "): ", status.error_message())));
}

grpc::Status GatewayService::Finish(const char* method,
                                    const absl::Status& status) const {
  if (options_.log && !status.ok() &&
      !IsCallersFault(static_cast<grpc::StatusCode>(status.code()))) {
    options_.log(absl::StrCat(method, " failed: ", status.ToString()));
  }
  return common::ToGrpcStatus(status);
}

absl::Status GatewayService::Read(
    grpc::ServerContext* context, int shard,
    const std::function<grpc::Status(Endpoint&, grpc::ClientContext*)>& call) {
  std::vector<std::string> tried;
  for (Endpoint* endpoint : shards_.ReadOrder(shard)) {
    std::unique_ptr<grpc::ClientContext> shard_context = ShardContext(context);
    const grpc::Status status = call(*endpoint, shard_context.get());
    if (status.error_code() != grpc::StatusCode::UNAVAILABLE) {
      return FromShard(shard, endpoint->address, status);
    }
    shards_.MarkDown(endpoint, status.error_message());
    tried.push_back(
        absl::StrCat(endpoint->address, ": ", status.error_message()));
  }
  if (absl::Status c = CancelledStatus(context); !c.ok()) return c;
  return absl::UnavailableError(absl::StrCat("shard ", shard,
                                             " has no serving replica (tried ",
                                             absl::StrJoin(tried, "; "), ")"));
}

// ---------------------------------------------------------------------------
// Writes: the owning shard's primary.

grpc::Status GatewayService::Upsert(grpc::ServerContext* context,
                                    const tpr::v1::UpsertRequest* request,
                                    tpr::v1::UpsertResponse* response) {
  const int shard = ShardOf(request->model().id(), shards_.count());
  Endpoint& primary = shards_.primary(shard);
  std::unique_ptr<grpc::ClientContext> shard_context = ShardContext(context);
  const grpc::Status status =
      primary.stub->Upsert(shard_context.get(), *request, response);
  return Finish("Upsert", FromShard(shard, primary.address, status));
}

grpc::Status GatewayService::Delete(grpc::ServerContext* context,
                                    const tpr::v1::DeleteRequest* request,
                                    tpr::v1::DeleteResponse* response) {
  const int shard = ShardOf(request->id(), shards_.count());
  Endpoint& primary = shards_.primary(shard);
  std::unique_ptr<grpc::ClientContext> shard_context = ShardContext(context);
  const grpc::Status status =
      primary.stub->Delete(shard_context.get(), *request, response);
  return Finish("Delete", FromShard(shard, primary.address, status));
}

grpc::Status GatewayService::BatchUpsertRaw(
    grpc::ServerContext* context, grpc::ServerReader<grpc::ByteBuffer>* reader,
    tpr::v1::BatchUpsertResponse* response) {
  // One BatchUpsert stream per shard primary, opened when the shard gets its
  // first model; each shard groups and syncs its own writes.
  struct ShardBatch {
    std::unique_ptr<grpc::ClientContext> context;
    tpr::v1::BatchUpsertResponse response;
    std::unique_ptr<grpc::ClientWriter<tpr::v1::UpsertRequest>> writer;
    bool broken = false;
  };
  std::vector<ShardBatch> batches(static_cast<size_t>(shards_.count()));
  tpr::common::StreamParser<tpr::v1::UpsertRequest> parser("BatchUpsert");
  grpc::ByteBuffer raw;
  tpr::v1::UpsertRequest request;
  absl::Status first_error;
  while (reader->Read(&raw)) {
    // A message that does not parse ends the reading; the shards' streams
    // are finished below (the models before it are kept), then it fails.
    first_error = parser.Parse(&raw, &request);
    if (!first_error.ok()) break;
    const int shard = ShardOf(request.model().id(), shards_.count());
    ShardBatch& batch = batches[static_cast<size_t>(shard)];
    if (batch.writer == nullptr) {
      batch.context = ShardContext(context);
      batch.writer = shards_.primary(shard).stub->BatchUpsert(
          batch.context.get(), &batch.response);
    }
    // A failed write means the shard's stream ended (its error comes with
    // Finish below); stop reading: the call fails anyway.
    if (!batch.writer->Write(request)) {
      batch.broken = true;
      break;
    }
    request.Clear();
  }
  // Every shard's answer is collected even after a failure: what a shard
  // acknowledged is durable there, and only a full set of OKs is an OK.
  for (size_t s = 0; s < batches.size(); ++s) {
    ShardBatch& batch = batches[s];
    if (batch.writer == nullptr) continue;
    if (!batch.broken) batch.writer->WritesDone();
    const grpc::Status status = batch.writer->Finish();
    if (status.ok()) {
      response->set_written(response->written() + batch.response.written());
      response->set_skipped(response->skipped() + batch.response.skipped());
    } else if (first_error.ok()) {
      first_error =
          FromShard(static_cast<int>(s),
                    shards_.primary(static_cast<int>(s)).address, status);
    }
  }
  if (!first_error.ok()) {
    response->Clear();
    return Finish("BatchUpsert", first_error);
  }
  if (absl::Status c = CancelledStatus(context); !c.ok())
    return Finish("BatchUpsert", c);
  return grpc::Status::OK;
}

// ---------------------------------------------------------------------------
// Reads.

grpc::Status GatewayService::Get(grpc::ServerContext* context,
                                 const tpr::v1::GetRequest* request,
                                 tpr::v1::Model* response) {
  const int shard = ShardOf(request->id(), shards_.count());
  return Finish("Get",
                Read(context, shard, [&](Endpoint& e, grpc::ClientContext* c) {
                  return e.stub->Get(c, *request, response);
                }));
}

grpc::Status GatewayService::GetThumbnail(
    grpc::ServerContext* context, const tpr::v1::GetThumbnailRequest* request,
    tpr::v1::Thumbnail* response) {
  const int shard = ShardOf(request->id(), shards_.count());
  return Finish("GetThumbnail",
                Read(context, shard, [&](Endpoint& e, grpc::ClientContext* c) {
                  return e.stub->GetThumbnail(c, *request, response);
                }));
}

grpc::Status GatewayService::GetPreview(
    grpc::ServerContext* context, const tpr::v1::GetPreviewRequest* request,
    grpc::ServerWriter<tpr::v1::PreviewChunk>* writer) {
  const int shard = ShardOf(request->id(), shards_.count());
  std::vector<tpr::v1::PreviewChunk> chunks;
  absl::Status status =
      Read(context, shard, [&](Endpoint& e, grpc::ClientContext* c) {
        chunks.clear();  // a failed address's part, before the next one
        std::unique_ptr<grpc::ClientReader<tpr::v1::PreviewChunk>> reader =
            e.stub->GetPreview(c, *request);
        tpr::v1::PreviewChunk chunk;
        while (reader->Read(&chunk)) chunks.push_back(std::move(chunk));
        return reader->Finish();
      });
  if (!status.ok()) return Finish("GetPreview", status);
  for (const tpr::v1::PreviewChunk& chunk : chunks) {
    if (!writer->Write(chunk)) {
      return Finish("GetPreview",
                    absl::CancelledError("client stopped reading the stream"));
    }
  }
  return grpc::Status::OK;
}

grpc::Status GatewayService::Stats(grpc::ServerContext* context,
                                   const tpr::v1::StatsRequest* request,
                                   tpr::v1::StatsResponse* response) {
  std::map<std::string, int64_t> labels;
  for (int s = 0; s < shards_.count(); ++s) {
    tpr::v1::ShardStats* shard = response->add_shards();
    shard->set_shard(s);
    absl::Status status =
        Read(context, s, [&](Endpoint& e, grpc::ClientContext* c) {
          shard->set_address(e.address);
          return e.stub->Stats(c, *request, shard->mutable_stats());
        });
    if (!status.ok()) {
      response->Clear();
      return Finish("Stats", status);
    }
    const tpr::v1::StatsResponse& one = shard->stats();
    response->set_models(response->models() + one.models());
    response->set_indexed(response->indexed() + one.indexed());
    response->set_buffered(response->buffered() + one.buffered());
    response->set_memory_bytes(response->memory_bytes() + one.memory_bytes());
    response->set_disk_bytes(response->disk_bytes() + one.disk_bytes());
    for (const auto& [label, count] : one.labels()) labels[label] += count;
    // The sums carry the labels; per shard only the counts, so the answer
    // stays bounded whatever the number of shards.
    shard->mutable_stats()->clear_labels();
  }
  // Like one indexer: the kMaxStatsLabels most populous labels, ties by
  // label. (Each shard reports its own top labels, so a label outside every
  // shard's top list is missing from the sums.)
  std::vector<std::pair<std::string, int64_t>> top(labels.begin(),
                                                   labels.end());
  auto more_models = [](const auto& a, const auto& b) {
    return a.second != b.second ? a.second > b.second : a.first < b.first;
  };
  if (top.size() > kMaxStatsLabels) {
    std::partial_sort(
        top.begin(), top.begin() + static_cast<std::ptrdiff_t>(kMaxStatsLabels),
        top.end(), more_models);
    top.resize(kMaxStatsLabels);
  }
  for (const auto& [label, count] : top)
    (*response->mutable_labels())[label] = count;
  return grpc::Status::OK;
}

grpc::Status GatewayService::List(grpc::ServerContext* context,
                                  const tpr::v1::ListRequest* request,
                                  tpr::v1::ListResponse* response) {
  if (request->page_size() < 0) {
    return Finish("List", absl::InvalidArgumentError(absl::StrCat(
                              "page_size is ", request->page_size(),
                              "; it must be >= 0")));
  }
  // The same page size rule as one indexer (indexer.proto).
  const int page_size =
      request->page_size() == 0 ? 100 : std::min(request->page_size(), 1000);
  absl::StatusOr<std::vector<ListPosition>> positions =
      DecodeListToken(request->page_token(), shards_.count());
  if (!positions.ok()) return Finish("List", positions.status());
  const size_t count = static_cast<size_t>(shards_.count());
  std::vector<tpr::v1::ListResponse> shard_pages(count);
  std::vector<ShardPage> pages(count);
  for (size_t s = 0; s < count; ++s) {
    if ((*positions)[s].done) continue;
    tpr::v1::ListRequest shard_request;
    shard_request.set_page_size(page_size);
    if (!(*positions)[s].after.empty()) {
      shard_request.set_page_token(
          EncodeIndexerListToken((*positions)[s].after));
    }
    shard_request.set_label(request->label());
    absl::Status status = Read(
        context, static_cast<int>(s), [&](Endpoint& e, grpc::ClientContext* c) {
          return e.stub->List(c, shard_request, &shard_pages[s]);
        });
    if (!status.ok()) return Finish("List", status);
    for (const tpr::v1::Model& m : shard_pages[s].models())
      pages[s].ids.push_back(m.id());
    absl::StatusOr<std::string> next =
        DecodeIndexerListToken(shard_pages[s].next_page_token());
    if (!next.ok()) {
      return Finish(
          "List", absl::InternalError(absl::StrCat(
                      "shard ", s, " answered a List page token ",
                      "this gateway cannot read: ", next.status().message())));
    }
    pages[s].next_token = *std::move(next);
  }
  ListMerge merge =
      MergeListPages(*positions, pages, static_cast<size_t>(page_size));
  // The page ends before kMaxListPageBytes of models (at least one), as one
  // indexer's does; the merge is greedy, so merging again with the shorter
  // size takes the same first models and gives the positions after them.
  size_t bytes = 0;
  for (size_t i = 0; i < merge.taken.size(); ++i) {
    const auto& [shard, index] = merge.taken[i];
    bytes +=
        shard_pages[static_cast<size_t>(shard)].models(index).ByteSizeLong() +
        6;
    if (bytes > kMaxListPageBytes && i > 0) {
      merge = MergeListPages(*positions, pages, i);
      break;
    }
  }
  for (const auto& [shard, index] : merge.taken) {
    *response->add_models() = std::move(
        *shard_pages[static_cast<size_t>(shard)].mutable_models(index));
  }
  if (!merge.last)
    response->set_next_page_token(EncodeListToken(merge.positions));
  return grpc::Status::OK;
}

// ---------------------------------------------------------------------------
// Search: exact k-NN over every shard.

namespace {

// One shard's search stream as the merge sees it.
struct ShardStream {
  int shard = 0;
  tpr::v1::SearchRequest request;
  std::vector<Endpoint*> candidates;  // serving addresses left to try
  Endpoint* endpoint = nullptr;
  std::unique_ptr<grpc::ClientContext> context;
  std::unique_ptr<grpc::ClientReader<tpr::v1::SearchResponse>> reader;
  bool received = false;  // anything read from the current address
  bool ended = false;     // stream finished (stats read or error)
  bool has_head = false;
  tpr::v1::Neighbor head;  // its progress moved to `last`
  // The shard's cumulative statistics as last read: the progress of the
  // last neighbour read, or its final SearchStats (tpr.v1.Neighbor.progress).
  tpr::v1::SearchStats last;
};

// The merge heap's order: the smallest (distance, id) on top.
struct HeadAfter {
  const std::vector<ShardStream>* streams;
  bool operator()(int a, int b) const {
    const tpr::v1::Neighbor& x = (*streams)[static_cast<size_t>(a)].head;
    const tpr::v1::Neighbor& y = (*streams)[static_cast<size_t>(b)].head;
    return RanksBefore(y.distance(), y.id(), x.distance(), x.id());
  }
};

}  // namespace

grpc::Status GatewayService::Search(
    grpc::ServerContext* context, const tpr::v1::SearchRequest* request,
    grpc::ServerWriter<tpr::v1::SearchResponse>* writer) {
  const auto start = std::chrono::steady_clock::now();
  // The checks one indexer makes before any work, so that k + 1 below and
  // the fan-out never run on a request every shard would refuse.
  if (request->k() < 1) {
    return Finish("Search", absl::InvalidArgumentError(absl::StrCat(
                                "k is ", request->k(), "; it must be >= 1")));
  }
  if (request->query_case() == tpr::v1::SearchRequest::QUERY_NOT_SET) {
    return Finish("Search", absl::InvalidArgumentError(
                                "search has no query: set signature or id"));
  }
  const int count = shards_.count();
  tpr::v1::SearchRequest shard_request = *request;
  shard_request.clear_exclude_self();
  int owner = -1;
  std::string exclude;
  if (request->query_case() == tpr::v1::SearchRequest::kId) {
    // The query signature comes from the owning shard; every shard then
    // ranks against the same signature (one indexer does the same with its
    // stored copy).
    owner = ShardOf(request->id(), count);
    tpr::v1::GetRequest get;
    get.set_id(request->id());
    tpr::v1::Model model;
    absl::Status got =
        Read(context, owner, [&](Endpoint& e, grpc::ClientContext* c) {
          return e.stub->Get(c, get, &model);
        });
    if (!got.ok()) return Finish("Search", got);
    *shard_request.mutable_signature() = std::move(*model.mutable_signature());
    if (request->exclude_self()) exclude = request->id();
  }

  // Start every shard's stream before reading any: the shards search in
  // parallel while the merge waits for the first heads.
  std::vector<ShardStream> streams(static_cast<size_t>(count));
  auto open = [&](ShardStream& st) -> bool {
    if (st.candidates.empty()) return false;
    st.endpoint = st.candidates.front();
    st.candidates.erase(st.candidates.begin());
    st.context = ShardContext(context);
    // Each neighbour carries the shard's statistics so far, so that a
    // stream cancelled below still counts the work it did up to the last
    // neighbour read.
    st.context->AddMetadata(tpr::common::kSearchProgressHeader, "1");
    st.reader = st.endpoint->stub->Search(st.context.get(), st.request);
    st.received = false;
    st.last.Clear();
    return true;
  };
  std::vector<std::string> tried;
  // Reads the next neighbour of `st` into its head (or ends it, keeping its
  // final statistics); fails over to the shard's next address when the
  // current one is unavailable before it sent anything.
  auto advance = [&](ShardStream& st) -> absl::Status {
    st.has_head = false;
    tpr::v1::SearchResponse item;
    while (!st.ended) {
      if (st.reader->Read(&item)) {
        st.received = true;
        if (item.has_neighbor()) {
          st.head = std::move(*item.mutable_neighbor());
          // A shard without progress (an older indexer) is counted by its
          // final statistics only.
          if (st.head.has_progress()) st.last = st.head.progress();
          st.head.clear_progress();
          st.has_head = true;
          return absl::OkStatus();
        }
        if (item.has_stats()) st.last = item.stats();
        continue;
      }
      const grpc::Status status = st.reader->Finish();
      if (status.ok()) {
        st.ended = true;
        return absl::OkStatus();
      }
      if (status.error_code() == grpc::StatusCode::UNAVAILABLE &&
          !st.received) {
        shards_.MarkDown(st.endpoint, status.error_message());
        tried.push_back(
            absl::StrCat(st.endpoint->address, ": ", status.error_message()));
        if (open(st)) continue;
        st.ended = true;
        if (absl::Status c = CancelledStatus(context); !c.ok()) return c;
        return absl::UnavailableError(
            absl::StrCat("shard ", st.shard, " has no serving replica (tried ",
                         absl::StrJoin(tried, "; "), ")"));
      }
      st.ended = true;
      return FromShard(st.shard, st.endpoint->address, status);
    }
    return absl::OkStatus();
  };
  // Cancels the streams still running and collects their ends.
  auto stop_all = [&]() {
    for (ShardStream& st : streams) {
      if (st.reader == nullptr || st.ended) continue;
      st.context->TryCancel();
      st.reader->Finish();
      st.ended = true;
    }
  };

  for (int s = 0; s < count; ++s) {
    ShardStream& st = streams[static_cast<size_t>(s)];
    st.shard = s;
    st.request = shard_request;
    if (s == owner && !exclude.empty()) {
      // The query model itself is on its owner and is dropped here, so the
      // owner must send one more to leave k others.
      st.request.set_k(request->k() == INT_MAX ? INT_MAX : request->k() + 1);
    }
    st.candidates = shards_.ReadOrder(s);  // never empty
    open(st);
  }
  std::vector<int> heap;
  HeadAfter after{&streams};
  for (ShardStream& st : streams) {
    if (absl::Status s = advance(st); !s.ok()) {
      stop_all();
      return Finish("Search", s);
    }
    if (st.has_head) heap.push_back(st.shard);
  }
  std::make_heap(heap.begin(), heap.end(), after);

  // The statistics: per shard, the work up to the last neighbour read from
  // it (or all of it, for a stream that ended), summed; the milliseconds
  // are the gateway's own. Exact by construction, whichever streams are
  // cancelled; work a shard did ahead of the gateway's reading is not
  // counted. Callers that ask get the same sum as each neighbour's progress.
  auto sum_stats = [&]() {
    tpr::v1::SearchStats sum;
    for (const ShardStream& st : streams) AddStats(st.last, &sum);
    sum.set_milliseconds(std::chrono::duration<double, std::milli>(
                             std::chrono::steady_clock::now() - start)
                             .count());
    return sum;
  };
  const bool progress = tpr::common::WantsSearchProgress(*context);
  tpr::v1::SearchResponse response;
  int sent = 0;
  while (sent < request->k() && !heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), after);
    ShardStream& st = streams[static_cast<size_t>(heap.back())];
    heap.pop_back();
    if (st.head.id() != exclude) {
      *response.mutable_neighbor() = st.head;
      response.mutable_neighbor()->set_rank(++sent);
      if (progress)
        *response.mutable_neighbor()->mutable_progress() = sum_stats();
      if (!writer->Write(response)) {
        stop_all();
        return Finish("Search", absl::CancelledError(
                                    "client stopped reading the stream"));
      }
      if (sent == request->k()) break;  // lazily: no more from any shard
    }
    if (absl::Status s = advance(st); !s.ok()) {
      stop_all();
      return Finish("Search", s);
    }
    if (st.has_head) {
      heap.push_back(st.shard);
      std::push_heap(heap.begin(), heap.end(), after);
    }
  }
  stop_all();
  if (absl::Status c = CancelledStatus(context); !c.ok())
    return Finish("Search", c);
  *response.mutable_stats() = sum_stats();
  writer->Write(response);
  return grpc::Status::OK;
}

}  // namespace tpr::gateway
