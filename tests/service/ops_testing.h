// Helpers for the operations tests (config, logging, auth, TLS, metrics):
// a health check for a named service, running a command and capturing its
// output, reading a file.
#ifndef TPR_TESTS_SERVICE_OPS_TESTING_H_
#define TPR_TESTS_SERVICE_OPS_TESTING_H_

#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <grpcpp/channel.h>
#include <grpcpp/client_context.h>
#include <grpcpp/impl/codegen/client_unary_call.h>
#include <grpcpp/impl/codegen/rpc_method.h>
#include <grpcpp/support/byte_buffer.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"

namespace tpr::testing {

// HealthStatus calls grpc.health.v1.Health/Check for `service` with raw
// bytes (gRPC's C++ package ships no health stub): the request is field 1
// (service, a string), the answer field 1 (status: 1 SERVING, 2
// NOT_SERVING). Returns the status value, or the call's error (NOT_FOUND for
// a service the server does not know).
inline absl::StatusOr<int> HealthStatus(const std::shared_ptr<grpc::Channel>& channel,
                                        const std::string& service) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  std::string bytes;
  if (!service.empty()) {
    bytes.push_back('\x0a');
    bytes.push_back(static_cast<char>(service.size()));
    bytes += service;
  }
  grpc::Slice slice(bytes);
  grpc::ByteBuffer request(&slice, 1);
  grpc::ByteBuffer response;
  const grpc::internal::RpcMethod method("/grpc.health.v1.Health/Check",
                                         grpc::internal::RpcMethod::NORMAL_RPC);
  grpc::Status s = grpc::internal::BlockingUnaryCall<grpc::ByteBuffer, grpc::ByteBuffer>(
      channel.get(), method, &context, request, &response);
  if (!s.ok()) {
    return absl::Status(static_cast<absl::StatusCode>(s.error_code()), s.error_message());
  }
  std::vector<grpc::Slice> slices;
  if (!response.Dump(&slices).ok()) return absl::InternalError("cannot read response");
  std::string answer;
  for (const grpc::Slice& piece : slices) {
    answer.append(reinterpret_cast<const char*>(piece.begin()), piece.size());
  }
  if (answer.empty()) return 0;  // UNKNOWN, the default value, is not sent.
  if (answer.size() != 2 || answer[0] != '\x08') return absl::InternalError("odd answer");
  return static_cast<int>(answer[1]);
}

// ReadText returns the whole file at `path` ("" when unreadable).
inline std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// ShellResult: what one shell command printed and returned.
struct ShellResult {
  int exit_code = -1;
  std::string out;  // stdout and stderr together
};

// RunShell runs `command` with /bin/sh, stderr merged into stdout.
inline ShellResult RunShell(const std::string& command) {
  ShellResult result;
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return result;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) result.out.append(buffer, n);
  const int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

}  // namespace tpr::testing

#endif  // TPR_TESTS_SERVICE_OPS_TESTING_H_
