// `tpr list`: stored models in id order. In text output an id or label
// holding a control character is escaped (TextField: "\n", "\t", "\x01",
// and "\\" for a backslash), so that each model stays on one line.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "client/cli/cli_util.h"
#include "client/cli/command.h"

namespace tpr::cli {
namespace {

int RunList(const Globals& g, const std::string& label) {
  std::optional<tpr::client::IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 2;
  absl::StatusOr<std::vector<tpr::v1::Model>> models = indexer->ListAll(label);
  if (!models.ok()) return Fail("list", models.status());
  for (const tpr::v1::Model& m : *models) {
    if (g.json) {
      std::printf("{\"id\":%s,\"label\":%s,\"added_unix_micros\":%lld}\n",
                  JsonString(m.id()).c_str(), JsonString(m.label()).c_str(),
                  static_cast<long long>(m.added_unix_micros()));
    } else {
      std::printf("%-48s %s\n", TextField(m.id()).c_str(),
                  TextField(m.label()).c_str());
    }
  }
  if (!g.json) std::fprintf(stderr, "(%zu models)\n", models->size());
  return 0;
}

const bool kRegistered = RegisterCommand(
    {"list",
     "list stored models in id order (text output escapes control "
     "characters in ids and labels: \\n, \\t, \\xHH, \\\\)",
     [](CLI::App& sub) {
       auto label = std::make_shared<std::string>();
       sub.add_option("--label", *label, "only models with this label");
       return [label](const Globals& g) { return RunList(g, *label); };
     },
     "tpr list --label dog1"});

}  // namespace
}  // namespace tpr::cli
