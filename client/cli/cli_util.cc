#include "client/cli/cli_util.h"

#include <google/protobuf/util/json_util.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <map>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace tpr::cli {

int Fail(const std::string& what, const absl::Status& status) {
  std::fprintf(stderr, "tpr: %s: %s\n", TextField(what).c_str(),
               TextField(status.ToString()).c_str());
  return 1;
}

absl::Status WriteBytesToFile(const std::string& path,
                              absl::string_view bytes) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  bool ok = f != nullptr;
  int error = ok ? 0 : errno;
  if (ok && std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size()) {
    ok = false;
    error = errno;
  }
  if (f != nullptr && std::fclose(f) != 0 && ok) {
    ok = false;
    error = errno;
  }
  if (ok) return absl::OkStatus();
  const std::string message =
      absl::StrCat("cannot write ", path, ": ", std::strerror(error));
  switch (error) {
    case ENOENT:
      return absl::NotFoundError(message);
    case EACCES:
    case EPERM:
      return absl::PermissionDeniedError(message);
    case ENOSPC:
    case EDQUOT:
      return absl::ResourceExhaustedError(message);
    default:
      return absl::FailedPreconditionError(message);
  }
}

std::string FailuresJson(const Failures& failures) {
  std::string out = "[";
  for (const auto& [id, why] : failures) {
    absl::StrAppend(&out, out.size() > 1 ? "," : "", "{\"id\":", JsonString(id),
                    ",\"error\":", JsonString(why), "}");
  }
  return out + "]";
}

void PrintFailures(const Failures& failures) {
  for (const auto& [id, why] : failures) {
    std::printf("  failed %s: %s\n", TextField(id).c_str(),
                TextField(why).c_str());
  }
}

int CountKind(const tpr::v1::Signature& signature, tpr::v1::FeatureKind kind) {
  int count = 0;
  for (const tpr::v1::Feature& f : signature.features())
    count += f.kind() == kind;
  return count;
}

std::string ToJson(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  // Only fails for messages with unresolvable Any fields, which ours lack.
  (void)google::protobuf::util::MessageToJsonString(message, &out, options);
  return out;
}

Progress::Progress(size_t total, std::string what)
    : total_(total),
      what_(std::move(what)),
      tty_(isatty(STDERR_FILENO) == 1),
      start_(Clock::now()) {}

void Progress::Step(const std::string& id, const std::string& outcome) {
  std::lock_guard<std::mutex> lock(mu_);
  ++done_;
  const double elapsed =
      std::chrono::duration<double>(Clock::now() - start_).count();
  const double rate = elapsed > 0 ? done_ / elapsed : 0;
  const double eta = rate > 0 ? (total_ - done_) / rate : 0;
  if (tty_) {
    constexpr int kWidth = 30;
    const int filled =
        total_ ? static_cast<int>(kWidth * done_ / total_) : kWidth;
    std::fprintf(
        stderr, "\r%s%s[%s%s] %zu/%zu  %.1f/s  ETA %.0fs  ", what_.c_str(),
        what_.empty() ? "" : " ", std::string(filled, '#').c_str(),
        std::string(kWidth - filled, '.').c_str(), done_, total_, rate, eta);
    if (done_ == total_) std::fprintf(stderr, "\n");
  } else {
    std::fprintf(stderr, "%zu/%zu %s %s (%.1f/s, ETA %.0fs)\n", done_, total_,
                 outcome.c_str(), TextField(id).c_str(), rate, eta);
  }
  std::fflush(stderr);
}

double Progress::Elapsed() const {
  return std::chrono::duration<double>(Clock::now() - start_).count();
}

std::optional<tpr::v1::Ranking> NamedRanking(absl::string_view name) {
  tpr::v1::Ranking ranking;
  if (name == "paper") {
    ranking.set_emd_weight(1.0);
  } else if (name == "spectrum") {
    ranking.set_spectral_weight(1.0);
  } else {
    return std::nullopt;
  }
  return ranking;
}

void AddIntentOption(CLI::App& command, tpr::v1::Intent* intent) {
  command
      .add_option_function<std::string>(
          "--intent",
          [intent](const std::string& name) {
            const std::string lower = absl::AsciiStrToLower(name);
            *intent = lower == "identity" ? tpr::v1::INTENT_IDENTITY
                      : lower == "kind"   ? tpr::v1::INTENT_KIND
                                          : tpr::v1::INTENT_BALANCED;
          },
          "what to search for: balanced (default), identity (this model in "
          "any pose) or kind (models of this kind)")
      ->check(
          CLI::IsMember({"balanced", "identity", "kind"}, CLI::ignore_case));
}

const char* IntentTitle(tpr::v1::Intent intent) {
  switch (intent) {
    case tpr::v1::INTENT_IDENTITY:
      return "identity";
    case tpr::v1::INTENT_KIND:
      return "kind";
    default:
      return "balanced";
  }
}

void AddHandlesOption(CLI::App& command, tpr::v1::ExtractOptions* options) {
  const std::map<std::string, tpr::v1::HandleTreatment> names = {
      {"cut", tpr::v1::HANDLE_TREATMENT_CUT},
      {"keep", tpr::v1::HANDLE_TREATMENT_KEEP}};
  command
      .add_option_function<tpr::v1::HandleTreatment>(
          "--handles",
          [options](const tpr::v1::HandleTreatment& handles) {
            options->set_handles(handles);
          },
          "handles of a closed mesh of genus > 0: cut (the default: "
          "cut to genus 0 along shortest cycles) or keep (the "
          "paper's method); compare signatures made the same way")
      ->transform(CLI::CheckedTransformer(names, CLI::ignore_case));
}

void AddTopologyOption(CLI::App& command, tpr::v1::ExtractOptions* options) {
  const std::map<std::string, tpr::v1::TopologyMethod> names = {
      {"persistence", tpr::v1::TOPOLOGY_METHOD_PERSISTENCE},
      {"paper", tpr::v1::TOPOLOGY_METHOD_PAPER}};
  command
      .add_option_function<tpr::v1::TopologyMethod>(
          "--topology",
          [options](const tpr::v1::TopologyMethod& topology) {
            options->set_topology(topology);
          },
          "critical points before the vote of 4.4: persistence (the "
          "default: protrusions shorter than point_min_prominence give no "
          "point) or paper (4.3's cycle filter); compare signatures made "
          "the same way")
      ->transform(CLI::CheckedTransformer(names, CLI::ignore_case));
}

}  // namespace tpr::cli
