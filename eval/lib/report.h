// The report writer of an evaluation: the scores of metrics.h as a text
// table (terminal), JSON (machines) and Markdown (docs/), plus the JSON
// primitives the `tpr` command prints with. One writer for `tpr eval` and
// tpr-eval-local, so that both print the same table and the same fields.
//
//   ClassSizes sizes = CountClasses(labels);
//   std::fputs(ScoresTable(scores, sizes).c_str(), stdout);
//   std::string json = "{" + MetricsJsonFields(scores.overall) +
//                      ",\"per_class\":" + PerClassJson(scores, sizes) + "}";
//   absl::Status s = WriteTextFile("out/tables.md", ScoresMarkdown("TPR",
//   scores, sizes));
#ifndef TPR_EVAL_LIB_REPORT_H_
#define TPR_EVAL_LIB_REPORT_H_

#include <map>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "common/json_text.h"
#include "eval/lib/metrics.h"

namespace tpr::eval {

// JsonString and TextField: the escapers of common/json_text.h, here
// beside the other report primitives.
using ::tpr::common::JsonString;
using ::tpr::common::TextField;

// JsonNumber returns `x` with full precision (%.17g, so that a reader can
// compare it with its own computation), or null when x is NaN or infinite:
// JSON has neither. Pure.
std::string JsonNumber(double x);

// MetricsJsonFields returns the fields of `m` without braces, for embedding:
// "queries":Q,"nn":..,"ft":..,"st":..,"e":..,"dcg":..,"map":..,"pr":[21].
std::string MetricsJsonFields(const Metrics& m);

// MetricsJson returns {MetricsJsonFields(m)}.
std::string MetricsJson(const Metrics& m);

// MetricsSummary returns one human line: "NN 0.812  FT 0.530  ST 0.701  E
// 0.402  DCG 0.820  mAP 0.610  (40 queries)".
std::string MetricsSummary(const Metrics& m);

// ClassSizes maps a class to its number of evaluated models.
using ClassSizes = std::map<std::string, int>;

// CountClasses returns the number of models of each label in `labels`.
ClassSizes CountClasses(const std::vector<std::string>& labels);

// PerClassJson returns {"class":{"models":n,<MetricsJsonFields>},...} for
// every class of `sizes`; a class without scores (one model: nothing to
// retrieve) has {"models":n,"queries":0}.
std::string PerClassJson(const Scores& scores, const ClassSizes& sizes);

// ScoresTable returns the text table: one row per class of `sizes` (models,
// NN, FT, ST, E, DCG, mAP; "-" and a note for a class without scores) and
// an ALL row with every class's models. Columns fit 80 characters for class
// names up to 24 characters.
std::string ScoresTable(const Scores& scores, const ClassSizes& sizes);

// ScoresMarkdown returns "#### title" and the same table in Markdown.
std::string ScoresMarkdown(const std::string& title, const Scores& scores,
                           const ClassSizes& sizes);

// WriteTextFile writes `text` to `path` (created or truncated).
// Errors: PERMISSION_DENIED naming the file when it cannot be written.
absl::Status WriteTextFile(const std::string& path, absl::string_view text);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_REPORT_H_
