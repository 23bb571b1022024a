// tpr-indexer over the wire (in-process server on a loopback port): CRUD
// round trips, searches against the brute-force EMD oracle, error codes,
// concurrency, health, cancellation; and IndexerCore under concurrent
// writers and searchers without the wire.
#include <atomic>
#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <thread>
#include <tuple>

#include "gtest/gtest.h"
#include "indexer/service/batch_writer.h"
#include "tests/sanitizers/sanitizer_build.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"
#include "tests/service/ops_testing.h"

namespace tpr::indexer::testing {
namespace {

using ::tpr::testing::TempDir;

tpr::v1::SearchRequest ById(const std::string& id, int k) {
  tpr::v1::SearchRequest r;
  r.set_id(id);
  r.set_k(k);
  return r;
}

tpr::v1::SearchRequest BySignature(const tpr::index::Signature& s, int k) {
  tpr::v1::SearchRequest r;
  *r.mutable_signature() = ToWire(s);
  r.set_k(k);
  return r;
}

using ::tpr::testing::kThreadSanitizer;

class IndexerServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (kThreadSanitizer) {
      // Debian's gRPC is not instrumented: TSan cannot see it hand a call
      // between its threads and reports hundreds of races per call, with
      // our interceptors' and handlers' frames on top.
      GTEST_SKIP() << "gRPC (Debian, not instrumented) hides its "
                      "synchronization from TSan";
    }
    CoreOptions core;
    core.persist_interval_ms = 0;
    // A small threshold so that the tree is rebuilt while tests write, and
    // searches cover tree, buffer and tombstones.
    core.index.rebuild_threshold = 16;
    core.max_k = 1000;
    server_ = std::make_unique<InProcessIndexer>(dir_.path(), core);
    ASSERT_TRUE(server_->Start().ok());
  }

  void AddAll(const std::vector<TestModel>& models) {
    for (const TestModel& m : models) {
      grpc::ClientContext context;
      tpr::v1::UpsertResponse response;
      ASSERT_TRUE(
          server_->stub()->Upsert(&context, ToRequest(m), &response).ok());
      ASSERT_TRUE(response.created());
    }
  }

  TempDir dir_;
  std::unique_ptr<InProcessIndexer> server_;
};

TEST_F(IndexerServiceTest, UpsertGetListDeleteStatsRoundTrip) {
  std::vector<TestModel> models = MakeModels(10, 2, 11);
  AddAll(models);
  auto* stub = server_->stub();

  // Upsert without overwrite: ALREADY_EXISTS; with overwrite: replaced and
  // the time added kept.
  tpr::v1::Model before;
  {
    grpc::ClientContext c;
    tpr::v1::GetRequest g;
    g.set_id(models[3].id);
    ASSERT_TRUE(stub->Get(&c, g, &before).ok());
    EXPECT_GT(before.added_unix_micros(), 0);
    EXPECT_EQ(before.label(), models[3].label);
    EXPECT_EQ(before.metadata().at("source"), "gen/" + models[3].id);
    EXPECT_EQ(before.signature().SerializeAsString(),
              ToWire(models[3].signature).SerializeAsString());
  }
  {
    grpc::ClientContext c;
    tpr::v1::UpsertResponse r;
    EXPECT_EQ(stub->Upsert(&c, ToRequest(models[3]), &r).error_code(),
              grpc::StatusCode::ALREADY_EXISTS);
  }
  TestModel relabelled = models[3];
  relabelled.label = "class1";
  relabelled.signature = models[4].signature;
  {
    grpc::ClientContext c;
    tpr::v1::UpsertResponse r;
    ASSERT_TRUE(
        stub->Upsert(&c, ToRequest(relabelled, /*overwrite=*/true), &r).ok());
    EXPECT_FALSE(r.created());
    grpc::ClientContext c2;
    tpr::v1::GetRequest g;
    g.set_id(models[3].id);
    tpr::v1::Model after;
    ASSERT_TRUE(stub->Get(&c2, g, &after).ok());
    EXPECT_EQ(after.added_unix_micros(), before.added_unix_micros());
    EXPECT_EQ(after.label(), "class1");
    EXPECT_EQ(after.signature().SerializeAsString(),
              ToWire(models[4].signature).SerializeAsString());
  }

  // List: pages of 3 concatenate to every id in order; label filter.
  std::vector<std::string> listed;
  std::string token;
  int pages = 0;
  do {
    grpc::ClientContext c;
    tpr::v1::ListRequest l;
    l.set_page_size(3);
    l.set_page_token(token);
    tpr::v1::ListResponse r;
    ASSERT_TRUE(stub->List(&c, l, &r).ok());
    for (const auto& m : r.models()) {
      listed.push_back(m.id());
      EXPECT_EQ(m.signature().features_size(), 0);  // omitted in lists
    }
    token = r.next_page_token();
    ++pages;
  } while (!token.empty() && pages < 100);
  std::vector<std::string> expected;
  for (const TestModel& m : models) expected.push_back(m.id);
  EXPECT_EQ(listed, expected);
  EXPECT_EQ(pages, 4);
  {
    grpc::ClientContext c;
    tpr::v1::ListRequest l;
    l.set_label("class0");
    tpr::v1::ListResponse r;
    ASSERT_TRUE(stub->List(&c, l, &r).ok());
    std::vector<std::string> got;
    for (const auto& m : r.models()) got.push_back(m.id());
    std::vector<std::string> want;
    for (const TestModel& m : models) {
      if (m.label == "class0" && m.id != models[3].id) want.push_back(m.id);
    }
    EXPECT_EQ(got, want);
  }

  // Delete, then NOT_FOUND for Get and a second Delete.
  {
    grpc::ClientContext c;
    tpr::v1::DeleteRequest d;
    d.set_id(models[0].id);
    tpr::v1::DeleteResponse r;
    ASSERT_TRUE(stub->Delete(&c, d, &r).ok());
    grpc::ClientContext c2;
    EXPECT_EQ(stub->Delete(&c2, d, &r).error_code(),
              grpc::StatusCode::NOT_FOUND);
    grpc::ClientContext c3;
    tpr::v1::GetRequest g;
    g.set_id(models[0].id);
    tpr::v1::Model m;
    EXPECT_EQ(stub->Get(&c3, g, &m).error_code(), grpc::StatusCode::NOT_FOUND);
  }

  // Stats: 9 models; labels counted after the relabel and the delete.
  {
    grpc::ClientContext c;
    tpr::v1::StatsResponse s;
    ASSERT_TRUE(stub->Stats(&c, tpr::v1::StatsRequest(), &s).ok());
    EXPECT_EQ(s.models(), 9);
    EXPECT_EQ(s.indexed() + s.buffered(), 9);
    // models 0,2,4,6,8 were class0; 0 deleted -> 4; class1 1,3,5,7,9 -> 5.
    EXPECT_EQ(s.labels().at("class0"), 4);
    EXPECT_EQ(s.labels().at("class1"), 5);
    EXPECT_GT(s.disk_bytes(), 0);
    // At least the 9 prepared signatures' coordinates: MakeModels gives 12
    // features x 8 bands, so 1 + 3 x 8 rows of 12 float32 values each.
    EXPECT_GE(s.memory_bytes(), 9 * 25 * 12 * 4);
  }
}

TEST_F(IndexerServiceTest, SearchMatchesBruteForce) {
  const std::vector<TestModel> models = MakeModels(80, 4, 21);
  AddAll(models);
  auto* stub = server_->stub();
  const std::vector<TestModel> queries = MakeModels(6, 4, 99, "q");

  for (const TestModel& q : queries) {
    SCOPED_TRACE(q.id);
    // Plain k-NN.
    SearchResult r = RunSearch(stub, BySignature(q.signature, 7));
    ASSERT_TRUE(r.status.ok()) << r.status.error_message();
    TPR_EXPECT_SAME_RANKING(r.neighbors, BruteForce(q.signature, models, 7));
    EXPECT_TRUE(r.got_stats);
    EXPECT_GT(r.stats.emd_computations(), 0);
    for (const auto& n : r.neighbors) {
      EXPECT_EQ(n.label(),
                models[static_cast<size_t>(std::stoi(n.id().substr(1)))].label);
    }

    // k > n returns everything, ranked.
    r = RunSearch(stub, BySignature(q.signature, 500));
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(r.neighbors, BruteForce(q.signature, models, 500));

    // Radius: the median distance keeps about half.
    const std::vector<Hit> all = BruteForce(q.signature, models, 500);
    const double radius = all[all.size() / 2].distance;
    tpr::v1::SearchRequest req = BySignature(q.signature, 500);
    req.set_radius(radius);
    r = RunSearch(stub, req);
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(r.neighbors,
                            BruteForce(q.signature, models, 500, radius));

    // Label filter, with k and radius.
    req = BySignature(q.signature, 5);
    req.set_label("class2");
    r = RunSearch(stub, req);
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(r.neighbors,
                            BruteForce(q.signature, models, 5, 0, "class2"));
    for (const auto& n : r.neighbors) EXPECT_EQ(n.label(), "class2");
    req.set_radius(radius);
    r = RunSearch(stub, req);
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(
        r.neighbors, BruteForce(q.signature, models, 5, radius, "class2"));
  }

  // By stored id, with and without the query model itself.
  for (int i : {0, 17, 79}) {
    const TestModel& m = models[static_cast<size_t>(i)];
    SearchResult r = RunSearch(stub, ById(m.id, 6));
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(r.neighbors, BruteForce(m.signature, models, 6));
    ASSERT_FALSE(r.neighbors.empty());
    EXPECT_EQ(r.neighbors[0].id(), m.id);
    EXPECT_EQ(r.neighbors[0].distance(), 0.0);
    tpr::v1::SearchRequest req = ById(m.id, 6);
    req.set_exclude_self(true);
    r = RunSearch(stub, req);
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(r.neighbors,
                            BruteForce(m.signature, models, 6, 0, "", m.id));
  }
}

TEST_F(IndexerServiceTest, IntentsAndRankingsAreExactThroughTheTree) {
  // SearchRequest.intent and .ranking through the real server: every intent
  // and every ranking equals the brute-force oracle of its weighting (order
  // and distances), with radius and label; the models carry spectra, so
  // the weightings rank differently. Bad weights and an unknown intent are
  // INVALID_ARGUMENT naming the field.
  const std::vector<TestModel> models = MakeModels(300, 4, 5, "m", 30);
  AddAll(models);
  auto* stub = server_->stub();
  const TestModel& m = models[11];
  std::set<std::vector<std::string>> orders;
  for (tpr::v1::Intent intent :
       {tpr::v1::INTENT_UNSPECIFIED, tpr::v1::INTENT_BALANCED,
        tpr::v1::INTENT_IDENTITY, tpr::v1::INTENT_KIND}) {
    tpr::v1::SearchRequest req = ById(m.id, 500);
    req.set_exclude_self(true);
    req.set_intent(intent);
    const tpr::index::TermWeights w = WeightsOf(req);
    SearchResult r = RunSearch(stub, req);
    ASSERT_TRUE(r.status.ok()) << r.status.error_message();
    const std::vector<Hit> want =
        BruteForce(m.signature, models, 500, 0, "", m.id, w);
    TPR_EXPECT_SAME_RANKING(r.neighbors, want);
    std::vector<std::string> order;
    for (const Hit& h : want) order.push_back(h.id);
    orders.insert(order);
    // k-NN: the tree prunes (fewer EMDs than models).
    req.set_k(5);
    r = RunSearch(stub, req);
    ASSERT_TRUE(r.status.ok()) << r.status.error_message();
    TPR_EXPECT_SAME_RANKING(r.neighbors,
                            BruteForce(m.signature, models, 5, 0, "", m.id, w));
    EXPECT_GT(r.stats.nodes_visited(), 0);
    EXPECT_LT(r.stats.emd_computations(), 299);
    // Radius (that weighting's distance) and label.
    const double radius = want[want.size() / 2].distance;
    req.set_k(500);
    req.set_radius(radius);
    req.set_label("class1");
    r = RunSearch(stub, req);
    ASSERT_TRUE(r.status.ok()) << r.status.error_message();
    TPR_EXPECT_SAME_RANKING(r.neighbors, BruteForce(m.signature, models, 500,
                                                    radius, "class1", m.id, w));
  }
  EXPECT_GE(orders.size(), 2u) << "intents rank differently";

  for (const tpr::index::TermWeights& w : std::vector<tpr::index::TermWeights>{
           {1, 0, 0}, {0, 1, 0}, {0.5, 0, 2}, {0, 1, 1}}) {
    tpr::v1::SearchRequest req = ById(m.id, 7);
    req.mutable_ranking()->set_emd_weight(w.emd);
    req.mutable_ranking()->set_spectral_weight(w.spectral);
    req.mutable_ranking()->set_heat_weight(w.heat);
    req.set_intent(tpr::v1::INTENT_KIND);  // ignored: the ranking wins
    SearchResult r = RunSearch(stub, req);
    ASSERT_TRUE(r.status.ok()) << r.status.error_message();
    TPR_EXPECT_SAME_RANKING(r.neighbors,
                            BruteForce(m.signature, models, 7, 0, "", "", w));
    if (w.emd == 0.0) {
      EXPECT_EQ(r.stats.emd_computations(), 0);
    }
  }

  for (auto [emd, spectral, heat] :
       std::vector<std::tuple<double, double, double>>{
           {-1, 0, 0}, {0, 0, 0}, {1, std::nan(""), 0}, {1, 0, -3}}) {
    tpr::v1::SearchRequest bad = ById(m.id, 5);
    bad.mutable_ranking()->set_emd_weight(emd);
    bad.mutable_ranking()->set_spectral_weight(spectral);
    bad.mutable_ranking()->set_heat_weight(heat);
    SearchResult r = RunSearch(stub, bad);
    EXPECT_EQ(r.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << emd << " " << spectral << " " << heat;
    EXPECT_NE(r.status.error_message().find("ranking"), std::string::npos)
        << r.status.error_message();
  }
  tpr::v1::SearchRequest unknown = ById(m.id, 5);
  unknown.set_intent(static_cast<tpr::v1::Intent>(42));
  SearchResult r = RunSearch(stub, unknown);
  EXPECT_EQ(r.status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(r.status.error_message().find("intent 42"), std::string::npos)
      << r.status.error_message();
}

TEST_F(IndexerServiceTest, SearchIsExactAfterDeletesAndOverwrites) {
  std::vector<TestModel> models = MakeModels(60, 3, 31);
  AddAll(models);
  auto* stub = server_->stub();
  const std::vector<TestModel> fresh = MakeModels(60, 3, 32);
  std::vector<TestModel> live;
  for (size_t i = 0; i < models.size(); ++i) {
    if (i % 3 == 0) {
      grpc::ClientContext c;
      tpr::v1::DeleteRequest d;
      d.set_id(models[i].id);
      tpr::v1::DeleteResponse r;
      ASSERT_TRUE(stub->Delete(&c, d, &r).ok());
    } else if (i % 3 == 1) {
      TestModel changed = models[i];
      changed.signature = fresh[i].signature;
      grpc::ClientContext c;
      tpr::v1::UpsertResponse r;
      ASSERT_TRUE(stub->Upsert(&c, ToRequest(changed, true), &r).ok());
      live.push_back(changed);
    } else {
      live.push_back(models[i]);
    }
  }
  for (const TestModel& q : MakeModels(4, 3, 33, "q")) {
    SearchResult r = RunSearch(stub, BySignature(q.signature, 100));
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(r.neighbors, BruteForce(q.signature, live, 100));
  }
}

TEST_F(IndexerServiceTest, BadInputGetsItsCodeAndServerKeepsServing) {
  const std::vector<TestModel> models = MakeModels(10, 2, 41);
  AddAll(models);
  auto* stub = server_->stub();
  auto search_code = [&](const tpr::v1::SearchRequest& r) {
    SearchResult res = RunSearch(stub, r);
    EXPECT_TRUE(res.neighbors.empty());
    return res.status.error_code();
  };
  EXPECT_EQ(search_code(ById(models[0].id, 0)),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(search_code(ById(models[0].id, -3)),
            grpc::StatusCode::INVALID_ARGUMENT);
  tpr::v1::SearchRequest negative = ById(models[0].id, 3);
  negative.set_radius(-0.5);
  EXPECT_EQ(search_code(negative), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(search_code(ById("no-such-model", 3)), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(search_code(ById(models[0].id, 1001)),
            grpc::StatusCode::RESOURCE_EXHAUSTED);
  tpr::v1::SearchRequest no_query;
  no_query.set_k(3);
  EXPECT_EQ(search_code(no_query), grpc::StatusCode::INVALID_ARGUMENT);

  // Malformed signatures: weights not summing to 1, unequal band lengths,
  // a feature without kind, no feature at all.
  tpr::v1::Signature bad_weights = ToWire(models[0].signature);
  bad_weights.mutable_features(0)->set_weight(bad_weights.features(0).weight() +
                                              0.3);
  tpr::v1::Signature bad_bands = ToWire(models[0].signature);
  bad_bands.mutable_features(1)->add_curvature(0.1);
  tpr::v1::Signature bad_kind = ToWire(models[0].signature);
  bad_kind.mutable_features(2)->set_kind(tpr::v1::FEATURE_KIND_UNSPECIFIED);
  for (const tpr::v1::Signature& bad :
       {bad_weights, bad_bands, bad_kind, tpr::v1::Signature()}) {
    tpr::v1::SearchRequest r;
    *r.mutable_signature() = bad;
    r.set_k(3);
    EXPECT_EQ(search_code(r), grpc::StatusCode::INVALID_ARGUMENT);
    tpr::v1::UpsertRequest u = ToRequest(models[1], true);
    *u.mutable_model()->mutable_signature() = bad;
    grpc::ClientContext c;
    tpr::v1::UpsertResponse resp;
    grpc::Status s = stub->Upsert(&c, u, &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(s.error_message().find(models[1].id), std::string::npos)
        << s.error_message();
  }

  // Ids: empty and too long.
  for (const std::string& id : {std::string(), std::string(1025, 'x')}) {
    TestModel m = models[0];
    m.id = id;
    grpc::ClientContext c;
    tpr::v1::UpsertResponse resp;
    EXPECT_EQ(stub->Upsert(&c, ToRequest(m), &resp).error_code(),
              grpc::StatusCode::INVALID_ARGUMENT);
  }
  // Oversized metadata.
  {
    tpr::v1::UpsertRequest u = ToRequest(models[2], true);
    (*u.mutable_model()->mutable_metadata())["blob"] = std::string(70000, 'b');
    grpc::ClientContext c;
    tpr::v1::UpsertResponse resp;
    EXPECT_EQ(stub->Upsert(&c, u, &resp).error_code(),
              grpc::StatusCode::RESOURCE_EXHAUSTED);
  }
  // A rejected model was not written.
  {
    grpc::ClientContext c;
    tpr::v1::GetRequest g;
    g.set_id(models[1].id);
    tpr::v1::Model m;
    ASSERT_TRUE(stub->Get(&c, g, &m).ok());
    EXPECT_EQ(m.signature().SerializeAsString(),
              ToWire(models[1].signature).SerializeAsString());
  }

  // Still serving, and exact.
  SearchResult r = RunSearch(stub, ById(models[0].id, 4));
  ASSERT_TRUE(r.status.ok());
  TPR_EXPECT_SAME_RANKING(r.neighbors,
                          BruteForce(models[0].signature, models, 4));
}

// A label of tens of MiB made List and Stats fail for
// every client. Labels are bounded (256 bytes), and List and Stats answers
// stay under gRPC's default 4 MiB receive limit by construction, even with
// every model at the largest id, label and metadata allowed. The stub's
// channel keeps gRPC's default limit, as any client's would.
TEST_F(IndexerServiceTest, LabelsAreBoundedAndListAndStatsStayUnderFourMiB) {
  auto* stub = server_->stub();
  const std::vector<TestModel> models = MakeModels(120, 3, 91);
  {
    tpr::v1::UpsertRequest u = ToRequest(models[0]);
    u.mutable_model()->set_label(std::string(20 << 20, 'L'));
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    tpr::v1::UpsertResponse resp;
    grpc::Status s = stub->Upsert(&c, u, &resp);
    // Past the server's 64 MiB receive limit it is not; the label check
    // answers, naming the length and the limit.
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << s.error_message();
    EXPECT_NE(s.error_message().find("label"), std::string::npos)
        << s.error_message();
    EXPECT_NE(s.error_message().find("256"), std::string::npos)
        << s.error_message();
  }
  {
    tpr::v1::UpsertRequest u = ToRequest(models[0]);
    u.mutable_model()->set_label(std::string(kMaxLabelBytes + 1, 'L'));
    grpc::ClientContext c;
    tpr::v1::UpsertResponse resp;
    EXPECT_EQ(stub->Upsert(&c, u, &resp).error_code(),
              grpc::StatusCode::INVALID_ARGUMENT);
  }
  // Every model as large as List can carry: longest id, longest label,
  // 64 KiB of metadata; each label distinct. 120 of them are ~7.9 MB.
  std::set<std::string> ids;
  {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    tpr::v1::BatchUpsertResponse resp;
    auto writer = stub->BatchUpsert(&c, &resp);
    for (size_t i = 0; i < models.size(); ++i) {
      tpr::v1::UpsertRequest u = ToRequest(models[i]);
      std::string id = absl::StrCat(models[i].id, "/");
      id.resize(kMaxIdBytes, 'i');
      u.mutable_model()->set_id(id);
      ids.insert(id);
      std::string label = absl::StrCat(i, "/");
      label.resize(kMaxLabelBytes, static_cast<char>('a' + i % 26));
      u.mutable_model()->set_label(label);
      auto& metadata = *u.mutable_model()->mutable_metadata();
      metadata.clear();
      metadata["blob"] = std::string(kMaxMetadataBytes - 4, 'm');
      ASSERT_TRUE(writer->Write(u));
    }
    writer->WritesDone();
    ASSERT_TRUE(writer->Finish().ok());
    ASSERT_EQ(resp.written(), static_cast<int64_t>(models.size()));
  }
  std::set<std::string> listed;
  std::string token;
  int pages = 0;
  do {
    grpc::ClientContext c;
    tpr::v1::ListRequest l;
    l.set_page_size(1000);
    l.set_page_token(token);
    tpr::v1::ListResponse r;
    grpc::Status s = stub->List(&c, l, &r);
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_LE(r.ByteSizeLong(), size_t{4} << 20);
    EXPECT_GT(r.models_size(), 0);
    for (const auto& m : r.models()) {
      EXPECT_TRUE(listed.insert(m.id()).second) << "listed twice";
      EXPECT_EQ(m.metadata().at("blob").size(), kMaxMetadataBytes - 4);
    }
    token = r.next_page_token();
    ASSERT_LT(++pages, 100);
  } while (!token.empty());
  EXPECT_EQ(listed, ids);
  EXPECT_GT(pages, 1) << "one page would be ~7.9 MB";

  // Stats: more distinct labels than it reports; the most populous first.
  {
    grpc::ClientContext c;
    tpr::v1::BatchUpsertResponse resp;
    auto writer = stub->BatchUpsert(&c, &resp);
    const std::vector<TestModel> more =
        MakeModels(kMaxStatsLabels + 50, 3, 92, "s");
    for (size_t i = 0; i < more.size(); ++i) {
      tpr::v1::UpsertRequest u = ToRequest(more[i]);
      std::string label = absl::StrCat("label", i, "-");
      label.resize(kMaxLabelBytes, 'z');
      // Labels 0..9 hold 3 models each, the rest one.
      u.mutable_model()->set_label(i < 30 ? absl::StrCat("popular", i % 10)
                                          : label);
      ASSERT_TRUE(writer->Write(u));
    }
    writer->WritesDone();
    ASSERT_TRUE(writer->Finish().ok());
  }
  grpc::ClientContext c;
  tpr::v1::StatsResponse stats;
  grpc::Status s = stub->Stats(&c, tpr::v1::StatsRequest(), &stats);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_LE(stats.ByteSizeLong(), size_t{4} << 20);
  EXPECT_EQ(stats.models(),
            static_cast<int64_t>(models.size() + kMaxStatsLabels + 50));
  EXPECT_EQ(stats.labels().size(), static_cast<int>(kMaxStatsLabels));
  for (int i = 0; i < 10; ++i)
    EXPECT_EQ(stats.labels().at(absl::StrCat("popular", i)), 3);
}

// Invalid UTF-8 in an id, garbage bytes and ids
// outside the alphabet get INVALID_ARGUMENT naming the problem, never
// INTERNAL with an empty message. Raw bytes go on the wire through a
// generic call, as a client in another language (or a fuzzer) sends them.
TEST_F(IndexerServiceTest, BadBytesAndIdsOutsideTheAlphabetAreInvalidArgument) {
  const std::vector<TestModel> models = MakeModels(2, 1, 95);
  auto raw_upsert = [&](const std::string& bytes) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::seconds(10));
    grpc::Slice slice(bytes.data(), bytes.size());
    grpc::ByteBuffer request(&slice, 1);
    grpc::ByteBuffer response;
    const grpc::internal::RpcMethod method(
        "/tpr.v1.Indexer/Upsert", grpc::internal::RpcMethod::NORMAL_RPC);
    return grpc::internal::BlockingUnaryCall<grpc::ByteBuffer,
                                             grpc::ByteBuffer>(
        server_->channel().get(), method, &context, request, &response);
  };
  // A valid request, serialized, then its id's bytes replaced by bytes that
  // are not UTF-8 (same length, so the framing stays valid).
  tpr::v1::UpsertRequest valid = ToRequest(models[0]);
  valid.mutable_model()->set_id("ID-TO-REPLACE");
  std::string bytes = valid.SerializeAsString();
  const size_t at = bytes.find("ID-TO-REPLACE");
  ASSERT_NE(at, std::string::npos);
  bytes.replace(at, 13, std::string("bad\xff\xfe-id-utf8", 13));
  for (const std::string& garbage :
       {bytes, std::string("\xff\xff\xff\xff\xff\xff", 6),
        std::string("\x0a\x05\x0a", 3)}) {
    grpc::Status s = raw_upsert(garbage);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << s.error_message();
    EXPECT_NE(s.error_message().find("UTF-8"), std::string::npos)
        << s.error_message();
    EXPECT_NE(s.error_message().find("Upsert"), std::string::npos)
        << s.error_message();
  }
  // The untouched request goes through the same raw path.
  EXPECT_TRUE(raw_upsert(ToRequest(models[0]).SerializeAsString()).ok());

  // Ids and labels outside the alphabet, sent through the generated stub.
  for (const auto& [id, label, problem] :
       std::vector<std::tuple<std::string, std::string, std::string>>{
           {"two\nlines", "", "U+000A"},
           {"tab\there", "", "U+0009"},
           {"del\x7f", "", "U+007F"},
           {"c1\xc2\x85", "", "U+0085"},
           {"ok-id", "bad\nlabel", "U+000A"}}) {
    TestModel m = models[1];
    m.id = id;
    m.label = label;
    grpc::ClientContext c;
    tpr::v1::UpsertResponse resp;
    grpc::Status s = server_->stub()->Upsert(&c, ToRequest(m), &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << id;
    EXPECT_NE(s.error_message().find(problem), std::string::npos)
        << s.error_message();
  }
  // Non-ASCII printable ids are fine.
  TestModel accented = models[1];
  accented.id = "caf\xc3\xa9/\xe6\xa8\xa1\xe5\x9e\x8b";
  grpc::ClientContext c;
  tpr::v1::UpsertResponse resp;
  EXPECT_TRUE(server_->stub()->Upsert(&c, ToRequest(accented), &resp).ok());
}

TEST_F(IndexerServiceTest, BatchUpsertCountsAndKeepsModelsBeforeAnError) {
  const std::vector<TestModel> models = MakeModels(40, 2, 51);
  auto* stub = server_->stub();
  {
    grpc::ClientContext c;
    tpr::v1::BatchUpsertResponse resp;
    auto writer = stub->BatchUpsert(&c, &resp);
    for (size_t i = 0; i < 30; ++i)
      ASSERT_TRUE(writer->Write(ToRequest(models[i])));
    // Duplicates without overwrite are skipped, with overwrite written.
    ASSERT_TRUE(writer->Write(ToRequest(models[0])));
    ASSERT_TRUE(writer->Write(ToRequest(models[1], true)));
    writer->WritesDone();
    ASSERT_TRUE(writer->Finish().ok());
    EXPECT_EQ(resp.written(), 31);
    EXPECT_EQ(resp.skipped(), 1);
  }
  {
    grpc::ClientContext c;
    tpr::v1::BatchUpsertResponse resp;
    auto writer = stub->BatchUpsert(&c, &resp);
    for (size_t i = 30; i < 35; ++i)
      ASSERT_TRUE(writer->Write(ToRequest(models[i])));
    TestModel bad = models[35];
    bad.signature.features.clear();
    writer->Write(ToRequest(bad));
    for (size_t i = 36; i < 40; ++i) writer->Write(ToRequest(models[i]));
    writer->WritesDone();
    grpc::Status s = writer->Finish();
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_NE(s.error_message().find(models[35].id), std::string::npos);
  }
  grpc::ClientContext c;
  tpr::v1::StatsResponse stats;
  ASSERT_TRUE(stub->Stats(&c, tpr::v1::StatsRequest(), &stats).ok());
  EXPECT_EQ(stats.models(), 35);  // 30 + the 5 before the bad one
  std::vector<TestModel> kept(models.begin(), models.begin() + 35);
  SearchResult r = RunSearch(stub, BySignature(models[39].signature, 50));
  ASSERT_TRUE(r.status.ok());
  TPR_EXPECT_SAME_RANKING(r.neighbors,
                          BruteForce(models[39].signature, kept, 50));
}

// Bytes that do not parse in the middle of a BatchUpsert stream
// were taken for the end of the stream (gRPC's typed reader reports both
// the same way): the call answered OK with the models before them written
// and the rest silently dropped. Now the call fails with INVALID_ARGUMENT
// naming the message; the models before it are kept (as for any error in
// the stream), none after it is read.
TEST_F(IndexerServiceTest, MalformedMessageInABatchUpsertStreamIsAnError) {
  const std::vector<TestModel> models = MakeModels(8, 2, 57);
  std::vector<std::string> stream;
  for (size_t i = 0; i < 3; ++i)
    stream.push_back(ToRequest(models[i]).SerializeAsString());
  // A request whose id is not UTF-8 (same length, so the framing holds),
  // and plain garbage.
  tpr::v1::UpsertRequest bad_utf8 = ToRequest(models[3]);
  bad_utf8.mutable_model()->set_id("ID-TO-REPLACE");
  std::string bad_bytes = bad_utf8.SerializeAsString();
  bad_bytes.replace(bad_bytes.find("ID-TO-REPLACE"), 13,
                    std::string("bad\xff\xfe-id-utf8", 13));
  const std::string method = "/tpr.v1.Indexer/BatchUpsert";
  for (const std::string& garbage :
       {std::string("\xff\xff\xff\xff\xff\xff", 6), bad_bytes}) {
    std::vector<std::string> messages = stream;
    messages.push_back(garbage);
    for (size_t i = 4; i < 8; ++i)
      messages.push_back(ToRequest(models[i]).SerializeAsString());
    grpc::Status s =
        ::tpr::testing::RawClientStream(server_->channel(), method, messages);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << s.error_message();
    EXPECT_NE(s.error_message().find("BatchUpsert: message 4 of the stream"),
              std::string::npos)
        << s.error_message();
    EXPECT_NE(s.error_message().find("tpr.v1.UpsertRequest"), std::string::npos)
        << s.error_message();
  }
  // The three before the bad message are stored, none after it.
  for (size_t i = 0; i < 8; ++i) {
    grpc::ClientContext c;
    tpr::v1::Model m;
    tpr::v1::GetRequest get;
    get.set_id(models[i].id);
    grpc::Status s = server_->stub()->Get(&c, get, &m);
    EXPECT_EQ(s.ok(), i < 3) << models[i].id << ": " << s.error_message();
  }
  // The same raw path takes a well-formed stream, and its counts are right.
  std::vector<std::string> good;
  for (size_t i = 3; i < 8; ++i)
    good.push_back(ToRequest(models[i]).SerializeAsString());
  std::string answer;
  grpc::Status s = ::tpr::testing::RawClientStream(server_->channel(), method,
                                                   good, &answer);
  ASSERT_TRUE(s.ok()) << s.error_message();
  tpr::v1::BatchUpsertResponse counts;
  ASSERT_TRUE(counts.ParseFromString(answer));
  EXPECT_EQ(counts.written(), 5);
}

TEST_F(IndexerServiceTest, ConcurrentWritersAndSearchersStayExact) {
  const std::vector<TestModel> base = MakeModels(60, 3, 61);
  AddAll(base);
  constexpr int kWriters = 3;
  constexpr int kSearchers = 2;
  constexpr int kWritesEach = 40;
  std::vector<std::vector<TestModel>> written(kWriters);
  std::atomic<int> errors{0};
  std::atomic<int> searches{0};
  std::atomic<bool> writers_done{false};
  std::vector<std::thread> threads;
  for (int w = 0; w < kWriters; ++w) {
    threads.emplace_back([&, w] {
      auto stub = tpr::v1::Indexer::NewStub(server_->channel());
      written[static_cast<size_t>(w)] =
          MakeModels(kWritesEach, 3, 100 + static_cast<uint64_t>(w),
                     absl::StrCat("w", w, "-"));
      for (const TestModel& m : written[static_cast<size_t>(w)]) {
        grpc::ClientContext c;
        tpr::v1::UpsertResponse r;
        if (!stub->Upsert(&c, ToRequest(m), &r).ok()) ++errors;
      }
    });
  }
  for (int s = 0; s < kSearchers; ++s) {
    threads.emplace_back([&, s] {
      auto stub = tpr::v1::Indexer::NewStub(server_->channel());
      const std::vector<TestModel> queries =
          MakeModels(5, 3, 200 + static_cast<uint64_t>(s), "q");
      // Bounded: until the writers finish, at most 200 searches.
      for (int i = 0; i < 200 && !writers_done.load(); ++i) {
        SearchResult r =
            RunSearch(stub.get(), BySignature(queries[i % 5].signature, 10));
        if (!r.status.ok() || r.neighbors.size() != 10 || !r.got_stats)
          ++errors;
        for (size_t j = 1; j < r.neighbors.size(); ++j) {
          if (r.neighbors[j].distance() < r.neighbors[j - 1].distance())
            ++errors;
        }
        ++searches;
      }
    });
  }
  for (int w = 0; w < kWriters; ++w) threads[static_cast<size_t>(w)].join();
  writers_done = true;
  for (size_t t = kWriters; t < threads.size(); ++t) threads[t].join();
  EXPECT_EQ(errors.load(), 0);
  EXPECT_GT(searches.load(), 0);

  std::vector<TestModel> all = base;
  for (const auto& w : written) all.insert(all.end(), w.begin(), w.end());
  for (const TestModel& q : MakeModels(4, 3, 300, "q")) {
    SearchResult r = RunSearch(server_->stub(), BySignature(q.signature, 25));
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(r.neighbors, BruteForce(q.signature, all, 25));
  }
}

// IndexerCore without the wire: writers (single upserts), a batch writer (group
// commits), a deleter and searchers at once, on a small rebuild threshold so
// that the tree is rebuilt in the background meanwhile, with two search threads
// per query. Every id has one signature for its whole life, so each neighbour
// a concurrent search returns must carry exactly its EMD to the query (no
// torn read), in ascending order; afterwards searches equal brute force
// over the final state.
TEST(IndexerCoreConcurrencyTest, WritersBatchesDeletesAndSearchersStayExact) {
  TempDir dir;
  CoreOptions options;
  options.data_dir = dir.path() + "/data";
  options.persist_interval_ms = 50;  // the tree persister runs meanwhile
  options.index.rebuild_threshold = 16;
  options.index.search_threads = 2;
  options.batch_group = 8;
  absl::StatusOr<std::unique_ptr<IndexerCore>> opened =
      IndexerCore::Open(options);
  ASSERT_TRUE(opened.ok()) << opened.status();
  IndexerCore* core = opened->get();
  const std::vector<TestModel> base = MakeModels(40, 3, 71);
  for (const TestModel& m : base) ASSERT_TRUE(core->Upsert(ToRequest(m)).ok());

  const std::vector<TestModel> single0 = MakeModels(30, 3, 72, "s0-");
  const std::vector<TestModel> single1 = MakeModels(30, 3, 73, "s1-");
  const std::vector<TestModel> batched = MakeModels(40, 3, 74, "b-");
  std::map<std::string, const TestModel*> by_id;
  for (const auto* set : {&base, &single0, &single1, &batched}) {
    for (const TestModel& m : *set) by_id[m.id] = &m;
  }
  std::atomic<int> errors{0};
  std::atomic<int> searches{0};
  std::atomic<int> writers_left{4};
  std::vector<std::thread> threads;
  for (const std::vector<TestModel>* set : {&single0, &single1}) {
    threads.emplace_back([&, set] {
      for (const TestModel& m : *set) {
        if (!core->Upsert(ToRequest(m)).ok()) ++errors;
      }
      --writers_left;
    });
  }
  threads.emplace_back([&] {
    for (size_t start = 0; start < batched.size(); start += 10) {
      BatchWriter batch(core);
      for (size_t i = start; i < start + 10; ++i) {
        if (!batch.Add(ToRequest(batched[i])).ok()) ++errors;
      }
      absl::StatusOr<tpr::v1::BatchUpsertResponse> counts = batch.Finish();
      if (!counts.ok() || counts->written() != 10) ++errors;
    }
    --writers_left;
  });
  threads.emplace_back([&] {
    for (size_t i = 0; i < base.size(); i += 2) {
      if (!core->Delete(base[i].id).ok()) ++errors;
    }
    --writers_left;
  });
  const std::vector<TestModel> queries = MakeModels(4, 3, 75, "q");
  for (int t = 0; t < 2; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 100 && (i < 3 || writers_left.load() > 0); ++i) {
        const TestModel& q =
            queries[static_cast<size_t>(i + t) % queries.size()];
        auto session = core->StartSearch(BySignature(q.signature, 8), nullptr);
        if (!session.ok()) {
          ++errors;
          continue;
        }
        double last = -1;
        int got = 0;
        while (std::optional<tpr::v1::Neighbor> n = (*session)->Next()) {
          ++got;
          auto it = by_id.find(n->id());
          if (it == by_id.end() || n->label() != it->second->label ||
              n->distance() < last ||
              std::abs(
                  n->distance() -
                  BruteForce(q.signature, {*it->second}, 1).front().distance) >
                  1e-9) {
            ++errors;
          }
          last = n->distance();
        }
        if (got != 8) ++errors;
        ++searches;
      }
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(errors.load(), 0);
  EXPECT_GT(searches.load(), 0);

  std::vector<TestModel> final_state;
  for (size_t i = 1; i < base.size(); i += 2) final_state.push_back(base[i]);
  for (const auto* set : {&single0, &single1, &batched}) {
    final_state.insert(final_state.end(), set->begin(), set->end());
  }
  EXPECT_EQ(core->Stats().models(), static_cast<int64_t>(final_state.size()));
  for (const TestModel& q : queries) {
    auto session = core->StartSearch(BySignature(q.signature, 30), nullptr);
    ASSERT_TRUE(session.ok()) << session.status();
    std::vector<tpr::v1::Neighbor> got;
    while (std::optional<tpr::v1::Neighbor> n = (*session)->Next())
      got.push_back(*n);
    TPR_EXPECT_SAME_RANKING(got, BruteForce(q.signature, final_state, 30));
  }
}

// A search sees the state of the moment it started: models relabelled (with
// a new signature), deleted or added while it runs do not show, and every
// result carries the label that went with the signature it was ranked by.
// The oracle is the brute-force ranking of the models as they were.
TEST_F(IndexerServiceTest, SearchSeesTheLabelsOfItsStartDespiteLaterWrites) {
  const std::vector<TestModel> before = MakeModels(40, 2, 81);
  AddAll(before);
  const tpr::index::Signature& query = before[7].signature;
  const std::string kept_label = before[7].label;
  auto all = server_->core()->StartSearch(BySignature(query, 40), nullptr);
  ASSERT_TRUE(all.ok()) << all.status();
  tpr::v1::SearchRequest filtered = BySignature(query, 40);
  filtered.set_label(kept_label);
  auto by_label = server_->core()->StartSearch(filtered, nullptr);
  ASSERT_TRUE(by_label.ok()) << by_label.status();

  // Writes after both searches started: relabel every model of the query's
  // class with a far signature, delete some of the other class, add new ones.
  const std::vector<TestModel> other = MakeModels(40, 2, 82, "n");
  for (size_t i = 0; i < before.size(); ++i) {
    grpc::ClientContext c;
    if (before[i].label == kept_label) {
      TestModel changed = before[i];
      changed.label = "relabelled";
      changed.signature = other[i].signature;
      tpr::v1::UpsertResponse r;
      ASSERT_TRUE(
          server_->stub()->Upsert(&c, ToRequest(changed, true), &r).ok());
    } else if (i % 4 == 1) {
      tpr::v1::DeleteRequest d;
      d.set_id(before[i].id);
      tpr::v1::DeleteResponse r;
      ASSERT_TRUE(server_->stub()->Delete(&c, d, &r).ok());
    } else {
      tpr::v1::UpsertResponse r;
      TestModel added = other[i];
      added.label = kept_label;
      ASSERT_TRUE(server_->stub()->Upsert(&c, ToRequest(added), &r).ok());
    }
  }

  std::map<std::string, std::string> label_before;
  for (const TestModel& m : before) label_before[m.id] = m.label;
  auto drain = [&](SearchSession& session) {
    std::vector<tpr::v1::Neighbor> out;
    while (std::optional<tpr::v1::Neighbor> n = session.Next())
      out.push_back(*n);
    return out;
  };
  const std::vector<tpr::v1::Neighbor> got_all = drain(**all);
  TPR_EXPECT_SAME_RANKING(got_all, BruteForce(query, before, 40));
  for (const tpr::v1::Neighbor& n : got_all)
    EXPECT_EQ(n.label(), label_before[n.id()]) << n.id();
  const std::vector<tpr::v1::Neighbor> got_label = drain(**by_label);
  TPR_EXPECT_SAME_RANKING(got_label,
                          BruteForce(query, before, 40, 0, kept_label));
  for (const tpr::v1::Neighbor& n : got_label)
    EXPECT_EQ(n.label(), kept_label) << n.id();

  // A search started now sees the new state.
  std::vector<TestModel> after;
  for (size_t i = 0; i < before.size(); ++i) {
    if (before[i].label == kept_label) {
      after.push_back({before[i].id, "relabelled", other[i].signature});
    } else if (i % 4 == 1) {
      continue;
    } else {
      after.push_back(before[i]);
      after.push_back({other[i].id, kept_label, other[i].signature});
    }
  }
  SearchResult now = RunSearch(server_->stub(), filtered);
  ASSERT_TRUE(now.status.ok());
  TPR_EXPECT_SAME_RANKING(now.neighbors,
                          BruteForce(query, after, 40, 0, kept_label));
  for (const tpr::v1::Neighbor& n : now.neighbors)
    EXPECT_EQ(n.label(), kept_label);
}

TEST_F(IndexerServiceTest, HealthAnswersServing) {
  absl::StatusOr<int> health =
      tpr::testing::HealthStatus(server_->channel(), "");
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_EQ(*health, 1);  // SERVING
}

TEST_F(IndexerServiceTest, ReflectionListsTheIndexerService) {
  absl::StatusOr<std::string> services = ReflectedServices(server_->channel());
  ASSERT_TRUE(services.ok()) << services.status();
  EXPECT_NE(services->find("tpr.v1.Indexer"), std::string::npos);
  EXPECT_NE(services->find("grpc.health.v1.Health"), std::string::npos);
}

TEST_F(IndexerServiceTest,
       ClientCancellationEndsTheStreamAndServerKeepsServing) {
  const std::vector<TestModel> models = MakeModels(120, 3, 71);
  AddAll(models);
  grpc::ClientContext context;
  auto reader =
      server_->stub()->Search(&context, BySignature(models[5].signature, 120));
  tpr::v1::SearchResponse response;
  ASSERT_TRUE(reader->Read(&response));
  ASSERT_TRUE(response.has_neighbor());
  context.TryCancel();
  while (reader->Read(&response)) {
  }
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
  SearchResult r =
      RunSearch(server_->stub(), BySignature(models[5].signature, 3));
  ASSERT_TRUE(r.status.ok());
  TPR_EXPECT_SAME_RANKING(r.neighbors,
                          BruteForce(models[5].signature, models, 3));
}

// A slow search (k = every model, large
// signatures) with a short deadline. The server stops between EMDs at the
// deadline: the call ends with DEADLINE_EXCEEDED, the search leaves the
// server soon after, having computed a small part of the full search's EMDs
// (the service's counters, independent of the client).
TEST_F(IndexerServiceTest, SearchStopsComputingAtTheClientsDeadline) {
  tpr::index::testing::SignatureGeneratorOptions options;
  options.seed = 93;
  options.features = 150;
  options.bands = 8;
  options.classes = 5;
  tpr::index::testing::SignatureGenerator gen(options);
  std::vector<TestModel> models;
  for (int i = 0; i < 300; ++i) {
    models.push_back({absl::StrCat("big", i), absl::StrCat("class", i % 5),
                      gen.Member(i % 5)});
  }
  {
    grpc::ClientContext c;
    tpr::v1::BatchUpsertResponse resp;
    auto writer = server_->stub()->BatchUpsert(&c, &resp);
    for (const TestModel& m : models) ASSERT_TRUE(writer->Write(ToRequest(m)));
    writer->WritesDone();
    ASSERT_TRUE(writer->Finish().ok());
  }
  server_->core()->WaitForRebuild();
  const tpr::index::Signature query = gen.Member(2);
  tpr::v1::SearchRequest request =
      BySignature(query, static_cast<int>(models.size()));

  // The full search, in process, for its time and work.
  const auto full_start = std::chrono::steady_clock::now();
  auto full = server_->core()->StartSearch(request, nullptr);
  ASSERT_TRUE(full.ok()) << full.status();
  size_t returned = 0;
  while ((*full)->Next().has_value()) ++returned;
  const double full_ms = std::chrono::duration<double, std::milli>(
                             std::chrono::steady_clock::now() - full_start)
                             .count();
  const int64_t full_emds = (*full)->Stats().emd_computations();
  ASSERT_EQ(returned, models.size());
  ASSERT_GE(full_emds, static_cast<int64_t>(models.size()));
  ASSERT_GT(full_ms, 100.0)
      << "the search is too quick to be cut by a deadline";

  const IndexerService::SearchCounters before =
      server_->service()->search_counters();
  const auto deadline_after =
      std::chrono::microseconds(static_cast<int64_t>(full_ms * 100));
  grpc::ClientContext context;
  const auto deadline =
      std::chrono::system_clock::now() + deadline_after;  // 10% of it
  context.set_deadline(deadline);
  auto reader = server_->stub()->Search(&context, request);
  tpr::v1::SearchResponse response;
  while (reader->Read(&response)) {
  }
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  // Wait for the server's handler to end (it may finish its current EMD).
  const auto give_up =
      std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (server_->service()->search_counters().running > 0 &&
         std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const double stopped_after_ms =
      std::chrono::duration<double, std::milli>(
          std::chrono::system_clock::now() - deadline)
          .count();
  const IndexerService::SearchCounters after =
      server_->service()->search_counters();
  EXPECT_EQ(after.running, 0);
  const int64_t emds = after.emd_computations - before.emd_computations;
  // At 10% of the time, about 10% of the EMDs; half leaves room for a
  // loaded machine while still failing a search that runs on.
  EXPECT_LT(emds, full_emds / 2)
      << "of " << full_emds << " in " << full_ms << " ms";
  EXPECT_LT(stopped_after_ms, full_ms / 2)
      << "full search: " << full_ms << " ms";
  std::printf(
      "full search %.0f ms, %lld EMDs; deadline at %.0f ms: %lld EMDs, stopped "
      "%.1f ms "
      "after the deadline\n",
      full_ms, static_cast<long long>(full_emds), full_ms / 10,
      static_cast<long long>(emds), stopped_after_ms);
}

}  // namespace
}  // namespace tpr::indexer::testing
