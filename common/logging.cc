#include "common/logging.h"

#include <time.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <random>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/json_text.h"

namespace tpr::common {
namespace {

std::atomic<LogFormat>& Format() {
  static std::atomic<LogFormat> format{LogFormat::kText};
  return format;
}

std::string UtcNow() {
  const auto micros = std::chrono::duration_cast<std::chrono::microseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  const time_t seconds = static_cast<time_t>(micros / 1000000);
  struct tm utc;
  gmtime_r(&seconds, &utc);
  return absl::StrFormat("%04d-%02d-%02dT%02d:%02d:%02d.%03dZ",
                         utc.tm_year + 1900, utc.tm_mon + 1, utc.tm_mday,
                         utc.tm_hour, utc.tm_min, utc.tm_sec,
                         static_cast<int>((micros / 1000) % 1000));
}

void WriteLine(const std::string& line) {
  static std::mutex* const mu = new std::mutex;
  std::lock_guard<std::mutex> lock(*mu);
  std::fwrite(line.data(), 1, line.size(), stderr);
  std::fflush(stderr);
}

void Event(absl::string_view level, absl::string_view service,
           absl::string_view message) {
  if (Format().load(std::memory_order_relaxed) == LogFormat::kJson) {
    WriteLine(absl::StrCat("{\"time\":\"", UtcNow(), "\",\"level\":\"", level,
                           "\",\"service\":", JsonString(service),
                           ",\"msg\":", JsonString(message), "}\n"));
  } else {
    WriteLine(absl::StrCat(UtcNow(), " ", service, ": ", message, "\n"));
  }
}

}  // namespace

absl::StatusOr<LogFormat> ParseLogFormat(absl::string_view name) {
  if (name == "text") return LogFormat::kText;
  if (name == "json") return LogFormat::kJson;
  return absl::InvalidArgumentError(
      absl::StrCat("unknown log format '", name, "' (expected text or json)"));
}

void SetLogFormat(LogFormat format) { Format().store(format); }
LogFormat GetLogFormat() { return Format().load(); }

void LogEvent(absl::string_view service, absl::string_view message) {
  Event("info", service, message);
}

void LogWarning(absl::string_view service, absl::string_view message) {
  Event("warning", service, message);
}

void LogCall(absl::string_view service, const CallRecord& call) {
  const bool quiet_code = call.code == 0 || call.code == 1 || call.code == 5;
  const absl::string_view level = quiet_code ? "info" : "warning";
  // gRPC and absl share the canonical codes and their names.
  const std::string code =
      absl::StatusCodeToString(static_cast<absl::StatusCode>(call.code));
  if (Format().load(std::memory_order_relaxed) == LogFormat::kJson) {
    std::string line = absl::StrCat(
        "{\"time\":\"", UtcNow(), "\",\"level\":\"", level,
        "\",\"service\":", JsonString(service),
        ",\"rpc\":", JsonString(call.method),
        ",\"peer\":", JsonString(call.peer), ",\"status\":\"", code, "\"");
    if (!call.status_message.empty()) {
      absl::StrAppend(&line, ",\"error\":", JsonString(call.status_message));
    }
    absl::StrAppend(
        &line, ",\"duration_ms\":", absl::StrFormat("%.3f", call.duration_ms),
        ",\"request_id\":", JsonString(call.request_id), "}\n");
    WriteLine(line);
  } else {
    std::string line =
        absl::StrCat(UtcNow(), " ", service, ": rpc=", call.method,
                     " peer=", call.peer, " status=", code);
    if (!call.status_message.empty()) {
      absl::StrAppend(&line, " error=", JsonString(call.status_message));
    }
    absl::StrAppend(&line,
                    " duration_ms=", absl::StrFormat("%.3f", call.duration_ms),
                    " request_id=", call.request_id, "\n");
    WriteLine(line);
  }
}

std::string NewRequestId() {
  thread_local std::mt19937_64 engine{std::random_device{}()};
  return absl::StrFormat("%016x", engine());
}

std::string SanitizeRequestId(absl::string_view id) {
  if (id.empty() || id.size() > 128) return "";
  for (char c : id) {
    if (!absl::ascii_isalnum(static_cast<unsigned char>(c)) && c != '.' &&
        c != '_' && c != ':' && c != '-') {
      return "";
    }
  }
  return std::string(id);
}

}  // namespace tpr::common
