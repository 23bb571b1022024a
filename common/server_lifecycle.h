// Server lifecycle shared by tpr-extractor and tpr-indexer: build a
// grpc::Server with the standard health service, server reflection (v1alpha)
// and message-size limits; wait for SIGTERM/SIGINT; shut down gracefully
// (stop accepting, let in-flight calls finish until a deadline, then cancel
// them). Every call passes the call interceptor (request ids, one log line
// per call, observers such as metrics: common/call_interceptor.h); the
// service's own health status is readiness (common/health.h).
//
//   tpr::common::ServerOptions options;
//   options.listen_address = "127.0.0.1:7002";
//   absl::StatusOr<tpr::common::StartedServer> s =
//       StartServer(options, {&service});
//   if (s.ok()) return ServeUntilSignal(*s->server, options, s->port);
//
// Header-only; it needs tpr_server_common (common/*.cc), gRPC::grpc++ and
// gRPC::grpc++_reflection.
#ifndef TPR_COMMON_SERVER_LIFECYCLE_H_
#define TPR_COMMON_SERVER_LIFECYCLE_H_

#include <errno.h>
#include <grpc/grpc.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/generic/async_generic_service.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/resource_quota.h>
#include <grpcpp/security/server_credentials.h>
#include <grpcpp/server.h>
#include <grpcpp/server_builder.h>
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <functional>
#include <initializer_list>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "common/auth.h"
#include "common/call_interceptor.h"
#include "common/health.h"
#include "common/listen_address.h"
#include "common/logging.h"
#include "common/metrics.h"

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
  // Whether every call (but health checks and reflection) is logged, one
  // line each (common/logging.h). Default false; the services' --log-calls.
  bool log_calls = false;
  // Receivers of every finished call (e.g. metrics). Default none.
  std::vector<CallObserver> call_observers;
  // The health-service name whose status is readiness, e.g.
  // "tpr.v1.Indexer". Empty: none (only the overall status). Default empty.
  std::string readiness_service;
  // Polled every readiness_poll_ms while serving: "" when ready, else the
  // reason. Empty function: always ready. Default empty, 1000 ms.
  ReadinessCheck readiness_check;
  int readiness_poll_ms = 1000;
  // API keys (common/auth.h): when set, every call but health checks and
  // reflection needs a key of a sufficient role, and SIGHUP reloads the
  // keys file (ServeUntilSignal). Kept alive by these options and by the
  // StartedServer. Default none.
  std::shared_ptr<ApiKeyAuthenticator> api_keys;
  // Prometheus metrics (common/metrics.h) every call is recorded into; the
  // caller serves them (Metrics::Serve). Kept alive by the StartedServer.
  // Default none.
  std::shared_ptr<Metrics> metrics;
  // Credentials the port is opened with (e.g. TLS, common/tls.h); StartServer
  // attaches api_keys' processor to them. nullptr: plaintext. Default nullptr.
  std::shared_ptr<grpc::ServerCredentials> credentials;
};

namespace internal {

// The credentials a port is opened with: options.credentials (plaintext
// when null) with the API-key processor attached when options.api_keys.
inline std::shared_ptr<grpc::ServerCredentials> ListeningCredentials(
    const ServerOptions& options) {
  std::shared_ptr<grpc::ServerCredentials> credentials = options.credentials;
  if (options.api_keys != nullptr) {
    if (credentials == nullptr) {
      credentials =
          InsecureServerCredentialsWithAuth(options.api_keys->Processor());
    } else {
      credentials->SetAuthMetadataProcessor(options.api_keys->Processor());
    }
  }
  if (credentials == nullptr) credentials = grpc::InsecureServerCredentials();
  return credentials;
}

// ListenExclusively adds `address` to `builder` with SO_REUSEPORT off (gRPC
// turns it on by default, which lets a second process share the port and
// take half of its calls): binding an address in use then fails, and
// BuildAndStart returns nullptr with *selected_port 0.
inline void ListenExclusively(
    grpc::ServerBuilder& builder, const std::string& address,
    const std::shared_ptr<grpc::ServerCredentials>& credentials,
    int* selected_port) {
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  builder.AddListeningPort(address, credentials, selected_port);
}

// The UNAVAILABLE status of a server that could not bind `address`, naming
// it and the cause (DescribeListenFailure).
inline absl::Status ListenError(const std::string& address) {
  return absl::UnavailableError(absl::StrCat("cannot listen on ", address, ": ",
                                             DescribeListenFailure(address)));
}

}  // namespace internal

// StartedServer: a running server and the port it actually bound.
// Destroying it stops the readiness monitor before the server.
struct StartedServer {
  // What the server's auth filter and interceptors point into, kept alive
  // until after the server (members are destroyed in reverse order).
  std::shared_ptr<ApiKeyAuthenticator> api_keys;
  std::shared_ptr<Metrics> metrics;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
  // Set when ServerOptions::readiness_service is.
  std::unique_ptr<ReadinessMonitor> readiness;
};

// StartServer builds and starts a server that serves `services` (sync or
// callback services; the caller keeps them alive until the server is shut
// down and destroyed) plus the default health service (overall status
// SERVING) and v1alpha server reflection. With options.metrics, a service
// that is a CallMetricsSource (common/metrics.h) first adds its metrics.
// The port is bound without SO_REUSEPORT: no other process can share it.
// Returns UNAVAILABLE naming the address and the cause when it cannot be
// bound (in use, bad host), INVALID_ARGUMENT for an empty address.
// Cost: thread start-up, a few milliseconds. Not thread-safe with respect to
// other StartServer calls (it flips gRPC's process-wide plugin switches).
inline absl::StatusOr<StartedServer> StartServer(
    const ServerOptions& options,
    std::initializer_list<grpc::Service*> services) {
  if (options.listen_address.empty()) {
    return absl::InvalidArgumentError("listen address is empty");
  }
  // Both switches are process-wide and must be set before the builder exists.
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  StartedServer started;
  started.api_keys = options.api_keys;
  started.metrics = options.metrics;
  if (options.api_keys != nullptr && options.metrics != nullptr) {
    // Refused calls never reach the interceptors: count them here.
    options.api_keys->SetRefusalObserver(
        [metrics = options.metrics](const std::string& method,
                                    absl::StatusCode code) {
          metrics->RecordRefused(method, static_cast<grpc::StatusCode>(code));
        });
  }
  std::shared_ptr<grpc::ServerCredentials> credentials =
      internal::ListeningCredentials(options);
  internal::ListenExclusively(builder, options.listen_address, credentials,
                              &started.port);
  {
    CallInterceptorOptions calls;
    calls.service = options.log_name;
    calls.log_calls = options.log_calls;
    calls.observers = options.call_observers;
    std::vector<
        std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>>
        interceptors;
    interceptors.push_back(MakeCallInterceptorFactory(std::move(calls)));
    if (options.metrics != nullptr) {
      for (grpc::Service* service : services) {
        if (auto* source = dynamic_cast<CallMetricsSource*>(service))
          source->AddCallMetrics(*options.metrics);
      }
      interceptors.push_back(options.metrics->InterceptorFactory());
    }
    builder.experimental().SetInterceptorCreators(std::move(interceptors));
  }
  builder.SetMaxReceiveMessageSize(options.max_receive_message_bytes);
  builder.SetMaxSendMessageSize(options.max_send_message_bytes);
  if (options.max_threads > 0) {
    grpc::ResourceQuota quota(absl::StrCat(options.log_name, "-quota"));
    quota.SetMaxThreads(options.max_threads);
    builder.SetResourceQuota(quota);
  }
  // Sync-API pollers wake this often; Shutdown() waits for each to notice,
  // so gRPC's default of 10 s made every graceful stop take seconds.
  builder.SetSyncServerOption(
      grpc::ServerBuilder::SyncServerOption::CQ_TIMEOUT_MSEC, 100);
  for (grpc::Service* service : services) builder.RegisterService(service);
  started.server = builder.BuildAndStart();
  if (started.server == nullptr || started.port == 0) {
    started.server.reset();
    return internal::ListenError(options.listen_address);
  }
  if (grpc::HealthCheckServiceInterface* health =
          started.server->GetHealthCheckService()) {
    health->SetServingStatus(true);
  }
  if (!options.readiness_service.empty()) {
    started.readiness = std::make_unique<ReadinessMonitor>(
        started.server.get(), options.readiness_service,
        options.readiness_check, options.readiness_poll_ms, options.log_name);
  }
  return started;
}

namespace internal {

// Answers every call of a method the server does not serve (on a loading
// server: every call but health checks) with UNAVAILABLE and a message.
class UnavailableGenericService final : public grpc::CallbackGenericService {
 public:
  explicit UnavailableGenericService(std::string message)
      : message_(std::move(message)) {}
  grpc::ServerGenericBidiReactor* CreateReactor(
      grpc::GenericCallbackServerContext*) override {
    class Reactor final : public grpc::ServerGenericBidiReactor {
     public:
      explicit Reactor(const std::string& message) {
        Finish(grpc::Status(grpc::StatusCode::UNAVAILABLE, message));
      }
      void OnDone() override { delete this; }
    };
    return new Reactor(message_);
  }

 private:
  const std::string message_;
};

}  // namespace internal

// LoadingServer: the stand-in StartLoadingServer returns. Destroying it
// shuts it down at once.
struct LoadingServer {
  std::shared_ptr<ApiKeyAuthenticator> api_keys;  // outlives the server
  std::unique_ptr<internal::UnavailableGenericService> service;
  std::unique_ptr<grpc::Server> server;
  // The port bound: give it to the real server (ListenAddressWithPort).
  int port = 0;
  ~LoadingServer() {
    if (server) {
      server->Shutdown(std::chrono::system_clock::now());
      server->Wait();
    }
  }
};

// StartLoadingServer listens on options.listen_address (same credentials and
// API keys as the real server) while a service opens its data, so that
// probes see a live process that is not ready yet: the overall health
// status (liveness) is SERVING, options.readiness_service (readiness) is
// NOT_SERVING, and every other call fails with UNAVAILABLE "<log_name> is
// not ready: <reason>", which clients retry. Once the data is open, destroy
// this one and start the real server on its port (ListenAddressWithPort):
// the port is bound exclusively (no SO_REUSEPORT), so it is closed for the
// moment between the two, and a client's connection attempt then is
// refused and retried. Its log line carries no "(port N)" (tests and
// scripts wait for that in the real server's "serving on" line). Errors as
// StartServer.
inline absl::StatusOr<std::unique_ptr<LoadingServer>> StartLoadingServer(
    const ServerOptions& options, const std::string& reason) {
  if (options.listen_address.empty()) {
    return absl::InvalidArgumentError("listen address is empty");
  }
  grpc::EnableDefaultHealthCheckService(true);
  auto loading = std::make_unique<LoadingServer>();
  loading->api_keys = options.api_keys;
  loading->service = std::make_unique<internal::UnavailableGenericService>(
      absl::StrCat(options.log_name, " is not ready: ", reason));
  grpc::ServerBuilder builder;
  std::shared_ptr<grpc::ServerCredentials> credentials =
      internal::ListeningCredentials(options);
  internal::ListenExclusively(builder, options.listen_address, credentials,
                              &loading->port);
  builder.RegisterCallbackGenericService(loading->service.get());
  builder.SetSyncServerOption(
      grpc::ServerBuilder::SyncServerOption::CQ_TIMEOUT_MSEC, 100);
  loading->server = builder.BuildAndStart();
  if (loading->server == nullptr || loading->port == 0) {
    loading->server.reset();
    return internal::ListenError(options.listen_address);
  }
  if (grpc::HealthCheckServiceInterface* health =
          loading->server->GetHealthCheckService()) {
    health->SetServingStatus(true);
    if (!options.readiness_service.empty()) {
      health->SetServingStatus(options.readiness_service, false);
    }
  }
  LogEvent(options.log_name,
           absl::StrCat("not ready: ", reason, "; health answers on port ",
                        loading->port));
  return loading;
}

// ListenAddressWithPort returns `address` ("HOST:PORT") with its port
// replaced by `port`.
inline std::string ListenAddressWithPort(const std::string& address, int port) {
  const size_t colon = address.rfind(':');
  return absl::StrCat(
      colon == std::string::npos ? address : address.substr(0, colon), ":",
      port);
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

// WaitForShutdownSignal installs SIGTERM/SIGINT/SIGHUP handlers (once per
// process) and blocks until SIGTERM or SIGINT arrives; returns the signal
// number. Each SIGHUP calls `on_hangup` (when set) and waits on. SIGPIPE is
// ignored as a side effect (a vanished client must not kill the server).
// Thread-safe to call from one thread at a time.
inline int WaitForShutdownSignal(
    const std::function<void()>& on_hangup = nullptr) {
  int* fds = internal::SignalPipe();
  if (fds[0] < 0) {
    if (pipe(fds) != 0) return -1;
    struct sigaction action = {};
    action.sa_handler = internal::OnShutdownSignal;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESTART;
    sigaction(SIGTERM, &action, nullptr);
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGHUP, &action, nullptr);
    signal(SIGPIPE, SIG_IGN);
  }
  unsigned char byte = 0;
  while (true) {
    const ssize_t n = read(fds[0], &byte, 1);
    if (n == 1 && byte == SIGHUP) {
      if (on_hangup) on_hangup();
      continue;
    }
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
inline void ShutdownGracefully(grpc::Server& server,
                               const ServerOptions& options) {
  if (grpc::HealthCheckServiceInterface* health =
          server.GetHealthCheckService()) {
    health->SetServingStatus(false);
  }
  server.Shutdown(std::chrono::system_clock::now() +
                  std::chrono::milliseconds(options.shutdown_grace_ms));
  server.Wait();
}

// ShutdownGracefully for a StartedServer: stops the readiness monitor first
// (readiness NOT_SERVING), then as above.
inline void ShutdownGracefully(StartedServer& started,
                               const ServerOptions& options) {
  if (started.readiness) started.readiness->Stop();
  ShutdownGracefully(*started.server, options);
}

namespace internal {

// ServeUntilSignalWith logs, waits for SIGTERM/SIGINT, calls `shut_down`,
// logs again; returns 0.
template <typename ShutDown>
int ServeUntilSignalWith(const ServerOptions& options, int port,
                         ShutDown shut_down) {
  LogEvent(options.log_name, absl::StrCat("serving on ", options.listen_address,
                                          " (port ", port, ")"));
  const int signo = WaitForShutdownSignal([&options] {
    if (options.api_keys == nullptr) return;
    LogEvent(options.log_name, "SIGHUP: reloading the API keys");
    (void)options.api_keys->Reload();  // Errors are logged; old keys stay.
  });
  LogEvent(options.log_name,
           absl::StrCat("signal ", signo, ": shutting down, grace ",
                        options.shutdown_grace_ms, " ms"));
  shut_down();
  LogEvent(options.log_name, "stopped");
  return 0;
}

}  // namespace internal

// ServeUntilSignal logs that the server is serving, blocks until SIGTERM or
// SIGINT, then shuts it down gracefully (see ShutdownGracefully) and logs
// each step. Returns the process exit code to use: 0.
inline int ServeUntilSignal(grpc::Server& server, const ServerOptions& options,
                            int port) {
  return internal::ServeUntilSignalWith(
      options, port, [&] { ShutdownGracefully(server, options); });
}

// ServeUntilSignal for a StartedServer (its readiness monitor stops, and
// readiness turns NOT_SERVING, when draining starts).
inline int ServeUntilSignal(StartedServer& started,
                            const ServerOptions& options) {
  return internal::ServeUntilSignalWith(
      options, started.port, [&] { ShutdownGracefully(started, options); });
}

}  // namespace tpr::common

#endif  // TPR_COMMON_SERVER_LIFECYCLE_H_
