// WebServer: tpr-web's HTTP side, an embedded cpp-httplib server (Debian's
// libcpp-httplib-dev). It serves the API routes (web/api.h) and the console
// (the built files of web/console at /), and does for every API request
// what the gRPC services' interceptor does for a call: a request id
// (X-Request-Id, taken from the client or generated, returned and passed
// to the services), the API-key check (Authorization: Bearer, the same
// keys file and roles, common/auth.h), one log line, Prometheus metrics.
// Plus /healthz (liveness) and /readyz (both services ready), open like
// the services' health checks, and bounded uploads (413 with a JSON error).
//
// Why cpp-httplib rather than civetweb (both in Debian 12): its C++ API
// takes per-route handlers with regex path parameters, parses multipart
// uploads and enforces a payload limit itself, and Debian builds it with
// OpenSSL, whose SSL_CTX it hands over (web/tls_identity.h reloads
// certificates there); civetweb would need all of that hand-written over a
// C callback API. Its blocking thread-per-connection model is no cost
// here: every request blocks on a gRPC call anyway.
//
//   WebServerOptions options;  options.listen = "127.0.0.1:8080";
//   absl::StatusOr<std::unique_ptr<WebServer>> server =
//       WebServer::Start(options, ApiRoutes(backends, &recent), backends);
//   ... (*server)->Stop();
#ifndef TPR_WEB_WEB_SERVER_H_
#define TPR_WEB_WEB_SERVER_H_

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "common/auth.h"
#include "common/metrics.h"
#include "common/tls.h"
#include "web/api.h"
#include "web/backends.h"

namespace httplib {
class Server;
}  // namespace httplib

namespace tpr::web {

// WebServerOptions: how WebServer listens and what it serves.
struct WebServerOptions {
  // HOST:PORT; port 0 picks a free one (see WebServer::port). Default
  // 127.0.0.1:8080.
  std::string listen = "127.0.0.1:8080";
  // Requests served at once (a thread each; further connections queue).
  // Default 16.
  int threads = 16;
  // Largest request body, in bytes (a mesh upload with its form); beyond
  // it 413 with code RESOURCE_EXHAUSTED. Default 64 MiB.
  int64_t max_upload_bytes = int64_t{64} << 20;
  // Directory of the built console (index.html and assets/); empty or
  // missing: / answers with how to build it. Default empty.
  std::string console_dir;
  // Log name and whether each API request is logged. Defaults "tpr-web",
  // true.
  std::string log_name = "tpr-web";
  bool log_requests = true;
  // API keys: when set, every /api/ route needs a key of the role its
  // gRPC method needs (Route::grpc_method). Default none (open).
  std::shared_ptr<common::ApiKeyAuthenticator> api_keys;
  // Where request counts and durations go. Default none.
  std::shared_ptr<common::Metrics> metrics;
  // HTTPS with these files when tls.cert_file is set. Default plaintext.
  common::TlsServerOptions tls;
};

// WebServer: a running HTTP server. Thread-safe.
class WebServer {
 public:
  // Start binds options.listen and serves `routes` on a background thread;
  // `backends` answers /readyz and must outlive the server. UNAVAILABLE
  // when the address cannot be bound, INVALID_ARGUMENT for a malformed
  // address, the TLS files' errors (NOT_FOUND, INVALID_ARGUMENT).
  static absl::StatusOr<std::unique_ptr<WebServer>> Start(
      const WebServerOptions& options, std::vector<Route> routes,
      const Backends* backends);
  ~WebServer();

  // The port bound.
  int port() const { return port_; }

  // Stop makes /readyz answer 503, stops accepting connections and waits
  // for the requests in progress. Idempotent.
  void Stop();

 private:
  struct Instruments;
  WebServer() = default;
  void Install(std::vector<Route> routes);
  void InstallConsole();
  void InstallHealth();

  WebServerOptions options_;
  const Backends* backends_ = nullptr;
  std::shared_ptr<void> tls_identity_;  // Outlives the server's SSL_CTX.
  std::unique_ptr<httplib::Server> server_;
  std::unique_ptr<Instruments> instruments_;
  std::thread thread_;
  std::atomic<bool> draining_{false};
  int port_ = 0;
};

}  // namespace tpr::web

#endif  // TPR_WEB_WEB_SERVER_H_
