// The operational flags every TPR service shares, added to its CLI11 app in
// one call and turned into ServerOptions in another, so that a service's
// main.cc (extractor, indexer, gateway) wires logging, configuration files,
// API keys, TLS and metrics in a few lines:
//
//   tpr::common::ServerFlags ops;
//   // --listen, --shutdown-grace-ms:
//   tpr::common::AddListenFlags(app, &server_options);
//   ... the service's own options ...
//   tpr::common::AddServerFlags(app, &ops);
//   auto config = tpr::common::AddConfigSupport(app, "TPR_INDEXER_");
//   CLI11_PARSE(app, argc, argv);
//   if (std::optional<int> exit_code =
//           tpr::common::FinishServerFlags(config, ops, &server_options)) {
//     return *exit_code;   // --print-config done, or a bad flag reported
//   }
#ifndef TPR_COMMON_SERVER_FLAGS_H_
#define TPR_COMMON_SERVER_FLAGS_H_

#include <CLI/CLI.hpp>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "common/config.h"
#include "common/server_lifecycle.h"
#include "common/tls.h"

namespace tpr::common {

// ServerFlags: the values of the shared flags (defaults as documented on
// each flag).
struct ServerFlags {
  // --log-format: "text" or "json". Default "text".
  std::string log_format = "text";
  // --log-calls: one log line per call. Default true.
  bool log_calls = true;
  // --api-keys: keys file (common/auth.h); empty: no keys, every call open.
  // Default empty.
  std::string api_keys;
  // --tls-cert, --tls-key, --tls-client-ca, --tls-refresh-s (common/tls.h);
  // no cert: plaintext.
  TlsServerOptions tls;
  // --metrics-listen HOST:PORT: serve Prometheus /metrics there; empty:
  // no metrics. Default empty.
  std::string metrics_listen;
  // --insecure: allow listening (or serving /metrics) beyond loopback
  // without TLS and API keys, for a deployment where something else (a
  // mesh sidecar, a private network) provides them; logged at every start.
  // Default false: ApplyServerFlags refuses such an address.
  bool insecure = false;
  // --threads of the indexer and the gateway (AddServerThreadsFlag): an
  // upper bound on gRPC's handler threads; 0: gRPC's default. Default 0.
  int server_threads = 0;
};

// AddListenFlags adds the two flags every service has, bound to `*options`
// (which must outlive parsing; its current values are the defaults shown):
// --listen HOST:PORT (options->listen_address; port 0 picks a free one,
// logged) and --shutdown-grace-ms (options->shutdown_grace_ms).
void AddListenFlags(CLI::App& app, ServerOptions* options);

// AddServerThreadsFlag adds --threads as an upper bound on the server's
// handler threads (flags->server_threads; ApplyServerFlags turns it into
// ServerOptions::max_threads). For services whose --threads means nothing
// else (tpr-extractor's --threads sizes its worker pool instead).
void AddServerThreadsFlag(CLI::App& app, ServerFlags* flags);

// AddServerFlags adds the shared flags to `app`, storing into `*flags`
// (which must outlive parsing). Call before AddConfigSupport so that the
// flags get environment variables too.
void AddServerFlags(CLI::App& app, ServerFlags* flags);

// ApplyServerFlags sets the process-wide log format and fills the matching
// fields of `*options` (opening the keys file; max_threads = server_threads
// + 2 when server_threads > 0, since gRPC needs a few threads of its own
// besides the handlers). Returns INVALID_ARGUMENT or
// NOT_FOUND naming the flag and the file or line at fault. Open defaults
// are refused (CheckOpenDefaults) before anything is opened.
absl::Status ApplyServerFlags(const ServerFlags& flags, ServerOptions* options);

// CheckOpenDefaults returns FAILED_PRECONDITION, saying how to fix it,
// when `listen_address` (the service's --listen) reaches beyond loopback
// (common/listen_address.h) without both TLS (--tls-cert) and API keys
// (--api-keys), or when --metrics-listen (plain HTTP, no keys) does;
// unless flags.insecure. Thread-safe.
absl::Status CheckOpenDefaults(const ServerFlags& flags,
                               const std::string& listen_address);

// FinishServerFlags runs after parsing: with --print-config it prints the
// effective configuration to stdout and returns 0 (the exit code);
// otherwise it applies the flags (ApplyServerFlags) and returns nullopt
// (serve), or prints the error to stderr under options->log_name and
// returns 2.
std::optional<int> FinishServerFlags(const ConfigSupport& config,
                                     const ServerFlags& flags,
                                     ServerOptions* options);

}  // namespace tpr::common

#endif  // TPR_COMMON_SERVER_FLAGS_H_
