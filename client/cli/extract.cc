// `tpr extract MESH...`: the signature summary of meshes, extracted by
// tpr-extractor (points, rings, mesh statistics, stage timings, warnings).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/cli_util.h"
#include "client/cli/command.h"

namespace tpr::cli {
namespace {

struct ExtractFlags {
  std::vector<std::string> meshes;
  // Sent with every mesh; --bands and --handles fill it.
  tpr::v1::ExtractOptions options;
};

void PrintSummary(const std::string& path, const tpr::v1::ExtractResponse& r) {
  const tpr::v1::Signature& s = r.signature();
  double total = 0;
  std::string stages;
  for (const tpr::v1::StageTiming& t : r.timings()) {
    total += t.milliseconds();
    absl::StrAppend(&stages, stages.empty() ? "" : ", ", t.stage(), " ",
                    absl::StrFormat("%.1f", t.milliseconds()));
  }
  std::printf(
      "%s: %d points, %d rings (%lld vertices, %lld faces, genus %lld); "
      "%.1f ms [%s]\n",
      TextField(path).c_str(), CountKind(s, tpr::v1::FEATURE_KIND_POINT),
      CountKind(s, tpr::v1::FEATURE_KIND_RING),
      static_cast<long long>(s.mesh().vertices()),
      static_cast<long long>(s.mesh().faces()),
      static_cast<long long>(s.mesh().genus()), total, stages.c_str());
  for (const std::string& w : r.warnings()) {
    std::printf("  warning: %s\n", TextField(w).c_str());
  }
}

int RunExtract(const Globals& g, const ExtractFlags& flags) {
  std::optional<tpr::client::ExtractorClient> client = ConnectExtractor(g);
  if (!client) return 1;
  int failures = 0;
  for (const std::string& path : flags.meshes) {
    absl::StatusOr<tpr::v1::ExtractResponse> r =
        client->ExtractFile(path, flags.options);
    if (!r.ok()) {
      ++failures;
      if (g.json) {
        std::printf("{\"file\":%s,\"error\":%s}\n", JsonString(path).c_str(),
                    JsonString(r.status().ToString()).c_str());
      } else {
        Fail(path, r.status());
      }
    } else if (g.json) {
      std::printf("{\"file\":%s,\"response\":%s}\n", JsonString(path).c_str(),
                  ToJson(*r).c_str());
    } else {
      PrintSummary(path, *r);
    }
  }
  return failures == 0 ? 0 : 1;
}

const bool kRegistered = RegisterCommand(
    {"extract", "print the signature summary of meshes", [](CLI::App& sub) {
       auto flags = std::make_shared<ExtractFlags>();
       sub.add_option("MESH", flags->meshes, "mesh files (OFF, OBJ, PLY, STL)")
           ->required();
       sub.add_option_function<int>(
           "--bands",
           [flags](const int& bands) { flags->options.set_bands(bands); },
           "geodesic bands per feature (0: default 20)");
       AddHandlesOption(sub, &flags->options);
       AddTopologyOption(sub, &flags->options);
       return [flags](const Globals& g) { return RunExtract(g, *flags); };
     }});

}  // namespace
}  // namespace tpr::cli
