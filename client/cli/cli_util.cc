#include "client/cli/cli_util.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/reflection.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <map>
#include <mutex>
#include <regex>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace tpr::cli {

namespace {
std::atomic<bool> json_errors{false};
std::mutex report_mu;

// "tpr-indexer" and "127.0.0.1:7002" from the SDK's "cannot reach
// tpr-indexer at 127.0.0.1:7002: ...".
bool Unreachable(absl::string_view message, std::string* service,
                 std::string* address) {
  static const std::regex kReach("cannot reach (tpr-[a-z]+) at ([^ ]+): ");
  std::cmatch m;
  const std::string text(message);
  if (!std::regex_search(text.c_str(), m, kReach)) return false;
  *service = m[1];
  *address = m[2];
  return true;
}

}  // namespace

void SetJsonErrors(bool json) { json_errors = json; }

void ReportError(const std::string& message, const std::string& hint,
                 bool usage, const std::string& code) {
  std::lock_guard<std::mutex> lock(report_mu);
  if (json_errors) {
    std::printf("{\"error\":{\"code\":%s,\"message\":%s,\"hint\":%s}}\n",
                JsonString(usage ? "USAGE" : code).c_str(),
                JsonString(message).c_str(), JsonString(hint).c_str());
    std::fflush(stdout);
    return;
  }
  std::fprintf(stderr, "tpr: %s\n", TextField(message).c_str());
  if (!hint.empty()) std::fprintf(stderr, "  hint: %s\n", hint.c_str());
}

std::string HintFor(const absl::Status& status) {
  std::string service, address;
  if (absl::IsUnavailable(status) &&
      Unreachable(status.message(), &service, &address)) {
    const std::string flag = service == "tpr-extractor"
                                 ? "--extractor (TPR_EXTRACTOR)"
                                 : "--indexer (TPR_INDEXER)";
    std::string hint = absl::StrCat(
        "start it with '", service, " --listen ", address,
        "' (scripts/demo starts every service), or give its address with ",
        flag);
    if (absl::StrContains(status.message(), "does it use TLS?")) {
      absl::StrAppend(&hint, "; a TLS server needs --tls and --tls-ca");
    } else if (absl::StrContains(status.message(), "handshake")) {
      absl::StrAppend(&hint,
                      "; for TLS check --tls-ca, --tls-server-name, and for "
                      "mutual TLS --tls-cert with --tls-key");
    }
    return hint;
  }
  if (absl::IsUnimplemented(status) &&
      absl::StrContains(status.message(), "it is not a tpr-")) {
    return "tpr-extractor listens on 7001 and tpr-indexer (or tpr-gateway) on "
           "7002 by default: check --extractor and --indexer (TPR_EXTRACTOR, "
           "TPR_INDEXER)";
  }
  return "";
}

int FailUsage(const std::string& message) {
  ReportError(message, "see 'tpr help COMMAND'", /*usage=*/true);
  return 2;
}

int Fail(const std::string& what, const absl::Status& status) {
  ReportError(absl::StrCat(what, ": ", status.ToString()), HintFor(status),
              /*usage=*/false, absl::StatusCodeToString(status.code()));
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

namespace {

using google::protobuf::FieldDescriptor;
using google::protobuf::Reflection;

std::string Base64(const std::string& bytes) {
  static const char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < bytes.size(); i += 3) {
    uint32_t v = static_cast<unsigned char>(bytes[i]) << 16;
    if (i + 1 < bytes.size())
      v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    if (i + 2 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 2]);
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? kAlphabet[(v >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? kAlphabet[v & 63] : '=';
  }
  return out;
}

void AppendMessage(const google::protobuf::Message& message, std::string* out);

// One value of `field` (element `index` when repeated, else -1).
void AppendValue(const google::protobuf::Message& message,
                 const FieldDescriptor* field, int index, std::string* out) {
  const Reflection* r = message.GetReflection();
  const bool rep = index >= 0;
  switch (field->cpp_type()) {
    case FieldDescriptor::CPPTYPE_INT32:
      absl::StrAppend(out, rep ? r->GetRepeatedInt32(message, field, index)
                               : r->GetInt32(message, field));
      break;
    case FieldDescriptor::CPPTYPE_INT64:
      absl::StrAppend(out, rep ? r->GetRepeatedInt64(message, field, index)
                               : r->GetInt64(message, field));
      break;
    case FieldDescriptor::CPPTYPE_UINT32:
      absl::StrAppend(out, rep ? r->GetRepeatedUInt32(message, field, index)
                               : r->GetUInt32(message, field));
      break;
    case FieldDescriptor::CPPTYPE_UINT64:
      absl::StrAppend(out, rep ? r->GetRepeatedUInt64(message, field, index)
                               : r->GetUInt64(message, field));
      break;
    case FieldDescriptor::CPPTYPE_DOUBLE:
      *out += JsonNumber(rep ? r->GetRepeatedDouble(message, field, index)
                             : r->GetDouble(message, field));
      break;
    case FieldDescriptor::CPPTYPE_FLOAT:
      *out += JsonNumber(rep ? r->GetRepeatedFloat(message, field, index)
                             : r->GetFloat(message, field));
      break;
    case FieldDescriptor::CPPTYPE_BOOL:
      *out += (rep ? r->GetRepeatedBool(message, field, index)
                   : r->GetBool(message, field))
                  ? "true"
                  : "false";
      break;
    case FieldDescriptor::CPPTYPE_ENUM:
      *out += JsonString((rep ? r->GetRepeatedEnum(message, field, index)
                              : r->GetEnum(message, field))
                             ->name());
      break;
    case FieldDescriptor::CPPTYPE_STRING: {
      const std::string v = rep ? r->GetRepeatedString(message, field, index)
                                : r->GetString(message, field);
      *out += JsonString(
          field->type() == FieldDescriptor::TYPE_BYTES ? Base64(v) : v);
      break;
    }
    case FieldDescriptor::CPPTYPE_MESSAGE:
      AppendMessage(rep ? r->GetRepeatedMessage(message, field, index)
                        : r->GetMessage(message, field),
                    out);
      break;
  }
}

void AppendMessage(const google::protobuf::Message& message, std::string* out) {
  const google::protobuf::Descriptor* d = message.GetDescriptor();
  const Reflection* r = message.GetReflection();
  *out += '{';
  bool first = true;
  for (int f = 0; f < d->field_count(); ++f) {
    const FieldDescriptor* field = d->field(f);
    // Unset message fields and unset members of a oneof are left out, as
    // protobuf's JSON printer does; every other field is printed.
    if (!field->is_repeated() &&
        (field->cpp_type() == FieldDescriptor::CPPTYPE_MESSAGE ||
         field->containing_oneof() != nullptr) &&
        !r->HasField(message, field)) {
      continue;
    }
    absl::StrAppend(out, first ? "" : ",", JsonString(field->name()), ":");
    first = false;
    if (field->is_map()) {
      *out += '{';
      const int n = r->FieldSize(message, field);
      for (int i = 0; i < n; ++i) {
        const google::protobuf::Message& entry =
            r->GetRepeatedMessage(message, field, i);
        const FieldDescriptor* key = entry.GetDescriptor()->map_key();
        std::string k;
        AppendValue(entry, key, -1, &k);
        if (k.empty() || k.front() != '"') k = JsonString(k);
        absl::StrAppend(out, i ? "," : "", k, ":");
        AppendValue(entry, entry.GetDescriptor()->map_value(), -1, out);
      }
      *out += '}';
    } else if (field->is_repeated()) {
      *out += '[';
      const int n = r->FieldSize(message, field);
      for (int i = 0; i < n; ++i) {
        if (i) *out += ',';
        AppendValue(message, field, i, out);
      }
      *out += ']';
    } else {
      AppendValue(message, field, -1, out);
    }
  }
  *out += '}';
}

}  // namespace

std::string ToJson(const google::protobuf::Message& message) {
  std::string out;
  AppendMessage(message, &out);
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
      ->check(CLI::IsMember({"balanced", "identity", "kind"}, CLI::ignore_case)
                  .description(""))
      ->type_name("balanced|identity|kind");
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
      ->transform(
          CLI::CheckedTransformer(names, CLI::ignore_case).description(""))
      ->type_name("cut|keep");
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
          "which bumps of the surface become topological points: "
          "persistence (the default: small protrusions give none) or paper "
          "(the cycle filter of Tam and Lau's paper); compare signatures "
          "made the same way")
      ->transform(
          CLI::CheckedTransformer(names, CLI::ignore_case).description(""))
      ->type_name("persistence|paper");
}

}  // namespace tpr::cli
