// Helpers for the tpr-web tests: the services and tpr-web as real
// processes on loopback, an HTTP client, and JSON answers read with
// protobuf's own JSON parser (google.protobuf.Struct), independent of the
// server's JSON writer.
#ifndef TPR_TESTS_WEB_WEB_TEST_UTIL_H_
#define TPR_TESTS_WEB_WEB_TEST_UTIL_H_

// Eigen (through extsvc_test_util.h) comes before httplib.h, which pulls
// in <resolv.h>, whose `_res` macro breaks Eigen's parameter names.
// clang-format off
#include "tests/service/extsvc_test_util.h"
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <httplib.h>
// clang-format on

#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"

namespace tpr::testing {

// ParseJson parses `text` into a Struct; an empty Struct when it is not a
// JSON object (the test then fails on the missing fields).
inline google::protobuf::Struct ParseJson(const std::string& text) {
  google::protobuf::Struct out;
  if (!google::protobuf::util::JsonStringToMessage(text, &out).ok())
    out.Clear();
  return out;
}

// Field returns the value of `name` in `object` (a null Value when absent).
inline const google::protobuf::Value& Field(
    const google::protobuf::Struct& object, const std::string& name) {
  static const google::protobuf::Value* const kNull =
      new google::protobuf::Value();
  auto it = object.fields().find(name);
  return it == object.fields().end() ? *kNull : it->second;
}

// ErrorCode returns the "code" of a JSON error body ("" when none).
inline std::string ErrorCode(const std::string& body) {
  return Field(ParseJson(body), "code").string_value();
}

// UrlEncode percent-encodes every byte but [A-Za-z0-9-._~].
inline std::string UrlEncode(const std::string& text) {
  std::string out;
  for (const unsigned char c : text) {
    if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~') {
      out += static_cast<char>(c);
    } else {
      char buffer[4];
      std::snprintf(buffer, sizeof(buffer), "%%%02X", c);
      out += buffer;
    }
  }
  return out;
}

// StartWeb starts tpr-web with `args` (plus --listen 127.0.0.1:0) and
// returns its process; the log goes to dir/name.log.
inline absl::Status StartWeb(ServiceProcess* web, const std::string& dir,
                             const std::string& name,
                             std::vector<std::string> args) {
  return web->Start(BinaryPath("tpr-web"), std::move(args),
                    absl::StrCat(dir, "/", name, ".log"));
}

}  // namespace tpr::testing

#endif  // TPR_TESTS_WEB_WEB_TEST_UTIL_H_
