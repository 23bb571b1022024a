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
#include "tpr/v1/extractor.grpc.pb.h"
#include "tpr/v1/extractor.pb.h"

namespace tpr::extractor_service {

// ServiceOptions bounds what one tpr-extractor process does at once.
//
// Memory bound: at most `max_concurrent` calls hold an upload, each at most
// `max_mesh_bytes`, plus the parsed meshes of at most `worker_threads`
// running extractions, so the peak is about max_concurrent x max_mesh_bytes
// + worker_threads x (mesh size x ~10). The defaults keep that near 1 GiB.
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
  // Upper bound on ExtractOptions.threads a client may ask for (Dijkstra
  // sweeps run in parallel inside one extraction). Default 2.
  int max_threads_per_extraction = 2;
};

// RunExtraction is the whole non-gRPC part of one call: intake of `bytes`
// (format and file name from `header`, the first request), extraction with
// `header.options()`, conversion to the response (signature with mesh stats,
// extractor version and options filled; timings starting with "intake";
// warnings of intake then extraction; the explanation when asked for).
// `cancelled` is polled between stages (the library's ExtractSignature itself
// is not interruptible, so a cancel during it takes effect when it returns).
// Errors: INVALID_ARGUMENT for empty bytes, bad options or a malformed mesh
// (intake's message), RESOURCE_EXHAUSTED above max_vertices, CANCELLED when
// `cancelled` returned true. Thread-safe. Cost: intake O(n log n) plus
// extraction (Table 4 of the paper).
absl::StatusOr<v1::ExtractResponse> RunExtraction(const std::string& bytes,
                                                  const v1::ExtractRequest& header,
                                                  const ServiceOptions& options,
                                                  const std::function<bool()>& cancelled);

// ExtractorService implements tpr.v1.Extractor with the callback API. The
// object must outlive the server it is registered with; its destructor
// waits for running extractions and joins the worker threads.
class ExtractorService final : public v1::Extractor::CallbackService {
 public:
  explicit ExtractorService(const ServiceOptions& options);
  ~ExtractorService() override;
  ExtractorService(const ExtractorService&) = delete;
  ExtractorService& operator=(const ExtractorService&) = delete;

  // Extract: see extractor.proto. Client-streaming upload; the reactor
  // buffers chunks, then queues the extraction on the worker pool.
  grpc::ServerReadReactor<v1::ExtractRequest>* Extract(
      grpc::CallbackServerContext* context, v1::ExtractResponse* response) override;

  // InFlight returns the number of admitted calls not yet done. Thread-safe.
  int InFlight() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace tpr::extractor_service

#endif  // TPR_EXTRACTOR_SERVICE_EXTRACTOR_SERVICE_H_
