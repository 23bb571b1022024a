// tpr-extractor: the stateless extraction service (tpr.v1.Extractor) with
// the standard health service and server reflection. Runs until SIGTERM or
// SIGINT, then stops accepting calls, lets in-flight extractions finish
// (grace period), and exits 0.
//
//   tpr-extractor --listen 127.0.0.1:7001 --threads 2
#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "common/config.h"
#include "common/server_flags.h"
#include "common/server_lifecycle.h"
#include "extractor/service/extractor_service.h"

int main(int argc, char** argv) {
  tpr::extractor::ServiceOptions service_options;
  tpr::common::ServerOptions server_options;
  server_options.listen_address = "127.0.0.1:7001";
  server_options.log_name = "tpr-extractor";

  CLI::App app{
      "tpr-extractor: stateless gRPC service turning meshes into TPR "
      "signatures"};
  tpr::common::AddListenFlags(app, &server_options);
  app.add_option("--threads", service_options.worker_threads,
                 "worker threads running intake + extraction; more calls queue")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  app.add_option(
         "--max-mesh-bytes", service_options.max_mesh_bytes,
         "largest upload in bytes; beyond it RESOURCE_EXHAUSTED at once")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--max-vertices", service_options.max_vertices,
                 "largest mesh in vertices; beyond it RESOURCE_EXHAUSTED")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--max-concurrent", service_options.max_concurrent,
                 "calls admitted at once (uploading, queued or running); "
                 "further calls get "
                 "RESOURCE_EXHAUSTED immediately")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--upload-idle-timeout-ms",
                 service_options.upload_idle_timeout_ms,
                 "refuse an upload (DEADLINE_EXCEEDED) that sends no message "
                 "for this long, "
                 "freeing its slot; 0 disables")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--min-upload-bytes-per-second",
                 service_options.min_upload_bytes_per_second,
                 "after the first --upload-idle-timeout-ms, refuse an upload "
                 "averaging less "
                 "than this (DEADLINE_EXCEEDED); 0 disables")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app.add_option("--max-threads-per-extraction",
                 service_options.max_threads_per_extraction,
                 "cap on ExtractOptions.threads a client may request")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  tpr::common::ServerFlags ops_flags;
  tpr::common::AddServerFlags(app, &ops_flags);
  tpr::common::ConfigSupport config =
      tpr::common::AddConfigSupport(app, "TPR_EXTRACTOR_");
  CLI11_PARSE(app, argc, argv);
  if (std::optional<int> exit_code =
          tpr::common::FinishServerFlags(config, ops_flags, &server_options)) {
    return *exit_code;
  }
  server_options.readiness_service = "tpr.v1.Extractor";

  // A chunk is under 4 MiB by contract (extractor.proto; the SDK sends 1
  // MiB): a larger message is refused by gRPC before it is buffered, so each
  // call holds at most one chunk beyond its upload buffer (memory bound in
  // extractor_service.h). 64 KiB of slack covers the header fields.
  server_options.max_receive_message_bytes = static_cast<int>(
      std::min<int64_t>(service_options.max_mesh_bytes, int64_t{4} << 20) +
      (64 << 10));

  // Destroyed after the server (declared first): its workers drain any job
  // still queued when the grace period ended.
  tpr::extractor::ExtractorService service(service_options);
  if (server_options.metrics != nullptr) {
    server_options.metrics->AddGaugeCallback(
        "tpr_extractor_admitted_calls",
        "Extract calls admitted (uploading, queued or running)",
        [&service] { return static_cast<double>(service.InFlight()); });
  }
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(server_options, {&service});
  if (!started.ok()) {
    std::fprintf(stderr, "tpr-extractor: %s\n",
                 started.status().ToString().c_str());
    return 1;
  }
  tpr::common::LogEvent(
      server_options.log_name,
      absl::StrCat("threads ", service_options.worker_threads,
                   ", max-concurrent ", service_options.max_concurrent,
                   ", max-mesh-bytes ", service_options.max_mesh_bytes,
                   ", max-vertices ", service_options.max_vertices,
                   ", upload-idle-timeout-ms ",
                   service_options.upload_idle_timeout_ms,
                   ", min-upload-bytes-per-second ",
                   service_options.min_upload_bytes_per_second));
  return tpr::common::ServeUntilSignal(*started, server_options);
}
