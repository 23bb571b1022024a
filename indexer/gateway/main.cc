// tpr-gateway: the stateless front of a sharded index. Serves the unchanged
// tpr.v1.Indexer service (with health and reflection) over S tpr-indexer
// shards (gateway_service.h); on SIGTERM/SIGINT it stops accepting calls,
// lets in-flight calls finish (grace period) and exits 0.
//
//   tpr-gateway --listen 127.0.0.1:7003 --shard 127.0.0.1:7100
//               --shard 127.0.0.1:7110,127.0.0.1:7111   (shard 1 has a replica)
//   tpr-gateway --listen 0.0.0.0:7003 --shard-map /etc/tpr/shards.txt
//   tpr-gateway ... --shard-tls --shard-tls-ca ca.pem --shard-api-key KEY
//               (or TPR_GATEWAY_SHARD_API_KEY): how it reaches secured shards
#include <chrono>
#include <fstream>
#include <functional>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "CLI/CLI.hpp"
#include "absl/strings/str_cat.h"
#include "client/peer/connection_flags.h"
#include "common/config.h"
#include "common/server_flags.h"
#include "common/server_lifecycle.h"
#include "indexer/gateway/gateway_service.h"
#include "indexer/gateway/shard_map.h"
#include "indexer/service/search_metrics.h"
#include "tpr/connection.h"

namespace {

// CheckShardPlaces asks every shard's primary once (a Stats call, which
// carries the shard's place in this map: gateway_service.h) whether it
// accepts its place. Returns exit code 2 after logging the shard, its
// address and its stored place when one refuses (the map lists the shards
// in another order); nullopt when all accept. A shard that cannot be
// reached is logged and checked on its first call instead.
std::optional<int> CheckShardPlaces(
    tpr::gateway::GatewayService& service,
    const std::function<void(const std::string&)>& log) {
  tpr::gateway::Shards& shards = service.shards();
  for (int s = 0; s < shards.count(); ++s) {
    tpr::gateway::Shards::Endpoint& primary = shards.primary(s);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::seconds(5));
    tpr::v1::StatsResponse stats;
    const grpc::Status status =
        primary.stub->Stats(&context, tpr::v1::StatsRequest(), &stats);
    if (status.error_code() == grpc::StatusCode::FAILED_PRECONDITION) {
      log(absl::StrCat("refusing to start: shard ", s, " (", primary.address,
                       ") refuses its place: ", status.error_message()));
      return 2;
    }
    if (!status.ok()) {
      log(absl::StrCat("shard ", s, " (", primary.address,
                       ") did not answer at start (", status.error_message(),
                       "); its place is checked on every call"));
    }
  }
  return std::nullopt;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "tpr-gateway: one tpr.v1.Indexer endpoint over sharded tpr-indexer "
      "processes"};
  tpr::common::ServerOptions server_options;
  server_options.listen_address = "127.0.0.1:7003";
  server_options.log_name = "tpr-gateway";
  tpr::gateway::GatewayOptions options;
  std::vector<std::string> shard_flags;
  std::string shard_map_path;
  tpr::common::ServerFlags ops_flags;
  tpr::common::AddListenFlags(app, &server_options);
  tpr::common::AddServerThreadsFlag(app, &ops_flags);
  app.add_option(
      "--shard", shard_flags,
      "One shard, in shard order: PRIMARY[,REPLICA...] (repeat per shard)");
  app.add_option(
      "--shard-map", shard_map_path,
      "File with one shard per line: PRIMARY [REPLICA ...] ('#' comments)");
  app.add_option("--health-interval-ms", options.health_interval_ms,
                 "How often every shard address is health-checked (0: never)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_option("--health-timeout-ms", options.health_timeout_ms,
                 "Deadline of one health check")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  std::string reads = "any";
  app.add_option("--reads", reads,
                 "Where reads go: any (any serving copy of a shard; a follower "
                 "may lag the primary's latest writes) or primary (the "
                 "primary only: every acknowledged write is seen)")
      ->check(CLI::IsMember({"any", "primary"}))
      ->capture_default_str();
  // How the gateway reaches the shards: the SDK's connection options.
  tpr::client::ConnectionOptions shard_connection;
  tpr::client::AddPeerConnectionFlags(app, "shard", "the shards",
                                      &shard_connection);
  app.add_option(
      "--shard-api-key", shard_connection.api_key,
      "API key sent to the shards (role write, admin for backups); prefer the "
      "environment variable TPR_GATEWAY_SHARD_API_KEY, which ps does not show");
  tpr::common::AddServerFlags(app, &ops_flags);
  tpr::common::ConfigSupport config =
      tpr::common::AddConfigSupport(app, "TPR_GATEWAY_", {"shard-api-key"});
  CLI11_PARSE(app, argc, argv);
  options.reads_from_primary = reads == "primary";
  if (std::optional<int> exit_code =
          tpr::common::FinishServerFlags(config, ops_flags, &server_options)) {
    return *exit_code;
  }
  // Readiness (the health status of "tpr.v1.Indexer") stays SERVING until
  // draining: a gateway can always answer, if need be with UNAVAILABLE
  // naming the shard that cannot.
  server_options.readiness_service = "tpr.v1.Indexer";

  const std::string name = server_options.log_name;
  auto log = [name](const std::string& line) {
    tpr::common::LogEvent(name, line);
  };
  if (shard_flags.empty() == shard_map_path.empty()) {
    log("give the shards either with --shard (repeated) or with --shard-map "
        "FILE");
    return 2;
  }
  absl::StatusOr<tpr::gateway::ShardMap> map;
  if (!shard_map_path.empty()) {
    std::ifstream in(shard_map_path);
    if (!in) {
      log(absl::StrCat("cannot read the shard map ", shard_map_path));
      return 2;
    }
    std::stringstream text;
    text << in.rdbuf();
    map = tpr::gateway::ParseShardMap(text.str());
  } else {
    map = tpr::gateway::ParseShardFlags(shard_flags);
  }
  if (!map.ok()) {
    log(map.status().ToString());
    return 2;
  }
  options.shards = std::move(*map);
  options.log = log;
  {
    grpc::ChannelArguments unused;  // the server name is passed on below
    absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> credentials =
        tpr::client::MakeChannelCredentials(shard_connection, &unused);
    if (!credentials.ok()) {
      log(absl::StrCat("--shard-tls*: ", credentials.status().message()));
      return 2;
    }
    options.shard_credentials = *std::move(credentials);
    options.shard_tls_server_name = shard_connection.tls_server_name;
    options.shard_api_key = shard_connection.api_key;
  }
  if (server_options.metrics != nullptr) {
    options.on_shard_call =
        tpr::gateway::ShardCallMetrics(*server_options.metrics);
    // The gateway serves tpr.v1.Indexer/Search, so it records the same
    // per-search metrics as an indexer.
    tpr::indexer::AddSearchMetrics(*server_options.metrics);
  }
  for (size_t s = 0; s < options.shards.shards.size(); ++s) {
    const tpr::gateway::ShardAddresses& shard = options.shards.shards[s];
    std::string replicas;
    for (const std::string& r : shard.replicas)
      absl::StrAppend(&replicas, " ", r);
    log(absl::StrCat(
        "shard ", s, ": primary ", shard.primary,
        replicas.empty() ? "" : absl::StrCat(", replicas", replicas)));
  }
  tpr::gateway::GatewayService service(std::move(options));
  if (std::optional<int> refused = CheckShardPlaces(service, log)) {
    return *refused;
  }
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(server_options, {&service});
  if (!started.ok()) {
    log(started.status().ToString());
    return 1;
  }
  return tpr::common::ServeUntilSignal(*started, server_options);
}
