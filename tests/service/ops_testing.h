// Helpers for the operations tests (config, logging, auth, TLS, metrics):
// a health check for a named service, running a command and capturing its
// output, reading a file, test certificates, scraping /metrics.
#ifndef TPR_TESTS_SERVICE_OPS_TESTING_H_
#define TPR_TESTS_SERVICE_OPS_TESTING_H_

#include <grpcpp/channel.h>
#include <grpcpp/client_context.h>
#include <grpcpp/impl/codegen/client_unary_call.h>
#include <grpcpp/impl/codegen/rpc_method.h>
#include <grpcpp/support/byte_buffer.h>
#include <sys/wait.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"
#include "common/grpc_status.h"

namespace tpr::testing {

// HealthStatus calls grpc.health.v1.Health/Check for `service` with raw
// bytes (gRPC's C++ package ships no health stub): the request is field 1
// (service, a string), the answer field 1 (status: 1 SERVING, 2
// NOT_SERVING). Returns the status value, or the call's error (NOT_FOUND for
// a service the server does not know).
inline absl::StatusOr<int> HealthStatus(
    const std::shared_ptr<grpc::Channel>& channel, const std::string& service) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(10));
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
  grpc::Status s =
      grpc::internal::BlockingUnaryCall<grpc::ByteBuffer, grpc::ByteBuffer>(
          channel.get(), method, &context, request, &response);
  if (!s.ok()) return tpr::common::FromGrpcStatus(s);
  std::vector<grpc::Slice> slices;
  if (!response.Dump(&slices).ok())
    return absl::InternalError("cannot read response");
  std::string answer;
  for (const grpc::Slice& piece : slices) {
    answer.append(reinterpret_cast<const char*>(piece.begin()), piece.size());
  }
  if (answer.empty()) return 0;  // UNKNOWN, the default value, is not sent.
  if (answer.size() != 2 || answer[0] != '\x08')
    return absl::InternalError("odd answer");
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
  std::string out;  // stdout (RunShell: stdout and stderr together)
};

// RunCommand runs `command` with /bin/sh and captures its stdout (stderr
// goes where the command sends it).
inline ShellResult RunCommand(const std::string& command) {
  ShellResult result;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return result;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0)
    result.out.append(buffer, n);
  const int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

// RunShell runs `command` with /bin/sh, stderr merged into stdout.
inline ShellResult RunShell(const std::string& command) {
  return RunCommand(command + " 2>&1");
}

// Makes, under `dir`: ca1 and ca2 (self-signed authorities), server1 (for
// localhost/127.0.0.1, signed by ca1), server2 (same names, signed by ca2),
// client1 (signed by ca1), client2 (signed by ca2). Each X has X.pem, X.key.
inline bool MakeCertificates(const std::string& dir) {
  const std::string ec =
      "-newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes";
  std::string script = absl::StrCat(
      "set -e; cd ", dir, "; ",
      "printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\\n' > san.ext; ",
      "printf 'extendedKeyUsage=clientAuth\\n' > client.ext; ");
  for (const char* ca : {"ca1", "ca2"}) {
    absl::StrAppend(&script, "openssl req -x509 ", ec, " -keyout ", ca,
                    ".key -out ", ca, ".pem -days 2 -subj /CN=tpr-test-", ca,
                    " 2>/dev/null; ");
  }
  for (const char* who : {"server1", "server2", "client1", "client2"}) {
    const std::string ca =
        "ca" + std::string(who).substr(std::string(who).size() - 1);
    const bool server = std::string(who).rfind("server", 0) == 0;
    absl::StrAppend(&script, "openssl req ", ec, " -keyout ", who, ".key -out ",
                    who, ".csr -subj /CN=", server ? "localhost" : who,
                    " 2>/dev/null; ", "openssl x509 -req -in ", who,
                    ".csr -CA ", ca, ".pem -CAkey ", ca,
                    ".key -CAcreateserial -days 2 -out ", who, ".pem -extfile ",
                    server ? "san.ext" : "client.ext", " 2>/dev/null; ");
  }
  return RunShell(script).exit_code == 0;
}

// The value of the sample `name` whose labels include every one of
// `labels` ("code=\"OK\""), or NaN when absent.
inline double Sample(const std::string& scrape, const std::string& name,
                     const std::vector<std::string>& labels = {}) {
  for (absl::string_view line : absl::StrSplit(scrape, '\n')) {
    if (line.empty() || line[0] == '#') continue;
    const size_t space = line.rfind(' ');
    if (space == absl::string_view::npos) continue;
    absl::string_view series = line.substr(0, space);
    const absl::string_view bare = series.substr(0, series.find('{'));
    if (bare != name) continue;
    bool all = true;
    for (const std::string& label : labels) {
      if (series.find(label) == absl::string_view::npos) all = false;
    }
    if (!all) continue;
    double value;
    if (absl::SimpleAtod(line.substr(space + 1), &value)) return value;
  }
  return std::nan("");
}

// The port from the "metrics: http://HOST:PORT/metrics" log line, or 0.
inline int MetricsPort(const std::string& log) {
  const size_t at = log.find("metrics: http://");
  if (at == std::string::npos) return 0;
  const size_t colon = log.find(':', at + 16);
  return colon == std::string::npos ? 0 : std::atoi(log.c_str() + colon + 1);
}

// ScrapeMetrics fetches http://127.0.0.1:PORT/metrics with curl.
inline ShellResult ScrapeMetrics(int port) {
  return RunShell(absl::StrCat("curl -sf http://127.0.0.1:", port, "/metrics"));
}

}  // namespace tpr::testing

#endif  // TPR_TESTS_SERVICE_OPS_TESTING_H_
