#include "common/server_flags.h"

#include <cstdio>

#include "absl/strings/str_cat.h"
#include "common/listen_address.h"
#include "common/logging.h"
#include "common/metrics.h"

namespace tpr::common {

void AddListenFlags(CLI::App& app, ServerOptions* options) {
  app.add_option(
         "--listen", options->listen_address,
         "HOST:PORT to listen on; port 0 picks a free one (logged on stderr)")
      ->capture_default_str();
  app.add_option("--shutdown-grace-ms", options->shutdown_grace_ms,
                 "on SIGTERM/SIGINT, how long in-flight calls may finish (ms)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
}

void AddServerThreadsFlag(CLI::App& app, ServerFlags* flags) {
  app.add_option("--threads", flags->server_threads,
                 "upper bound on server threads (0: gRPC's default)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
}

void AddServerFlags(CLI::App& app, ServerFlags* flags) {
  app.add_option("--log-format", flags->log_format,
                 "log lines as 'text' or 'json' (time, level, service, rpc, "
                 "peer, status, "
                 "duration_ms, request_id)")
      ->capture_default_str()
      ->check(CLI::IsMember({"text", "json"}));
  app.add_flag("--log-calls,!--no-log-calls", flags->log_calls,
               "log one line per call (health checks and reflection excepted)")
      ->default_str(flags->log_calls ? "true" : "false");
  app.add_option("--api-keys", flags->api_keys,
                 "file of hashed API keys with roles (tpr key new); when "
                 "given, every call but "
                 "health and reflection needs 'authorization: Bearer KEY'; "
                 "reloaded on SIGHUP "
                 "and when the file changes");
  app.add_option("--tls-cert", flags->tls.cert_file,
                 "PEM certificate chain: serve TLS (with --tls-key); re-read "
                 "when it changes");
  app.add_option("--tls-key", flags->tls.key_file,
                 "PEM private key of --tls-cert");
  app.add_option(
      "--tls-client-ca", flags->tls.client_ca_file,
      "PEM authority: require client certificates it signed (mutual TLS)");
  app.add_option("--tls-refresh-s", flags->tls.refresh_interval_s,
                 "how often the TLS files are checked for changes (seconds)")
      ->capture_default_str()
      ->check(CLI::Range(1, 86400));
  app.add_option("--metrics-listen", flags->metrics_listen,
                 "HOST:PORT serving Prometheus metrics at /metrics (port 0: a "
                 "free one, logged); loopback unless --insecure");
  app.add_flag("--insecure", flags->insecure,
               "allow --listen or --metrics-listen beyond loopback without "
               "TLS and API keys (e.g. behind a mesh sidecar that provides "
               "TLS); logged at every start");
}

absl::Status CheckOpenDefaults(const ServerFlags& flags,
                               const std::string& listen_address) {
  if (flags.insecure) return absl::OkStatus();
  const bool tls = !flags.tls.cert_file.empty();
  const bool keys = !flags.api_keys.empty();
  if (!IsLoopbackAddress(listen_address) && !(tls && keys)) {
    return absl::FailedPreconditionError(absl::StrCat(
        "--listen ", listen_address, " reaches beyond this machine without ",
        tls ? "API keys" : (keys ? "TLS" : "TLS and API keys"),
        ": give --tls-cert/--tls-key and --api-keys, listen on 127.0.0.1, or "
        "pass --insecure where something else (a mesh sidecar, a private "
        "network) secures the traffic"));
  }
  if (!flags.metrics_listen.empty() &&
      !IsLoopbackAddress(flags.metrics_listen)) {
    return absl::FailedPreconditionError(absl::StrCat(
        "--metrics-listen ", flags.metrics_listen,
        " reaches beyond this machine, and /metrics is plain HTTP without "
        "keys: serve it on 127.0.0.1 (scrape through a local agent or "
        "proxy) or pass --insecure"));
  }
  return absl::OkStatus();
}

absl::Status ApplyServerFlags(const ServerFlags& flags,
                              ServerOptions* options) {
  if (absl::Status open = CheckOpenDefaults(flags, options->listen_address);
      !open.ok()) {
    return open;
  }
  if (flags.insecure && (!IsLoopbackAddress(options->listen_address) ||
                         (!flags.metrics_listen.empty() &&
                          !IsLoopbackAddress(flags.metrics_listen)))) {
    LogWarning(
        options->log_name,
        absl::StrCat(
            "--insecure: serving ", options->listen_address,
            flags.metrics_listen.empty()
                ? ""
                : absl::StrCat(" and /metrics on ", flags.metrics_listen),
            " beyond loopback",
            flags.tls.cert_file.empty() ? ", without TLS" : "",
            flags.api_keys.empty() ? ", without API keys" : ""));
  }
  absl::StatusOr<LogFormat> format = ParseLogFormat(flags.log_format);
  if (!format.ok())
    return absl::InvalidArgumentError(
        absl::StrCat("--log-format: ", format.status().message()));
  SetLogFormat(*format);
  options->log_calls = flags.log_calls;
  if (flags.server_threads > 0) options->max_threads = flags.server_threads + 2;
  const TlsServerOptions& tls = flags.tls;
  if (!tls.cert_file.empty() || !tls.key_file.empty() ||
      !tls.client_ca_file.empty()) {
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials =
        MakeTlsServerCredentials(tls);
    if (!credentials.ok()) return credentials.status();
    options->credentials = *std::move(credentials);
  }
  if (!flags.metrics_listen.empty()) {
    auto metrics = std::make_shared<Metrics>();
    if (absl::Status s = metrics->Serve(flags.metrics_listen); !s.ok())
      return s;
    const std::string host =
        flags.metrics_listen.substr(0, flags.metrics_listen.rfind(':'));
    LogEvent(options->log_name, absl::StrCat("metrics: http://", host, ":",
                                             metrics->port(), "/metrics"));
    options->metrics = std::move(metrics);
  }
  if (!flags.api_keys.empty()) {
    absl::StatusOr<std::shared_ptr<ApiKeyAuthenticator>> keys =
        ApiKeyAuthenticator::Open(flags.api_keys, options->log_name);
    if (!keys.ok()) {
      return absl::Status(
          keys.status().code(),
          absl::StrCat("--api-keys: ", keys.status().message()));
    }
    options->api_keys = *std::move(keys);
  }
  return absl::OkStatus();
}

std::optional<int> FinishServerFlags(const ConfigSupport& config,
                                     const ServerFlags& flags,
                                     ServerOptions* options) {
  if (config.print_requested()) {
    std::fputs(config.Effective().c_str(), stdout);
    return 0;
  }
  if (absl::Status s = ApplyServerFlags(flags, options); !s.ok()) {
    std::fprintf(stderr, "%s: %s\n", options->log_name.c_str(),
                 std::string(s.message()).c_str());
    return 2;
  }
  return std::nullopt;
}

}  // namespace tpr::common
