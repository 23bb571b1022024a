// Prometheus metrics (common/metrics.h) through the real binaries with
// --metrics-listen: after known actions (three generated meshes extracted
// and stored, two Stats calls, a Get of an unknown id, one search), the
// scraped /metrics holds exactly those counts, the per-search histograms sum
// to the SearchStats the client received, the stage histograms to the
// response's timings, the upload histogram to the bytes sent, and the
// scrape-time gauges to the index's size. A busy or bad metrics address is
// refused at start. The index and storage metrics follow a known history:
// a batch past the rebuild threshold (one tree rebuild), then overwrites
// and deletes of tree entries (tombstones), each write timed and synced.
#include <grpcpp/create_channel.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>
#include <sys/socket.h>

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"
#include "tests/service/ops_testing.h"
#include "tpr/client.h"

namespace tpr::testing {
namespace {

std::string Scrape(int port) {
  const ShellResult r = ScrapeMetrics(port);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  return r.out;
}

// Starts `binary` (with `args`) serving metrics on a free port, logging to
// DIR/NAME.log; returns the metrics port, 0 when it did not start.
int StartWithMetrics(ServiceProcess* process, const std::string& binary,
                     std::vector<std::string> args, const TempDir& dir,
                     const std::string& name) {
  args.push_back("--metrics-listen");
  args.push_back("127.0.0.1:0");
  const std::string log = dir.path() + "/" + name + ".log";
  const absl::Status started = process->Start(BinaryPath(binary), args, log);
  EXPECT_TRUE(started.ok()) << started << ReadText(log);
  return started.ok() ? MetricsPort(ReadText(log)) : 0;
}

// StartWithMetrics for a tpr-indexer on DIR/data.
int StartIndexerWithMetrics(ServiceProcess* indexer, const TempDir& dir) {
  return StartWithMetrics(indexer, "tpr-indexer",
                          {"--data-dir", dir.path() + "/data"}, dir, "indexer");
}

TEST(MetricsTest, ScrapedValuesMatchKnownActions) {
  TempDir dir;
  ServiceProcess extractor;
  const int extractor_port =
      StartWithMetrics(&extractor, "tpr-extractor", {}, dir, "extractor");
  ServiceProcess indexer;
  const int indexer_port =
      StartWithMetrics(&indexer, "tpr-indexer",
                       {"--data-dir", dir.path() + "/data"}, dir, "indexer");
  ASSERT_GT(extractor_port, 0);
  ASSERT_GT(indexer_port, 0);

  // Nothing yet: no call counted, no model.
  std::string before = Scrape(indexer_port);
  EXPECT_EQ(Sample(before, "tpr_indexer_models"), 0) << before;
  EXPECT_TRUE(std::isnan(Sample(before, "tpr_rpc_requests_total",
                                {"method=\"/tpr.v1.Indexer/Stats\""})));

  absl::StatusOr<client::ExtractorClient> ex =
      client::ExtractorClient::Connect(extractor.address());
  absl::StatusOr<client::IndexerClient> ix =
      client::IndexerClient::Connect(indexer.address());
  ASSERT_TRUE(ex.ok() && ix.ok());
  absl::StatusOr<std::vector<GeneratedFile>> files =
      GenerateSet(dir.path() + "/set", 3, 1, 600);
  ASSERT_TRUE(files.ok()) << files.status();
  double uploaded = 0;
  std::map<std::string, double> stage_seconds;
  for (const GeneratedFile& f : *files) {
    absl::StatusOr<v1::ExtractResponse> r = ex->ExtractBytes(f.off, "m.off");
    ASSERT_TRUE(r.ok()) << r.status();
    uploaded += static_cast<double>(f.off.size());
    for (const v1::StageTiming& t : r->timings())
      stage_seconds[t.stage()] += t.milliseconds() / 1000;
    v1::Model model;
    model.set_id(f.relative_path);
    model.set_label(f.label);
    *model.mutable_signature() = r->signature();
    ASSERT_TRUE(ix->Upsert(model, /*overwrite=*/true).ok());
  }
  ASSERT_TRUE(ix->Stats().ok());
  ASSERT_TRUE(ix->Stats().ok());
  EXPECT_EQ(ix->Get("no/such/id").status().code(), absl::StatusCode::kNotFound);
  v1::SearchRequest query;
  query.set_id(files->front().relative_path);
  query.set_k(2);
  std::unique_ptr<client::SearchStream> stream = ix->Search(query);
  for (v1::Neighbor n; stream->Next(&n);) {
  }
  ASSERT_TRUE(stream->Finish().ok());
  ASSERT_NE(stream->Stats(), nullptr);
  const v1::SearchStats stats = *stream->Stats();

  const std::string m = Scrape(indexer_port);
  const std::string ok = "code=\"OK\"";
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total",
                   {ok, "method=\"/tpr.v1.Indexer/Upsert\""}),
            3)
      << m;
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total",
                   {ok, "method=\"/tpr.v1.Indexer/Stats\""}),
            2);
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total",
                   {"code=\"NOT_FOUND\"", "method=\"/tpr.v1.Indexer/Get\""}),
            1);
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total",
                   {ok, "method=\"/tpr.v1.Indexer/Search\""}),
            1);
  EXPECT_EQ(Sample(m, "tpr_rpc_duration_seconds_count",
                   {ok, "method=\"/tpr.v1.Indexer/Stats\""}),
            2);
  EXPECT_GT(Sample(m, "tpr_rpc_duration_seconds_sum",
                   {ok, "method=\"/tpr.v1.Indexer/Upsert\""}),
            0);
  EXPECT_EQ(Sample(m, "tpr_rpc_duration_seconds_bucket",
                   {ok, "method=\"/tpr.v1.Indexer/Stats\"", "le=\"+Inf\""}),
            2);
  EXPECT_EQ(
      Sample(m, "tpr_rpc_in_flight", {"method=\"/tpr.v1.Indexer/Stats\""}), 0);
  EXPECT_EQ(Sample(m, "tpr_indexer_search_emd_computations_count"), 1);
  EXPECT_EQ(Sample(m, "tpr_indexer_search_emd_computations_sum"),
            static_cast<double>(stats.emd_computations()))
      << m;
  EXPECT_EQ(Sample(m, "tpr_indexer_search_lower_bounds_sum"),
            static_cast<double>(stats.lower_bounds()));
  EXPECT_NEAR(Sample(m, "tpr_indexer_search_duration_seconds_sum"),
              stats.milliseconds() / 1000, 1e-9);
  EXPECT_EQ(Sample(m, "tpr_indexer_models"), 3);
  EXPECT_EQ(
      Sample(m, "tpr_indexer_indexed") + Sample(m, "tpr_indexer_buffered"), 3);
  EXPECT_GT(Sample(m, "tpr_indexer_disk_bytes"), 0);
  EXPECT_EQ(m.find("no/such/id"), std::string::npos) << "no per-id labels";
  EXPECT_EQ(m.find("request_id"), std::string::npos);
  // Histograms, not summaries (prometheus-cpp's own exposer_* metrics aside).
  for (absl::string_view line : absl::StrSplit(m, '\n')) {
    if (absl::StartsWith(line, "# TYPE tpr_")) {
      EXPECT_FALSE(absl::EndsWith(line, " summary")) << line;
    }
  }

  const std::string e = Scrape(extractor_port);
  EXPECT_EQ(Sample(e, "tpr_rpc_requests_total",
                   {ok, "method=\"/tpr.v1.Extractor/Extract\""}),
            3)
      << e;
  EXPECT_EQ(Sample(e, "tpr_extractor_mesh_bytes_count"), 3);
  EXPECT_EQ(Sample(e, "tpr_extractor_mesh_bytes_sum"), uploaded);
  ASSERT_FALSE(stage_seconds.empty());
  for (const auto& [stage, seconds] : stage_seconds) {
    const std::string label = absl::StrCat("stage=\"", stage, "\"");
    EXPECT_EQ(Sample(e, "tpr_extractor_stage_duration_seconds_count", {label}),
              3)
        << stage;
    EXPECT_NEAR(Sample(e, "tpr_extractor_stage_duration_seconds_sum", {label}),
                seconds, 1e-6)
        << stage;
  }
  EXPECT_EQ(Sample(e, "tpr_extractor_admitted_calls"), 0);
}

// Waits up to 30 s for `name` to reach `value` in the scrape of `port`;
// returns the last scrape.
std::string ScrapeUntil(int port, const std::string& name, double value) {
  std::string m;
  for (int i = 0; i < 300; ++i) {
    m = Scrape(port);
    if (Sample(m, name) == value) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return m;
}

TEST(MetricsTest, IndexAndStorageMetricsFollowKnownWrites) {
  TempDir dir;
  ServiceProcess indexer;
  const int port = StartIndexerWithMetrics(&indexer, dir);
  ASSERT_GT(port, 0);
  std::string m = Scrape(port);
  EXPECT_EQ(Sample(m, "tpr_indexer_tree_rebuilds_total"), 0) << m;
  EXPECT_EQ(Sample(m, "tpr_indexer_tombstoned"), 0);
  EXPECT_EQ(Sample(m, "tpr_indexer_storage_write_duration_seconds_count"), 0);

  // 600 models in one batch: past the index's rebuild threshold (512
  // buffered), so exactly one background rebuild puts them all in the tree.
  absl::StatusOr<client::IndexerClient> ix =
      client::IndexerClient::Connect(indexer.address());
  ASSERT_TRUE(ix.ok());
  const std::vector<indexer::testing::TestModel> models =
      indexer::testing::MakeModels(600, 6, 11);
  std::unique_ptr<client::BatchUpsertWriter> batch = ix->BatchUpsert();
  for (const indexer::testing::TestModel& t : models) {
    ASSERT_TRUE(batch->Write(indexer::testing::ToRequest(t).model(), false));
  }
  ASSERT_TRUE(batch->Finish().ok());
  m = ScrapeUntil(port, "tpr_indexer_indexed", 600);
  EXPECT_EQ(Sample(m, "tpr_indexer_tree_rebuilds_total"), 1) << m;
  EXPECT_EQ(Sample(m, "tpr_indexer_indexed"), 600);
  EXPECT_EQ(Sample(m, "tpr_indexer_buffered"), 0);
  EXPECT_EQ(Sample(m, "tpr_indexer_tombstoned"), 0);
  EXPECT_GT(Sample(m, "tpr_indexer_memory_bytes"), 0);
  EXPECT_GT(Sample(m, "tpr_indexer_storage_memtable_bytes") +
                Sample(m, "tpr_indexer_storage_sst_bytes"),
            0);
  const double writes_before =
      Sample(m, "tpr_indexer_storage_write_duration_seconds_count");
  const double syncs_before =
      Sample(m, "tpr_indexer_storage_wal_sync_duration_seconds_count");
  EXPECT_GE(writes_before, 3) << "600 models in groups of at most 256";
  EXPECT_GE(syncs_before, writes_before);
  EXPECT_EQ(Sample(m, "tpr_indexer_storage_wal_syncs_total"), syncs_before)
      << m;

  // Two overwrites and three deletes of tree entries: five tombstones (an
  // overwrite's new version waits in the buffer), five synced writes.
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(
        ix->Upsert(indexer::testing::ToRequest(models[static_cast<size_t>(i)])
                       .model(),
                   /*overwrite=*/true)
            .ok());
  }
  for (int i = 2; i < 5; ++i)
    ASSERT_TRUE(ix->Delete(models[static_cast<size_t>(i)].id).ok());
  m = Scrape(port);
  EXPECT_EQ(Sample(m, "tpr_indexer_tombstoned"), 5) << m;
  EXPECT_EQ(Sample(m, "tpr_indexer_indexed"), 595);
  EXPECT_EQ(Sample(m, "tpr_indexer_buffered"), 2);
  EXPECT_EQ(Sample(m, "tpr_indexer_models"), 597);
  EXPECT_EQ(Sample(m, "tpr_indexer_tree_rebuilds_total"), 1);
  EXPECT_EQ(Sample(m, "tpr_indexer_storage_write_duration_seconds_count"),
            writes_before + 5);
  EXPECT_GT(Sample(m, "tpr_indexer_storage_write_duration_seconds_sum"), 0);
  // One log sync per write; the background tree persister may add one.
  const double syncs =
      Sample(m, "tpr_indexer_storage_wal_sync_duration_seconds_count");
  EXPECT_GE(syncs, syncs_before + 5);
  EXPECT_LE(syncs, syncs_before + 6);
  EXPECT_EQ(Sample(m, "tpr_indexer_storage_wal_sync_duration_seconds_bucket",
                   {"le=\"+Inf\""}),
            syncs);
  // No stall at this size; the counters exist and are zero.
  EXPECT_EQ(Sample(m, "tpr_indexer_storage_stall_seconds_total"), 0);
  EXPECT_EQ(Sample(m, "tpr_indexer_storage_delayed_stalls_total"), 0);
  EXPECT_EQ(Sample(m, "tpr_indexer_storage_stopped_stalls_total"), 0);
  EXPECT_NE(m.find("# TYPE tpr_indexer_tree_rebuilds_total counter"),
            std::string::npos);
}

// A client choosing method names cannot grow the label set: calls to
// methods the server does not serve are counted (UNIMPLEMENTED) under one
// method label, never under the names the client sent.
TEST(MetricsTest, UnknownMethodsShareOneLabel) {
  TempDir dir;
  ServiceProcess indexer;
  const int port = StartIndexerWithMetrics(&indexer, dir);
  ASSERT_GT(port, 0);
  std::shared_ptr<grpc::Channel> channel = grpc::CreateChannel(
      indexer.address(), grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  for (int i = 0; i < 5; ++i) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::seconds(10));
    grpc::Slice empty("");
    grpc::ByteBuffer request(&empty, 1), response;
    grpc::Status status;
    std::mutex mu;
    std::condition_variable done_cv;
    bool done = false;
    stub.UnaryCall(&context, absl::StrCat("/tpr.v1.Indexer/NoSuchMethod", i),
                   {}, &request, &response, [&](grpc::Status s) {
                     std::lock_guard<std::mutex> lock(mu);
                     status = std::move(s);
                     done = true;
                     done_cv.notify_all();
                   });
    std::unique_lock<std::mutex> lock(mu);
    done_cv.wait(lock, [&] { return done; });
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNIMPLEMENTED)
        << status.error_message();
  }
  absl::StatusOr<client::IndexerClient> ix =
      client::IndexerClient::Connect(indexer.address());
  ASSERT_TRUE(ix.ok());
  ASSERT_TRUE(ix->Stats().ok());
  const std::string m = Scrape(port);
  EXPECT_EQ(m.find("NoSuchMethod"), std::string::npos) << m;
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total",
                   {"code=\"UNIMPLEMENTED\"", "method=\"unknown\""}),
            5)
      << m;
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total",
                   {"code=\"OK\"", "method=\"/tpr.v1.Indexer/Stats\""}),
            1);
}

TEST(MetricsTest, UnusableAddressIsRefusedAtStart) {
  TempDir dir;
  const ShellResult r = RunShell(absl::StrCat(
      BinaryPath("tpr-extractor"), " --metrics-listen 203.0.113.1:9"));
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("--metrics-listen"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace tpr::testing
