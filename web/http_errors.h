// How tpr-web reports a failure over HTTP: the gRPC status code (the same
// canonical codes the services answer with) mapped to an HTTP status, and a
// JSON body {"code": "NOT_FOUND", "message": "...", "requestId": "..."}.
//
//   int http = tpr::web::HttpStatusOf(absl::StatusCode::kNotFound);  // 404
//   std::string body = tpr::web::ErrorJson(status, request_id);
//
// The mapping follows google.api's HTTP rules (and grpc-gateway's), so a
// client can branch on either the HTTP status or the code name.
#ifndef TPR_WEB_HTTP_ERRORS_H_
#define TPR_WEB_HTTP_ERRORS_H_

#include <string>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"

namespace tpr::web {

// kJsonType is the Content-Type of every JSON answer. The charset also
// keeps cpp-httplib from compressing the reply (it compresses exactly
// "application/json", with brotli at quality 11 when the client accepts
// it: milliseconds per reply, more than the API's whole budget).
inline constexpr char kJsonType[] = "application/json; charset=utf-8";

// HttpStatusOf returns the HTTP status for `code`:
//   OK 200, CANCELLED 499, INVALID_ARGUMENT / FAILED_PRECONDITION /
//   OUT_OF_RANGE 400, UNAUTHENTICATED 401, PERMISSION_DENIED 403,
//   NOT_FOUND 404, ALREADY_EXISTS / ABORTED 409, RESOURCE_EXHAUSTED 429,
//   UNIMPLEMENTED 501, UNAVAILABLE 503, DEADLINE_EXCEEDED 504, and 500 for
//   UNKNOWN, INTERNAL, DATA_LOSS and any other value. Thread-safe, O(1).
int HttpStatusOf(absl::StatusCode code);

// CodeName returns the gRPC code's canonical name ("NOT_FOUND",
// "INVALID_ARGUMENT"), "UNKNOWN" for a value outside 0..16. Thread-safe.
std::string CodeName(absl::StatusCode code);

// ErrorJson returns the JSON error body for `status` (which must not be
// OK): {"code":"<CodeName>","message":"<message>","requestId":"<id>"},
// with the message JSON-escaped; requestId is left out when empty.
// Thread-safe, O(length of the message).
std::string ErrorJson(const absl::Status& status, absl::string_view request_id);

// JsonQuote returns `text` as a JSON string literal, quotes included
// (control characters as \u00XX, bytes >= 0x80 passed through, so UTF-8
// stays UTF-8). Thread-safe, O(length).
std::string JsonQuote(absl::string_view text);

}  // namespace tpr::web

#endif  // TPR_WEB_HTTP_ERRORS_H_
