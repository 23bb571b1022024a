#include "extractor/service/extractor_service.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <optional>
#include <set>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "common/grpc_status.h"
#include "common/status_macros.h"
#include "common/stream_messages.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/service/convert.h"
#include "extractor/service/extract_metrics.h"
#include "extractor/service/media.h"

namespace tpr::extractor {
namespace {

double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now() - start)
      .count();
}

// A fixed set of threads draining a FIFO queue. Hand-written (a dozen lines)
// rather than pulling TBB in for one queue.
class WorkerPool {
 public:
  explicit WorkerPool(int threads) {
    for (int i = 0; i < std::max(1, threads); ++i) {
      threads_.emplace_back([this] { Loop(); });
    }
  }
  ~WorkerPool() {
    {
      absl::MutexLock lock(&mu_);
      stopping_ = true;
    }
    for (std::thread& t : threads_) t.join();
  }
  void Submit(std::function<void()> job) {
    absl::MutexLock lock(&mu_);
    queue_.push_back(std::move(job));
  }

 private:
  void Loop() {
    while (true) {
      std::function<void()> job;
      {
        absl::MutexLock lock(&mu_);
        mu_.Await(absl::Condition(
            +[](WorkerPool* p) { return p->stopping_ || !p->queue_.empty(); },
            this));
        // Drain the queue before stopping: every queued job owns a call that
        // must be finished.
        if (queue_.empty()) return;
        job = std::move(queue_.front());
        queue_.pop_front();
      }
      job();
    }
  }

  absl::Mutex mu_;
  std::deque<std::function<void()>> queue_ ABSL_GUARDED_BY(mu_);
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  std::vector<std::thread> threads_;
};

// CheckStreamMessage refuses what message `index` (0-based) of an upload
// must not carry: an unknown format value in the first; any header field
// (format, file_name, options, media: first message only) in a later one.
// INVALID_ARGUMENT naming the field.
absl::Status CheckStreamMessage(const v1::ExtractRequest& request, int index) {
  if (index == 0) {
    if (!v1::MeshFormat_IsValid(request.format())) {
      return absl::InvalidArgumentError(absl::StrCat(
          "format is ", request.format(), ", not a MeshFormat value"));
    }
    return absl::OkStatus();
  }
  const char* field = nullptr;
  if (request.format() != 0) field = "format";
  if (!request.file_name().empty()) field = "file_name";
  if (request.has_options()) field = "options";
  if (request.has_media()) field = "media";
  if (field == nullptr) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrCat(field, " is set in message ", index + 1,
                   " of the upload; only the first message may carry it"));
}

}  // namespace

absl::StatusOr<v1::ExtractResponse> RunExtraction(
    std::string bytes, const v1::ExtractRequest& header,
    const ServiceOptions& options, const std::function<bool()>& cancelled) {
  if (bytes.empty()) {
    return absl::InvalidArgumentError("the upload carried no mesh data");
  }
  TPR_ASSIGN_OR_RETURN(
      extract::Options extract_options,
      OptionsFromProto(header.options(), options.max_threads_per_extraction));
  if (cancelled())
    return absl::CancelledError("extraction cancelled before intake");

  extract::IntakeOptions intake_options;
  intake_options.max_vertices = options.max_vertices;
  const auto intake_start = std::chrono::steady_clock::now();
  TPR_ASSIGN_OR_RETURN(
      extract::LoadedMesh loaded,
      extract::LoadMeshFromBuffer(bytes, FormatFromProto(header.format()),
                                  header.file_name(), intake_options));
  const double intake_ms = MillisecondsSince(intake_start);
  std::string().swap(bytes);  // the upload is parsed: free it before extraction
  if (cancelled())
    return absl::CancelledError("extraction cancelled after intake");

  // The overlay draws the features: explain for it, without changing the
  // options the signature records or the explanation returned.
  extract::Options run_options = extract_options;
  run_options.explain |= NeedsExplanation(header.media());
  TPR_ASSIGN_OR_RETURN(
      extract::ExtractResult result,
      extract::ExtractSignature(loaded.mesh, loaded.stats, run_options));
  if (cancelled())
    return absl::CancelledError("extraction cancelled after extraction");

  v1::ExtractResponse response;
  // Intake's statistics are the mesh "as the extractor read it".
  result.signature.stats = loaded.stats;
  *response.mutable_signature() =
      SignatureToProto(result.signature, extract_options);
  v1::StageTiming* intake = response.add_timings();
  intake->set_stage("intake");
  intake->set_milliseconds(intake_ms);
  for (const extract::StageTiming& t : result.timings) {
    v1::StageTiming* out = response.add_timings();
    out->set_stage(t.stage);
    out->set_milliseconds(t.milliseconds);
  }
  for (const std::string& w : loaded.warnings) response.add_warnings(w);
  for (const std::string& w : result.warnings) response.add_warnings(w);
  if (extract_options.explain && result.explanation.has_value()) {
    *response.mutable_explanation() =
        ExplanationToProto(*result.explanation, loaded.mesh);
  }
  if (WantsMedia(header.media())) {
    std::vector<std::string> warnings;
    *response.mutable_media() =
        MakeMedia(loaded.mesh, result, header.media(), &warnings);
    for (std::string& w : warnings) response.add_warnings(std::move(w));
  }
  return response;
}

namespace {

using Clock = std::chrono::steady_clock;

class ExtractReactor;

// Refuses uploads that stall or crawl (ServiceOptions::upload_idle_timeout_ms,
// min_upload_bytes_per_second): a thread wakes a few times per idle timeout,
// asks every open call whether its upload has expired, and finishes those
// that have. Calls register when admitted and unregister in OnDone.
class UploadWatchdog {
 public:
  explicit UploadWatchdog(const ServiceOptions& options);
  ~UploadWatchdog();
  void Add(ExtractReactor* call) {
    absl::MutexLock lock(&mu_);
    calls_.insert(call);
  }
  void Remove(ExtractReactor* call) {
    absl::MutexLock lock(&mu_);
    calls_.erase(call);
  }

 private:
  void Loop();

  absl::Mutex mu_;
  std::set<ExtractReactor*> calls_ ABSL_GUARDED_BY(mu_);
  bool stopping_ ABSL_GUARDED_BY(mu_) = false;
  absl::Duration period_;
  std::thread thread_;
};

}  // namespace

struct ExtractorService::State {
  explicit State(const ServiceOptions& o)
      : options(o), watchdog(o), pool(o.worker_threads) {}
  const ServiceOptions options;
  std::atomic<int> in_flight{0};
  UploadWatchdog watchdog;
  // Declared last: destroyed first, so queued jobs still see valid state.
  WorkerPool pool;
};

namespace {

// One Extract call. Lifetime: created by the service, deleted in OnDone,
// which gRPC calls once Finish has completed and every reaction returned.
// The worker job touches the reactor only up to its Finish call.
//
// Exactly one party finishes the call. While uploading (phase_ kUploading)
// that is OnReadDone or, for an expired upload, the watchdog; each claims
// the call by leaving kUploading under mu_, so the other then does
// nothing. Once the upload is complete (kQueued) only the worker finishes.
class ExtractReactor final : public grpc::ServerReadReactor<grpc::ByteBuffer> {
 public:
  ExtractReactor(ExtractorService::State* state,
                 grpc::CallbackServerContext* context,
                 v1::ExtractResponse* response)
      : state_(state),
        options_(&state->options),
        context_(context),
        response_(response),
        admitted_(Clock::now()),
        last_message_(admitted_) {
    StartRead(&raw_);
    // After StartRead: the watchdog may finish the call from now on.
    state_->watchdog.Add(this);
  }

  void OnReadDone(bool ok) override {
    absl::MutexLock lock(&mu_);
    if (phase_ != Phase::kUploading) return;  // the watchdog finished it
    if (!ok) {
      // End of the upload (or a broken stream / cancel).
      if (cancelled_.load() || context_->IsCancelled()) {
        FinishLocked(
            grpc::Status(grpc::StatusCode::CANCELLED, "upload cancelled"));
        return;
      }
      if (!got_first_) {
        FinishLocked(
            grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                         "the upload carried no messages (no mesh data)"));
        return;
      }
      phase_ = Phase::kQueued;
      state_->pool.Submit([this] { Work(); });
      return;
    }
    last_message_ = Clock::now();
    if (absl::Status bad = parser_.Parse(&raw_, &request_); !bad.ok()) {
      FinishLocked(common::ToGrpcStatus(bad));
      return;
    }
    if (absl::Status bad = CheckStreamMessage(request_, messages_++);
        !bad.ok()) {
      FinishLocked(common::ToGrpcStatus(bad));
      return;
    }
    if (!got_first_) {
      got_first_ = true;
      header_.set_format(request_.format());
      header_.set_file_name(request_.file_name());
      *header_.mutable_options() = request_.options();
      *header_.mutable_media() = request_.media();
    }
    std::string* chunk = request_.mutable_data();
    if (static_cast<int64_t>(bytes_.size() + chunk->size()) >
        options_->max_mesh_bytes) {
      // Stop reading now: the rest of the stream is never buffered.
      FinishLocked(grpc::Status(
          grpc::StatusCode::RESOURCE_EXHAUSTED,
          absl::StrCat("mesh upload exceeds the server limit of ",
                       options_->max_mesh_bytes, " bytes (--max-mesh-bytes)")));
      return;
    }
    if (bytes_.empty()) {
      bytes_.swap(*chunk);  // most uploads are one chunk: no copy
    } else {
      // Reserve the limit once instead of growing geometrically: growth
      // would briefly hold old and new buffers (up to 3x the data), while
      // untouched reserved pages cost no resident memory.
      if (bytes_.capacity() < static_cast<size_t>(options_->max_mesh_bytes)) {
        bytes_.reserve(static_cast<size_t>(options_->max_mesh_bytes));
      }
      bytes_.append(*chunk);
      chunk->clear();
    }
    if (cancelled_.load()) {
      FinishLocked(
          grpc::Status(grpc::StatusCode::CANCELLED, "upload cancelled"));
      return;
    }
    StartRead(&raw_);
  }

  void OnCancel() override { cancelled_.store(true); }

  void OnDone() override {
    state_->watchdog.Remove(this);
    state_->in_flight.fetch_sub(1);
    delete this;
  }

  // Expire returns why the upload must be refused at `now`, claiming the
  // call (the caller must then Finish it with that status), or nullopt when
  // it is not uploading or is within both limits. Thread-safe.
  std::optional<grpc::Status> Expire(Clock::time_point now) {
    absl::MutexLock lock(&mu_);
    if (phase_ != Phase::kUploading) return std::nullopt;
    const int64_t idle_ms = options_->upload_idle_timeout_ms;
    const int64_t rate = options_->min_upload_bytes_per_second;
    std::optional<grpc::Status> refusal;
    if (idle_ms > 0 &&
        now - last_message_ >= std::chrono::milliseconds(idle_ms)) {
      refusal = grpc::Status(
          grpc::StatusCode::DEADLINE_EXCEEDED,
          absl::StrCat("upload stalled: no message for ", idle_ms,
                       " ms (server --upload-idle-timeout-ms) after ",
                       bytes_.size(), " bytes"));
    } else if (rate > 0) {
      const double beyond_grace_s =
          std::chrono::duration<double>(now - admitted_).count() -
          idle_ms / 1000.0;
      if (beyond_grace_s > 0 &&
          static_cast<double>(bytes_.size()) < rate * beyond_grace_s) {
        refusal = grpc::Status(
            grpc::StatusCode::DEADLINE_EXCEEDED,
            absl::StrCat("upload too slow: ", bytes_.size(), " bytes in ",
                         static_cast<int64_t>(beyond_grace_s * 1000 + idle_ms),
                         " ms, below the server minimum of ", rate,
                         " bytes/s after the first ", idle_ms,
                         " ms (--min-upload-bytes-per-second)"));
      }
    }
    if (refusal.has_value()) {
      phase_ = Phase::kFinished;
      std::string().swap(bytes_);
    }
    return refusal;
  }

 private:
  enum class Phase { kUploading, kQueued, kFinished };

  // Finishes from a reaction: gRPC defers the resulting OnDone until the
  // reaction returns, so holding mu_ here is safe.
  void FinishLocked(grpc::Status status) ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    phase_ = Phase::kFinished;
    std::string().swap(bytes_);
    Finish(std::move(status));
  }

  void Work() {
    absl::StatusOr<v1::ExtractResponse> result = RunExtraction(
        std::move(bytes_), header_, *options_,
        [this] { return cancelled_.load() || context_->IsCancelled(); });
    if (result.ok()) *response_ = *std::move(result);
    Finish(common::ToGrpcStatus(result.status()));
  }

  ExtractorService::State* const state_;
  const ServiceOptions* const options_;
  grpc::CallbackServerContext* const context_;
  v1::ExtractResponse* const response_;
  const Clock::time_point admitted_;
  absl::Mutex mu_;
  Phase phase_ ABSL_GUARDED_BY(mu_) = Phase::kUploading;
  Clock::time_point last_message_ ABSL_GUARDED_BY(mu_);
  grpc::ByteBuffer raw_;  // the message being read, parsed by parser_
  common::StreamParser<v1::ExtractRequest> parser_{"Extract"};
  v1::ExtractRequest request_;
  v1::ExtractRequest header_;
  // Written under mu_ while uploading; the worker owns it once kQueued.
  std::string bytes_;
  bool got_first_ = false;
  int messages_ = 0;  // messages of the upload read so far
  std::atomic<bool> cancelled_{false};
};

UploadWatchdog::UploadWatchdog(const ServiceOptions& options) {
  if (options.upload_idle_timeout_ms <= 0 &&
      options.min_upload_bytes_per_second <= 0)
    return;
  // A few checks per idle timeout, so that a stalled upload is refused
  // within about 1.25 timeouts; at most every 250 ms otherwise.
  const int64_t idle = options.upload_idle_timeout_ms;
  period_ = absl::Milliseconds(idle > 0 ? std::clamp<int64_t>(idle / 4, 5, 250)
                                        : 250);
  thread_ = std::thread([this] { Loop(); });
}

UploadWatchdog::~UploadWatchdog() {
  {
    absl::MutexLock lock(&mu_);
    stopping_ = true;
  }
  if (thread_.joinable()) thread_.join();
}

void UploadWatchdog::Loop() {
  while (true) {
    std::vector<std::pair<ExtractReactor*, grpc::Status>> expired;
    {
      absl::MutexLock lock(&mu_);
      mu_.AwaitWithTimeout(absl::Condition(&stopping_), period_);
      if (stopping_) return;
      const Clock::time_point now = Clock::now();
      for (ExtractReactor* call : calls_) {
        if (std::optional<grpc::Status> s = call->Expire(now))
          expired.emplace_back(call, *s);
      }
    }
    // Outside both locks: Finish may run OnDone on this thread, which
    // unregisters (mu_) and deletes the call. A claimed call cannot finish
    // any other way, so it is alive until this Finish.
    for (auto& [call, status] : expired) call->Finish(std::move(status));
  }
}

// Answers a call refused at admission without reading it.
class RejectReactor final : public grpc::ServerReadReactor<grpc::ByteBuffer> {
 public:
  explicit RejectReactor(int limit) {
    Finish(
        grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                     absl::StrCat("too many extractions in flight (limit ",
                                  limit, ", --max-concurrent); retry later")));
  }
  void OnDone() override { delete this; }
};

}  // namespace

// The index of Extract among tpr.v1.Extractor's methods (extractor.proto).
constexpr int kExtractMethod = 0;

ExtractorService::ExtractorService(const ServiceOptions& options)
    : state_(std::make_unique<State>(options)) {
  // The generated handler reads tpr.v1.ExtractRequest, and gRPC's typed
  // reader ends the stream on a message that does not parse; this one reads
  // raw bytes (common/stream_messages.h).
  MarkMethodCallback(
      kExtractMethod,
      common::RawCallbackClientStreamHandler<v1::ExtractRequest,
                                             v1::ExtractResponse>(
          GetHandler(kExtractMethod), "Extract",
          [this](grpc::CallbackServerContext* context,
                 v1::ExtractResponse* response) {
            return ExtractRaw(context, response);
          }));
}

ExtractorService::~ExtractorService() = default;

grpc::ServerReadReactor<grpc::ByteBuffer>* ExtractorService::ExtractRaw(
    grpc::CallbackServerContext* context, v1::ExtractResponse* response) {
  if (state_->in_flight.fetch_add(1) >= state_->options.max_concurrent) {
    state_->in_flight.fetch_sub(1);
    return new RejectReactor(state_->options.max_concurrent);
  }
  return new ExtractReactor(state_.get(), context, response);
}

int ExtractorService::InFlight() const { return state_->in_flight.load(); }

void ExtractorService::AddCallMetrics(common::Metrics& metrics) {
  AddExtractMetrics(metrics);
}

}  // namespace tpr::extractor
