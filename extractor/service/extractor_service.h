// tpr.v1.Extractor: the stateless gRPC service that turns an uploaded mesh
// into a TPR signature (Tam & Lau 2007, sections 4-5) with the library in
// extractor/lib. Handlers only validate, buffer and convert; the work runs
// on a fixed pool of worker threads.
//
//   ServiceOptions options;  options.worker_threads = 2;
//   ExtractorService service(options);
//   builder.RegisterService(&service);   // then build and run the server
//   // ... server->Shutdown(); then destroy `service` (joins its workers).
#ifndef TPR_EXTRACTOR_SERVICE_EXTRACTOR_SERVICE_H_
#define TPR_EXTRACTOR_SERVICE_EXTRACTOR_SERVICE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "common/metrics.h"
#include "tpr/v1/extractor.grpc.pb.h"
#include "tpr/v1/extractor.pb.h"

namespace tpr::extractor {

// ServiceOptions bounds what one tpr-extractor process does at once.
//
// Memory bound: at most `max_concurrent` calls hold an upload, each buffer
// at most `max_mesh_bytes` and never reallocated (it reserves that much
// address space once; Linux backs only the pages written), plus one chunk
// in flight per call (gRPC's message limit, 4 MiB + slack: see main.cc),
// plus the intake and extraction memory of at most `worker_threads` meshes
// (a call's upload buffer is freed as soon as intake has parsed it; the
// parsed mesh is bounded by `max_vertices`). Peak resident memory is thus
// about max_concurrent x max_mesh_bytes + worker_threads x (intake and
// extraction of one mesh); tests/service/extractor_service_test.cc
// measures it on a real process (VmHWM) under hostile uploads.
//
// Time bound: an upload that stalls for `upload_idle_timeout_ms`, or that
// averages less than `min_upload_bytes_per_second` after that grace, is
// refused, so slow clients cannot hold every slot: a slot is held for at
// most upload_idle_timeout_ms + max_mesh_bytes / min_upload_bytes_per_second
// while uploading.
struct ServiceOptions {
  // Threads that run intake and extraction; extractions beyond this wait in
  // a FIFO queue (they count against max_concurrent). Default 2.
  int worker_threads = 2;
  // Largest accepted upload, in bytes. The upload is refused with
  // RESOURCE_EXHAUSTED as soon as the running total crosses it; the rest of
  // the stream is not read. Default 64 MiB.
  int64_t max_mesh_bytes = int64_t{64} << 20;
  // Largest accepted mesh, in vertices (intake's IntakeOptions::max_vertices);
  // RESOURCE_EXHAUSTED above it. Default 2,000,000.
  int64_t max_vertices = 2'000'000;
  // Calls admitted at once (uploading, queued or running). A call beyond it
  // gets RESOURCE_EXHAUSTED immediately, without reading its upload, so a
  // burst can never exhaust memory; clients retry with backoff. Default 16.
  int max_concurrent = 16;
  // An upload that delivers no message for this long (from admission, or
  // since its last message) is refused with DEADLINE_EXCEEDED naming the
  // flag, and its slot freed. 0 disables. Default 10,000 ms.
  int64_t upload_idle_timeout_ms = 10'000;
  // Once upload_idle_timeout_ms has passed since admission, an upload must
  // have received at least this many bytes per second elapsed beyond that
  // grace; one that falls behind is refused with DEADLINE_EXCEEDED naming
  // the flag. 0 disables. Default 131,072 (128 KiB/s, a 1 Mbit/s link): a
  // 64 MiB upload may take up to about 8.5 minutes.
  int64_t min_upload_bytes_per_second = 128 << 10;
  // Upper bound on ExtractOptions.threads a client may ask for (Dijkstra
  // sweeps run in parallel inside one extraction). Default 2.
  int max_threads_per_extraction = 2;
};

// RunExtraction is the whole non-gRPC part of one call: intake of `bytes`
// (format and file name from `header`, the first request), extraction with
// `header.options()`, conversion to the response (signature with mesh stats,
// extractor version and options filled; timings starting with "intake";
// warnings of intake then extraction; the explanation when asked for).
// `bytes` is taken by value and freed as soon as intake has parsed it, so
// that the upload and the extraction's working memory never coexist.
// `cancelled` is polled between stages (the library's ExtractSignature itself
// is not interruptible, so a cancel during it takes effect when it returns).
// Errors: INVALID_ARGUMENT for empty bytes, bad options or a malformed mesh
// (intake's message), RESOURCE_EXHAUSTED above max_vertices, CANCELLED when
// `cancelled` returned true. Thread-safe. Cost: intake O(n log n) plus
// extraction (Table 4 of the paper).
absl::StatusOr<v1::ExtractResponse> RunExtraction(
    std::string bytes, const v1::ExtractRequest& header,
    const ServiceOptions& options, const std::function<bool()>& cancelled);

// ExtractorService implements tpr.v1.Extractor with the callback API. The
// object must outlive the server it is registered with; its destructor
// waits for running extractions and joins the worker threads.
class ExtractorService final : public v1::Extractor::CallbackService,
                               public common::CallMetricsSource {
 public:
  explicit ExtractorService(const ServiceOptions& options);
  ~ExtractorService() override;
  ExtractorService(const ExtractorService&) = delete;
  ExtractorService& operator=(const ExtractorService&) = delete;

  // Extract: see extractor.proto. Client-streaming upload; the reactor
  // buffers chunks (refusing stalled or crawling uploads, see
  // ServiceOptions), then queues the extraction on the worker pool. The
  // stream is read as raw bytes (common/stream_messages.h): the constructor
  // registers this handler in place of the generated typed one, so that a
  // message that does not parse is INVALID_ARGUMENT naming it rather than
  // taken for the end of the upload.
  grpc::ServerReadReactor<grpc::ByteBuffer>* ExtractRaw(
      grpc::CallbackServerContext* context, v1::ExtractResponse* response);

  // InFlight returns the number of admitted calls not yet done. Thread-safe.
  int InFlight() const;

  // AddCallMetrics adds the Extract calls' metrics (extract_metrics.h).
  void AddCallMetrics(common::Metrics& metrics) override;

  // State is defined in the .cc; named here only so that the call objects
  // there can refer to it.
  struct State;

 private:
  std::unique_ptr<State> state_;
};

}  // namespace tpr::extractor

#endif  // TPR_EXTRACTOR_SERVICE_EXTRACTOR_SERVICE_H_
