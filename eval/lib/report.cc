#include "eval/lib/report.h"

#include <cmath>
#include <fstream>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace tpr::eval {
namespace {

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

// Hand-written rather than through a JSON library: the reports are a few
// flat objects, and a string escaper and a number formatter are all they
// need (protobuf's printer serves the messages the CLI prints whole).
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
