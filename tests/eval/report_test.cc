// The report writer: JSON that a strict parser accepts whatever bytes a name
// holds, numbers that read back exactly (null for non-finite), text fields
// that stay on one line, and the table and Markdown forms of one Scores.
#include "eval/lib/report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>

#include "eval/lib/metrics.h"

namespace tpr::eval {
namespace {

// A small strict JSON string parser (RFC 8259), the oracle for JsonString:
// returns the decoded bytes, or "<invalid>" when `json` is not exactly one
// valid string literal of valid UTF-8.
std::string ParseJsonString(const std::string& json) {
  const std::string kInvalid = "<invalid>";
  if (json.size() < 2 || json.front() != '"' || json.back() != '"')
    return kInvalid;
  std::string out;
  for (size_t i = 1; i + 1 < json.size(); ++i) {
    const unsigned char c = json[i];
    if (c < 0x20 || c == '"') return kInvalid;
    if (c >= 0x80) {
      // Multi-byte UTF-8: lead byte and continuation bytes.
      const int length = c >= 0xF0 ? 4 : c >= 0xE0 ? 3 : c >= 0xC2 ? 2 : 0;
      if (length == 0 || i + length > json.size() - 1) return kInvalid;
      for (int k = 1; k < length; ++k) {
        if ((static_cast<unsigned char>(json[i + k]) & 0xC0) != 0x80)
          return kInvalid;
      }
      out.append(json, i, length);
      i += length - 1;
      continue;
    }
    if (c != '\\') {
      out += static_cast<char>(c);
      continue;
    }
    if (++i + 1 >= json.size() + 1) return kInvalid;
    switch (json[i]) {
      case '"':
        out += '"';
        break;
      case '\\':
        out += '\\';
        break;
      case '/':
        out += '/';
        break;
      case 'b':
        out += '\b';
        break;
      case 'f':
        out += '\f';
        break;
      case 'n':
        out += '\n';
        break;
      case 'r':
        out += '\r';
        break;
      case 't':
        out += '\t';
        break;
      case 'u': {
        if (i + 4 >= json.size()) return kInvalid;
        const long code =
            std::strtol(json.substr(i + 1, 4).c_str(), nullptr, 16);
        i += 4;
        if (code < 0x80) {
          out += static_cast<char>(code);
        } else if (code == 0xFFFD) {
          out += "\xEF\xBF\xBD";
        } else {
          return kInvalid;  // not produced by JsonString
        }
        break;
      }
      default:
        return kInvalid;
    }
  }
  return out;
}

TEST(ReportTest, JsonStringRoundTripsEveryAsciiByte) {
  std::string all;
  for (int c = 1; c < 0x80; ++c) all += static_cast<char>(c);
  all += '\0';
  const std::string json = JsonString(all);
  EXPECT_EQ(ParseJsonString(json), all) << json;
}

TEST(ReportTest, JsonStringKeepsUtf8AndReplacesInvalidBytes) {
  const std::string utf8 =
      "caf\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x90\x95";  // é € 🐕
  EXPECT_EQ(ParseJsonString(JsonString(utf8)), utf8);
  // A lone continuation byte, a truncated sequence, an overlong '/', a
  // surrogate: each invalid byte becomes U+FFFD, and the rest is kept.
  EXPECT_EQ(JsonString("a\x80z"), "\"a\\ufffdz\"");
  EXPECT_EQ(JsonString("a\xE2\x82"), "\"a\\ufffd\\ufffd\"");
  EXPECT_EQ(JsonString("\xC0\xAF"), "\"\\ufffd\\ufffd\"");
  EXPECT_EQ(JsonString("\xED\xA0\x80"), "\"\\ufffd\\ufffd\\ufffd\"");
  EXPECT_NE(ParseJsonString(JsonString("\xFF\xFE id\n")), "<invalid>");
}

TEST(ReportTest, JsonNumberIsExactAndNullForNonFinite) {
  for (double x : {0.0, -0.0, 1.0 / 3, 1e-300, 6.02214076e23, -2.5}) {
    EXPECT_EQ(std::strtod(JsonNumber(x).c_str(), nullptr), x) << JsonNumber(x);
  }
  EXPECT_EQ(JsonNumber(std::numeric_limits<double>::infinity()), "null");
  EXPECT_EQ(JsonNumber(-std::numeric_limits<double>::infinity()), "null");
  EXPECT_EQ(JsonNumber(std::nan("")), "null");
}

TEST(ReportTest, TextFieldKeepsOneLineAndIsReversible) {
  EXPECT_EQ(TextField("dog/dog_3.off"), "dog/dog_3.off");
  EXPECT_EQ(TextField("a\nb\tc\rd"), "a\\nb\\tc\\rd");
  EXPECT_EQ(TextField(std::string("x\x01y\x7f", 4)), "x\\x01y\\x7f");
  EXPECT_EQ(TextField("back\\slash"), "back\\\\slash");
  // "a\n" (two characters, backslash and n) and "a<newline>" differ.
  EXPECT_NE(TextField("a\\n"), TextField("a\n"));
  EXPECT_EQ(TextField("caf\xC3\xA9"), "caf\xC3\xA9");
  for (unsigned char c = 0; c < 0x20; ++c) {
    EXPECT_EQ(
        TextField(std::string(1, static_cast<char>(c))).find_first_of("\n\r"),
        std::string::npos);
  }
}

Scores TwoClassScores() {
  const std::vector<std::string> labels = {"A", "A", "B", "B", "C"};
  std::vector<Query> queries = {
      {0, {{1, 0.1}, {2, 0.2}, {3, 0.3}, {4, 0.4}}},
      {1, {{2, 0.1}, {0, 0.2}, {3, 0.3}, {4, 0.4}}},
      {2, {{3, 0.1}, {0, 0.2}, {1, 0.3}, {4, 0.4}}},
      {3, {{2, 0.1}, {0, 0.2}, {1, 0.3}, {4, 0.4}}},
  };
  return Evaluate(labels, queries);
}

TEST(ReportTest, TableAndMarkdownShowEveryClassAndTheOverallRow) {
  const Scores s = TwoClassScores();
  const ClassSizes sizes = CountClasses({"A", "A", "B", "B", "C"});
  EXPECT_EQ(sizes.at("A"), 2);
  EXPECT_EQ(sizes.at("C"), 1);
  const std::string table = ScoresTable(s, sizes);
  EXPECT_NE(table.find("class"), std::string::npos);
  EXPECT_NE(table.find("(one model: no query)"), std::string::npos) << table;
  const size_t all = table.find("\nALL ");
  ASSERT_NE(all, std::string::npos) << table;
  // ALL counts every model, and its NN is the overall one (3 of 4 queries).
  EXPECT_NE(table.find("      5  0.750", all), std::string::npos) << table;
  for (const std::string& line : {table}) EXPECT_LE(line.find('\n'), 80u);
  const std::string md = ScoresMarkdown("TPR", s, sizes);
  EXPECT_EQ(md.rfind("#### TPR\n", 0), 0u);
  EXPECT_NE(md.find("| **all** | 5 | 0.750 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| C | 1 | - |"), std::string::npos) << md;
}

TEST(ReportTest, PerClassJsonEscapesNamesAndMarksClassesWithoutQueries) {
  Scores s = TwoClassScores();
  ClassSizes sizes = CountClasses({"A", "A", "B", "B", "C"});
  s.per_class["we\"ird\n"] = s.per_class["A"];
  sizes["we\"ird\n"] = 2;
  const std::string json = PerClassJson(s, sizes);
  EXPECT_NE(json.find("\"we\\\"ird\\n\":{\"models\":2,\"queries\":2,"),
            std::string::npos)
      << json;
  EXPECT_NE(json.find("\"C\":{\"models\":1,\"queries\":0}"), std::string::npos)
      << json;
  EXPECT_EQ(json.find('\n'), std::string::npos);
  const std::string m = MetricsJson(s.overall);
  EXPECT_EQ(m.front(), '{');
  EXPECT_EQ(m.back(), '}');
  EXPECT_NE(m.find("\"nn\":0.75,"), std::string::npos) << m;
}

}  // namespace
}  // namespace tpr::eval
