// The C++ SDK (tpr/client.h) against the real service binaries on loopback:
// channel targets, extraction over two load-balanced extractors, batch
// upsert, k-NN streams compared with an in-process brute-force EMD ranking,
// early stop, error codes, retries while a server comes up, fail-over.
#include "tpr/client.h"

#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <map>
#include <thread>

#include "tests/service/extsvc_test_util.h"

namespace tpr::client {
namespace {

using ::tpr::testing::Ranked;

TEST(ChannelTargetTest, MapsAddressListsToResolverTargets) {
  EXPECT_EQ(*ChannelTarget("127.0.0.1:7001"), "ipv4:127.0.0.1:7001");
  EXPECT_EQ(*ChannelTarget("127.0.0.1:7001, 127.0.0.1:7002"),
            "ipv4:127.0.0.1:7001,127.0.0.1:7002");
  EXPECT_EQ(*ChannelTarget("[::1]:7001,[::1]:7002"),
            "ipv6:[::1]:7001,[::1]:7002");
  EXPECT_EQ(*ChannelTarget("localhost:7001"), "dns:///localhost:7001");
  EXPECT_EQ(*ChannelTarget("dns:///tpr.example:7001"),
            "dns:///tpr.example:7001");
  EXPECT_EQ(*ChannelTarget("unix:/run/tpr.sock"), "unix:/run/tpr.sock");
  EXPECT_TRUE(absl::IsInvalidArgument(ChannelTarget("").status()));
  EXPECT_TRUE(absl::IsInvalidArgument(ChannelTarget("127.0.0.1").status()));
  EXPECT_TRUE(absl::IsInvalidArgument(ChannelTarget("a:1,b:2").status()));
  EXPECT_TRUE(
      absl::IsInvalidArgument(ChannelTarget("127.0.0.1:1,[::1]:2").status()));
}

class SdkEndToEndTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    cluster_ = new testing::Cluster;
    absl::Status s = cluster_->Start(/*extractors=*/2);
    ASSERT_TRUE(s.ok()) << s;
  }
  static void TearDownTestSuite() {
    delete cluster_;
    cluster_ = nullptr;
  }
  static testing::Cluster* cluster_;
};
testing::Cluster* SdkEndToEndTest::cluster_ = nullptr;

TEST_F(SdkEndToEndTest, BatchAddThenSearchMatchesBruteForceAndStopsEarly) {
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(cluster_->dir() + "/set", 3, 2, 1500);
  ASSERT_TRUE(files.ok()) << files.status();
  absl::StatusOr<ExtractorClient> extractor =
      ExtractorClient::Connect(cluster_->extractor_addresses());
  ASSERT_TRUE(extractor.ok()) << extractor.status();
  absl::StatusOr<IndexerClient> indexer =
      IndexerClient::Connect(cluster_->indexer().address());
  ASSERT_TRUE(indexer.ok()) << indexer.status();

  std::vector<std::pair<std::string, v1::Signature>> models;
  std::unique_ptr<BatchUpsertWriter> batch = indexer->BatchUpsert();
  for (const testing::GeneratedFile& f : *files) {
    absl::StatusOr<v1::ExtractResponse> r =
        extractor->ExtractBytes(f.off, f.relative_path);
    ASSERT_TRUE(r.ok()) << f.relative_path << ": " << r.status();
    v1::Model model;
    model.set_id("sdk/" + f.relative_path);
    model.set_label(f.label);
    *model.mutable_signature() = r->signature();
    models.emplace_back(model.id(), r->signature());
    ASSERT_TRUE(batch->Write(model, /*overwrite=*/false));
  }
  absl::StatusOr<v1::BatchUpsertResponse> written = batch->Finish();
  ASSERT_TRUE(written.ok()) << written.status();
  EXPECT_EQ(written->written(), static_cast<int64_t>(models.size()));

  // Get returns the signature as extracted.
  absl::StatusOr<v1::Model> got = indexer->Get(models[0].first);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(
      got->signature(), models[0].second));
  EXPECT_GT(got->added_unix_micros(), 0);

  for (const auto& [id, signature] : models) {
    v1::SearchRequest request;
    *request.mutable_signature() = signature;
    request.set_k(static_cast<int>(models.size()));
    request.set_label("");
    std::unique_ptr<SearchStream> stream = indexer->Search(request);
    std::vector<Ranked> streamed;
    for (v1::Neighbor n; stream->Next(&n);) {
      EXPECT_EQ(n.rank(), static_cast<int>(streamed.size()) + 1);
      if (n.id().rfind("sdk/", 0) == 0)
        streamed.push_back({n.distance(), n.id()});
    }
    ASSERT_TRUE(stream->Finish().ok());
    ASSERT_NE(stream->Stats(), nullptr);
    absl::StatusOr<std::vector<Ranked>> expected =
        testing::BruteForceRanking(signature, models);
    ASSERT_TRUE(expected.ok()) << expected.status();
    EXPECT_EQ(streamed.size(), models.size());
    EXPECT_EQ(testing::SameRanking(streamed, *expected), "") << "query " << id;
    EXPECT_EQ(streamed.front().distance, 0.0);
  }

  // Early stop: read one neighbour, cancel, the stream ends without error.
  v1::SearchRequest request;
  request.set_id(models[0].first);
  request.set_k(static_cast<int>(models.size()));
  std::unique_ptr<SearchStream> stream = indexer->Search(request);
  v1::Neighbor first;
  ASSERT_TRUE(stream->Next(&first));
  stream->Cancel();
  v1::Neighbor more;
  EXPECT_FALSE(stream->Next(&more));
  EXPECT_TRUE(stream->Finish().ok());

  // Paged listing sees every model in id order.
  absl::StatusOr<std::vector<v1::Model>> listed =
      indexer->ListAll(files->front().label);
  ASSERT_TRUE(listed.ok()) << listed.status();
  EXPECT_EQ(listed->size(), 2u);
  absl::StatusOr<v1::StatsResponse> stats = indexer->Stats();
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_GE(stats->models(), static_cast<int64_t>(models.size()));
}

TEST_F(SdkEndToEndTest, ErrorsCarryTheirCodesAndTheServiceKeepsServing) {
  absl::StatusOr<IndexerClient> indexer =
      IndexerClient::Connect(cluster_->indexer().address());
  ASSERT_TRUE(indexer.ok());
  absl::StatusOr<ExtractorClient> extractor =
      ExtractorClient::Connect(cluster_->extractor_addresses());
  ASSERT_TRUE(extractor.ok());
  EXPECT_TRUE(absl::IsNotFound(indexer->Get("no/such/id").status()));
  EXPECT_TRUE(absl::IsNotFound(indexer->Delete("no/such/id")));
  EXPECT_TRUE(
      absl::IsNotFound(extractor->ExtractFile("/no/such/mesh.off").status()));

  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(cluster_->dir() + "/errors", 1, 1, 800);
  ASSERT_TRUE(files.ok());
  absl::StatusOr<v1::ExtractResponse> r =
      extractor->ExtractBytes(files->at(0).off, "a.off");
  ASSERT_TRUE(r.ok()) << r.status();
  v1::Model model;
  model.set_id("errors/a");
  *model.mutable_signature() = r->signature();
  absl::StatusOr<bool> created = indexer->Upsert(model, /*overwrite=*/false);
  ASSERT_TRUE(created.ok()) << created.status();
  EXPECT_TRUE(*created);
  EXPECT_TRUE(absl::IsAlreadyExists(indexer->Upsert(model, false).status()));
  absl::StatusOr<bool> replaced = indexer->Upsert(model, /*overwrite=*/true);
  ASSERT_TRUE(replaced.ok());
  EXPECT_FALSE(*replaced);

  v1::SearchRequest bad_k;
  bad_k.set_id("errors/a");
  bad_k.set_k(0);
  EXPECT_TRUE(absl::IsInvalidArgument(indexer->Search(bad_k)->Finish()));
  v1::SearchRequest bad_radius;
  bad_radius.set_id("errors/a");
  bad_radius.set_k(3);
  bad_radius.set_radius(-1);
  EXPECT_TRUE(absl::IsInvalidArgument(indexer->Search(bad_radius)->Finish()));
  v1::SearchRequest unknown;
  unknown.set_id("no/such/id");
  unknown.set_k(3);
  EXPECT_TRUE(absl::IsNotFound(indexer->Search(unknown)->Finish()));

  EXPECT_TRUE(indexer->Delete("errors/a").ok());
  EXPECT_TRUE(absl::IsNotFound(indexer->Get("errors/a").status()));
  EXPECT_TRUE(indexer->Stats().ok());
}

// An idempotent call made before the server listens succeeds once it does:
// UNAVAILABLE is retried with backoff.
TEST(SdkRetryTest, RetriesUnavailableUntilTheServerComesUp) {
  const int port = testing::FreePort();
  ASSERT_GT(port, 0);
  const std::string address = absl::StrCat("127.0.0.1:", port);
  testing::TempDir dir;
  testing::ServiceProcess process;
  std::thread starter([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(400));
    absl::Status s = process.Start(testing::BinaryPath("tpr-extractor"), {},
                                   dir.path() + "/extractor.log", address);
    EXPECT_TRUE(s.ok()) << s;
  });
  CallOptions call;
  call.max_attempts = 12;
  call.initial_backoff = absl::Milliseconds(100);
  call.max_backoff = absl::Milliseconds(400);
  call.timeout = absl::Seconds(30);
  absl::StatusOr<ExtractorClient> client =
      ExtractorClient::Connect(address, call);
  ASSERT_TRUE(client.ok());
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(dir.path() + "/set", 1, 1, 600);
  ASSERT_TRUE(files.ok());
  absl::StatusOr<v1::ExtractResponse> r =
      client->ExtractBytes(files->at(0).off, "a.off");
  starter.join();
  EXPECT_TRUE(r.ok()) << r.status();

  // With retries disabled, a dead address fails fast with UNAVAILABLE.
  CallOptions once;
  once.max_attempts = 1;
  absl::StatusOr<ExtractorClient> dead = ExtractorClient::Connect(
      absl::StrCat("127.0.0.1:", testing::FreePort()), once);
  ASSERT_TRUE(dead.ok());
  EXPECT_TRUE(absl::IsUnavailable(
      dead->ExtractBytes(files->at(0).off, "a.off").status()));
}

// Round robin over two extractors: after one stops, calls keep succeeding.
TEST(SdkLoadBalancingTest, SurvivesOneOfTwoExtractorsStopping) {
  testing::Cluster cluster;
  ASSERT_TRUE(cluster.Start(/*extractors=*/2).ok());
  absl::StatusOr<ExtractorClient> client =
      ExtractorClient::Connect(cluster.extractor_addresses());
  ASSERT_TRUE(client.ok());
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(cluster.dir() + "/set", 1, 1, 600);
  ASSERT_TRUE(files.ok());
  for (int i = 0; i < 4; ++i) {
    EXPECT_TRUE(client->ExtractBytes(files->at(0).off, "a.off").ok());
  }
  EXPECT_EQ(cluster.extractor(0).Stop(SIGTERM), 0);
  for (int i = 0; i < 4; ++i) {
    absl::StatusOr<v1::ExtractResponse> r =
        client->ExtractBytes(files->at(0).off, "a.off");
    EXPECT_TRUE(r.ok()) << r.status();
  }
}

}  // namespace
}  // namespace tpr::client
