// tpr-extractor: the stateless extraction service (tpr.v1.Extractor) with
// the standard health service and server reflection. Runs until SIGTERM or
// SIGINT, then stops accepting calls, lets in-flight extractions finish
// (grace period), and exits 0.
//
//   tpr-extractor --listen 127.0.0.1:7001 --threads 2
#include <cstdio>
#include <optional>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "absl/strings/str_cat.h"
#include "common/config.h"
#include "common/server_flags.h"
#include "common/server_lifecycle.h"
#include "extractor/service/extractor_service.h"

int main(int argc, char** argv) {
  tpr::extractor_service::ServiceOptions service_options;
  tpr::common::ServerOptions server_options;
  server_options.listen_address = "127.0.0.1:7001";
  server_options.log_name = "tpr-extractor";

  CLI::App app{"tpr-extractor: stateless gRPC service turning meshes into TPR signatures"};
  app.add_option("--listen", server_options.listen_address,
                 "HOST:PORT to listen on; port 0 picks a free one (logged on stderr)")
      ->capture_default_str();
  app.add_option("--threads", service_options.worker_threads,
                 "worker threads running intake + extraction; more calls queue")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  app.add_option("--max-mesh-bytes", service_options.max_mesh_bytes,
                 "largest upload in bytes; beyond it RESOURCE_EXHAUSTED at once")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--max-vertices", service_options.max_vertices,
                 "largest mesh in vertices; beyond it RESOURCE_EXHAUSTED")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--max-concurrent", service_options.max_concurrent,
                 "calls admitted at once (uploading, queued or running); further calls get "
                 "RESOURCE_EXHAUSTED immediately")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--max-threads-per-extraction", service_options.max_threads_per_extraction,
                 "cap on ExtractOptions.threads a client may request")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  app.add_option("--shutdown-grace-ms", server_options.shutdown_grace_ms,
                 "on SIGTERM/SIGINT, how long in-flight calls may finish")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
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

  // A chunk is at most 4 MiB by convention (1 MiB recommended); allow some
  // slack above it but never more than the whole-mesh limit.
  server_options.max_receive_message_bytes = static_cast<int>(
      std::min<int64_t>(service_options.max_mesh_bytes + (1 << 20), int64_t{64} << 20));

  // Destroyed after the server (declared first): its workers drain any job
  // still queued when the grace period ended.
  tpr::extractor_service::ExtractorService service(service_options);
  if (server_options.metrics != nullptr) {
    server_options.metrics->AddGaugeCallback(
        "tpr_extractor_admitted_calls", "Extract calls admitted (uploading, queued or running)",
        [&service] { return static_cast<double>(service.InFlight()); });
  }
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(server_options, {&service});
  if (!started.ok()) {
    std::fprintf(stderr, "tpr-extractor: %s\n", started.status().ToString().c_str());
    return 1;
  }
  tpr::common::LogEvent(
      server_options.log_name,
      absl::StrCat("threads ", service_options.worker_threads, ", max-concurrent ",
                   service_options.max_concurrent, ", max-mesh-bytes ",
                   service_options.max_mesh_bytes, ", max-vertices ",
                   service_options.max_vertices));
  return tpr::common::ServeUntilSignal(*started, server_options);
}
