// Logging shared by the TPR services: one line per event on stderr, as text
// ("<UTC time> <service>: <message>") or as JSON (--log-format=json: one
// object per line with time, level, service, and for a call rpc, peer,
// status, duration_ms and request_id), plus the request id of a call.
//
//   tpr::common::SetLogFormat(tpr::common::LogFormat::kJson);
//   tpr::common::LogEvent("tpr-indexer", "data directory opened");
//
// What is never logged: request or response messages (mesh bytes, metadata
// values), and the `authorization` header (API keys). A call line carries
// only the method name, the peer address, the status code and message, the
// duration and the request id.
//
// Debian's Abseil 20220623 has no absl/log, so this is a small hand-written
// logger: each line is formatted first and written with one fwrite under a
// mutex, so concurrent events never interleave.
#ifndef TPR_COMMON_LOGGING_H_
#define TPR_COMMON_LOGGING_H_

#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace tpr::common {

// LogFormat: how LogEvent and LogCall write a line.
enum class LogFormat {
  kText,  // "2026-11-30T03:50:00.123Z tpr-indexer: message"
  // {"time":"...","level":"info","service":"tpr-indexer","msg":"message"}
  kJson,
};

// ParseLogFormat maps "text" or "json" to a LogFormat. Returns
// INVALID_ARGUMENT naming the value otherwise. Thread-safe.
absl::StatusOr<LogFormat> ParseLogFormat(absl::string_view name);

// SetLogFormat sets the process-wide format (default kText). Thread-safe;
// meant to be called once at start-up, before serving.
void SetLogFormat(LogFormat format);
LogFormat GetLogFormat();

// LogEvent writes one line for `message` from `service` at level "info"
// (LogWarning: "warning"). The text form is "<time> <service>: <message>".
// Thread-safe. Cost: one formatted write to stderr, a few microseconds.
void LogEvent(absl::string_view service, absl::string_view message);
void LogWarning(absl::string_view service, absl::string_view message);

// CallRecord: what is logged (and measured) about one finished call.
struct CallRecord {
  // Full method name, "/tpr.v1.Indexer/Search".
  std::string method;
  // The peer as gRPC reports it, "ipv4:127.0.0.1:50312".
  std::string peer;
  // gRPC status code (grpc::StatusCode as an int) and its message.
  int code = 0;
  std::string status_message;
  // From the arrival of the call's metadata to the sending of its status.
  double duration_ms = 0;
  // The call's request id (see kRequestIdHeader).
  std::string request_id;
};

// LogCall writes one line for a finished call: level "info" when the code
// is OK, NOT_FOUND or CANCELLED, "warning" otherwise. Text form:
// "<time> <service>: rpc=/tpr.v1.Indexer/Search peer=... status=OK
// duration_ms=1.234 request_id=...". Thread-safe.
void LogCall(absl::string_view service, const CallRecord& call);

// kRequestIdHeader is the metadata key of the request id: read from the
// client's initial metadata, generated when absent, and returned in the
// call's trailing metadata.
inline constexpr char kRequestIdHeader[] = "x-request-id";

// NewRequestId returns a fresh random request id: 16 lower-case hex digits
// (64 random bits). Thread-safe. Cost: well under a microsecond.
std::string NewRequestId();

// SanitizeRequestId returns `id` when it is 1 to 128 characters of
// [A-Za-z0-9._:-] (so a client cannot inject log lines or JSON), and an
// empty string otherwise. Thread-safe.
std::string SanitizeRequestId(absl::string_view id);

}  // namespace tpr::common

#endif  // TPR_COMMON_LOGGING_H_
