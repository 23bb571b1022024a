// Shared output plumbing of the `tpr` subcommands: error printing, the
// escapers (from eval/lib/report.h), and the progress bar.
//
//   Progress progress(items.size(), "adding");
//   ParallelFor(items.size(), jobs,
//               [&](size_t i) { progress.Step(id, "added"); });
//   if (!status.ok()) return Fail("add", status);
#ifndef TPR_CLIENT_CLI_CLI_UTIL_H_
#define TPR_CLIENT_CLI_CLI_UTIL_H_

#include <google/protobuf/message.h>

#include <chrono>
#include <cstddef>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"
#include "common/parallel.h"
#include "eval/lib/report.h"
#include "tpr/v1/indexer.pb.h"
#include "tpr/v1/signature.pb.h"

namespace CLI {
class App;
}  // namespace CLI

namespace tpr::cli {

// One escaper and one loop for the whole command (eval/lib is shared with
// tpr-eval-local).
using tpr::common::ParallelFor;
using tpr::eval::JsonNumber;
using tpr::eval::JsonString;
using tpr::eval::TextField;

// SetJsonErrors makes every error of the process a JSON object on stdout
// (--json) instead of text on stderr. Call once, before any output.
void SetJsonErrors(bool json);

// ReportError prints one error: "tpr: MESSAGE" and "  hint: HINT" (when
// not empty) on stderr, or under SetJsonErrors(true) one line
// {"error":{"code":C,"message":M,"hint":H}} on stdout, C being "USAGE" for
// a usage error. Thread-safe.
void ReportError(const std::string& message, const std::string& hint,
                 bool usage, const std::string& code = "");

// Fail reports "WHAT: STATUS" (ReportError, code = the status's code), with
// a hint for the mistakes a user makes most (a service not running or at
// another address, plaintext against TLS, one service's address given for
// the other), and returns exit code 1.
int Fail(const std::string& what, const absl::Status& status);

// FailUsage reports MESSAGE as a usage error (ReportError) and returns
// exit code 2.
int FailUsage(const std::string& message);

// HintFor returns the hint Fail prints for `status` ("" when none). Pure.
std::string HintFor(const absl::Status& status);

// WriteBytesToFile writes `bytes` to `path`, replacing it. Errors: the
// file cannot be opened or written (the message names the path and the
// system's reason): NOT_FOUND for a missing directory, PERMISSION_DENIED,
// RESOURCE_EXHAUSTED for a full disk, FAILED_PRECONDITION otherwise.
absl::Status WriteBytesToFile(const std::string& path, absl::string_view bytes);

// Failures: (id, reason) of each item a command could not handle.
using Failures = std::vector<std::pair<std::string, std::string>>;

// FailuresJson returns `failures` as a JSON array of {"id","error"} objects.
std::string FailuresJson(const Failures& failures);

// PrintFailures prints one line "  failed ID: REASON" per failure on stdout.
void PrintFailures(const Failures& failures);

// CountKind returns the number of features of `kind` in `signature`.
int CountKind(const tpr::v1::Signature& signature, tpr::v1::FeatureKind kind);

// NamedRanking returns the SearchRequest.ranking that a `--rank-by` name
// stands for: "paper" ranks by the EMD of Eq. 7 alone, "spectrum" by the
// spectral term alone. "default", "" and any other name give nullopt: the
// intent's weighting. Every one is served by the indexer's VP-tree.
// Thread-safe.
std::optional<tpr::v1::Ranking> NamedRanking(absl::string_view name);

// AddIntentOption adds `--intent balanced|identity|kind` (case ignored) to
// a command that searches; when given, it sets *intent (SearchRequest.
// intent): balanced, the default, or identity ("this model in any pose")
// or kind ("models of this kind"). CLI11 refuses any other word, naming
// it. `intent` must outlive the parse.
void AddIntentOption(CLI::App& command, tpr::v1::Intent* intent);

// IntentTitle returns "balanced", "identity" or "kind" for a wire intent
// (INTENT_UNSPECIFIED reads as balanced). Thread-safe.
const char* IntentTitle(tpr::v1::Intent intent);

// AddHandlesOption adds `--handles cut|keep` (case ignored) to a command
// that extracts meshes; when given, it sets options->handles: what the
// extractor does with the handles of a closed mesh of genus > 0. "keep" is
// the paper's method; unset leaves HANDLE_TREATMENT_UNSPECIFIED, the
// extractor's default (cut). CLI11 refuses any other word, naming it.
// `options` must outlive the parse.
void AddHandlesOption(CLI::App& command, tpr::v1::ExtractOptions* options);

// AddTopologyOption adds `--topology persistence|paper` (case ignored) to a
// command that extracts meshes; when given, it sets options->topology: how
// the extractor cleans the critical points before Topological Point
// Selection. "paper" is the paper's method (4.3); unset leaves
// TOPOLOGY_METHOD_UNSPECIFIED, the extractor's default (persistence). CLI11
// refuses any other word, naming it. `options` must outlive the parse.
void AddTopologyOption(CLI::App& command, tpr::v1::ExtractOptions* options);

// ToJson returns `message` as one line of JSON: proto field names, every
// scalar field printed, every number a JSON number (64-bit integers too,
// unlike protobuf's JSON mapping; NaN and infinities as null), enums by
// name, bytes in base64, maps as objects, unset message fields left out.
// Valid JSON whatever the strings hold (JsonString).
std::string ToJson(const google::protobuf::Message& message);

// Progress reports work done on stderr: a redrawn bar with rate and ETA on a
// terminal, one line per step otherwise ("3/9 added dog/dog_3.off ...").
// Thread-safe.
class Progress {
 public:
  // `total` steps; `what` prefixes the bar on a terminal ("" for none).
  explicit Progress(size_t total, std::string what = "");
  // Step counts one unit of work on `id` that ended as `outcome`.
  void Step(const std::string& id, const std::string& outcome);
  // Elapsed returns the seconds since construction.
  double Elapsed() const;

 private:
  using Clock = std::chrono::steady_clock;
  std::mutex mu_;
  size_t done_ = 0;
  const size_t total_;
  const std::string what_;
  const bool tty_;
  const Clock::time_point start_;
};

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_CLI_UTIL_H_
