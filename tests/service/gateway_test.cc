// tpr-gateway in process: three indexer shards and one reference indexer
// (IndexerCore + IndexerService on loopback) holding the same corpus, the
// gateway (GatewayService) in front of the shards. Every answer through the
// gateway must equal the reference indexer's: search rankings to the last
// bit of every distance (ties, radius, label filter, exclude_self, k above
// the corpus, after deletes), and both against the brute-force oracle;
// List pages, Stats sums, Get/Upsert/Delete errors; a stopped shard fails
// the call with UNAVAILABLE naming it; search statistics are the shards'
// sums, also when streams are cancelled early; reads go to any serving replica
// and writes to the primary; once k neighbours are sent the other shards'
// streams are cancelled (seen by a shard whose stream never ends).
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <mutex>
#include <optional>
#include <tuple>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/call_interceptor.h"
#include "indexer/gateway/gateway_service.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"

namespace tpr::gateway {
namespace {

using ::tpr::indexer::testing::BruteForce;
using ::tpr::indexer::testing::Hit;
using ::tpr::indexer::testing::InProcessIndexer;
using ::tpr::indexer::testing::MakeModels;
using ::tpr::indexer::testing::RunSearch;
using ::tpr::indexer::testing::SearchResult;
using ::tpr::indexer::testing::TestModel;
using ::tpr::indexer::testing::ToRequest;
using ::tpr::indexer::testing::ToWire;
using ::tpr::indexer::testing::WeightsOf;
using ::tpr::testing::TempDir;

constexpr int kShards = 3;

grpc::Status Ingest(tpr::v1::Indexer::Stub* stub,
                    const std::vector<TestModel>& models,
                    tpr::v1::BatchUpsertResponse* response) {
  grpc::ClientContext context;
  auto writer = stub->BatchUpsert(&context, response);
  for (const TestModel& m : models) {
    if (!writer->Write(ToRequest(m))) break;
  }
  writer->WritesDone();
  return writer->Finish();
}

std::vector<std::string> ListAll(tpr::v1::Indexer::Stub* stub, int page_size,
                                 const std::string& label, int* pages) {
  std::vector<std::string> ids;
  tpr::v1::ListRequest request;
  request.set_page_size(page_size);
  request.set_label(label);
  *pages = 0;
  for (int guard = 0; guard < 10000; ++guard) {
    grpc::ClientContext context;
    tpr::v1::ListResponse response;
    grpc::Status status = stub->List(&context, request, &response);
    EXPECT_TRUE(status.ok()) << status.error_message();
    if (!status.ok()) break;
    ++*pages;
    EXPECT_LE(response.models_size(), page_size);
    for (const tpr::v1::Model& m : response.models()) {
      EXPECT_EQ(m.signature().features_size(), 0);
      ids.push_back(m.id());
    }
    if (response.next_page_token().empty()) break;
    request.set_page_token(response.next_page_token());
  }
  return ids;
}

class GatewayTest : public ::testing::Test {
 protected:
  void SetUp() override {
    for (int s = 0; s < kShards; ++s) {
      shards_.push_back(std::make_unique<InProcessIndexer>(
          absl::StrCat(dir_.path(), "/shard", s)));
      ASSERT_TRUE(shards_.back()->Start().ok());
    }
    reference_ = std::make_unique<InProcessIndexer>(dir_.path() + "/single");
    ASSERT_TRUE(reference_->Start().ok());
    GatewayOptions options;
    for (auto& shard : shards_)
      options.shards.shards.push_back({shard->address(), {}});
    options.health_interval_ms = 0;  // tests call CheckNow
    service_ = std::make_unique<GatewayService>(options);
    server_options_.shutdown_grace_ms = 2000;
    absl::StatusOr<tpr::common::StartedServer> started =
        tpr::common::StartServer(server_options_, {service_.get()});
    ASSERT_TRUE(started.ok()) << started.status();
    server_ = std::move(started->server);
    gateway_address_ = absl::StrCat("127.0.0.1:", started->port);
    gateway_ = tpr::v1::Indexer::NewStub(grpc::CreateChannel(
        gateway_address_, grpc::InsecureChannelCredentials()));

    // The corpus: generated models, plus exact copies of some under other
    // ids (ties at equal distance, spread over the shards by their ids).
    // With spectra, so that intents and rankings rank differently.
    models_ = MakeModels(240, 6, 17, "m", /*spectrum=*/30);
    for (int i = 0; i < 30; i += 3) {
      for (const char* suffix : {"_a", "_b", "_c"}) {
        TestModel copy = models_[static_cast<size_t>(i)];
        copy.id = absl::StrCat("dup", i, suffix);
        models_.push_back(copy);
      }
    }
    tpr::v1::BatchUpsertResponse single, sharded;
    ASSERT_TRUE(Ingest(reference_->stub(), models_, &single).ok());
    grpc::Status status = Ingest(gateway_.get(), models_, &sharded);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(sharded.written(), static_cast<int64_t>(models_.size()));
    EXPECT_EQ(sharded.written(), single.written());
  }

  void TearDown() override {
    if (server_) tpr::common::ShutdownGracefully(*server_, server_options_);
    server_.reset();
  }

  // Runs `request` on both and expects identical answers, also equal to the
  // brute-force oracle. Returns the number of neighbours.
  size_t ExpectSameAnswer(const tpr::v1::SearchRequest& request) {
    SearchResult want = RunSearch(reference_->stub(), request);
    SearchResult got = RunSearch(gateway_.get(), request);
    EXPECT_TRUE(want.status.ok()) << want.status.error_message();
    EXPECT_TRUE(got.status.ok()) << got.status.error_message();
    EXPECT_TRUE(got.got_stats);
    EXPECT_EQ(got.neighbors.size(), want.neighbors.size())
        << request.ShortDebugString();
    for (size_t i = 0;
         i < std::min(got.neighbors.size(), want.neighbors.size()); ++i) {
      EXPECT_EQ(got.neighbors[i].id(), want.neighbors[i].id())
          << "rank " << i + 1;
      // Bit-identical: the same EMD of the same pair of signatures.
      EXPECT_EQ(got.neighbors[i].distance(), want.neighbors[i].distance())
          << "rank " << i + 1;
      EXPECT_EQ(got.neighbors[i].label(), want.neighbors[i].label());
      EXPECT_EQ(got.neighbors[i].rank(), static_cast<int>(i + 1));
    }
    // The oracle, over the live corpus.
    tpr::index::Signature query;
    std::string exclude;
    if (request.has_signature()) {
      query = *indexer::ToIndexSignature(request.signature());
    } else {
      for (const TestModel& m : live()) {
        if (m.id == request.id()) query = m.signature;
      }
      if (request.exclude_self()) exclude = request.id();
    }
    std::vector<indexer::testing::Hit> oracle =
        BruteForce(query, live(), request.k(), request.radius(),
                   request.label(), exclude, WeightsOf(request));
    EXPECT_EQ(got.neighbors.size(), oracle.size())
        << request.ShortDebugString();
    for (size_t i = 0; i < std::min(got.neighbors.size(), oracle.size()); ++i) {
      EXPECT_EQ(got.neighbors[i].id(), oracle[i].id) << "rank " << i + 1;
      EXPECT_NEAR(got.neighbors[i].distance(), oracle[i].distance, 1e-9);
    }
    return got.neighbors.size();
  }

  std::vector<TestModel> live() const {
    std::vector<TestModel> out;
    for (const TestModel& m : models_) {
      if (!deleted_.count(m.id)) out.push_back(m);
    }
    return out;
  }

  TempDir dir_;
  std::vector<std::unique_ptr<InProcessIndexer>> shards_;
  std::unique_ptr<InProcessIndexer> reference_;
  std::unique_ptr<GatewayService> service_;
  tpr::common::ServerOptions server_options_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<tpr::v1::Indexer::Stub> gateway_;
  std::string gateway_address_;
  std::vector<TestModel> models_;
  std::set<std::string> deleted_;
};

TEST_F(GatewayTest, ModelsLiveOnTheirOwnShard) {
  std::vector<int64_t> expected(kShards, 0);
  for (const TestModel& m : models_)
    ++expected[static_cast<size_t>(ShardOf(m.id, kShards))];
  for (int s = 0; s < kShards; ++s) {
    grpc::ClientContext context;
    tpr::v1::StatsResponse stats;
    ASSERT_TRUE(shards_[static_cast<size_t>(s)]
                    ->stub()
                    ->Stats(&context, {}, &stats)
                    .ok());
    EXPECT_EQ(stats.models(), expected[static_cast<size_t>(s)])
        << "shard " << s;
    EXPECT_GT(stats.models(), 0);
  }
}

TEST_F(GatewayTest, SearchEqualsOneIndexerIncludingTiesRadiusLabelsAndLargeK) {
  const int n = static_cast<int>(models_.size());
  size_t total = 0;
  for (const char* id : {"m00000", "m00003", "dup9_b", "m00118", "m00239"}) {
    for (int k : {1, 4, 12, n + 10}) {
      for (bool exclude_self : {false, true}) {
        tpr::v1::SearchRequest request;
        request.set_id(id);
        request.set_k(k);
        request.set_exclude_self(exclude_self);
        total += ExpectSameAnswer(request);
        request.set_label("class3");
        total += ExpectSameAnswer(request);
      }
    }
  }
  // Radius: about the 20th neighbour's distance of one query.
  SearchResult probe = RunSearch(reference_->stub(), [] {
    tpr::v1::SearchRequest r;
    r.set_id("m00005");
    r.set_k(20);
    return r;
  }());
  ASSERT_EQ(probe.neighbors.size(), 20u);
  tpr::v1::SearchRequest within;
  within.set_id("m00005");
  within.set_k(n);
  within.set_radius(probe.neighbors.back().distance());
  EXPECT_GE(ExpectSameAnswer(within), 20u);
  // By signature: members of the generator's classes, not in the corpus.
  tpr::index::testing::SignatureGeneratorOptions options;
  options.seed = 99;
  options.features = 12;
  options.bands = 8;
  options.classes = 6;
  tpr::index::testing::SignatureGenerator gen(options);
  for (int q = 0; q < 4; ++q) {
    tpr::v1::SearchRequest request;
    *request.mutable_signature() = ToWire(gen.Member(q));
    request.set_k(q == 0 ? n + 1 : 15);
    total += ExpectSameAnswer(request);
  }
  EXPECT_GT(total, 1000u);
}

TEST_F(GatewayTest, IntentsAndRankingsPassThroughAndMergeExactly) {
  // SearchRequest.intent and .ranking reach every shard; each searches its
  // tree under that weighting, and the merge equals one indexer's answer
  // and the brute-force oracle of the same weighting (ExpectSameAnswer).
  // The corpus carries spectra, so the weightings rank differently.
  const int n = static_cast<int>(models_.size());
  size_t total = 0;
  for (const char* id : {"m00003", "dup9_b"}) {
    for (int k : {5, n + 10}) {
      for (tpr::v1::Intent intent :
           {tpr::v1::INTENT_UNSPECIFIED, tpr::v1::INTENT_BALANCED,
            tpr::v1::INTENT_IDENTITY, tpr::v1::INTENT_KIND}) {
        tpr::v1::SearchRequest request;
        request.set_id(id);
        request.set_k(k);
        request.set_exclude_self(k == 5);
        request.set_intent(intent);
        total += ExpectSameAnswer(request);
        request.set_label("class2");
        total += ExpectSameAnswer(request);
      }
      tpr::v1::SearchRequest request;
      request.set_id(id);
      request.set_k(k);
      request.set_exclude_self(k == 5);
      request.mutable_ranking()->set_emd_weight(1.0);
      total += ExpectSameAnswer(request);
      request.mutable_ranking()->set_spectral_weight(3.0);
      request.mutable_ranking()->set_heat_weight(0.5);
      total += ExpectSameAnswer(request);
      request.mutable_ranking()->set_emd_weight(0.0);
      total += ExpectSameAnswer(request);
    }
  }
  EXPECT_GT(total, static_cast<size_t>(4 * n));
  // A bad intent is refused by the shards, named.
  tpr::v1::SearchRequest bad;
  bad.set_id("m00003");
  bad.set_k(3);
  bad.set_intent(static_cast<tpr::v1::Intent>(9));
  SearchResult r = RunSearch(gateway_.get(), bad);
  EXPECT_EQ(r.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(r.status.error_message().find("intent"), std::string::npos)
      << r.status.error_message();
}

TEST_F(GatewayTest, TiesAcrossShardsComeInIdOrder) {
  // m00009 and its three copies are at distance 0 from each other; their ids
  // lie on different shards, and the merge must order them as one indexer.
  std::set<int> shards;
  for (const char* id : {"m00009", "dup9_a", "dup9_b", "dup9_c"})
    shards.insert(ShardOf(id, kShards));
  EXPECT_GT(shards.size(), 1u);
  tpr::v1::SearchRequest request;
  request.set_id("dup9_b");
  request.set_k(6);
  ExpectSameAnswer(request);
  SearchResult got = RunSearch(gateway_.get(), request);
  ASSERT_GE(got.neighbors.size(), 4u);
  EXPECT_EQ(got.neighbors[0].id(), "dup9_a");
  EXPECT_EQ(got.neighbors[1].id(), "dup9_b");
  EXPECT_EQ(got.neighbors[2].id(), "dup9_c");
  EXPECT_EQ(got.neighbors[3].id(), "m00009");
  EXPECT_EQ(got.neighbors[3].distance(), 0.0);
}

TEST_F(GatewayTest, SearchAfterDeletesAndOverwrites) {
  for (const char* id : {"m00001", "m00002", "dup0_a", "m00100", "m00150"}) {
    for (tpr::v1::Indexer::Stub* stub : {reference_->stub(), gateway_.get()}) {
      grpc::ClientContext context;
      tpr::v1::DeleteRequest request;
      request.set_id(id);
      tpr::v1::DeleteResponse response;
      ASSERT_TRUE(stub->Delete(&context, request, &response).ok()) << id;
    }
    deleted_.insert(id);
  }
  for (const char* id : {"m00000", "dup0_b", "m00149"}) {
    tpr::v1::SearchRequest request;
    request.set_id(id);
    request.set_k(static_cast<int>(models_.size()));
    request.set_exclude_self(true);
    ExpectSameAnswer(request);
  }
  // Deleting again: NOT_FOUND, as from one indexer.
  grpc::ClientContext context;
  tpr::v1::DeleteRequest again;
  again.set_id("m00001");
  tpr::v1::DeleteResponse response;
  EXPECT_EQ(gateway_->Delete(&context, again, &response).error_code(),
            grpc::StatusCode::NOT_FOUND);
}

TEST_F(GatewayTest, UnaryCallsAnswerAsOneIndexer) {
  grpc::ClientContext get_context;
  tpr::v1::GetRequest get;
  get.set_id("m00042");
  tpr::v1::Model model;
  ASSERT_TRUE(gateway_->Get(&get_context, get, &model).ok());
  EXPECT_EQ(model.label(), "class0");
  EXPECT_GT(model.signature().features_size(), 0);

  grpc::ClientContext missing_context;
  get.set_id("no-such-model");
  EXPECT_EQ(gateway_->Get(&missing_context, get, &model).error_code(),
            grpc::StatusCode::NOT_FOUND);

  grpc::ClientContext dup_context;
  tpr::v1::UpsertResponse upserted;
  EXPECT_EQ(gateway_->Upsert(&dup_context, ToRequest(models_[7]), &upserted)
                .error_code(),
            grpc::StatusCode::ALREADY_EXISTS);
  grpc::ClientContext over_context;
  ASSERT_TRUE(
      gateway_->Upsert(&over_context, ToRequest(models_[7], true), &upserted)
          .ok());
  EXPECT_FALSE(upserted.created());

  tpr::v1::SearchRequest bad;
  bad.set_id("m00001");
  bad.set_k(0);
  EXPECT_EQ(RunSearch(gateway_.get(), bad).status.error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  bad.set_k(3);
  bad.set_radius(-1);
  EXPECT_EQ(RunSearch(gateway_.get(), bad).status.error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  bad.set_radius(0);
  bad.set_id("no-such-model");
  EXPECT_EQ(RunSearch(gateway_.get(), bad).status.error_code(),
            grpc::StatusCode::NOT_FOUND);

  // A batch with one bad model fails; the shards keep what they acknowledged.
  std::vector<TestModel> batch = MakeModels(20, 2, 3, "batch");
  batch[11].signature.features.clear();
  tpr::v1::BatchUpsertResponse counts;
  EXPECT_EQ(Ingest(gateway_.get(), batch, &counts).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

// A message that does not parse in a BatchUpsert stream was taken
// for its end (OK for a truncated batch). Through the gateway it fails with
// INVALID_ARGUMENT naming the message; the models before it are on their
// shards, none after it.
TEST_F(GatewayTest, MalformedMessageInABatchUpsertStreamIsAnError) {
  const std::vector<TestModel> batch = MakeModels(8, 2, 5, "raw");
  std::vector<std::string> messages;
  for (size_t i = 0; i < batch.size(); ++i) {
    messages.push_back(i == 3 ? std::string("\xff\xff\xff\xff", 4)
                              : ToRequest(batch[i]).SerializeAsString());
  }
  grpc::Status s = ::tpr::testing::RawClientStream(
      grpc::CreateChannel(gateway_address_, grpc::InsecureChannelCredentials()),
      "/tpr.v1.Indexer/BatchUpsert", messages);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
      << s.error_message();
  EXPECT_NE(s.error_message().find("BatchUpsert: message 4 of the stream"),
            std::string::npos)
      << s.error_message();
  for (size_t i = 0; i < batch.size(); ++i) {
    if (i == 3) continue;
    grpc::ClientContext context;
    tpr::v1::GetRequest get;
    get.set_id(batch[i].id);
    tpr::v1::Model model;
    const grpc::Status got = gateway_->Get(&context, get, &model);
    EXPECT_EQ(got.ok(), i < 3) << batch[i].id << ": " << got.error_message();
  }
}

TEST_F(GatewayTest, ListMergesShardsInIdOrder) {
  int pages = 0;
  int reference_pages = 0;
  const std::vector<std::string> want =
      ListAll(reference_->stub(), 1000, "", &reference_pages);
  ASSERT_EQ(want.size(), models_.size());
  for (int page_size : {1, 7, 100, 1000}) {
    EXPECT_EQ(ListAll(gateway_.get(), page_size, "", &pages), want)
        << page_size;
    EXPECT_EQ(pages,
              (static_cast<int>(want.size()) + page_size - 1) / page_size)
        << page_size;
  }
  EXPECT_EQ(ListAll(gateway_.get(), 9, "class4", &pages),
            ListAll(reference_->stub(), 9, "class4", &reference_pages));
  grpc::ClientContext context;
  tpr::v1::ListRequest foreign;
  foreign.set_page_token("m00010");  // an indexer's token is not the gateway's
  tpr::v1::ListResponse response;
  EXPECT_EQ(gateway_->List(&context, foreign, &response).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(GatewayTest, ListPagesStayUnderTwoMebibytes) {
  // 90 models of ~60 KiB metadata each: ~5.4 MB in all, so pages must end
  // early (as one indexer's do) and the paging must still list every id.
  std::vector<TestModel> big = MakeModels(90, 3, 41, "big");
  for (const TestModel& m : big) {
    tpr::v1::UpsertRequest request = ToRequest(m);
    (*request.mutable_model()->mutable_metadata())["blob"] =
        std::string(60 << 10, 'x');
    grpc::ClientContext context;
    tpr::v1::UpsertResponse response;
    ASSERT_TRUE(gateway_->Upsert(&context, request, &response).ok());
  }
  tpr::v1::ListRequest request;
  request.set_page_size(1000);
  std::vector<std::string> ids;
  int pages = 0;
  for (; pages < 100; ++pages) {
    grpc::ClientContext context;
    tpr::v1::ListResponse response;
    ASSERT_TRUE(gateway_->List(&context, request, &response).ok());
    EXPECT_LE(response.ByteSizeLong(), size_t{2} << 20) << "page " << pages;
    for (const tpr::v1::Model& m : response.models()) ids.push_back(m.id());
    if (response.next_page_token().empty()) break;
    request.set_page_token(response.next_page_token());
  }
  EXPECT_GE(pages, 2);
  int reference_pages = 0;
  std::vector<std::string> want =
      ListAll(reference_->stub(), 1000, "", &reference_pages);
  for (const TestModel& m : big) want.push_back(m.id);
  std::sort(want.begin(), want.end());
  EXPECT_EQ(ids, want);
}

TEST_F(GatewayTest, StatsSumsAndListsEachShard) {
  grpc::ClientContext a, b;
  tpr::v1::StatsResponse want, got;
  ASSERT_TRUE(reference_->stub()->Stats(&a, {}, &want).ok());
  ASSERT_TRUE(gateway_->Stats(&b, {}, &got).ok());
  EXPECT_EQ(got.models(), want.models());
  EXPECT_EQ(got.indexed() + got.buffered(), want.models());
  using Labels = std::map<std::string, int64_t>;
  EXPECT_EQ(Labels(got.labels().begin(), got.labels().end()),
            Labels(want.labels().begin(), want.labels().end()));
  ASSERT_EQ(got.shards_size(), kShards);
  int64_t sum = 0;
  for (int s = 0; s < kShards; ++s) {
    EXPECT_EQ(got.shards(s).shard(), s);
    EXPECT_EQ(got.shards(s).address(),
              shards_[static_cast<size_t>(s)]->address());
    sum += got.shards(s).stats().models();
  }
  EXPECT_EQ(sum, got.models());
}

// Counts of a SearchStats as a tuple, to compare them at once.
std::tuple<int64_t, int64_t, int64_t> Counts(const tpr::v1::SearchStats& s) {
  return {s.emd_computations(), s.lower_bounds(), s.nodes_visited()};
}

// Checks one stream asked with progress: every neighbour carries it, counts
// never decrease, and the final statistics are at least the last progress.
void ExpectProgressGrows(const SearchResult& r) {
  ASSERT_TRUE(r.got_stats);
  std::tuple<int64_t, int64_t, int64_t> last{0, 0, 0};
  for (const tpr::v1::Neighbor& n : r.neighbors) {
    ASSERT_TRUE(n.has_progress()) << "rank " << n.rank();
    EXPECT_GE(n.progress().emd_computations(), std::get<0>(last));
    EXPECT_GE(n.progress().lower_bounds(), std::get<1>(last));
    EXPECT_GE(n.progress().nodes_visited(), std::get<2>(last));
    last = Counts(n.progress());
  }
  EXPECT_GE(r.stats.emd_computations(), std::get<0>(last));
  EXPECT_GE(r.stats.lower_bounds(), std::get<1>(last));
  EXPECT_GE(r.stats.nodes_visited(), std::get<2>(last));
}

// The oracle of the gateway's statistics: `direct` holds each shard's
// answer to the same request asked directly with progress, `answer` the
// gateway's k-NN answer. The gateway reads lazily: each shard's first
// neighbour, then the shard's next after each one it sends, except after
// the k-th (the answer is complete and the other streams are cancelled); a
// read past a shard's last neighbour gets its final statistics. The sum is,
// per shard, its statistics at its last read. *cancelled counts the shards
// whose stream the gateway stopped before its end.
tpr::v1::SearchStats ExpectedSum(const std::vector<SearchResult>& direct,
                                 const std::vector<tpr::v1::Neighbor>& answer,
                                 int k, int* cancelled) {
  std::vector<size_t> reads(direct.size(), 1);
  for (size_t i = 0; i < answer.size(); ++i) {
    if (static_cast<int>(i) + 1 < k)
      ++reads[static_cast<size_t>(ShardOf(answer[i].id(), kShards))];
  }
  tpr::v1::SearchStats sum;
  *cancelled = 0;
  for (size_t s = 0; s < direct.size(); ++s) {
    const tpr::v1::SearchStats& at =
        reads[s] <= direct[s].neighbors.size()
            ? direct[s].neighbors[reads[s] - 1].progress()
            : direct[s].stats;
    *cancelled += reads[s] <= direct[s].neighbors.size() ? 1 : 0;
    sum.set_emd_computations(sum.emd_computations() + at.emd_computations());
    sum.set_lower_bounds(sum.lower_bounds() + at.lower_bounds());
    sum.set_nodes_visited(sum.nodes_visited() + at.nodes_visited());
  }
  return sum;
}

// Search statistics through the gateway are the shards' own, summed: each
// shard asked directly with the same request, with each neighbour's
// progress, is the oracle (ExpectedSum). With k above the corpus every
// shard's stream runs to its end; with a small k the gateway cancels the
// shards' streams once k neighbours are sent, and their work up to the last
// neighbour read still counts (before Neighbor.progress it was lost).
// Neighbours carry progress only when asked, through the gateway too, where
// each is the running sum and the last equals the final statistics.
TEST_F(GatewayTest, SearchStatisticsAreTheShardsSums) {
  for (auto& shard : shards_) shard->core()->WaitForRebuild();
  struct Case {
    size_t query;
    int k;
    const char* label;
  };
  for (const Case& c : {Case{0, 1000, ""}, Case{57, 1000, "class1"},
                        Case{131, 1000, ""}, Case{0, 1, ""}, Case{57, 10, ""},
                        Case{131, 7, "class1"}, Case{200, 25, ""}}) {
    SCOPED_TRACE(
        absl::StrCat("query ", c.query, " k ", c.k, " label '", c.label, "'"));
    tpr::v1::SearchRequest request;
    *request.mutable_signature() = ToWire(models_[c.query].signature);
    request.set_k(c.k);
    request.set_label(c.label);
    SearchResult got = RunSearch(gateway_.get(), request);
    ASSERT_TRUE(got.status.ok()) << got.status.error_message();
    ASSERT_TRUE(got.got_stats);
    for (const tpr::v1::Neighbor& n : got.neighbors)
      EXPECT_FALSE(n.has_progress()) << "not asked for, rank " << n.rank();
    for (const tpr::v1::Neighbor& n :
         RunSearch(shards_[0]->stub(), request).neighbors) {
      EXPECT_FALSE(n.has_progress()) << "not asked for, rank " << n.rank();
    }

    std::vector<SearchResult> direct;
    for (auto& shard : shards_) {
      direct.push_back(RunSearch(shard->stub(), request, /*progress=*/true));
      ASSERT_TRUE(direct.back().status.ok());
      ExpectProgressGrows(direct.back());
    }
    int cancelled = 0;
    const tpr::v1::SearchStats want =
        ExpectedSum(direct, got.neighbors, c.k, &cancelled);
    EXPECT_GT(want.emd_computations(), 0);
    EXPECT_EQ(Counts(got.stats), Counts(want));
    // A small k cancels shards (the case the sum used to miss); k above
    // the corpus runs every stream to its end.
    EXPECT_EQ(cancelled > 0, c.k < 100) << cancelled << " cancelled";

    SearchResult through = RunSearch(gateway_.get(), request, true);
    ASSERT_TRUE(through.status.ok()) << through.status.error_message();
    ASSERT_EQ(through.neighbors.size(), got.neighbors.size());
    ExpectProgressGrows(through);
    EXPECT_EQ(Counts(through.stats), Counts(want));
    if (static_cast<int>(through.neighbors.size()) == c.k) {
      EXPECT_EQ(Counts(through.neighbors.back().progress()), Counts(want));
    }
  }
}

// Replicas: reads go to any serving copy of a shard (or, with
// reads_from_primary, the primary only), writes only to its primary. One shard
// with a primary and a replica holding the same models (the gateway cannot tell
// a follower from any other copy); the replica also holds one model the primary
// lacks, so that which copy answered shows.
TEST_F(GatewayTest, ReadsGoToAnyServingReplicaWritesToThePrimary) {
  InProcessIndexer primary(dir_.path() + "/r-primary");
  InProcessIndexer replica(dir_.path() + "/r-replica");
  ASSERT_TRUE(primary.Start().ok());
  ASSERT_TRUE(replica.Start().ok());
  const std::vector<TestModel> corpus(models_.begin(), models_.begin() + 40);
  tpr::v1::BatchUpsertResponse ignored;
  ASSERT_TRUE(Ingest(primary.stub(), corpus, &ignored).ok());
  ASSERT_TRUE(Ingest(replica.stub(), corpus, &ignored).ok());
  std::vector<TestModel> marker = MakeModels(1, 1, 99, "only-on-replica");
  ASSERT_TRUE(Ingest(replica.stub(), marker, &ignored).ok());

  GatewayOptions options;
  options.shards.shards.push_back({primary.address(), {replica.address()}});
  options.health_interval_ms = 0;
  GatewayService service(options);
  // Replicas are read only once a health check has found them SERVING (a
  // follower still catching up is not); the test runs the checks itself.
  service.shards().CheckNow();
  tpr::common::ServerOptions server_options;
  server_options.shutdown_grace_ms = 1000;
  absl::StatusOr<tpr::common::StartedServer> started =
      tpr::common::StartServer(server_options, {&service});
  ASSERT_TRUE(started.ok()) << started.status();
  auto gateway = tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(absl::StrCat("127.0.0.1:", started->port),
                          grpc::InsecureChannelCredentials()));
  auto get = [&](const std::string& id) {
    grpc::ClientContext context;
    tpr::v1::GetRequest request;
    request.set_id(id);
    tpr::v1::Model model;
    return gateway->Get(&context, request, &model).error_code();
  };
  auto models = [&]() -> int64_t {
    grpc::ClientContext context;
    tpr::v1::StatsResponse stats;
    return gateway->Stats(&context, {}, &stats).ok() ? stats.models() : -1;
  };

  // Both serving: reads alternate between the two copies.
  int on_replica = 0;
  for (int i = 0; i < 8; ++i)
    on_replica += get(marker[0].id) == grpc::StatusCode::OK;
  EXPECT_GT(on_replica, 0);
  EXPECT_LT(on_replica, 8);

  // --reads=primary: the same shard through a second gateway reads only
  // from the primary, which lacks the marker (every read says NOT_FOUND,
  // none reaches the replica); Stats counts the primary's 40 models.
  GatewayOptions primary_options = options;
  primary_options.reads_from_primary = true;
  GatewayService primary_only(primary_options);
  primary_only.shards().CheckNow();
  absl::StatusOr<tpr::common::StartedServer> primary_started =
      tpr::common::StartServer(server_options, {&primary_only});
  ASSERT_TRUE(primary_started.ok()) << primary_started.status();
  auto primary_gateway = tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(absl::StrCat("127.0.0.1:", primary_started->port),
                          grpc::InsecureChannelCredentials()));
  for (int i = 0; i < 8; ++i) {
    grpc::ClientContext context;
    tpr::v1::GetRequest request;
    request.set_id(marker[0].id);
    tpr::v1::Model model;
    EXPECT_EQ(primary_gateway->Get(&context, request, &model).error_code(),
              grpc::StatusCode::NOT_FOUND);
  }
  {
    grpc::ClientContext context;
    tpr::v1::StatsResponse stats;
    ASSERT_TRUE(primary_gateway->Stats(&context, {}, &stats).ok());
    EXPECT_EQ(stats.models(), 40);
  }

  // A write reaches the primary only.
  std::vector<TestModel> fresh = MakeModels(1, 1, 98, "written");
  {
    grpc::ClientContext context;
    tpr::v1::UpsertResponse upserted;
    ASSERT_TRUE(gateway->Upsert(&context, ToRequest(fresh[0]), &upserted).ok());
  }
  EXPECT_TRUE(primary.core()->Get(fresh[0].id).ok());
  EXPECT_TRUE(absl::IsNotFound(replica.core()->Get(fresh[0].id).status()));

  // The primary stops: every read is served by the replica; writes fail
  // naming the shard, never landing on the replica.
  primary.Stop();
  for (int i = 0; i < 4; ++i)
    EXPECT_EQ(get(marker[0].id), grpc::StatusCode::OK);
  EXPECT_EQ(models(), 41);
  tpr::v1::SearchRequest search;
  *search.mutable_signature() = ToWire(corpus[3].signature);
  search.set_k(5);
  SearchResult found = RunSearch(gateway.get(), search);
  EXPECT_TRUE(found.status.ok()) << found.status.error_message();
  EXPECT_EQ(found.neighbors.size(), 5u);
  {
    grpc::ClientContext context;
    tpr::v1::UpsertResponse upserted;
    grpc::Status refused =
        gateway->Upsert(&context, ToRequest(fresh[0], true), &upserted);
    EXPECT_EQ(refused.error_code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_NE(refused.error_message().find("shard 0"), std::string::npos)
        << refused.error_message();
  }
  EXPECT_TRUE(absl::IsNotFound(replica.core()->Get(fresh[0].id).status()));
  // Primary-only reads fail naming the shard while its primary is down,
  // though the replica serves.
  {
    grpc::ClientContext context;
    tpr::v1::GetRequest request;
    request.set_id(marker[0].id);
    tpr::v1::Model model;
    grpc::Status refused = primary_gateway->Get(&context, request, &model);
    EXPECT_EQ(refused.error_code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_NE(refused.error_message().find("shard 0"), std::string::npos)
        << refused.error_message();
  }
  tpr::common::ShutdownGracefully(*primary_started, server_options);
  tpr::common::ShutdownGracefully(*started, server_options);
}

TEST_F(GatewayTest, AStoppedShardFailsTheCallNamingIt) {
  shards_[1]->Stop();
  tpr::v1::SearchRequest request;
  *request.mutable_signature() = ToWire(models_[0].signature);
  request.set_k(5);
  SearchResult got = RunSearch(gateway_.get(), request);
  EXPECT_EQ(got.status.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_NE(got.status.error_message().find("shard 1"), std::string::npos)
      << got.status.error_message();
  EXPECT_TRUE(got.neighbors.empty());
  // After a health check too (the address is then known down up front).
  service_->shards().CheckNow();
  got = RunSearch(gateway_.get(), request);
  EXPECT_EQ(got.status.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_NE(got.status.error_message().find("shard 1"), std::string::npos);
  // Ids on the other shards still read; ids on shard 1 fail naming it.
  for (const TestModel& m : models_) {
    grpc::ClientContext context;
    tpr::v1::GetRequest get;
    get.set_id(m.id);
    tpr::v1::Model model;
    grpc::Status status = gateway_->Get(&context, get, &model);
    if (ShardOf(m.id, kShards) == 1) {
      EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE);
    } else {
      EXPECT_TRUE(status.ok()) << status.error_message();
    }
  }
  grpc::ClientContext stats_context;
  tpr::v1::StatsResponse stats;
  EXPECT_EQ(gateway_->Stats(&stats_context, {}, &stats).error_code(),
            grpc::StatusCode::UNAVAILABLE);
}

// A shard whose search never runs out of neighbours: it streams neighbours
// farther than any real one (distance 1e6 + i) until its call ends, then
// records how many it sent and whether its call was cancelled. Once the
// gateway stops reading, Write blocks (HTTP/2 flow control), so only a
// cancellation, or the caller's deadline, ends the call.
class EndlessShard final : public tpr::v1::Indexer::Service {
 public:
  // At most this many neighbours (about 300 MB on the wire), so that the
  // handler ends even if nothing stops it.
  static constexpr int64_t kMaxNeighbors = 10'000'000;
  struct End {
    int64_t sent = 0;
    bool cancelled = false;
  };

  grpc::Status Search(
      grpc::ServerContext* context, const tpr::v1::SearchRequest*,
      grpc::ServerWriter<tpr::v1::SearchResponse>* writer) override {
    tpr::v1::SearchResponse response;
    const bool progress = tpr::common::WantsSearchProgress(*context);
    int64_t sent = 0;
    for (; sent < kMaxNeighbors; ++sent) {
      tpr::v1::Neighbor* n = response.mutable_neighbor();
      n->set_id(absl::StrCat("far", sent));
      n->set_rank(static_cast<int>(sent + 1));
      n->set_distance(1e6 + static_cast<double>(sent));
      if (progress) *n->mutable_progress() = Progress(sent);
      if (!writer->Write(response)) break;
    }
    std::lock_guard<std::mutex> lock(mu_);
    ends_.push_back({sent, context->IsCancelled()});
    ended_.notify_all();
    return grpc::Status::OK;
  }

  // Progress returns the statistics this shard reports with its neighbour
  // number `i` (0-based) when asked: made-up counts growing with i.
  static tpr::v1::SearchStats Progress(int64_t i) {
    tpr::v1::SearchStats s;
    s.set_emd_computations(100 * (i + 1));
    s.set_lower_bounds(10 * (i + 1));
    s.set_nodes_visited(i + 1);
    return s;
  }

  // Waits up to `timeout` for a search to have ended; returns its end, or
  // nullopt.
  std::optional<End> WaitForEnd(std::chrono::seconds timeout) {
    std::unique_lock<std::mutex> lock(mu_);
    if (!ended_.wait_for(lock, timeout, [&] { return !ends_.empty(); }))
      return std::nullopt;
    return ends_.front();
  }

 private:
  std::mutex mu_;
  std::condition_variable ended_;
  std::vector<End> ends_;
};

// "shard streams are cancelled once k neighbours have been sent",
// observed on the shard. Shard 0 (a real indexer) holds every near model;
// shard 1 would stream neighbours for ever. The gateway sends shard 0's k
// nearest (the oracle: brute force over shard 0's models) and must then
// cancel shard 1's stream: the call ends OK long before its deadline, and
// shard 1 sees its call cancelled with neighbours still to send. Without the
// cancellation the gateway would wait for shard 1's end, which only the
// deadline brings (the call would fail with DEADLINE_EXCEEDED). The statistics
// count shard 1's work: its progress at the one neighbour the gateway read
// (its first, never sent), plus shard 0's at its k-th neighbour (the oracle:
// shard 0 asked directly).
TEST(GatewaySearchTest, CancelsTheShardStreamsOnceKNeighboursAreSent) {
  TempDir dir;
  InProcessIndexer near(dir.path() + "/near");
  ASSERT_TRUE(near.Start().ok());
  const std::vector<TestModel> models = MakeModels(40, 4, 23);
  tpr::v1::BatchUpsertResponse written;
  ASSERT_TRUE(Ingest(near.stub(), models, &written).ok());
  ASSERT_EQ(written.written(), static_cast<int64_t>(models.size()));
  near.core()->WaitForRebuild();

  EndlessShard endless;
  tpr::common::ServerOptions shard_options;
  shard_options.listen_address = "127.0.0.1:0";
  shard_options.shutdown_grace_ms = 2000;
  absl::StatusOr<tpr::common::StartedServer> shard =
      tpr::common::StartServer(shard_options, {&endless});
  ASSERT_TRUE(shard.ok()) << shard.status();

  GatewayOptions options;
  options.shards.shards.push_back({near.address(), {}});
  options.shards.shards.push_back(
      {absl::StrCat("127.0.0.1:", shard->port), {}});
  options.health_interval_ms = 0;
  GatewayService gateway(options);
  tpr::common::ServerOptions gateway_options;
  gateway_options.listen_address = "127.0.0.1:0";
  gateway_options.shutdown_grace_ms = 2000;
  absl::StatusOr<tpr::common::StartedServer> front =
      tpr::common::StartServer(gateway_options, {&gateway});
  ASSERT_TRUE(front.ok()) << front.status();
  auto stub = tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(absl::StrCat("127.0.0.1:", front->port),
                          grpc::InsecureChannelCredentials()));

  constexpr int kK = 10;
  tpr::v1::SearchRequest request;
  *request.mutable_signature() = ToWire(models[3].signature);
  request.set_k(kK);
  const SearchResult got = RunSearch(stub.get(), request);  // 60 s deadline
  ASSERT_TRUE(got.status.ok()) << got.status.error_message();
  const std::vector<Hit> want = BruteForce(models[3].signature, models, kK);
  ASSERT_EQ(got.neighbors.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(got.neighbors[i].id(), want[i].id) << "rank " << i + 1;
    EXPECT_DOUBLE_EQ(got.neighbors[i].distance(), want[i].distance)
        << "rank " << i + 1;
  }

  ASSERT_TRUE(got.got_stats);
  const SearchResult direct = RunSearch(near.stub(), request, true);
  ASSERT_TRUE(direct.status.ok());
  ASSERT_GE(direct.neighbors.size(), static_cast<size_t>(kK));
  const tpr::v1::SearchStats& near_at_k = direct.neighbors[kK - 1].progress();
  const tpr::v1::SearchStats endless_first = EndlessShard::Progress(0);
  EXPECT_GT(near_at_k.emd_computations(), 0);
  EXPECT_EQ(got.stats.emd_computations(),
            near_at_k.emd_computations() + endless_first.emd_computations());
  EXPECT_EQ(got.stats.lower_bounds(),
            near_at_k.lower_bounds() + endless_first.lower_bounds());
  EXPECT_EQ(got.stats.nodes_visited(),
            near_at_k.nodes_visited() + endless_first.nodes_visited());

  const std::optional<EndlessShard::End> end =
      endless.WaitForEnd(std::chrono::seconds(30));
  ASSERT_TRUE(end.has_value()) << "shard 1 still streams after the call ended";
  EXPECT_TRUE(end->cancelled) << "shard 1's call ended without a cancellation";
  EXPECT_LT(end->sent, EndlessShard::kMaxNeighbors)
      << "shard 1 ran out instead of being stopped";
  EXPECT_GE(end->sent, 1);  // its first neighbour was in the merge
  std::printf("shard 1 was cancelled after sending %lld neighbours\n",
              static_cast<long long>(end->sent));
  tpr::common::ShutdownGracefully(*front->server, gateway_options);
  tpr::common::ShutdownGracefully(*shard->server, shard_options);
}

}  // namespace
}  // namespace tpr::gateway
