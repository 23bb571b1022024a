// Prometheus metrics (common/metrics.h) through the real binaries with
// --metrics-listen: after known actions (three generated meshes extracted
// and stored, two Stats calls, a Get of an unknown id, one search), the
// scraped /metrics holds exactly those counts, the per-search histograms sum
// to the SearchStats the client received, the stage histograms to the
// response's timings, the upload histogram to the bytes sent, and the
// scrape-time gauges to the index's size. A busy or bad metrics address is
// refused at start.
#include <sys/socket.h>

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/ops_testing.h"
#include "tpr/client.h"

namespace tpr::testing {
namespace {

// The value of the sample `name` whose labels include every one of
// `labels` ("code=\"OK\""), or NaN when absent.
double Sample(const std::string& scrape, const std::string& name,
              const std::vector<std::string>& labels = {}) {
  for (absl::string_view line : absl::StrSplit(scrape, '\n')) {
    if (line.empty() || line[0] == '#') continue;
    const size_t space = line.rfind(' ');
    if (space == absl::string_view::npos) continue;
    absl::string_view series = line.substr(0, space);
    const absl::string_view bare = series.substr(0, series.find('{'));
    if (bare != name) continue;
    bool all = true;
    for (const std::string& label : labels) {
      if (series.find(label) == absl::string_view::npos) all = false;
    }
    if (!all) continue;
    double value;
    if (absl::SimpleAtod(line.substr(space + 1), &value)) return value;
  }
  return std::nan("");
}

// The port from the "metrics: http://HOST:PORT/metrics" log line, or 0.
int MetricsPort(const std::string& log) {
  const size_t at = log.find("metrics: http://");
  if (at == std::string::npos) return 0;
  const size_t colon = log.find(':', at + 16);
  return colon == std::string::npos ? 0 : std::atoi(log.c_str() + colon + 1);
}

std::string Scrape(int port) {
  const ShellResult r = RunShell(absl::StrCat("curl -sf http://127.0.0.1:", port, "/metrics"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  return r.out;
}

TEST(MetricsTest, ScrapedValuesMatchKnownActions) {
  TempDir dir;
  ServiceProcess extractor;
  ASSERT_TRUE(extractor
                  .Start(BinaryPath("tpr-extractor"), {"--metrics-listen", "127.0.0.1:0"},
                         dir.path() + "/extractor.log")
                  .ok());
  ServiceProcess indexer;
  ASSERT_TRUE(indexer
                  .Start(BinaryPath("tpr-indexer"),
                         {"--data-dir", dir.path() + "/data", "--metrics-listen", "127.0.0.1:0"},
                         dir.path() + "/indexer.log")
                  .ok());
  const int extractor_port = MetricsPort(ReadText(extractor.log_path()));
  const int indexer_port = MetricsPort(ReadText(indexer.log_path()));
  ASSERT_GT(extractor_port, 0) << ReadText(extractor.log_path());
  ASSERT_GT(indexer_port, 0) << ReadText(indexer.log_path());

  // Nothing yet: no call counted, no model.
  std::string before = Scrape(indexer_port);
  EXPECT_EQ(Sample(before, "tpr_indexer_models"), 0) << before;
  EXPECT_TRUE(std::isnan(Sample(before, "tpr_rpc_requests_total",
                                {"method=\"/tpr.v1.Indexer/Stats\""})));

  absl::StatusOr<client::ExtractorClient> ex = client::ExtractorClient::Connect(extractor.address());
  absl::StatusOr<client::IndexerClient> ix = client::IndexerClient::Connect(indexer.address());
  ASSERT_TRUE(ex.ok() && ix.ok());
  absl::StatusOr<std::vector<GeneratedFile>> files = GenerateSet(dir.path() + "/set", 3, 1, 600);
  ASSERT_TRUE(files.ok()) << files.status();
  double uploaded = 0;
  std::map<std::string, double> stage_seconds;
  for (const GeneratedFile& f : *files) {
    absl::StatusOr<v1::ExtractResponse> r = ex->ExtractBytes(f.off, "m.off");
    ASSERT_TRUE(r.ok()) << r.status();
    uploaded += static_cast<double>(f.off.size());
    for (const v1::StageTiming& t : r->timings()) stage_seconds[t.stage()] += t.milliseconds() / 1000;
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
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total", {ok, "method=\"/tpr.v1.Indexer/Upsert\""}), 3) << m;
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total", {ok, "method=\"/tpr.v1.Indexer/Stats\""}), 2);
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total",
                   {"code=\"NOT_FOUND\"", "method=\"/tpr.v1.Indexer/Get\""}), 1);
  EXPECT_EQ(Sample(m, "tpr_rpc_requests_total", {ok, "method=\"/tpr.v1.Indexer/Search\""}), 1);
  EXPECT_EQ(Sample(m, "tpr_rpc_duration_seconds_count", {ok, "method=\"/tpr.v1.Indexer/Stats\""}), 2);
  EXPECT_GT(Sample(m, "tpr_rpc_duration_seconds_sum", {ok, "method=\"/tpr.v1.Indexer/Upsert\""}), 0);
  EXPECT_EQ(Sample(m, "tpr_rpc_duration_seconds_bucket",
                   {ok, "method=\"/tpr.v1.Indexer/Stats\"", "le=\"+Inf\""}), 2);
  EXPECT_EQ(Sample(m, "tpr_rpc_in_flight", {"method=\"/tpr.v1.Indexer/Stats\""}), 0);
  EXPECT_EQ(Sample(m, "tpr_indexer_search_emd_computations_count"), 1);
  EXPECT_EQ(Sample(m, "tpr_indexer_search_emd_computations_sum"),
            static_cast<double>(stats.emd_computations())) << m;
  EXPECT_EQ(Sample(m, "tpr_indexer_search_lower_bounds_sum"),
            static_cast<double>(stats.lower_bounds()));
  EXPECT_NEAR(Sample(m, "tpr_indexer_search_duration_seconds_sum"), stats.milliseconds() / 1000,
              1e-9);
  EXPECT_EQ(Sample(m, "tpr_indexer_models"), 3);
  EXPECT_EQ(Sample(m, "tpr_indexer_indexed") + Sample(m, "tpr_indexer_buffered"), 3);
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
  EXPECT_EQ(Sample(e, "tpr_rpc_requests_total", {ok, "method=\"/tpr.v1.Extractor/Extract\""}), 3)
      << e;
  EXPECT_EQ(Sample(e, "tpr_extractor_mesh_bytes_count"), 3);
  EXPECT_EQ(Sample(e, "tpr_extractor_mesh_bytes_sum"), uploaded);
  ASSERT_FALSE(stage_seconds.empty());
  for (const auto& [stage, seconds] : stage_seconds) {
    const std::string label = absl::StrCat("stage=\"", stage, "\"");
    EXPECT_EQ(Sample(e, "tpr_extractor_stage_duration_seconds_count", {label}), 3) << stage;
    EXPECT_NEAR(Sample(e, "tpr_extractor_stage_duration_seconds_sum", {label}), seconds, 1e-6)
        << stage;
  }
  EXPECT_EQ(Sample(e, "tpr_extractor_admitted_calls"), 0);
}

TEST(MetricsTest, UnusableAddressIsRefusedAtStart) {
  TempDir dir;
  const ShellResult r = RunShell(absl::StrCat(BinaryPath("tpr-extractor"),
                                              " --metrics-listen 203.0.113.1:9"));
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("--metrics-listen"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace tpr::testing
