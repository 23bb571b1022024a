// The server interceptor every TPR service installs (through StartServer in
// common/server_lifecycle.h). For each call it
//   - takes the request id from the client's `x-request-id` metadata, or
//     generates one (common/logging.h), makes it visible to the handler in
//     ServerContext::client_metadata(), and returns it in the trailing
//     metadata;
//   - times the call from its metadata to its status;
//   - turns gRPC's answer to a request that does not parse (INTERNAL, no
//     message) into INVALID_ARGUMENT saying so;
//   - at the end, hands a CallRecord to the observers (metrics) and, unless
//     the call is a health check or reflection, logs one line (LogCall).
// Calls refused by the API-key check (common/auth.h) never reach the
// interceptor: that check logs and counts them itself.
#ifndef TPR_COMMON_CALL_INTERCEPTOR_H_
#define TPR_COMMON_CALL_INTERCEPTOR_H_

#include <grpcpp/server_context.h>
#include <grpcpp/support/server_interceptor.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/logging.h"

namespace tpr::common {

// kSearchProgressHeader is the metadata key with which a Search call asks for
// each neighbour's cumulative statistics (value "1"; tpr.v1.Neighbor.progress).
// tpr-gateway sends it to its shards; tpr-indexer and tpr-gateway honour it.
inline constexpr char kSearchProgressHeader[] = "tpr-search-progress";

// WantsSearchProgress returns whether the call carries kSearchProgressHeader
// with the value "1". Thread-safe for the call's handler. Cost: O(metadata).
inline bool WantsSearchProgress(const grpc::ServerContext& context) {
  const auto& metadata = context.client_metadata();
  auto it = metadata.find(kSearchProgressHeader);
  return it != metadata.end() && it->second == "1";
}

// CallObserver receives every finished call (health and reflection
// included). Called on a gRPC thread; must be thread-safe and quick.
using CallObserver = std::function<void(const CallRecord&)>;

// CallInterceptorOptions: what the interceptor does with a finished call.
struct CallInterceptorOptions {
  // Service name written in log lines. Default "tpr".
  std::string service = "tpr";
  // Whether each call (but health checks and reflection) is logged.
  // Default false (the services turn it on with --log-calls).
  bool log_calls = false;
  // Receivers of every finished call. Default none.
  std::vector<CallObserver> observers;
};

// MakeCallInterceptorFactory returns the factory to hand to
// grpc::ServerBuilder::experimental().SetInterceptorCreators. The options
// are copied. Thread-safe. Cost per call: O(1) beyond reading the request
// id from the metadata, plus the log line and the observers (measured with
// metrics on by bench_service BM_SecurityAndMetricsOverhead).
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>
MakeCallInterceptorFactory(CallInterceptorOptions options);

// RequestIdOf returns the request id of the call behind `context` (the
// client's, or the one the interceptor generated), or "" when the call did
// not pass through the interceptor. A gateway forwards it in its own calls
// as `x-request-id`. Thread-safe for the call's handler.
std::string RequestIdOf(const grpc::ServerContextBase& context);

}  // namespace tpr::common

#endif  // TPR_COMMON_CALL_INTERCEPTOR_H_
