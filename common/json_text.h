// Text escapers for output meant for machines (JSON string literals) and
// for people (one field of a line of text). Header-only with no dependency
// beyond Abseil's strings, so that the servers' logs and configuration
// dumps, the evaluation reports and the `tpr` command escape the same way.
//
//   std::string line = absl::StrCat("{\"id\":", common::JsonString(id), "}");
//   std::printf("%s\n", common::TextField(id).c_str());
#ifndef TPR_COMMON_JSON_TEXT_H_
#define TPR_COMMON_JSON_TEXT_H_

#include <cstddef>
#include <string>

#include "absl/strings/str_format.h"
#include "absl/strings/string_view.h"

namespace tpr::common {
namespace json_text_internal {

// Length of the valid UTF-8 sequence starting at s[i], or 0 when the bytes
// there are not one (overlong forms, surrogates and code points beyond
// U+10FFFF included, as RFC 3629 rules them out).
inline size_t Utf8SequenceLength(absl::string_view s, size_t i) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = byte(i);
  size_t length = 0;
  unsigned char low = 0x80, high = 0xBF;  // bounds of the second byte
  if (c >= 0xC2 && c <= 0xDF) {
    length = 2;
  } else if (c >= 0xE0 && c <= 0xEF) {
    length = 3;
    if (c == 0xE0) low = 0xA0;   // overlong
    if (c == 0xED) high = 0x9F;  // surrogates
  } else if (c >= 0xF0 && c <= 0xF4) {
    length = 4;
    if (c == 0xF0) low = 0x90;   // overlong
    if (c == 0xF4) high = 0x8F;  // beyond U+10FFFF
  } else {
    return 0;
  }
  if (i + length > s.size()) return 0;
  if (byte(i + 1) < low || byte(i + 1) > high) return 0;
  for (size_t k = 2; k < length; ++k) {
    if (byte(i + k) < 0x80 || byte(i + k) > 0xBF) return 0;
  }
  return length;
}

// AppendEscaped appends ASCII byte c with the escapes JSON and the text
// output share (backslash, newline, carriage return, tab), the JSON-only
// ones when `json` ('"', backspace, form feed), and any other control byte
// as \u00XX (JSON) or \xXX (text).
inline void AppendEscaped(unsigned char c, bool json, std::string* out) {
  switch (c) {
    case '\\':
      *out += "\\\\";
      return;
    case '\n':
      *out += "\\n";
      return;
    case '\r':
      *out += "\\r";
      return;
    case '\t':
      *out += "\\t";
      return;
    case '"':
      *out += json ? "\\\"" : "\"";
      return;
    case '\b':
      if (json) {
        *out += "\\b";
        return;
      }
      break;
    case '\f':
      if (json) {
        *out += "\\f";
        return;
      }
      break;
  }
  if (c < 0x20 || c == 0x7F) {
    // Two calls, not one with a chosen format: absl checks the format
    // at compile time and clang refuses a format that is not a constant.
    if (json) {
      absl::StrAppendFormat(out, "\\u%04x", c);
    } else {
      absl::StrAppendFormat(out, "\\x%02x", c);
    }
  } else {
    out->push_back(static_cast<char>(c));
  }
}

}  // namespace json_text_internal

// JsonString returns `s` as a JSON string literal (RFC 8259): quote,
// backslash and control characters escaped (\n, \t, \r, \b, \f or \u00XX),
// valid UTF-8 kept as is, and each byte that is not part of valid UTF-8
// replaced by U+FFFD, so that the output is always valid JSON whatever
// bytes an id holds. O(size). Pure.
inline std::string JsonString(absl::string_view s) {
  std::string out = "\"";
  for (size_t i = 0; i < s.size();) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x80) {
      const size_t length = json_text_internal::Utf8SequenceLength(s, i);
      if (length == 0) {
        out += "\\ufffd";
        ++i;
      } else {
        out.append(s.data() + i, length);
        i += length;
      }
      continue;
    }
    json_text_internal::AppendEscaped(c, /*json=*/true, &out);
    ++i;
  }
  return out + "\"";
}

// TextField returns `s` safe to print as one field of a line of text
// output: a backslash becomes "\\", a newline "\n", a tab "\t", a carriage
// return "\r" and any other control byte (below 0x20, and 0x7F) "\xHH", so
// that an id or label can neither break a line nor move the cursor, and
// an id printed this way reads back unambiguously. Other bytes (UTF-8
// included) are kept. Pure.
inline std::string TextField(absl::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char ch : s) {
    const unsigned char c = static_cast<unsigned char>(ch);
    if (c >= 0x80) {
      out += ch;
    } else {
      json_text_internal::AppendEscaped(c, /*json=*/false, &out);
    }
  }
  return out;
}

}  // namespace tpr::common

#endif  // TPR_COMMON_JSON_TEXT_H_
