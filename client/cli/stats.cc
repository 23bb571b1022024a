// `tpr stats`: index counts and sizes, models per label.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <map>
#include <string>

#include "client/cli/cli_util.h"
#include "client/cli/command.h"

namespace tpr::cli {
namespace {

int RunStats(const Globals& g) {
  std::optional<tpr::client::IndexerClient> indexer = ConnectIndexer(g);
  if (!indexer) return 2;
  absl::StatusOr<tpr::v1::StatsResponse> s = indexer->Stats();
  if (!s.ok()) return Fail("stats", s.status());
  if (g.json) {
    std::printf("%s\n", ToJson(*s).c_str());
    return 0;
  }
  std::printf(
      "models:   %lld (%lld in the VP-tree, %lld buffered)\ndisk:     %.1f "
      "MiB\n",
      static_cast<long long>(s->models()), static_cast<long long>(s->indexed()),
      static_cast<long long>(s->buffered()), s->disk_bytes() / 1048576.0);
  std::map<std::string, int64_t> labels(s->labels().begin(), s->labels().end());
  for (const auto& [label, count] : labels) {
    std::printf("label:    %-24s %lld\n",
                label.empty() ? "(none)" : TextField(label).c_str(),
                static_cast<long long>(count));
  }
  return 0;
}

const bool kRegistered = RegisterCommand(
    {"stats", "index counts and sizes",
     [](CLI::App&) { return [](const Globals& g) { return RunStats(g); }; },
     "tpr stats"});

}  // namespace
}  // namespace tpr::cli
