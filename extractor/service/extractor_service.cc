#include "extractor/service/extractor_service.h"

#include <atomic>
#include <chrono>
#include <deque>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "common/grpc_status.h"
#include "common/status_macros.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/service/convert.h"

namespace tpr::extractor_service {
namespace {

double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
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
            +[](WorkerPool* p) { return p->stopping_ || !p->queue_.empty(); }, this));
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

}  // namespace

absl::StatusOr<v1::ExtractResponse> RunExtraction(const std::string& bytes,
                                                  const v1::ExtractRequest& header,
                                                  const ServiceOptions& options,
                                                  const std::function<bool()>& cancelled) {
  if (bytes.empty()) {
    return absl::InvalidArgumentError("the upload carried no mesh data");
  }
  TPR_ASSIGN_OR_RETURN(extract::Options extract_options,
                       OptionsFromProto(header.options(), options.max_threads_per_extraction));
  if (cancelled()) return absl::CancelledError("extraction cancelled before intake");

  extract::IntakeOptions intake_options;
  intake_options.max_vertices = options.max_vertices;
  const auto intake_start = std::chrono::steady_clock::now();
  TPR_ASSIGN_OR_RETURN(extract::LoadedMesh loaded,
                       extract::LoadMeshFromBuffer(bytes, FormatFromProto(header.format()),
                                                   header.file_name(), intake_options));
  const double intake_ms = MillisecondsSince(intake_start);
  if (cancelled()) return absl::CancelledError("extraction cancelled after intake");

  TPR_ASSIGN_OR_RETURN(extract::ExtractResult result,
                       extract::ExtractSignature(loaded.mesh, loaded.stats, extract_options));
  if (cancelled()) return absl::CancelledError("extraction cancelled after extraction");

  v1::ExtractResponse response;
  // Intake's statistics are the mesh "as the extractor read it".
  result.signature.stats = loaded.stats;
  *response.mutable_signature() = SignatureToProto(result.signature, extract_options);
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
    *response.mutable_explanation() = ExplanationToProto(*result.explanation);
  }
  return response;
}

struct ExtractorService::State {
  explicit State(const ServiceOptions& o) : options(o), pool(o.worker_threads) {}
  const ServiceOptions options;
  std::atomic<int> in_flight{0};
  // Declared last: destroyed first, so queued jobs still see valid state.
  WorkerPool pool;
};

namespace {

// One Extract call. Lifetime: created by the service, deleted in OnDone,
// which gRPC calls once Finish has completed and every reaction returned.
// The worker job touches the reactor only up to its Finish call.
class ExtractReactor final : public grpc::ServerReadReactor<v1::ExtractRequest> {
 public:
  ExtractReactor(const ServiceOptions* options, WorkerPool* pool, std::atomic<int>* in_flight,
                 grpc::CallbackServerContext* context, v1::ExtractResponse* response)
      : options_(options),
        pool_(pool),
        in_flight_(in_flight),
        context_(context),
        response_(response) {
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      // End of the upload (or a broken stream / cancel).
      if (cancelled_.load() || context_->IsCancelled()) {
        Finish(grpc::Status(grpc::StatusCode::CANCELLED, "upload cancelled"));
        return;
      }
      if (!got_first_) {
        Finish(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                            "the upload carried no messages (no mesh data)"));
        return;
      }
      pool_->Submit([this] { Work(); });
      return;
    }
    if (!got_first_) {
      got_first_ = true;
      header_.set_format(request_.format());
      header_.set_file_name(request_.file_name());
      *header_.mutable_options() = request_.options();
    }
    const std::string& chunk = request_.data();
    if (static_cast<int64_t>(bytes_.size() + chunk.size()) > options_->max_mesh_bytes) {
      // Stop reading now: the rest of the stream is never buffered.
      Finish(grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                          absl::StrCat("mesh upload exceeds the server limit of ",
                                       options_->max_mesh_bytes, " bytes (--max-mesh-bytes)")));
      return;
    }
    bytes_.append(chunk);
    if (cancelled_.load()) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "upload cancelled"));
      return;
    }
    StartRead(&request_);
  }

  void OnCancel() override { cancelled_.store(true); }

  void OnDone() override {
    in_flight_->fetch_sub(1);
    delete this;
  }

 private:
  void Work() {
    absl::StatusOr<v1::ExtractResponse> result = RunExtraction(
        bytes_, header_, *options_,
        [this] { return cancelled_.load() || context_->IsCancelled(); });
    std::string().swap(bytes_);  // free the upload before waiting on the wire
    if (result.ok()) *response_ = *std::move(result);
    Finish(ToGrpcStatus(result.status()));
  }

  const ServiceOptions* options_;
  WorkerPool* pool_;
  std::atomic<int>* in_flight_;
  grpc::CallbackServerContext* context_;
  v1::ExtractResponse* response_;
  v1::ExtractRequest request_;
  v1::ExtractRequest header_;
  std::string bytes_;
  bool got_first_ = false;
  std::atomic<bool> cancelled_{false};
};

// Answers a call refused at admission without reading it.
class RejectReactor final : public grpc::ServerReadReactor<v1::ExtractRequest> {
 public:
  explicit RejectReactor(int limit) {
    Finish(grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                        absl::StrCat("too many extractions in flight (limit ", limit,
                                     ", --max-concurrent); retry later")));
  }
  void OnDone() override { delete this; }
};

}  // namespace

ExtractorService::ExtractorService(const ServiceOptions& options)
    : state_(std::make_unique<State>(options)) {}

ExtractorService::~ExtractorService() = default;

grpc::ServerReadReactor<v1::ExtractRequest>* ExtractorService::Extract(
    grpc::CallbackServerContext* context, v1::ExtractResponse* response) {
  if (state_->in_flight.fetch_add(1) >= state_->options.max_concurrent) {
    state_->in_flight.fetch_sub(1);
    return new RejectReactor(state_->options.max_concurrent);
  }
  return new ExtractReactor(&state_->options, &state_->pool, &state_->in_flight, context,
                            response);
}

int ExtractorService::InFlight() const { return state_->in_flight.load(); }

}  // namespace tpr::extractor_service
