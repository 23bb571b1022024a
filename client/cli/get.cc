// `tpr get ID...`: stored models with their signature summary and metadata.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "absl/time/time.h"
#include "client/cli/cli_util.h"
#include "client/cli/command.h"

namespace tpr::cli {
namespace {

void PrintModel(const tpr::v1::Model& m) {
  const tpr::v1::Signature& s = m.signature();
  const absl::Time added = absl::FromUnixMicros(m.added_unix_micros());
  std::printf(
      "id:       %s\nlabel:    %s\nadded:    %s\nfeatures: %d points, %d "
      "rings (%d bands)\nmesh:     %lld vertices, %lld faces, genus %lld, "
      "%lld components\nversion:  %s\n",
      TextField(m.id()).c_str(), TextField(m.label()).c_str(),
      absl::FormatTime("%Y-%m-%d %H:%M:%S UTC", added, absl::UTCTimeZone())
          .c_str(),
      CountKind(s, tpr::v1::FEATURE_KIND_POINT),
      CountKind(s, tpr::v1::FEATURE_KIND_RING), s.options().bands(),
      static_cast<long long>(s.mesh().vertices()),
      static_cast<long long>(s.mesh().faces()),
      static_cast<long long>(s.mesh().genus()),
      static_cast<long long>(s.mesh().components()),
      TextField(s.extractor_version()).c_str());
  for (const auto& [key, value] : m.metadata()) {
    std::printf("meta:     %s = %s\n", TextField(key).c_str(),
                TextField(value).c_str());
  }
}

int RunGet(const Globals& g, const std::vector<std::string>& ids) {
  std::optional<tpr::client::IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 1;
  int failures = 0;
  for (const std::string& id : ids) {
    absl::StatusOr<tpr::v1::Model> m = indexer->Get(id);
    if (!m.ok()) {
      ++failures;
      Fail(id, m.status());
    } else if (g.json) {
      std::printf("%s\n", ToJson(*m).c_str());
    } else {
      PrintModel(*m);
    }
  }
  return failures == 0 ? 0 : 1;
}

const bool kRegistered = RegisterCommand(
    {"get", "show stored models", [](CLI::App& sub) {
       auto ids = std::make_shared<std::vector<std::string>>();
       sub.add_option("ID", *ids, "model ids")->required();
       return [ids](const Globals& g) { return RunGet(g, *ids); };
     }});

}  // namespace
}  // namespace tpr::cli
