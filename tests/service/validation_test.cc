// Requests are validated the same way wherever they arrive, through the
// real binaries on loopback: List page tokens are opaque and sealed (an id
// or a damaged token is INVALID_ARGUMENT naming page_token, at one
// tpr-indexer and at a tpr-gateway alike, and paging through either still
// lists every id once); tpr-extractor refuses an unknown format value and a
// header field (format, file_name, options, media) sent after the first
// message, naming the field; tpr-indexer refuses a signature whose band
// count differs from its models', for a write and for a search, naming
// options.bands.
#include <grpcpp/client_context.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "extractor/synth/synth.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"
#include "tpr/v1/extractor.pb.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::testing {
namespace {

using ::tpr::indexer::testing::MakeModels;
using ::tpr::indexer::testing::TestModel;
using ::tpr::indexer::testing::ToRequest;

std::unique_ptr<tpr::v1::Indexer::Stub> StubOf(const ServiceProcess& p) {
  return tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(p.address(), grpc::InsecureChannelCredentials()));
}

grpc::Status ListPage(tpr::v1::Indexer::Stub* stub, const std::string& token,
                      int page_size, tpr::v1::ListResponse* response) {
  grpc::ClientContext context;
  tpr::v1::ListRequest request;
  request.set_page_size(page_size);
  request.set_page_token(token);
  return stub->List(&context, request, response);
}

// Every id through List pages of `page_size`.
std::vector<std::string> ListAll(tpr::v1::Indexer::Stub* stub, int page_size) {
  std::vector<std::string> ids;
  std::string token;
  do {
    tpr::v1::ListResponse page;
    if (!ListPage(stub, token, page_size, &page).ok()) return {};
    for (const tpr::v1::Model& m : page.models()) ids.push_back(m.id());
    token = page.next_page_token();
  } while (!token.empty());
  return ids;
}

void ExpectInvalidNaming(const grpc::Status& status, const std::string& field,
                         const std::string& where) {
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
      << where << ": " << status.error_message();
  EXPECT_NE(status.error_message().find(field), std::string::npos)
      << where << ": " << status.error_message();
}

class ValidationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_FALSE(dir_.path().empty());
    for (int s = 0; s < 2; ++s) {
      ASSERT_TRUE(shards_[s]
                      .Start(BinaryPath("tpr-indexer"),
                             {"--data-dir", absl::StrCat(dir_.path(), "/d", s)},
                             absl::StrCat(dir_.path(), "/shard", s, ".log"))
                      .ok());
    }
    ASSERT_TRUE(gateway_
                    .Start(BinaryPath("tpr-gateway"),
                           {"--shard", shards_[0].address(), "--shard",
                            shards_[1].address()},
                           dir_.path() + "/gateway.log")
                    .ok());
    ASSERT_TRUE(single_
                    .Start(BinaryPath("tpr-indexer"),
                           {"--data-dir", dir_.path() + "/single"},
                           dir_.path() + "/single.log")
                    .ok());
    for (ServiceProcess* p : {&gateway_, &single_}) {
      auto stub = StubOf(*p);
      for (const TestModel& m : models_) {
        grpc::ClientContext context;
        tpr::v1::UpsertResponse response;
        ASSERT_TRUE(stub->Upsert(&context, ToRequest(m), &response).ok());
      }
    }
  }

  TempDir dir_;
  ServiceProcess shards_[2];
  ServiceProcess gateway_;
  ServiceProcess single_;
  const std::vector<TestModel> models_ = MakeModels(12, 3, 5);
};

TEST_F(ValidationTest, PageTokensAreSealedAtTheIndexerAndTheGateway) {
  std::vector<std::string> want;
  for (const TestModel& m : models_) want.push_back(m.id);
  for (ServiceProcess* p : {&single_, &gateway_}) {
    const std::string where = p == &single_ ? "indexer" : "gateway";
    auto stub = StubOf(*p);
    EXPECT_EQ(ListAll(stub.get(), 5), want) << where;
    tpr::v1::ListResponse page;
    ASSERT_TRUE(ListPage(stub.get(), "", 5, &page).ok());
    const std::string token = page.next_page_token();
    ASSERT_FALSE(token.empty());
    EXPECT_EQ(token.find(models_[4].id), std::string::npos)
        << where << ": the token shows the id";
    // An id, garbage, and the real token with one character changed.
    std::string damaged = token;
    damaged[damaged.size() / 2] =
        damaged[damaged.size() / 2] == 'A' ? 'B' : 'A';
    for (const std::string& bad :
         {models_[4].id, std::string("!!!"), damaged}) {
      tpr::v1::ListResponse response;
      ExpectInvalidNaming(ListPage(stub.get(), bad, 5, &response), "page_token",
                          where + " token '" + bad + "'");
    }
  }
  // Neither takes the other's token.
  tpr::v1::ListResponse from_indexer, from_gateway, response;
  ASSERT_TRUE(ListPage(StubOf(single_).get(), "", 5, &from_indexer).ok());
  ASSERT_TRUE(ListPage(StubOf(gateway_).get(), "", 5, &from_gateway).ok());
  ExpectInvalidNaming(ListPage(StubOf(gateway_).get(),
                               from_indexer.next_page_token(), 5, &response),
                      "page_token", "indexer token at the gateway");
  ExpectInvalidNaming(ListPage(StubOf(single_).get(),
                               from_gateway.next_page_token(), 5, &response),
                      "page_token", "gateway token at the indexer");
}

TEST_F(ValidationTest, SignaturesOfAnotherBandCountAreRefused) {
  // The stored models have 8 bands; these have 3.
  tpr::index::testing::SignatureGeneratorOptions o;
  o.features = 12;
  o.bands = 3;
  o.seed = 9;
  tpr::index::testing::SignatureGenerator gen(o);
  const TestModel three{"three-bands", "class0", gen.Member(0)};
  for (ServiceProcess* p : {&single_, &gateway_}) {
    const std::string where = p == &single_ ? "indexer" : "gateway";
    auto stub = StubOf(*p);
    {
      grpc::ClientContext context;
      tpr::v1::UpsertResponse response;
      ExpectInvalidNaming(stub->Upsert(&context, ToRequest(three), &response),
                          "options.bands is 3", where + " upsert");
    }
    {
      grpc::ClientContext context;
      tpr::v1::SearchRequest request;
      request.set_k(3);
      *request.mutable_signature() = indexer::testing::ToWire(three.signature);
      auto reader = stub->Search(&context, request);
      tpr::v1::SearchResponse response;
      while (reader->Read(&response)) {
      }
      ExpectInvalidNaming(reader->Finish(), "options.bands", where + " search");
    }
    grpc::ClientContext context;
    tpr::v1::GetRequest get;
    get.set_id(three.id);
    tpr::v1::Model model;
    EXPECT_EQ(stub->Get(&context, get, &model).error_code(),
              grpc::StatusCode::NOT_FOUND)
        << where;
  }
}

class ExtractorValidationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(extractor_
                    .Start(BinaryPath("tpr-extractor"), {"--threads", "1"},
                           dir_.path() + "/extractor.log")
                    .ok());
    synth::ShapeOptions options;
    options.target_vertices = 300;
    absl::StatusOr<extract::Mesh> mesh =
        synth::GenerateShape(synth::ClassNames()[0], 0, options);
    ASSERT_TRUE(mesh.ok());
    off_ = ToOff(*mesh);
  }

  // The upload of off_ in two messages, `first` and `second` completed
  // with the two halves of the bytes.
  grpc::Status Upload(tpr::v1::ExtractRequest first,
                      tpr::v1::ExtractRequest second) {
    first.set_data(off_.substr(0, off_.size() / 2));
    second.set_data(off_.substr(off_.size() / 2));
    auto channel = grpc::CreateChannel(extractor_.address(),
                                       grpc::InsecureChannelCredentials());
    return RawClientStream(
        channel, "/tpr.v1.Extractor/Extract",
        {first.SerializeAsString(), second.SerializeAsString()});
  }

  TempDir dir_;
  ServiceProcess extractor_;
  std::string off_;
};

TEST_F(ExtractorValidationTest, HeaderFieldsOnlyInTheFirstMessage) {
  tpr::v1::ExtractRequest header;
  header.set_file_name("shape.off");
  header.set_format(tpr::v1::MESH_FORMAT_OFF);
  EXPECT_TRUE(Upload(header, {}).ok());
  tpr::v1::ExtractRequest later;
  later.mutable_options()->set_bands(4);
  ExpectInvalidNaming(Upload(header, later), "options", "options later");
  later.Clear();
  later.set_file_name("other.off");
  ExpectInvalidNaming(Upload(header, later), "file_name", "file_name later");
  later.Clear();
  later.set_format(tpr::v1::MESH_FORMAT_OFF);
  ExpectInvalidNaming(Upload(header, later), "format", "format later");
  later.Clear();
  later.mutable_media()->set_thumbnail(true);
  ExpectInvalidNaming(Upload(header, later), "media", "media later");
}

TEST_F(ExtractorValidationTest, UnknownFormatValueIsRefused) {
  tpr::v1::ExtractRequest header;
  header.set_file_name("shape.off");
  header.set_format(static_cast<tpr::v1::MeshFormat>(77));
  ExpectInvalidNaming(Upload(header, {}), "format is 77", "format 77");
}

}  // namespace
}  // namespace tpr::testing
