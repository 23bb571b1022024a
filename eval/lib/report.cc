#include "eval/lib/report.h"

#include <cmath>
#include <fstream>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace tpr::eval {
namespace {

// Length of the valid UTF-8 sequence starting at s[i], or 0 when the bytes
// there are not one (overlong forms, surrogates and code points beyond
// U+10FFFF included, as RFC 3629 rules them out).
size_t Utf8SequenceLength(absl::string_view s, size_t i) {
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

void AppendRow(std::string* out, const std::string& cls, int models,
               const Metrics* m) {
  if (m == nullptr) {
    absl::StrAppendFormat(out,
                          "%-24s %6d %6s %6s %6s %6s %6s %6s  (one model: no "
                          "query)\n",
                          cls, models, "-", "-", "-", "-", "-", "-");
    return;
  }
  absl::StrAppendFormat(out, "%-24s %6d %6.3f %6.3f %6.3f %6.3f %6.3f %6.3f\n",
                        cls, models, m->nn, m->ft, m->st, m->e, m->dcg, m->map);
}

int TotalModels(const ClassSizes& sizes) {
  int total = 0;
  for (const auto& [cls, n] : sizes) total += n;
  return total;
}

}  // namespace

namespace {

// AppendEscaped appends ASCII byte c with the escapes JSON and the text
// output share (backslash, newline, carriage return, tab), the JSON-only
// ones when `json` ('"', backspace, form feed), and any other control byte
// as \u00XX (JSON) or \xXX (text).
void AppendEscaped(unsigned char c, bool json, std::string* out) {
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

}  // namespace

// Hand-written rather than through a JSON library: the reports are a few
// flat objects, and a string escaper and a number formatter are all they
// need (protobuf's printer serves the messages the CLI prints whole).
std::string JsonString(absl::string_view s) {
  std::string out = "\"";
  for (size_t i = 0; i < s.size();) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c >= 0x80) {
      const size_t length = Utf8SequenceLength(s, i);
      if (length == 0) {
        out += "\\ufffd";
        ++i;
      } else {
        out.append(s.data() + i, length);
        i += length;
      }
      continue;
    }
    AppendEscaped(c, /*json=*/true, &out);
    ++i;
  }
  return out + "\"";
}

std::string TextField(absl::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char ch : s) {
    const unsigned char c = static_cast<unsigned char>(ch);
    if (c >= 0x80) {
      out += ch;
    } else {
      AppendEscaped(c, /*json=*/false, &out);
    }
  }
  return out;
}

std::string JsonNumber(double x) {
  if (!std::isfinite(x)) return "null";
  return absl::StrFormat("%.17g", x);
}

std::string MetricsJsonFields(const Metrics& m) {
  std::string out =
      absl::StrCat("\"queries\":", m.queries, ",\"nn\":", JsonNumber(m.nn),
                   ",\"ft\":", JsonNumber(m.ft), ",\"st\":", JsonNumber(m.st),
                   ",\"e\":", JsonNumber(m.e), ",\"dcg\":", JsonNumber(m.dcg),
                   ",\"map\":", JsonNumber(m.map), ",\"pr\":[");
  for (int r = 0; r < kRecallLevels; ++r) {
    absl::StrAppend(&out, r ? "," : "", JsonNumber(m.pr[r]));
  }
  return out + "]";
}

std::string MetricsJson(const Metrics& m) {
  return absl::StrCat("{", MetricsJsonFields(m), "}");
}

std::string MetricsSummary(const Metrics& m) {
  return absl::StrFormat(
      "NN %.3f  FT %.3f  ST %.3f  E %.3f  DCG %.3f  mAP %.3f  (%d queries)",
      m.nn, m.ft, m.st, m.e, m.dcg, m.map, m.queries);
}

ClassSizes CountClasses(const std::vector<std::string>& labels) {
  ClassSizes sizes;
  for (const std::string& label : labels) ++sizes[label];
  return sizes;
}

std::string PerClassJson(const Scores& scores, const ClassSizes& sizes) {
  std::string out = "{";
  for (const auto& [cls, n] : sizes) {
    auto it = scores.per_class.find(cls);
    absl::StrAppend(&out, out.size() > 1 ? "," : "", JsonString(cls),
                    ":{\"models\":", n, ",",
                    it == scores.per_class.end()
                        ? std::string("\"queries\":0")
                        : MetricsJsonFields(it->second),
                    "}");
  }
  return out + "}";
}

std::string ScoresTable(const Scores& scores, const ClassSizes& sizes) {
  std::string out =
      absl::StrFormat("%-24s %6s %6s %6s %6s %6s %6s %6s\n", "class", "models",
                      "NN", "FT", "ST", "E", "DCG", "mAP");
  for (const auto& [cls, n] : sizes) {
    auto it = scores.per_class.find(cls);
    AppendRow(&out, cls, n,
              it == scores.per_class.end() ? nullptr : &it->second);
  }
  AppendRow(&out, "ALL", TotalModels(sizes), &scores.overall);
  return out;
}

std::string ScoresMarkdown(const std::string& title, const Scores& scores,
                           const ClassSizes& sizes) {
  std::string out =
      absl::StrCat("#### ", title,
                   "\n\n| class | models | NN | FT | ST | E | DCG | mAP |\n"
                   "|---|---:|---:|---:|---:|---:|---:|---:|\n");
  auto row = [&](const std::string& cls, int n, const Metrics* m) {
    if (m == nullptr) {
      absl::StrAppendFormat(&out, "| %s | %d | - | - | - | - | - | - |\n", cls,
                            n);
      return;
    }
    absl::StrAppendFormat(
        &out, "| %s | %d | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f |\n", cls, n,
        m->nn, m->ft, m->st, m->e, m->dcg, m->map);
  };
  for (const auto& [cls, n] : sizes) {
    auto it = scores.per_class.find(cls);
    row(cls, n, it == scores.per_class.end() ? nullptr : &it->second);
  }
  row("**all**", TotalModels(sizes), &scores.overall);
  return out + "\n";
}

absl::Status WriteTextFile(const std::string& path, absl::string_view text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  out.close();
  if (!out) {
    return absl::PermissionDeniedError(absl::StrCat("cannot write ", path));
  }
  return absl::OkStatus();
}

}  // namespace tpr::eval
