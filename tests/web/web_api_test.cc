// tpr-web's API through the real binary, in front of a real tpr-extractor
// and tpr-indexer on loopback: every route, the errors the services and
// tpr-web itself give (as JSON with the gRPC code name and the mapped
// HTTP status), request ids, metrics, console files. The oracle of every
// answer is the same call made through gRPC with the SDK.
#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/grpc_status.h"
#include "tests/web/web_test_util.h"
#include "tpr/client.h"

namespace tpr::testing {
namespace {

using google::protobuf::Struct;

// An id with characters that need encoding in a URL path and query.
const char kOddId[] = "odd dir/name %2F?#&+ \xC3\xA9.off";

class WebApiTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    env_ = new Env();
    Env& e = *env_;
    ASSERT_TRUE(e.cluster.Start().ok());
    absl::StatusOr<std::vector<GeneratedFile>> files =
        GenerateSet(e.cluster.dir() + "/shapes", 4, 3, 1500);
    ASSERT_TRUE(files.ok()) << files.status();
    e.files = *files;
    auto extractor =
        client::ExtractorClient::Connect(e.cluster.extractor_addresses());
    auto indexer =
        client::IndexerClient::Connect(e.cluster.indexer().address());
    ASSERT_TRUE(extractor.ok() && indexer.ok());
    e.indexer = std::make_unique<client::IndexerClient>(*indexer);
    e.extractor = std::make_unique<client::ExtractorClient>(*extractor);
    for (const GeneratedFile& f : e.files) {
      absl::StatusOr<v1::ExtractResponse> r =
          extractor->ExtractBytes(f.off, f.relative_path);
      ASSERT_TRUE(r.ok()) << r.status();
      v1::Model model;
      model.set_id(f.relative_path);
      model.set_label(f.label);
      *model.mutable_signature() = r->signature();
      ASSERT_TRUE(indexer->Upsert(model, true).ok());
      if (&f == &e.files[0]) {
        model.set_id(kOddId);
        ASSERT_TRUE(indexer->Upsert(model, true).ok());
      }
    }
    ASSERT_TRUE(
        StartWeb(&e.web, e.cluster.dir(), "web",
                 {"--extractor", e.cluster.extractor_addresses(), "--indexer",
                  e.cluster.indexer().address(), "--max-upload-bytes",
                  "2000000", "--metrics-listen", "127.0.0.1:0"})
            .ok());
  }
  static void TearDownTestSuite() {
    delete env_;
    env_ = nullptr;
  }

  void SetUp() override {
    ASSERT_NE(env_, nullptr);
    ASSERT_GT(env_->web.port(), 0);
  }

  static httplib::Client Client() {
    httplib::Client c("127.0.0.1", env_->web.port());
    c.set_read_timeout(120, 0);
    return c;
  }

  // Search through gRPC: the oracle of the API's answers.
  static std::vector<v1::Neighbor> GrpcSearch(const v1::SearchRequest& r) {
    std::vector<v1::Neighbor> out;
    std::unique_ptr<client::SearchStream> stream = env_->indexer->Search(r);
    for (v1::Neighbor n; stream->Next(&n);) out.push_back(n);
    EXPECT_TRUE(stream->Finish().ok());
    return out;
  }

  static void ExpectSameNeighbors(const Struct& reply,
                                  const std::vector<v1::Neighbor>& expected) {
    const auto& got = Field(reply, "neighbors").list_value().values();
    ASSERT_EQ(got.size(), static_cast<int>(expected.size()));
    for (int i = 0; i < got.size(); ++i) {
      const Struct& n = got[i].struct_value();
      EXPECT_EQ(Field(n, "id").string_value(), expected[i].id());
      EXPECT_EQ(Field(n, "label").string_value(), expected[i].label());
      EXPECT_EQ(Field(n, "rank").number_value(), expected[i].rank());
      EXPECT_DOUBLE_EQ(Field(n, "distance").number_value(),
                       expected[i].distance());
    }
  }

  struct Env {
    Cluster cluster;
    std::vector<GeneratedFile> files;
    std::unique_ptr<client::ExtractorClient> extractor;
    std::unique_ptr<client::IndexerClient> indexer;
    ServiceProcess web;
  };
  static Env* env_;
};

WebApiTest::Env* WebApiTest::env_ = nullptr;

TEST_F(WebApiTest, SearchByIdMatchesGrpc) {
  for (const char* intent : {"", "balanced", "identity", "kind"}) {
    const GeneratedFile& f = env_->files[4];
    httplib::Result r = Client().Get(
        absl::StrCat("/api/v1/search?k=5&id=", UrlEncode(f.relative_path),
                     *intent ? "&intent=" : "", intent));
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 200) << r->body;
    EXPECT_EQ(r->get_header_value("Content-Type"),
              "application/json; charset=utf-8");
    v1::SearchRequest q;
    q.set_id(f.relative_path);
    q.set_k(5);
    if (*intent) {
      v1::Intent value = v1::INTENT_UNSPECIFIED;
      ASSERT_TRUE(v1::Intent_Parse(
          absl::StrCat("INTENT_", absl::AsciiStrToUpper(intent)), &value));
      q.set_intent(value);
    }
    const Struct reply = ParseJson(r->body);
    ExpectSameNeighbors(reply, GrpcSearch(q));
    EXPECT_GT(Field(Field(reply, "stats").struct_value(), "emdComputations")
                  .string_value()
                  .size(),
              0u);
  }
}

TEST_F(WebApiTest, SearchFiltersByLabelAndExcludesSelf) {
  const GeneratedFile& f = env_->files[0];
  const std::string other = env_->files.back().label;
  httplib::Result r = Client().Get(
      absl::StrCat("/api/v1/search?k=50&exclude_self=true&label=", other,
                   "&id=", UrlEncode(f.relative_path)));
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  v1::SearchRequest q;
  q.set_id(f.relative_path);
  q.set_k(50);
  q.set_label(other);
  q.set_exclude_self(true);
  const std::vector<v1::Neighbor> expected = GrpcSearch(q);
  ASSERT_EQ(expected.size(), 3u);  // The three poses of that class.
  ExpectSameNeighbors(ParseJson(r->body), expected);
}

TEST_F(WebApiTest, SearchByUploadFindsTheSameMeshAtDistanceZero) {
  const GeneratedFile& f = env_->files[7];
  // Multipart, as the console sends it, with the explanation.
  httplib::MultipartFormDataItems form = {
      {"mesh", f.off, "query.off", "application/octet-stream"},
      {"k", "4", "", ""}};
  httplib::Result r = Client().Post("/api/v1/search?explain=1", form);
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  const Struct reply = ParseJson(r->body);
  const auto& neighbors = Field(reply, "neighbors").list_value().values();
  ASSERT_EQ(neighbors.size(), 4);
  EXPECT_EQ(Field(neighbors[0].struct_value(), "id").string_value(),
            f.relative_path);
  EXPECT_EQ(Field(neighbors[0].struct_value(), "distance").number_value(), 0);
  // The query's own signature and explanation, one placement per feature.
  const Struct& query = Field(reply, "query").struct_value();
  const auto& features =
      Field(Field(query, "signature").struct_value(), "features")
          .list_value()
          .values();
  const auto& placed =
      Field(Field(query, "explanation").struct_value(), "featureVertices")
          .list_value()
          .values();
  ASSERT_GT(features.size(), 0);
  EXPECT_EQ(placed.size(), features.size());
  // Same answer as gRPC with the signature the extractor gives.
  absl::StatusOr<v1::ExtractResponse> extracted =
      env_->extractor->ExtractBytes(f.off, "query.off");
  ASSERT_TRUE(extracted.ok());
  v1::SearchRequest q;
  *q.mutable_signature() = extracted->signature();
  q.set_k(4);
  ExpectSameNeighbors(reply, GrpcSearch(q));

  // The raw file as the body, named by ?file_name=.
  r = Client().Post("/api/v1/search?k=4&file_name=q.off", f.off,
                    "application/octet-stream");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  ExpectSameNeighbors(ParseJson(r->body), GrpcSearch(q));
}

TEST_F(WebApiTest, SearchAcceptsASearchRequestAsJson) {
  const GeneratedFile& f = env_->files[2];
  httplib::Result r =
      Client().Post("/api/v1/search",
                    absl::StrCat("{\"id\":\"", f.relative_path, "\",\"k\":3}"),
                    "application/json");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  v1::SearchRequest q;
  q.set_id(f.relative_path);
  q.set_k(3);
  ExpectSameNeighbors(ParseJson(r->body), GrpcSearch(q));
  r = Client().Post("/api/v1/search", "{\"k\":\"many\"}", "application/json");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 400);
  EXPECT_EQ(ErrorCode(r->body), "INVALID_ARGUMENT");
}

TEST_F(WebApiTest, GetModelDecodesAnyIdCharacters) {
  for (const std::string& id :
       {std::string(kOddId), env_->files[1].relative_path}) {
    httplib::Result r =
        Client().Get(absl::StrCat("/api/v1/models/", UrlEncode(id)));
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 200) << r->body;
    absl::StatusOr<v1::Model> expected = env_->indexer->Get(id);
    ASSERT_TRUE(expected.ok());
    v1::Model got;
    ASSERT_TRUE(
        google::protobuf::util::JsonStringToMessage(r->body, &got).ok());
    EXPECT_EQ(got.id(), id);
    EXPECT_EQ(got.SerializeAsString(), expected->SerializeAsString());
  }
  // The odd id also works as a search query parameter.
  httplib::Result r =
      Client().Get(absl::StrCat("/api/v1/search?k=1&id=", UrlEncode(kOddId)));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200) << r->body;
}

TEST_F(WebApiTest, ListPagesAndFiltersByLabel) {
  std::vector<std::string> got;
  std::string token;
  int pages = 0;
  do {
    httplib::Result r = Client().Get(absl::StrCat(
        "/api/v1/models?page_size=5&page_token=", UrlEncode(token)));
    ASSERT_TRUE(r);
    ASSERT_EQ(r->status, 200) << r->body;
    v1::ListResponse page;
    ASSERT_TRUE(
        google::protobuf::util::JsonStringToMessage(r->body, &page).ok());
    EXPECT_LE(page.models_size(), 5);
    for (const v1::Model& m : page.models()) got.push_back(m.id());
    token = page.next_page_token();
    ++pages;
  } while (!token.empty() && pages < 100);
  absl::StatusOr<std::vector<v1::Model>> all = env_->indexer->ListAll();
  ASSERT_TRUE(all.ok());
  std::vector<std::string> expected;
  for (const v1::Model& m : *all) expected.push_back(m.id());
  EXPECT_EQ(got, expected);
  EXPECT_GE(pages, 3);

  const std::string label = env_->files[3].label;
  httplib::Result r = Client().Get("/api/v1/models?label=" + label);
  ASSERT_TRUE(r);
  v1::ListResponse page;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(r->body, &page).ok());
  absl::StatusOr<std::vector<v1::Model>> labelled =
      env_->indexer->ListAll(label);
  ASSERT_TRUE(labelled.ok());
  EXPECT_EQ(page.models_size(), static_cast<int>(labelled->size()));
  for (const v1::Model& m : page.models()) EXPECT_EQ(m.label(), label);
}

TEST_F(WebApiTest, StatsAndStatus) {
  httplib::Result r = Client().Get("/api/v1/stats");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  v1::StatsResponse stats;
  ASSERT_TRUE(
      google::protobuf::util::JsonStringToMessage(r->body, &stats).ok());
  absl::StatusOr<v1::StatsResponse> expected = env_->indexer->Stats();
  ASSERT_TRUE(expected.ok());
  EXPECT_EQ(stats.models(), expected->models());
  EXPECT_EQ(stats.models(), static_cast<int64_t>(env_->files.size() + 1));
  EXPECT_EQ(stats.labels().size(), expected->labels().size());

  ASSERT_TRUE(Client().Get("/api/v1/search?k=2&id=" +
                           UrlEncode(env_->files[0].relative_path)));
  r = Client().Get("/api/v1/status");
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 200) << r->body;
  const Struct status = ParseJson(r->body);
  for (const char* service : {"extractor", "indexer"}) {
    const Struct& s = Field(status, service).struct_value();
    EXPECT_TRUE(Field(s, "ready").bool_value()) << service;
    EXPECT_EQ(Field(s, "reason").string_value(), "");
  }
  EXPECT_EQ(
      Field(Field(status, "indexer").struct_value(), "address").string_value(),
      env_->cluster.indexer().address());
  const Struct& searches = Field(status, "searches").struct_value();
  EXPECT_GE(Field(searches, "total").number_value(), 1);
  EXPECT_GT(Field(searches, "indexerP50Ms").number_value(), 0);
  EXPECT_EQ(
      Field(Field(status, "stats").struct_value(), "models").string_value(),
      absl::StrCat(expected->models()));
}

// Thumbnails and previews answer what the indexer's GetThumbnail and
// GetPreview answer: the bytes, or its error code as JSON.
TEST_F(WebApiTest, ThumbnailsAndPreviewsPassTheIndexerAnswerThrough) {
  auto channel = client::MakeChannel(env_->cluster.indexer().address());
  ASSERT_TRUE(channel.ok());
  std::unique_ptr<v1::Indexer::Stub> stub = v1::Indexer::NewStub(*channel);
  for (const std::string& id :
       {env_->files[0].relative_path, std::string(kOddId)}) {
    grpc::ClientContext context;
    v1::GetThumbnailRequest request;
    request.set_id(id);
    v1::Thumbnail thumbnail;
    const grpc::Status s = stub->GetThumbnail(&context, request, &thumbnail);
    httplib::Result r =
        Client().Get(absl::StrCat("/api/v1/thumbnails/", UrlEncode(id)));
    ASSERT_TRUE(r);
    if (s.ok()) {
      EXPECT_EQ(r->status, 200);
      EXPECT_EQ(r->get_header_value("Content-Type"), "image/png");
      EXPECT_EQ(r->body, thumbnail.png());
    } else {
      const absl::Status a = common::FromGrpcStatus(s);
      EXPECT_EQ(ErrorCode(r->body), absl::StatusCodeToString(a.code()))
          << r->body;
      const std::string message =
          Field(ParseJson(r->body), "message").string_value();
      if (s.error_message().empty()) {
        EXPECT_TRUE(absl::StrContains(message, "/tpr.v1.Indexer/GetThumbnail"))
            << message;
      } else {
        EXPECT_EQ(message, s.error_message());
      }
      EXPECT_GE(r->status, 400);
    }
    grpc::ClientContext preview_context;
    v1::GetPreviewRequest preview_request;
    preview_request.set_id(id);
    auto reader = stub->GetPreview(&preview_context, preview_request);
    std::string ply;
    for (v1::PreviewChunk chunk; reader->Read(&chunk);) ply += chunk.data();
    const grpc::Status ps = reader->Finish();
    r = Client().Get(absl::StrCat("/api/v1/previews/", UrlEncode(id)));
    ASSERT_TRUE(r);
    if (ps.ok()) {
      EXPECT_EQ(r->status, 200);
      EXPECT_EQ(r->body, ply);
      EXPECT_TRUE(absl::StartsWith(r->body, "ply\n"));
    } else {
      EXPECT_EQ(ErrorCode(r->body),
                absl::StatusCodeToString(common::FromGrpcStatus(ps).code()));
    }
  }
  // An unknown id is NOT_FOUND whether or not media is served.
  httplib::Result r = Client().Get("/api/v1/thumbnails/no-such-model.off");
  ASSERT_TRUE(r);
  EXPECT_TRUE(r->status == 404 || r->status == 501) << r->body;
}

TEST_F(WebApiTest, AddAndDeleteModel) {
  const GeneratedFile& f = env_->files[5];
  httplib::MultipartFormDataItems form = {
      {"mesh", f.off, "added.off", "application/octet-stream"},
      {"id", "added/one.off", "", ""},
      {"label", "added", "", ""}};
  httplib::Result r = Client().Post("/api/v1/models", form);
  ASSERT_TRUE(r);
  ASSERT_EQ(r->status, 201) << r->body;
  absl::StatusOr<v1::Model> stored = env_->indexer->Get("added/one.off");
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->label(), "added");
  // Again without overwrite: the indexer's ALREADY_EXISTS, as 409.
  r = Client().Post("/api/v1/models", form);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 409);
  EXPECT_EQ(ErrorCode(r->body), "ALREADY_EXISTS");
  r = Client().Post("/api/v1/models?overwrite=1", form);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200) << r->body;
  r = Client().Delete("/api/v1/models/" + UrlEncode("added/one.off"));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200) << r->body;
  EXPECT_TRUE(absl::IsNotFound(env_->indexer->Get("added/one.off").status()));
  r = Client().Delete("/api/v1/models/" + UrlEncode("added/one.off"));
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 404);
  EXPECT_EQ(ErrorCode(r->body), "NOT_FOUND");
}

// Each error: the HTTP status, the code name, and a message naming the
// problem.
TEST_F(WebApiTest, ErrorsAreJsonWithCodeAndMessage) {
  struct Case {
    std::string method, path, body, content_type;
    int http;
    std::string code, message_part;
  };
  const std::string id = UrlEncode(env_->files[0].relative_path);
  const std::vector<Case> cases = {
      {"GET", "/api/v1/models/no%20such.off", "", "", 404, "NOT_FOUND",
       "no such.off"},
      {"GET", "/api/v1/search?id=no-such.off", "", "", 404, "NOT_FOUND",
       "no-such.off"},
      {"GET", "/api/v1/search?k=0&id=" + id, "", "", 400, "INVALID_ARGUMENT",
       "k:"},
      {"GET", "/api/v1/search?k=ten&id=" + id, "", "", 400, "INVALID_ARGUMENT",
       "k:"},
      {"GET", "/api/v1/search?radius=-1&id=" + id, "", "", 400,
       "INVALID_ARGUMENT", "radius"},
      {"GET", "/api/v1/search?intent=pose&id=" + id, "", "", 400,
       "INVALID_ARGUMENT", "intent"},
      {"GET", "/api/v1/search?exclude_self=maybe&id=" + id, "", "", 400,
       "INVALID_ARGUMENT", "exclude_self"},
      {"GET", "/api/v1/search", "", "", 400, "INVALID_ARGUMENT", "id"},
      {"GET", "/api/v1/models?page_size=0", "", "", 400, "INVALID_ARGUMENT",
       "page_size"},
      {"POST", "/api/v1/search", "", "application/octet-stream", 400,
       "INVALID_ARGUMENT", "no mesh"},
      {"POST", "/api/v1/search?file_name=bad.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n",
       "application/octet-stream", 400, "INVALID_ARGUMENT", ""},
      {"POST", "/api/v1/search?format=dwg", "x", "application/octet-stream",
       400, "INVALID_ARGUMENT", "format"},
      {"POST", "/api/v1/search", std::string(2100000, 'x'),
       "application/octet-stream", 413, "RESOURCE_EXHAUSTED",
       "--max-upload-bytes"},
      {"POST", "/api/v1/models?file_name=a.off", "OFF\n",
       "application/octet-stream", 400, "INVALID_ARGUMENT", "id"},
      {"GET", "/api/v1/nothing-here", "", "", 404, "NOT_FOUND", "no route"},
  };
  for (const Case& c : cases) {
    httplib::Result r =
        c.method == "GET"
            ? Client().Get(c.path)
            : Client().Post(c.path, c.body, c.content_type.c_str());
    ASSERT_TRUE(r) << c.path;
    EXPECT_EQ(r->status, c.http)
        << c.method << " " << c.path << ": " << r->body;
    EXPECT_EQ(r->get_header_value("Content-Type"),
              "application/json; charset=utf-8")
        << c.path;
    EXPECT_EQ(ErrorCode(r->body), c.code) << c.path << ": " << r->body;
    const std::string message =
        Field(ParseJson(r->body), "message").string_value();
    EXPECT_FALSE(message.empty()) << c.path;
    EXPECT_TRUE(absl::StrContains(message, c.message_part))
        << c.path << ": " << message;
  }
}

TEST_F(WebApiTest, RequestIdsAreKeptOrMade) {
  httplib::Result r =
      Client().Get("/api/v1/stats", {{"X-Request-Id", "test-request-42"}});
  ASSERT_TRUE(r);
  EXPECT_EQ(r->get_header_value("X-Request-Id"), "test-request-42");
  r = Client().Get("/api/v1/stats", {{"X-Request-Id", "bad id\nwith newline"}});
  ASSERT_TRUE(r);
  const std::string made = r->get_header_value("X-Request-Id");
  EXPECT_EQ(made.size(), 16u);
  EXPECT_NE(made, "bad id\nwith newline");
  // The id reached the indexer: its log line carries it.
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_TRUE(absl::StrContains(ReadText(env_->cluster.indexer().log_path()),
                                "request_id=test-request-42"));
}

TEST_F(WebApiTest, HealthReadinessMetricsAndConsole) {
  httplib::Result r = Client().Get("/healthz");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  r = Client().Get("/readyz");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200) << r->body;
  r = Client().Get("/");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_TRUE(
      absl::StartsWith(r->get_header_value("Content-Type"), "text/html"));
#ifdef TPR_CONSOLE_BUILT
  EXPECT_TRUE(absl::StrContains(r->body, "<title>TPR Search</title>"))
      << r->body;
  // Its script, gzip-compressed when asked for (httplib's client inflates
  // it again), identical either way.
  const size_t src = r->body.find("src=\"/assets/");
  ASSERT_NE(src, std::string::npos);
  const std::string asset =
      r->body.substr(src + 5, r->body.find('"', src + 5) - src - 5);
  httplib::Client plain("127.0.0.1", env_->web.port());
  httplib::Result raw = plain.Get(asset, {{"Accept-Encoding", "identity"}});
  ASSERT_TRUE(raw);
  EXPECT_EQ(raw->status, 200);
  EXPECT_EQ(raw->get_header_value("Content-Encoding"), "");
  EXPECT_EQ(raw->get_header_value("Content-Type"),
            "application/javascript; charset=utf-8");
  httplib::Client gzip("127.0.0.1", env_->web.port());
  gzip.set_decompress(true);
  httplib::Result zipped = gzip.Get(asset, {{"Accept-Encoding", "gzip"}});
  ASSERT_TRUE(zipped);
  EXPECT_EQ(zipped->get_header_value("Content-Encoding"), "gzip");
  EXPECT_EQ(zipped->body, raw->body);
  EXPECT_GT(raw->body.size(), 100000u);
  r = Client().Get("/assets/no-such-file.js");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 404);
  EXPECT_EQ(ErrorCode(r->body), "NOT_FOUND");
#endif
  ASSERT_TRUE(Client().Get("/api/v1/stats"));
  const std::string log = ReadText(env_->web.log_path());
  const size_t at = log.find("metrics: http://127.0.0.1:");
  ASSERT_NE(at, std::string::npos) << log;
  const int port = std::atoi(log.c_str() + at + 26);
  httplib::Client metrics("127.0.0.1", port);
  r = metrics.Get("/metrics");
  ASSERT_TRUE(r);
  EXPECT_TRUE(absl::StrContains(
      r->body,
      "tpr_http_requests_total{route=\"GET /api/v1/stats\",status=\"200\"}"))
      << r->body;
  EXPECT_TRUE(absl::StrContains(
      r->body,
      "tpr_http_request_duration_seconds_count{route=\"GET /api/v1/stats\"}"));
}

// Services that are down or slow: UNAVAILABLE (503) and DEADLINE_EXCEEDED
// (504), and /readyz says which service.
TEST(WebBackendsTest, DownAndSlowServices) {
  TempDir dir;
  ServiceProcess web;
  const std::string dead = absl::StrCat("127.0.0.1:", FreePort());
  ASSERT_TRUE(
      StartWeb(&web, dir.path(), "web",
               {"--extractor", dead, "--indexer", dead, "--timeout", "2"})
          .ok());
  httplib::Client c("127.0.0.1", web.port());
  httplib::Result r = c.Get("/api/v1/stats");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503);
  EXPECT_EQ(ErrorCode(r->body), "UNAVAILABLE");
  r = c.Post("/api/v1/search?file_name=a.off", "OFF\n",
             "application/octet-stream");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503);
  EXPECT_EQ(ErrorCode(r->body), "UNAVAILABLE");
  r = c.Get("/readyz");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 503);
  EXPECT_TRUE(absl::StrContains(r->body, "extractor " + dead)) << r->body;
  r = c.Get("/api/v1/status");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  const Struct status = ParseJson(r->body);
  EXPECT_FALSE(
      Field(Field(status, "indexer").struct_value(), "ready").bool_value());
  EXPECT_EQ(
      Field(Field(status, "statsError").struct_value(), "code").string_value(),
      "UNAVAILABLE");

  // A deadline shorter than any extraction of a 20k-vertex mesh.
  Cluster cluster;
  ASSERT_TRUE(cluster.Start().ok());
  ServiceProcess slow;
  ASSERT_TRUE(
      StartWeb(&slow, dir.path(), "slow",
               {"--extractor", cluster.extractor_addresses(), "--indexer",
                cluster.indexer().address(), "--timeout", "0.005"})
          .ok());
  synth::ShapeOptions options;
  options.target_vertices = 20000;
  absl::StatusOr<extract::Mesh> mesh =
      synth::GenerateShape(synth::ClassNames()[0], 0, options);
  ASSERT_TRUE(mesh.ok());
  httplib::Client s("127.0.0.1", slow.port());
  s.set_read_timeout(60, 0);
  r = s.Post("/api/v1/search?file_name=big.off", ToOff(*mesh),
             "application/octet-stream");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 504) << r->body;
  EXPECT_EQ(ErrorCode(r->body), "DEADLINE_EXCEEDED");
  // SIGTERM: stops accepting, finishes, exits 0.
  EXPECT_EQ(slow.Stop(SIGTERM), 0);
  EXPECT_TRUE(absl::StrContains(ReadText(slow.log_path()), "stopped"));
}

// The indexer's RESOURCE_EXHAUSTED (k above its --max-k) is 429.
TEST(WebBackendsTest, IndexerLimitIsTooManyRequests) {
  TempDir dir;
  ServiceProcess indexer;
  ASSERT_TRUE(indexer
                  .Start(BinaryPath("tpr-indexer"),
                         {"--data-dir", dir.path() + "/data", "--max-k", "5"},
                         dir.path() + "/indexer.log")
                  .ok());
  ServiceProcess web;
  ASSERT_TRUE(StartWeb(&web, dir.path(), "web",
                       {"--extractor", indexer.address(), "--indexer",
                        indexer.address()})
                  .ok());
  httplib::Client c("127.0.0.1", web.port());
  httplib::Result r =
      c.Post("/api/v1/search", "{\"id\":\"x\",\"k\":6}", "application/json");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 429) << r->body;
  EXPECT_EQ(ErrorCode(r->body), "RESOURCE_EXHAUSTED");
  // The extractor route against a server without that service.
  r = c.Post("/api/v1/search?file_name=a.off", "OFF\n",
             "application/octet-stream");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 501) << r->body;
  EXPECT_EQ(ErrorCode(r->body), "UNIMPLEMENTED");
}

}  // namespace
}  // namespace tpr::testing
