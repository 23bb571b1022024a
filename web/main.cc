// tpr-web: the HTTP/JSON API (/api/v1/..., web/api.h) and the web console
// (/) in front of tpr-extractor and tpr-indexer (or tpr-gateway). Stateless:
// any number of copies can serve the same services. Runs until SIGTERM or
// SIGINT, then stops accepting connections, lets requests in progress
// finish and exits 0.
//
//   tpr-web --listen 127.0.0.1:8080 --extractor 127.0.0.1:7001
//           --indexer 127.0.0.1:7002
//
// --extractor, --indexer and --api-key read TPR_EXTRACTOR, TPR_INDEXER and
// TPR_API_KEY, as `tpr` does. Its own TLS is the services' flags
// (--tls-cert, --tls-key, --tls-client-ca); how it reaches TLS services is
// --backend-tls* (as tpr-gateway's --shard-tls*), since `tpr`'s --tls-cert
// names a client certificate and tpr-web is a server first. Every other
// flag also reads TPR_WEB_<FLAG>.
#include <signal.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <optional>
#include <string>

#include "absl/strings/str_cat.h"
#include "client/peer/connection_flags.h"
#include "common/config.h"
#include "common/logging.h"
#include "common/server_flags.h"
#include "common/server_lifecycle.h"
#include "web/api.h"
#include "web/backends.h"
#include "web/recent_searches.h"
#include "web/web_server.h"

#ifndef TPR_CONSOLE_DIR
#define TPR_CONSOLE_DIR ""
#endif

int main(int argc, char** argv) {
  // A client that goes away mid-reply must not kill the server (TLS
  // writes go through write(2), not send with MSG_NOSIGNAL).
  signal(SIGPIPE, SIG_IGN);
  CLI::App app{
      "tpr-web: HTTP/JSON API and web console over tpr-extractor and "
      "tpr-indexer"};
  tpr::common::ServerOptions server_options;
  server_options.listen_address = "127.0.0.1:8080";
  server_options.log_name = "tpr-web";
  tpr::web::WebServerOptions web;
  tpr::web::BackendOptions backends;
  tpr::web::ApiOptions api;
  web.console_dir = TPR_CONSOLE_DIR;
  tpr::common::AddListenFlags(app, &server_options);
  app.add_option("--extractor", backends.extractor,
                 "tpr-extractor address(es), HOST:PORT[,HOST:PORT]")
      ->capture_default_str();
  app.add_option("--indexer", backends.indexer,
                 "tpr-indexer or tpr-gateway address(es), HOST:PORT[,...]")
      ->capture_default_str();
  app.add_option("--api-key", backends.connection.api_key,
                 "API key tpr-web sends to the services; without it each "
                 "request's own 'Authorization: Bearer' is passed on (prefer "
                 "TPR_API_KEY: a flag shows in ps)");
  tpr::client::AddPeerConnectionFlags(
      app, "backend", "the extractor and the indexer", &backends.connection);
  app.add_option("--timeout", backends.timeout_s,
                 "deadline of each call to the services, in seconds")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--threads", web.threads, "HTTP requests served at once")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  app.add_option("--max-upload-bytes", web.max_upload_bytes,
                 "largest request body (a mesh upload); beyond it 413")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--max-k", api.max_k, "largest k a search may ask for")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--console-dir", web.console_dir,
                 "directory of the built console (index.html), served at /")
      ->capture_default_str();
  tpr::common::ServerFlags ops_flags;
  tpr::common::AddServerFlags(app, &ops_flags);
  tpr::common::ConfigSupport config =
      tpr::common::AddConfigSupport(app, "TPR_WEB_", {"api-key"});
  // The names `tpr` reads, rather than TPR_WEB_*.
  app.get_option("--extractor")->envname("TPR_EXTRACTOR");
  app.get_option("--indexer")->envname("TPR_INDEXER");
  app.get_option("--api-key")->envname("TPR_API_KEY");
  CLI11_PARSE(app, argc, argv);
  if (std::optional<int> exit_code =
          tpr::common::FinishServerFlags(config, ops_flags, &server_options)) {
    return *exit_code;
  }
  absl::StatusOr<std::unique_ptr<tpr::web::Backends>> connected =
      tpr::web::Backends::Connect(backends);
  if (!connected.ok()) {
    std::fprintf(stderr, "tpr-web: %s\n",
                 std::string(connected.status().message()).c_str());
    return 2;
  }
  web.listen = server_options.listen_address;
  web.log_name = server_options.log_name;
  web.log_requests = ops_flags.log_calls;
  web.api_keys = server_options.api_keys;
  web.metrics = server_options.metrics;
  web.tls = ops_flags.tls;
  tpr::web::RecentSearches searches;
  absl::StatusOr<std::unique_ptr<tpr::web::WebServer>> server =
      tpr::web::WebServer::Start(
          web, tpr::web::ApiRoutes(connected->get(), &searches, api),
          connected->get());
  if (!server.ok()) {
    std::fprintf(stderr, "tpr-web: %s\n", server.status().ToString().c_str());
    return 1;
  }
  tpr::common::LogEvent(
      server_options.log_name,
      absl::StrCat("extractor ", backends.extractor, ", indexer ",
                   backends.indexer, web.tls.cert_file.empty() ? "" : ", https",
                   web.api_keys ? ", API keys on" : ""));
  return tpr::common::internal::ServeUntilSignalWith(
      server_options, (*server)->port(), [&server] { (*server)->Stop(); });
}
