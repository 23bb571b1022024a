#include "web/web_server.h"

#include <httplib.h>
#include <prometheus/counter.h>
#include <prometheus/gauge.h>
#include <prometheus/histogram.h>
#include <sys/socket.h>

#include <chrono>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "common/listen_address.h"
#include "common/logging.h"
#include "web/console_files.h"
#include "web/http_errors.h"
#include "web/tls_identity.h"

namespace tpr::web {

// Instruments: the HTTP metric families (histograms, labelled by route
// name and status only, never by id).
struct WebServer::Instruments {
  explicit Instruments(prometheus::Registry& registry)
      : requests(prometheus::BuildCounter()
                     .Name("tpr_http_requests_total")
                     .Help("API requests answered, by route and HTTP status")
                     .Register(registry)),
        duration(prometheus::BuildHistogram()
                     .Name("tpr_http_request_duration_seconds")
                     .Help("API request duration, from the parsed request to "
                           "the reply, by route")
                     .Register(registry)),
        in_flight(prometheus::BuildGauge()
                      .Name("tpr_http_in_flight")
                      .Help("API requests being answered")
                      .Register(registry)
                      .Add({})) {}
  prometheus::Family<prometheus::Counter>& requests;
  prometheus::Family<prometheus::Histogram>& duration;
  prometheus::Gauge& in_flight;
};

namespace {

absl::Status SplitListen(const std::string& listen, std::string* host,
                         int* port) {
  const size_t colon = listen.rfind(':');
  if (colon == std::string::npos ||
      !absl::SimpleAtoi(listen.substr(colon + 1), port) || *port < 0 ||
      *port > 65535) {
    return absl::InvalidArgumentError(
        absl::StrCat("--listen: '", listen, "' is not HOST:PORT"));
  }
  *host = listen.substr(0, colon);
  if (host->size() >= 2 && host->front() == '[' && host->back() == ']')
    *host = host->substr(1, host->size() - 2);
  if (host->empty()) *host = "0.0.0.0";
  return absl::OkStatus();
}

// Error bodies for what httplib answers itself (no route, body too large,
// malformed request) and for any handler reply left without a body.
absl::Status StatusForHttp(int http, const httplib::Request& request,
                           int64_t max_upload_bytes) {
  switch (http) {
    case 400:
      return absl::InvalidArgumentError("malformed HTTP request");
    case 404:
      return absl::NotFoundError(
          absl::StrCat("no route ", request.method, " ", request.path));
    case 413:
      return absl::ResourceExhaustedError(
          absl::StrCat("request body larger than ", max_upload_bytes,
                       " bytes (tpr-web --max-upload-bytes)"));
    case 416:
      return absl::OutOfRangeError("requested range not satisfiable");
    default:
      return absl::UnknownError(absl::StrCat("HTTP status ", http));
  }
}

std::string RequestIdOf(const httplib::Request& request) {
  std::string id =
      common::SanitizeRequestId(request.get_header_value("X-Request-Id"));
  return id.empty() ? common::NewRequestId() : id;
}

}  // namespace

absl::StatusOr<std::unique_ptr<WebServer>> WebServer::Start(
    const WebServerOptions& options, std::vector<Route> routes,
    const Backends* backends) {
  std::string host;
  int port = 0;
  if (absl::Status s = SplitListen(options.listen, &host, &port); !s.ok())
    return s;
  std::unique_ptr<WebServer> web(new WebServer());
  web->options_ = options;
  web->backends_ = backends;
  if (!options.tls.cert_file.empty()) {
    absl::StatusOr<std::shared_ptr<TlsIdentity>> identity =
        TlsIdentity::Open(options.tls);
    if (!identity.ok()) return identity.status();
    TlsIdentity* raw = identity->get();
    web->tls_identity_ = *identity;
    auto server = std::make_unique<httplib::SSLServer>(
        [raw](SSL_CTX& ctx) { return raw->Install(&ctx); });
    if (!server->is_valid()) {
      return absl::InvalidArgumentError(
          absl::StrCat("--tls-client-ca: ", options.tls.client_ca_file,
                       " is not a PEM certificate authority"));
    }
    web->server_ = std::move(server);
  } else {
    web->server_ = std::make_unique<httplib::Server>();
  }
  if (options.metrics != nullptr)
    web->instruments_ =
        std::make_unique<Instruments>(options.metrics->registry());
  httplib::Server& server = *web->server_;
  const int threads = options.threads;
  server.new_task_queue = [threads] {
    return new httplib::ThreadPool(threads);
  };
  server.set_payload_max_length(static_cast<size_t>(options.max_upload_bytes));
  server.set_keep_alive_max_count(1000);
  // A reply goes out as headers then body, two writes: with Nagle's
  // algorithm the second waits for the client's delayed ACK, 40 ms.
  server.set_tcp_nodelay(true);
  server.set_read_timeout(30, 0);
  server.set_default_headers(
      {{"X-Content-Type-Options", "nosniff"},
       {"Content-Security-Policy",
        "default-src 'self'; img-src 'self' data: blob:; style-src 'self' "
        "'unsafe-inline'; frame-ancestors 'none'"}});
  const int64_t max_upload = options.max_upload_bytes;
  server.set_error_handler(httplib::Server::HandlerWithResponse(
      [max_upload](const httplib::Request& request,
                   httplib::Response& response) {
        if (!response.body.empty())
          return httplib::Server::HandlerResponse::Unhandled;
        const absl::Status status =
            StatusForHttp(response.status, request, max_upload);
        response.set_content(ErrorJson(status, ""), kJsonType);
        return httplib::Server::HandlerResponse::Handled;
      }));
  web->InstallHealth();
  web->Install(std::move(routes));
  web->InstallConsole();
  // httplib's default socket options set SO_REUSEPORT, which would let a
  // second tpr-web share the port; bind exclusively instead.
  server.set_socket_options([](socket_t sock) {
    const int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  });
  web->port_ = port == 0 ? server.bind_to_any_port(host)
                         : (server.bind_to_port(host, port) ? port : -1);
  if (web->port_ <= 0) {
    return absl::UnavailableError(
        absl::StrCat("cannot listen on ", options.listen, ": ",
                     common::DescribeListenFailure(options.listen)));
  }
  web->thread_ = std::thread([&server] { server.listen_after_bind(); });
  return web;
}

WebServer::~WebServer() { Stop(); }

void WebServer::Stop() {
  draining_ = true;
  if (server_ != nullptr) server_->stop();
  if (thread_.joinable()) thread_.join();
}

void WebServer::Install(std::vector<Route> routes) {
  for (Route& route : routes) {
    auto shared = std::make_shared<Route>(std::move(route));
    httplib::Server::Handler handler = [this, shared](
                                           const httplib::Request& request,
                                           httplib::Response& response) {
      const auto start = std::chrono::steady_clock::now();
      if (instruments_) instruments_->in_flight.Increment();
      CallMeta meta;
      meta.request_id = RequestIdOf(request);
      meta.authorization = request.get_header_value("Authorization");
      Reply reply;
      absl::Status allowed = absl::OkStatus();
      if (options_.api_keys != nullptr) {
        allowed =
            options_.api_keys->Check(shared->grpc_method, meta.authorization);
      }
      reply = allowed.ok() ? shared->handler(request, meta)
                           : ErrorReply(allowed, meta.request_id);
      response.status = reply.http_status;
      response.set_content(std::move(reply.body), reply.content_type.c_str());
      for (const auto& [name, value] : reply.headers)
        response.set_header(name.c_str(), value);
      response.set_header("X-Request-Id", meta.request_id);
      const double seconds = std::chrono::duration<double>(
                                 std::chrono::steady_clock::now() - start)
                                 .count();
      if (instruments_) {
        instruments_->in_flight.Decrement();
        instruments_->requests
            .Add({{"route", shared->name},
                  {"status", std::to_string(reply.http_status)}})
            .Increment();
        instruments_->duration
            .Add({{"route", shared->name}}, common::SecondsBuckets())
            .Observe(seconds);
      }
      if (options_.log_requests) {
        common::CallRecord record;
        record.method = shared->name;
        record.peer =
            absl::StrCat(request.remote_addr, ":", request.remote_port);
        record.code = static_cast<int>(reply.status.code());
        record.status_message = std::string(reply.status.message());
        record.duration_ms = seconds * 1000.0;
        record.request_id = meta.request_id;
        common::LogCall(options_.log_name, record);
      }
    };
    if (shared->method == "GET") {
      server_->Get(shared->pattern, handler);
    } else if (shared->method == "POST") {
      server_->Post(shared->pattern, handler);
    } else if (shared->method == "DELETE") {
      server_->Delete(shared->pattern, handler);
    }
  }
}

void WebServer::InstallHealth() {
  server_->Get("/healthz", [](const httplib::Request&, httplib::Response& r) {
    r.set_content("{\"status\":\"SERVING\"}", kJsonType);
  });
  server_->Get("/readyz", [this](const httplib::Request&,
                                 httplib::Response& r) {
    std::string reason;
    if (draining_) {
      reason = "shutting down";
    } else if (std::string e = backends_->ExtractorReadiness(); !e.empty()) {
      reason =
          absl::StrCat("extractor ", backends_->options().extractor, ": ", e);
    } else if (std::string i = backends_->IndexerReadiness(); !i.empty()) {
      reason = absl::StrCat("indexer ", backends_->options().indexer, ": ", i);
    }
    if (reason.empty()) {
      r.set_content("{\"status\":\"SERVING\"}", kJsonType);
      return;
    }
    r.status = 503;
    r.set_content(
        ErrorJson(absl::UnavailableError(absl::StrCat("not ready: ", reason)),
                  ""),
        kJsonType);
  });
}

void WebServer::InstallConsole() {
  absl::StatusOr<ConsoleFiles> files =
      options_.console_dir.empty() ? absl::NotFoundError("no --console-dir")
                                   : ConsoleFiles::Load(options_.console_dir);
  if (!files.ok()) {
    common::LogWarning(
        options_.log_name,
        absl::StrCat("console not served: ", files.status().message()));
    server_->Get("/", [](const httplib::Request&, httplib::Response& r) {
      r.set_content(
          "<!doctype html><title>tpr-web</title><p>The console is not built "
          "(no index.html in tpr-web's --console-dir). Run scripts/setup with "
          "Node.js installed. The API is at /api/v1/.",
          "text/html; charset=utf-8");
    });
    return;
  }
  auto shared = std::make_shared<const ConsoleFiles>(*std::move(files));
  // Registered after the API routes, so it only sees the other paths.
  server_->Get("/(.*)",
               [shared](const httplib::Request& request, httplib::Response& r) {
                 const ConsoleFiles::File* file = shared->Find(request.path);
                 if (file == nullptr) {
                   r.status = 404;
                   return;  // The error handler writes the JSON body.
                 }
                 r.set_header("Cache-Control", file->cache_control);
                 r.set_header("Vary", "Accept-Encoding");
                 if (!file->gzip.empty() &&
                     absl::StrContains(
                         request.get_header_value("Accept-Encoding"), "gzip")) {
                   r.set_header("Content-Encoding", "gzip");
                   r.set_content(file->gzip, file->content_type.c_str());
                 } else {
                   r.set_content(file->bytes, file->content_type.c_str());
                 }
               });
}

}  // namespace tpr::web
