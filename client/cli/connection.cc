#include "client/cli/connection.h"

#include <CLI/CLI.hpp>

#include "client/cli/cli_util.h"

namespace tpr::cli {

void AddGlobalFlags(CLI::App* app, Globals* g) {
  app->add_option("--extractor", g->extractor,
                  "tpr-extractor address(es), HOST:PORT[,HOST:PORT]")
      ->envname("TPR_EXTRACTOR")
      ->capture_default_str();
  app->add_option("--indexer", g->indexer,
                  "tpr-indexer address(es), HOST:PORT[,HOST:PORT]")
      ->envname("TPR_INDEXER")
      ->capture_default_str();
  app->add_flag("--json", g->json, "machine output: one JSON object per line");
  app->add_option("--timeout", g->timeout_s, "deadline per call, in seconds")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
}

tpr::client::CallOptions CallOptionsFor(const Globals& g) {
  tpr::client::CallOptions call;
  call.timeout = absl::Seconds(g.timeout_s);
  return call;
}

std::optional<tpr::client::ExtractorClient> ConnectExtractor(const Globals& g) {
  absl::StatusOr<tpr::client::ExtractorClient> client =
      tpr::client::ExtractorClient::Connect(g.extractor, CallOptionsFor(g));
  if (!client.ok()) {
    Fail("--extractor", client.status());
    return std::nullopt;
  }
  return *std::move(client);
}

std::optional<tpr::client::IndexerClient> ConnectIndexer(const Globals& g) {
  absl::StatusOr<tpr::client::IndexerClient> client =
      tpr::client::IndexerClient::Connect(g.indexer, CallOptionsFor(g));
  if (!client.ok()) {
    Fail("--indexer", client.status());
    return std::nullopt;
  }
  return *std::move(client);
}

}  // namespace tpr::cli
