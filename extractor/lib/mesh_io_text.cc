// The readers' shared text scanner (mesh_io_text.h).
#include "extractor/lib/mesh_io_text.h"

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <system_error>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace tpr::extract::mesh_io {

using absl::string_view;

bool LineReader::Next(string_view* line) {
  if (pos_ >= bytes_.size()) return false;
  size_t end = bytes_.find('\n', pos_);
  if (end == string_view::npos) end = bytes_.size();
  *line = bytes_.substr(pos_, end - pos_);
  if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
  pos_ = end + 1;
  ++number_;
  return true;
}

bool TokenCursor::Next(string_view* token) {
  while (pos_ < line_.size() && IsSpace(line_[pos_])) ++pos_;
  if (pos_ >= line_.size()) return false;
  size_t end = pos_;
  while (end < line_.size() && !IsSpace(line_[end])) ++end;
  *token = line_.substr(pos_, end - pos_);
  pos_ = end;
  return true;
}

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' ||
         c == '\v';
}

bool HasBinaryBytes(string_view line) {
  for (char c : line) {
    const unsigned char u = static_cast<unsigned char>(c);
    if ((u < 0x20 && !IsSpace(c)) || u == 0x7f) return true;
  }
  return false;
}

void SplitTokens(string_view line, std::vector<string_view>* tokens,
                 size_t max_tokens) {
  tokens->clear();
  TokenCursor cursor(line);
  string_view token;
  while (tokens->size() < max_tokens && cursor.Next(&token)) {
    tokens->push_back(token);
  }
}

string_view StripComment(string_view line) {
  const size_t hash = line.find('#');
  return hash == string_view::npos ? line : line.substr(0, hash);
}

namespace {

// StripPlusSign removes one leading '+' (std::from_chars takes only '-')
// and returns false when what is left cannot be a number: empty, or a
// second sign ("+-1", "++1"), which strtod refuses too. Without the second
// check "+-0.866" was read as -0.866 (fuzz finding, tests/fuzz/findings).
bool StripPlusSign(string_view* token) {
  if (token->empty() || (*token)[0] != '+') return !token->empty();
  token->remove_prefix(1);
  return !token->empty() && (*token)[0] != '+' && (*token)[0] != '-';
}

}  // namespace

bool ParseDouble(string_view token, double* value) {
  if (!StripPlusSign(&token)) return false;
  auto result =
      std::from_chars(token.data(), token.data() + token.size(), *value);
  if (result.ec == std::errc::result_out_of_range &&
      result.ptr == token.data() + token.size()) {
    // Overflow or underflow: strtod gives the infinity or the subnormal.
    const std::string copy(token);
    *value = std::strtod(copy.c_str(), nullptr);
    return true;
  }
  return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

bool ParseInt(string_view token, int64_t* value) {
  if (!StripPlusSign(&token)) return false;
  auto result =
      std::from_chars(token.data(), token.data() + token.size(), *value);
  return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

std::string Quote(string_view token) {
  std::string s(token.substr(0, 40));
  for (char& c : s) {
    if (static_cast<unsigned char>(c) < 0x20 ||
        static_cast<unsigned char>(c) >= 0x7f) {
      c = '?';
    }
  }
  return absl::StrCat("'", s, token.size() > 40 ? "...'" : "'");
}

absl::Status Invalid(string_view format, string_view message) {
  return absl::InvalidArgumentError(absl::StrCat(format, ": ", message));
}

absl::Status InvalidAt(string_view format, int64_t line, string_view message) {
  return absl::InvalidArgumentError(
      absl::StrCat(format, " line ", line, ": ", message));
}

absl::Status TooManyVertices(int64_t n, const IntakeOptions& options) {
  return absl::ResourceExhaustedError(
      absl::StrCat("mesh has ", n, " vertices; the limit is ",
                   options.max_vertices, " (IntakeOptions::max_vertices)"));
}

absl::Status TooManyFaces(int64_t n, const IntakeOptions& options) {
  return absl::ResourceExhaustedError(
      absl::StrCat("mesh has at least ", n, " triangles; the limit is ",
                   options.max_faces, " (IntakeOptions::max_faces)"));
}

absl::Status CheckCoordinateValue(string_view format, string_view where,
                                  double value) {
  if (!std::isfinite(value)) {
    return Invalid(format, absl::StrCat(where, " has a non-finite coordinate"));
  }
  if (std::fabs(value) > kMaxCoordinate) {
    return Invalid(format, absl::StrCat(where, ": coordinate ", value,
                                        " exceeds the supported magnitude ",
                                        kMaxCoordinate));
  }
  return absl::OkStatus();
}

absl::Status ParseCoordinate(string_view format, int64_t line, int64_t vertex,
                             string_view token, double* value) {
  string_view digits = token;
  const bool signed_ok = StripPlusSign(&digits);
  float f = 0.0f;
  auto result =
      std::from_chars(digits.data(), digits.data() + digits.size(), f);
  const bool whole = result.ptr == digits.data() + digits.size();
  double d = f;
  if (!signed_ok || !whole ||
      (result.ec != std::errc() &&
       result.ec != std::errc::result_out_of_range)) {
    return InvalidAt(
        format, line,
        absl::StrCat("vertex ", vertex, ": expected a coordinate, got ",
                     Quote(token)));
  }
  if (result.ec == std::errc::result_out_of_range) {
    // Beyond float: the double value tells an overflow (reported below)
    // from an underflow, which rounds to float's subnormal or zero.
    const std::string copy(digits);
    d = std::strtod(copy.c_str(), nullptr);
    if (std::isfinite(d) && std::fabs(d) <= kMaxCoordinate) {
      d = std::strtof(copy.c_str(), nullptr);
    }
  }
  if (!std::isfinite(d)) {
    return InvalidAt(
        format, line,
        absl::StrCat("vertex ", vertex, " has a non-finite coordinate ",
                     Quote(token)));
  }
  if (std::fabs(d) > kMaxCoordinate) {
    return InvalidAt(
        format, line,
        absl::StrCat("vertex ", vertex, ": coordinate ", Quote(token),
                     " exceeds the supported magnitude ", kMaxCoordinate));
  }
  *value = d;
  return absl::OkStatus();
}

uint32_t LoadLe32(const char* p) {
  const auto* u = reinterpret_cast<const unsigned char*>(p);
  return static_cast<uint32_t>(u[0]) | (static_cast<uint32_t>(u[1]) << 8) |
         (static_cast<uint32_t>(u[2]) << 16) |
         (static_cast<uint32_t>(u[3]) << 24);
}

}  // namespace tpr::extract::mesh_io
