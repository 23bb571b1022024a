// Server lifecycle shared by tpr-extractor and tpr-indexer: build a
// grpc::Server with the standard health service, server reflection (v1alpha)
// and message-size limits; wait for SIGTERM/SIGINT; shut down gracefully
// (stop accepting, let in-flight calls finish until a deadline, then cancel
// them). Also a tiny stderr logger, one line per event (Debian's Abseil
// 20220623 has no absl/log).
//
//   tpr::common::ServerOptions options;  options.listen_address = "127.0.0.1:7002";
//   absl::StatusOr<tpr::common::StartedServer> s = StartServer(options, {&service});
//   if (s.ok()) return ServeUntilSignal(*s->server, options, s->port);
//
// Header-only so that both services' main.cc and the tests use it without a
// library of its own; it needs gRPC::grpc++ and gRPC::grpc++_reflection.
#ifndef TPR_COMMON_SERVER_LIFECYCLE_H_
#define TPR_COMMON_SERVER_LIFECYCLE_H_

#include <errno.h>
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/resource_quota.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server.h>
#include <grpcpp/server_builder.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace tpr::common {

// ServerOptions: how StartServer builds the server.
struct ServerOptions {
  // "HOST:PORT" to listen on; port 0 picks a free port (see
  // StartedServer::port). Default: loopback with a free port.
  std::string listen_address = "127.0.0.1:0";
  // Largest message accepted from a client, in bytes. Default 64 MiB (a
  // client-streamed mesh chunk or a large batch item fits comfortably).
  int max_receive_message_bytes = 64 << 20;
  // Largest message sent to a client, in bytes. Default 64 MiB.
  int max_send_message_bytes = 64 << 20;
  // Upper bound on the threads gRPC may use for this server (sync API
  // handlers and pollers), via grpc::ResourceQuota::SetMaxThreads. 0 leaves
  // gRPC's default (unbounded). Default 0.
  int max_threads = 0;
  // On shutdown, how long in-flight calls may run before gRPC cancels them,
  // in milliseconds. Default 10000.
  int shutdown_grace_ms = 10000;
  // Name written in front of every log line. Default "tpr".
  std::string log_name = "tpr";
};

// LogEvent writes one line "<UTC time> <name>: <message>" to stderr. The whole
// line is written with a single fwrite under a mutex, so concurrent events do
// not interleave. Thread-safe. Cost: one formatted write.
inline void LogEvent(absl::string_view name, absl::string_view message) {
  static std::mutex* const mu = new std::mutex;
  const auto now = std::chrono::system_clock::now();
  const auto micros = std::chrono::duration_cast<std::chrono::microseconds>(
                          now.time_since_epoch())
                          .count();
  const time_t seconds = static_cast<time_t>(micros / 1000000);
  struct tm utc;
  gmtime_r(&seconds, &utc);
  char stamp[96];
  std::snprintf(stamp, sizeof(stamp), "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ",
                utc.tm_year + 1900, utc.tm_mon + 1, utc.tm_mday, utc.tm_hour,
                utc.tm_min, utc.tm_sec, static_cast<int>((micros / 1000) % 1000));
  const std::string line = absl::StrCat(stamp, " ", name, ": ", message, "\n");
  std::lock_guard<std::mutex> lock(*mu);
  std::fwrite(line.data(), 1, line.size(), stderr);
  std::fflush(stderr);
}

// StartedServer: a running server and the port it actually bound.
struct StartedServer {
  std::unique_ptr<grpc::Server> server;
  int port = 0;
};

// StartServer builds and starts a server that serves `services` (sync or
// callback services; the caller keeps them alive until the server is shut
// down and destroyed) plus the default health service (overall status
// SERVING) and v1alpha server reflection.
// Returns UNAVAILABLE when the address cannot be bound (in use, bad host),
// INVALID_ARGUMENT for an empty address.
// Cost: thread start-up, a few milliseconds. Not thread-safe with respect to
// other StartServer calls (it flips gRPC's process-wide plugin switches).
inline absl::StatusOr<StartedServer> StartServer(
    const ServerOptions& options, std::initializer_list<grpc::Service*> services) {
  if (options.listen_address.empty()) {
    return absl::InvalidArgumentError("listen address is empty");
  }
  // Both switches are process-wide and must be set before the builder exists.
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  StartedServer started;
  builder.AddListeningPort(options.listen_address,
                           grpc::InsecureServerCredentials(), &started.port);
  builder.SetMaxReceiveMessageSize(options.max_receive_message_bytes);
  builder.SetMaxSendMessageSize(options.max_send_message_bytes);
  if (options.max_threads > 0) {
    grpc::ResourceQuota quota(absl::StrCat(options.log_name, "-quota"));
    quota.SetMaxThreads(options.max_threads);
    builder.SetResourceQuota(quota);
  }
  // Sync-API pollers wake this often; Shutdown() waits for each to notice,
  // so gRPC's default of 10 s made every graceful stop take seconds.
  builder.SetSyncServerOption(grpc::ServerBuilder::SyncServerOption::CQ_TIMEOUT_MSEC, 100);
  for (grpc::Service* service : services) builder.RegisterService(service);
  started.server = builder.BuildAndStart();
  if (started.server == nullptr || started.port == 0) {
    return absl::UnavailableError(
        absl::StrCat("cannot listen on ", options.listen_address,
                     " (address in use or not resolvable)"));
  }
  if (grpc::HealthCheckServiceInterface* health =
          started.server->GetHealthCheckService()) {
    health->SetServingStatus(true);
  }
  return started;
}

namespace internal {

// The self-pipe: a signal handler may only call async-signal-safe functions,
// so it writes the signal number to a pipe that ServeUntilSignal reads. This
// works whatever threads gRPC started before the handler was installed
// (sigwait would need the signals blocked in every thread first).
inline int* SignalPipe() {
  static int fds[2] = {-1, -1};
  return fds;
}

inline void OnShutdownSignal(int signo) {
  const int saved_errno = errno;
  const unsigned char byte = static_cast<unsigned char>(signo);
  ssize_t ignored = write(SignalPipe()[1], &byte, 1);
  (void)ignored;
  errno = saved_errno;
}

}  // namespace internal

// WaitForShutdownSignal installs SIGTERM/SIGINT handlers (once per process)
// and blocks until one of them arrives; returns the signal number. SIGPIPE is
// ignored as a side effect (a vanished client must not kill the server).
// Thread-safe to call from one thread at a time.
inline int WaitForShutdownSignal() {
  int* fds = internal::SignalPipe();
  if (fds[0] < 0) {
    if (pipe(fds) != 0) return -1;
    struct sigaction action = {};
    action.sa_handler = internal::OnShutdownSignal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESTART;
    sigaction(SIGTERM, &action, nullptr);
    sigaction(SIGINT, &action, nullptr);
    signal(SIGPIPE, SIG_IGN);
  }
  unsigned char byte = 0;
  while (true) {
    const ssize_t n = read(fds[0], &byte, 1);
    if (n == 1) return byte;
    if (n < 0 && errno == EINTR) continue;
    return -1;
  }
}

// ShutdownGracefully stops accepting calls, lets in-flight calls finish for
// up to options.shutdown_grace_ms (then gRPC cancels them: streaming handlers
// see the cancellation and return), and waits until the server has stopped.
// The health service reports NOT_SERVING from the first moment. Blocks for at
// most the grace period plus the handlers' reaction time.
inline void ShutdownGracefully(grpc::Server& server, const ServerOptions& options) {
  if (grpc::HealthCheckServiceInterface* health = server.GetHealthCheckService()) {
    health->SetServingStatus(false);
  }
  server.Shutdown(std::chrono::system_clock::now() +
                  std::chrono::milliseconds(options.shutdown_grace_ms));
  server.Wait();
}

// ServeUntilSignal logs that the server is serving, blocks until SIGTERM or
// SIGINT, then shuts it down gracefully (see ShutdownGracefully) and logs
// each step. Returns the process exit code to use: 0.
inline int ServeUntilSignal(grpc::Server& server, const ServerOptions& options,
                            int port) {
  LogEvent(options.log_name,
           absl::StrCat("serving on ", options.listen_address, " (port ", port, ")"));
  const int signo = WaitForShutdownSignal();
  LogEvent(options.log_name,
           absl::StrCat("signal ", signo, ": shutting down, grace ",
                        options.shutdown_grace_ms, " ms"));
  ShutdownGracefully(server, options);
  LogEvent(options.log_name, "stopped");
  return 0;
}

}  // namespace tpr::common

#endif  // TPR_COMMON_SERVER_LIFECYCLE_H_
