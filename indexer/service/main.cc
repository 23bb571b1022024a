// tpr-indexer: the stateful index service. Parses flags, opens the data
// directory (IndexerCore), serves tpr.v1.Indexer and tpr.v1.IndexerAdmin
// (backups, replication) with health and reflection, and on SIGTERM/SIGINT
// finishes in-flight calls, persists the VP-tree and exits 0.
//
//   tpr-indexer --listen 127.0.0.1:7002 --data-dir /var/lib/tpr
//   tpr-indexer --listen 127.0.0.1:7012 --data-dir /var/lib/tpr-f
//       --follow 127.0.0.1:7002
//   tpr-indexer ... --follow HOST:7002 --follow-tls --follow-tls-ca ca.pem
//               (and TPR_INDEXER_FOLLOW_API_KEY): a secured primary
//
// A follower (follower.h) that fell behind its primary's kept log re-executes
// itself after a graceful stop, and copies the primary again at start.
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>

#include "CLI/CLI.hpp"
#include "absl/strings/str_cat.h"
#include "client/peer/connection_flags.h"
#include "common/config.h"
#include "common/metrics.h"
#include "common/server_flags.h"
#include "common/server_lifecycle.h"
#include "indexer/service/admin_service.h"
#include "indexer/service/follower.h"
#include "indexer/service/indexer_core.h"
#include "indexer/service/indexer_service.h"
#include "tpr/connection.h"

int main(int argc, char** argv) {
  CLI::App app{
      "tpr-indexer: stores TPR signatures and answers EMD k-NN searches"};
  tpr::common::ServerOptions server_options;
  server_options.listen_address = "127.0.0.1:7002";
  server_options.log_name = "tpr-indexer";
  std::string data_dir;
  int max_searches = 16;
  int max_k = 10000;
  tpr::common::ServerFlags ops_flags;
  tpr::common::AddListenFlags(app, &server_options);
  std::string follow;
  std::string follow_api_key;
  tpr::indexer::StorageOptions storage_options;
  app.add_option("--data-dir", data_dir,
                 "Directory of the RocksDB store (created if missing)")
      ->required();
  std::string backup_root;
  app.add_option("--backup-root", backup_root,
                 "Directory that backups (tpr backup --to) and restores (tpr "
                 "restore --from, --into) must lie under; none: both refused");
  tpr::common::AddServerThreadsFlag(app, &ops_flags);
  app.add_option("--max-concurrent-searches", max_searches,
                 "Searches running at once; more get RESOURCE_EXHAUSTED")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--max-k", max_k, "Largest k a search may ask for")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option(
      "--follow", follow,
      "Be a read-only follower of the primary tpr-indexer at HOST:PORT "
      "(copies it into an empty --data-dir, then tails its write-ahead log)");
  app.add_option(
      "--follow-api-key", follow_api_key,
      "API key (admin role) this follower presents to its primary; prefer the "
      "environment variable TPR_INDEXER_FOLLOW_API_KEY, which ps does not "
      "show");
  tpr::client::ConnectionOptions primary_connection;
  tpr::client::AddPeerConnectionFlags(app, "follow", "the primary",
                                      &primary_connection);
  app.add_option("--wal-keep-seconds", storage_options.wal_keep_seconds,
                 "Keep closed write-ahead logs this long for followers (s)")
      ->capture_default_str();
  app.add_option(
         "--wal-keep-mb", storage_options.wal_keep_mb,
         "Keep at most this many MB of closed write-ahead logs for followers")
      ->capture_default_str();
  tpr::common::AddServerFlags(app, &ops_flags);
  tpr::common::ConfigSupport config =
      tpr::common::AddConfigSupport(app, "TPR_INDEXER_", {"follow-api-key"});
  CLI11_PARSE(app, argc, argv);
  if (std::optional<int> exit_code =
          tpr::common::FinishServerFlags(config, ops_flags, &server_options)) {
    return *exit_code;
  }
  server_options.readiness_service = "tpr.v1.Indexer";

  const std::string name = server_options.log_name;
  auto log = [name](const std::string& line) {
    tpr::common::LogEvent(name, line);
  };

  tpr::indexer::CoreOptions core_options;
  core_options.data_dir = data_dir;
  core_options.storage = storage_options;
  core_options.follow = follow;
  core_options.max_k = max_k;
  core_options.log = log;
  if (server_options.metrics != nullptr) {
    // Storage latencies, as histograms (RocksDB's own are percentiles,
    // which replicas cannot aggregate).
    prometheus::Registry& registry = server_options.metrics->registry();
    prometheus::Histogram* write_seconds =
        &prometheus::BuildHistogram()
             .Name("tpr_indexer_storage_write_duration_seconds")
             .Help(
                 "Each durable model write: lookups, RocksDB write with its "
                 "log sync, "
                 "acknowledgement record")
             .Register(registry)
             .Add({}, tpr::common::FineSecondsBuckets());
    prometheus::Histogram* sync_seconds =
        &prometheus::BuildHistogram()
             .Name("tpr_indexer_storage_wal_sync_duration_seconds")
             .Help("Each fsync of RocksDB's write-ahead log")
             .Register(registry)
             .Add({}, tpr::common::FineSecondsBuckets());
    core_options.storage.on_write = [write_seconds](double s) {
      write_seconds->Observe(s);
    };
    core_options.storage.on_wal_sync = [sync_seconds](double s) {
      sync_seconds->Observe(s);
    };
  }
  // While the data directory opens (a store scan, possibly a tree build),
  // the port already answers health checks: alive, not ready; other calls
  // get UNAVAILABLE. The real server then takes the same port over (closed
  // for the moment in between: clients reconnect).
  absl::StatusOr<std::unique_ptr<tpr::common::LoadingServer>> loading =
      tpr::common::StartLoadingServer(server_options,
                                      "loading the data directory");
  if (!loading.ok()) {
    log(loading.status().ToString());
    return 1;
  }
  server_options.listen_address = tpr::common::ListenAddressWithPort(
      server_options.listen_address, (*loading)->port);
  // A follower copies its primary first (health: alive, not ready).
  tpr::indexer::FollowerOptions follower_options;
  if (!follow.empty()) {
    follower_options.primary = follow;
    follower_options.data_dir = data_dir;
    follower_options.api_key = follow_api_key;
    grpc::ChannelArguments unused;  // the server name is passed on below
    absl::StatusOr<std::shared_ptr<grpc::ChannelCredentials>> credentials =
        tpr::client::MakeChannelCredentials(primary_connection, &unused);
    if (!credentials.ok()) {
      log(absl::StrCat("--follow-tls*: ", credentials.status().message()));
      return 2;
    }
    follower_options.credentials = *std::move(credentials);
    follower_options.tls_server_name = primary_connection.tls_server_name;
    follower_options.log = log;
    if (absl::Status st = tpr::indexer::PrepareFollowerDir(follower_options);
        !st.ok()) {
      log(absl::StrCat("cannot start as a follower: ", st.ToString()));
      return 1;
    }
  }

  absl::StatusOr<std::unique_ptr<tpr::indexer::IndexerCore>> core =
      tpr::indexer::IndexerCore::Open(core_options);
  if (!core.ok()) {
    log(absl::StrCat("cannot open the data directory: ",
                     core.status().ToString()));
    return 1;
  }
  if (server_options.metrics != nullptr) {
    const tpr::indexer::IndexerCore* c = core->get();
    tpr::common::Metrics& m = *server_options.metrics;
    const tpr::index::SignatureIndex* index = &c->index();
    m.AddGaugeCallback(
        "tpr_indexer_tombstoned",
        "Deleted or replaced entries still in the VP-tree",
        [index] { return static_cast<double>(index->tombstoned()); });
    m.AddCounterCallback(
        "tpr_indexer_tree_rebuilds_total", "VP-tree rebuilds completed",
        [index] { return static_cast<double>(index->rebuilds()); });
    m.AddGaugeCallback(
        "tpr_indexer_memory_bytes", "Heap bytes of the in-memory index",
        [index] { return static_cast<double>(index->MemoryBytes()); });
    // RocksDB's counters and sizes (one read per series at each scrape; each
    // is a few property reads).
    auto engine = [c](uint64_t tpr::indexer::EngineStats::*field) {
      return
          [c, field] { return static_cast<double>(c->engine_stats().*field); };
    };
    using tpr::indexer::EngineStats;
    m.AddCounterCallback(
        "tpr_indexer_storage_stall_seconds_total",
        "Time RocksDB delayed or stopped writes (STALL_MICROS)", [c] {
          return static_cast<double>(c->engine_stats().stall_micros) / 1e6;
        });
    m.AddCounterCallback("tpr_indexer_storage_delayed_stalls_total",
                         "Times RocksDB entered the delayed-write condition",
                         engine(&EngineStats::delayed_stalls));
    m.AddCounterCallback("tpr_indexer_storage_stopped_stalls_total",
                         "Times RocksDB entered the stopped-write condition",
                         engine(&EngineStats::stopped_stalls));
    m.AddCounterCallback("tpr_indexer_storage_wal_syncs_total",
                         "Syncs of RocksDB's write-ahead log",
                         engine(&EngineStats::wal_syncs));
    m.AddGaugeCallback(
        "tpr_indexer_storage_live_data_bytes",
        "RocksDB's estimate of its live data (rocksdb.estimate-live-data-size)",
        engine(&EngineStats::live_data_bytes));
    m.AddGaugeCallback("tpr_indexer_storage_sst_bytes",
                       "RocksDB table files (rocksdb.total-sst-files-size)",
                       engine(&EngineStats::sst_bytes));
    m.AddGaugeCallback("tpr_indexer_storage_memtable_bytes",
                       "RocksDB memtables (rocksdb.cur-size-all-mem-tables)",
                       engine(&EngineStats::memtable_bytes));
    m.AddGaugeCallback("tpr_indexer_models", "Models stored", [c] {
      return static_cast<double>(c->Stats().models());
    });
    m.AddGaugeCallback(
        "tpr_indexer_indexed", "Models in the VP-tree proper",
        [c] { return static_cast<double>(c->Stats().indexed()); });
    m.AddGaugeCallback(
        "tpr_indexer_buffered", "Models waiting in the insert buffer",
        [c] { return static_cast<double>(c->Stats().buffered()); });
    m.AddGaugeCallback(
        "tpr_indexer_disk_bytes", "Size of the data directory, bytes",
        [c] { return static_cast<double>(c->Stats().disk_bytes()); });
  }
  // Readiness: NOT_SERVING while writes fail for lack of disk space (it
  // turns back by itself once space is freed).
  server_options.readiness_check = [c = core->get()] {
    return c->WriteReadiness();
  };
  tpr::indexer::ServiceOptions service_options;
  service_options.max_concurrent_searches = max_searches;
  service_options.log = log;
  tpr::indexer::IndexerService service(core->get(), service_options);
  std::unique_ptr<tpr::indexer::Follower> follower;
  std::atomic<bool> resync{false};
  if (!follow.empty()) {
    follower =
        std::make_unique<tpr::indexer::Follower>(core->get(), follower_options);
    tpr::indexer::Follower* f = follower.get();
    // A follower is ready once caught up and while its disk has room.
    server_options.readiness_check = [f, c = core->get()] {
      std::string reason = f->Readiness();
      return reason.empty() ? c->WriteReadiness() : reason;
    };
  }
  tpr::indexer::AdminOptions admin_options;
  admin_options.log = log;
  admin_options.backup_root = backup_root;
  tpr::indexer::IndexerAdminService admin(core->get(), follower.get(),
                                          admin_options);

  // The port is bound exclusively: the stand-in lets it go first.
  loading->reset();
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(server_options, {&service, &admin});
  if (!started.ok()) {
    log(started.status().ToString());
    return 1;
  }
  if (follower != nullptr) {
    // Fallen behind the primary's kept log: stop gracefully (as on SIGTERM),
    // then start again, which copies the primary afresh.
    follower->Start([&resync] {
      resync = true;
      std::raise(SIGTERM);
    });
  }
  const int code = tpr::common::internal::ServeUntilSignalWith(
      server_options, started->port, [&] {
        admin.Stop();
        if (follower != nullptr) follower->Stop();
        tpr::common::ShutdownGracefully(*started, server_options);
      });
  started->server.reset();
  follower.reset();
  (*core)->Close();
  core->reset();
  log("data directory closed");
  if (resync) {
    log("restarting to copy the primary afresh");
    execv("/proc/self/exe", argv);
    log("cannot restart; exiting with 75 (EX_TEMPFAIL) for the supervisor to "
        "restart");
    return 75;
  }
  return code;
}
