// `tpr remove ID...`: delete stored models.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "client/cli/cli_util.h"
#include "client/cli/command.h"

namespace tpr::cli {
namespace {

int RunRemove(const Globals& g, const std::vector<std::string>& ids) {
  std::optional<tpr::client::IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 2;
  int failures = 0;
  for (const std::string& id : ids) {
    absl::Status s = indexer->Delete(id);
    if (!s.ok()) {
      ++failures;
      Fail(id, s);
    } else if (g.json) {
      std::printf("{\"removed\":%s}\n", JsonString(id).c_str());
    } else {
      std::printf("removed %s\n", TextField(id).c_str());
    }
  }
  return failures == 0 ? 0 : 1;
}

const bool kRegistered = RegisterCommand(
    {"remove", "delete stored models",
     [](CLI::App& sub) {
       auto ids = std::make_shared<std::vector<std::string>>();
       sub.add_option("ID", *ids, "model ids")->required();
       return [ids](const Globals& g) { return RunRemove(g, *ids); };
     },
     "tpr remove dog1/T305.obj dog1/T306.obj"});

}  // namespace
}  // namespace tpr::cli
