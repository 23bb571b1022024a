// Thumbnails and previews through the services, on loopback: the extractor
// returns exactly what the library makes from the same bytes (the oracle:
// thumbnail.h and preview.h called here), and the indexer stores what it
// is given and gives it back byte for byte, apart from the model (Get and
// List never carry the bytes), through restarts, replacements and deletes,
// with NOT_FOUND naming what is missing; GetPreview in 64 KiB chunks; the
// gateway routes both calls to the id's shard.
#include <grpcpp/client_context.h>
#include <grpcpp/create_channel.h>
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "common/server_lifecycle.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/lib/preview.h"
#include "extractor/lib/thumbnail.h"
#include "extractor/service/extractor_service.h"
#include "extractor/synth/synth.h"
#include "indexer/gateway/gateway_service.h"
#include "indexer/gateway/shard_map.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"
#include "tpr/client.h"

namespace tpr {
namespace {

using ::tpr::indexer::testing::InProcessIndexer;
using ::tpr::indexer::testing::MakeModels;
using ::tpr::indexer::testing::TestModel;
using ::tpr::indexer::testing::ToRequest;
using ::tpr::testing::TempDir;
using ::tpr::testing::ToOff;

std::string BodyOff(int vertices) {
  synth::ShapeOptions options;
  options.target_vertices = vertices;
  absl::StatusOr<extract::Mesh> mesh =
      synth::GenerateShape("quadruped_slender", 2, options);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? ToOff(*mesh) : std::string();
}

// A well-formed-looking pair of media: a PNG signature and a PLY header
// followed by `ply_bytes` of filler (the indexer stores bytes; it checks
// only that each starts as its format does).
v1::ModelMedia FakeMedia(size_t ply_bytes, char fill) {
  v1::ModelMedia media;
  media.set_thumbnail_png(std::string("\x89PNG\r\n\x1a\n", 8) +
                          std::string(300, fill));
  media.set_preview_ply("ply\n" + std::string(ply_bytes, fill));
  return media;
}

class ExtractorMediaTest : public ::testing::Test {
 protected:
  void SetUp() override {
    service_ = std::make_unique<extractor::ExtractorService>(
        extractor::ServiceOptions{});
    common::ServerOptions server_options;
    server_options.listen_address = "127.0.0.1:0";
    absl::StatusOr<common::StartedServer> started =
        common::StartServer(server_options, {service_.get()});
    ASSERT_TRUE(started.ok()) << started.status();
    server_ = std::move(started->server);
    absl::StatusOr<client::ExtractorClient> c =
        client::ExtractorClient::Connect(
            absl::StrCat("127.0.0.1:", started->port));
    ASSERT_TRUE(c.ok()) << c.status();
    client_ = std::make_unique<client::ExtractorClient>(*c);
  }
  void TearDown() override {
    if (server_) {
      server_->Shutdown(std::chrono::system_clock::now() +
                        std::chrono::seconds(5));
      server_->Wait();
    }
  }

  std::unique_ptr<extractor::ExtractorService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<client::ExtractorClient> client_;
};

TEST_F(ExtractorMediaTest, ReturnsTheLibrarysPicturesAndTheSameSignature) {
  const std::string off = BodyOff(8000);
  ASSERT_FALSE(off.empty());
  v1::MediaOptions media;
  media.set_thumbnail(true);
  media.set_thumbnail_overlay(true);
  media.set_preview(true);
  absl::StatusOr<v1::ExtractResponse> with =
      client_->ExtractBytes(off, "body.off", {}, media);
  ASSERT_TRUE(with.ok()) << with.status();
  absl::StatusOr<v1::ExtractResponse> without =
      client_->ExtractBytes(off, "body.off", {});
  ASSERT_TRUE(without.ok()) << without.status();

  // The oracle: the library on the same bytes.
  absl::StatusOr<extract::LoadedMesh> loaded = extract::LoadMeshFromBuffer(
      off, extract::MeshFormat::kOff, "body.off", {});
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  extract::Options options;
  options.explain = true;
  absl::StatusOr<extract::ExtractResult> result =
      extract::ExtractSignature(loaded->mesh, loaded->stats, options);
  ASSERT_TRUE(result.ok()) << result.status();
  absl::StatusOr<std::string> png = extract::RenderThumbnailPng(
      loaded->mesh,
      extract::OverlayFromExplanation(result->signature, *result->explanation),
      {});
  absl::StatusOr<std::string> ply =
      extract::MakePreviewPly(loaded->mesh, extract::PreviewOptions{});
  ASSERT_TRUE(png.ok() && ply.ok());
  EXPECT_EQ(with->media().thumbnail_png(), *png);
  EXPECT_EQ(with->media().preview_ply(), *ply);

  // Pictures never change the signature, and the overlay's explanation is
  // neither recorded in the options nor returned.
  EXPECT_EQ(with->signature().SerializeAsString(),
            without->signature().SerializeAsString());
  EXPECT_FALSE(with->signature().options().explain());
  EXPECT_FALSE(with->has_explanation());
  EXPECT_FALSE(without->has_media());

  // Without the overlay: the picture of the bare surface.
  media.set_thumbnail_overlay(false);
  media.set_preview(false);
  absl::StatusOr<v1::ExtractResponse> plain =
      client_->ExtractBytes(off, "body.off", {}, media);
  ASSERT_TRUE(plain.ok()) << plain.status();
  EXPECT_EQ(plain->media().thumbnail_png(),
            *extract::RenderThumbnailPng(loaded->mesh, {}, {}));
  EXPECT_TRUE(plain->media().preview_ply().empty());
}

TEST_F(ExtractorMediaTest, ExplanationCarriesFeaturePositions) {
  const std::string off = BodyOff(3000);
  absl::StatusOr<extract::LoadedMesh> loaded = extract::LoadMeshFromBuffer(
      off, extract::MeshFormat::kOff, "body.off", {});
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  v1::ExtractOptions options;
  options.set_explain(true);
  absl::StatusOr<v1::ExtractResponse> r =
      client_->ExtractBytes(off, "body.off", options);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_GT(r->explanation().feature_vertices_size(), 0);
  for (const auto& f : r->explanation().feature_vertices()) {
    ASSERT_EQ(f.positions_size(), 3 * f.vertices_size());
    for (int i = 0; i < f.vertices_size(); ++i) {
      const Eigen::Vector3d& p = loaded->mesh.positions[f.vertices(i)];
      for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(f.positions(3 * i + c), static_cast<float>(p[c]));
      }
    }
  }
}

class IndexerMediaTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = std::make_unique<InProcessIndexer>(dir_.path() + "/index");
    ASSERT_TRUE(server_->Start().ok());
    Connect();
    models_ = MakeModels(4, 2, 5);
  }
  void Connect() {
    absl::StatusOr<client::IndexerClient> c =
        client::IndexerClient::Connect(server_->address());
    ASSERT_TRUE(c.ok()) << c.status();
    client_ = std::make_unique<client::IndexerClient>(*c);
  }
  absl::Status Put(const TestModel& m, const v1::ModelMedia* media) {
    v1::UpsertRequest request = ToRequest(m, true);
    if (media != nullptr) *request.mutable_model()->mutable_media() = *media;
    return client_->Upsert(request.model(), true).status();
  }

  TempDir dir_;
  std::unique_ptr<InProcessIndexer> server_;
  std::unique_ptr<client::IndexerClient> client_;
  std::vector<TestModel> models_;
};

TEST_F(IndexerMediaTest, StoredApartAndReturnedByteForByte) {
  // 200 KiB of preview: four chunks.
  const v1::ModelMedia media = FakeMedia(200 << 10, 'a');
  ASSERT_TRUE(Put(models_[0], &media).ok());
  ASSERT_TRUE(Put(models_[1], nullptr).ok());

  absl::StatusOr<v1::Model> got = client_->Get(models_[0].id);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_TRUE(got->media_stored());
  EXPECT_FALSE(got->has_media());
  EXPECT_FALSE(client_->Get(models_[1].id)->media_stored());
  absl::StatusOr<v1::ListResponse> page = client_->List({});
  ASSERT_TRUE(page.ok());
  ASSERT_EQ(page->models_size(), 2);
  EXPECT_TRUE(page->models(0).media_stored());
  EXPECT_FALSE(page->models(0).has_media());
  EXPECT_FALSE(page->models(1).media_stored());

  EXPECT_EQ(*client_->GetThumbnail(models_[0].id), media.thumbnail_png());
  EXPECT_EQ(*client_->GetPreview(models_[0].id), media.preview_ply());

  // The raw stream: 64 KiB chunks, the size announced on the first only.
  grpc::ClientContext context;
  v1::GetPreviewRequest request;
  request.set_id(models_[0].id);
  auto reader = server_->stub()->GetPreview(&context, request);
  std::vector<v1::PreviewChunk> chunks;
  for (v1::PreviewChunk c; reader->Read(&c);) chunks.push_back(c);
  ASSERT_TRUE(reader->Finish().ok());
  const size_t total = media.preview_ply().size();
  ASSERT_EQ(chunks.size(), (total + (64 << 10) - 1) / (64 << 10));
  EXPECT_EQ(chunks[0].total_bytes(), static_cast<int64_t>(total));
  for (size_t i = 0; i < chunks.size(); ++i) {
    EXPECT_EQ(chunks[i].data().size(),
              i + 1 < chunks.size() ? size_t{64 << 10}
                                    : total - (chunks.size() - 1) * (64 << 10));
    if (i > 0) {
      EXPECT_EQ(chunks[i].total_bytes(), 0);
    }
  }

  // Kept across a restart.
  server_->Stop();
  ASSERT_TRUE(server_->Start().ok());
  Connect();
  EXPECT_EQ(*client_->GetPreview(models_[0].id), media.preview_ply());
  EXPECT_TRUE(client_->Get(models_[0].id)->media_stored());
}

TEST_F(IndexerMediaTest, NotFoundSaysWhichAndNamesTheUpdate) {
  ASSERT_TRUE(Put(models_[0], nullptr).ok());
  absl::StatusOr<std::string> unknown = client_->GetThumbnail("no/such/id");
  EXPECT_TRUE(absl::IsNotFound(unknown.status())) << unknown.status();
  EXPECT_NE(unknown.status().message().find("no model with id 'no/such/id'"),
            std::string::npos)
      << unknown.status();
  for (bool thumbnail : {true, false}) {
    absl::StatusOr<std::string> none =
        thumbnail ? client_->GetThumbnail(models_[0].id)
                  : client_->GetPreview(models_[0].id);
    EXPECT_TRUE(absl::IsNotFound(none.status())) << none.status();
    EXPECT_NE(none.status().message().find(thumbnail ? "has no thumbnail"
                                                     : "has no preview"),
              std::string::npos)
        << none.status();
    EXPECT_NE(none.status().message().find("tpr add --update"),
              std::string::npos)
        << none.status();
  }
  EXPECT_TRUE(absl::IsNotFound(client_->GetPreview("no/such/id").status()));
  // A thumbnail alone: the preview is still missing.
  v1::ModelMedia only_thumbnail = FakeMedia(10, 'b');
  only_thumbnail.clear_preview_ply();
  ASSERT_TRUE(Put(models_[1], &only_thumbnail).ok());
  EXPECT_TRUE(client_->GetThumbnail(models_[1].id).ok());
  EXPECT_TRUE(absl::IsNotFound(client_->GetPreview(models_[1].id).status()));
}

TEST_F(IndexerMediaTest, ReplacedAndDeletedWithTheModel) {
  const v1::ModelMedia first = FakeMedia(1000, 'c');
  const v1::ModelMedia second = FakeMedia(2000, 'd');
  ASSERT_TRUE(Put(models_[0], &first).ok());
  ASSERT_TRUE(Put(models_[0], &second).ok());
  EXPECT_EQ(*client_->GetPreview(models_[0].id), second.preview_ply());
  // An upsert without media removes the old ones: they showed another mesh.
  ASSERT_TRUE(Put(models_[0], nullptr).ok());
  EXPECT_FALSE(client_->Get(models_[0].id)->media_stored());
  EXPECT_TRUE(absl::IsNotFound(client_->GetThumbnail(models_[0].id).status()));
  EXPECT_TRUE(absl::IsNotFound(
      server_->core()->storage().GetMedia(models_[0].id).status()));

  // Deleting the model deletes its media: the id added again has none.
  ASSERT_TRUE(Put(models_[1], &first).ok());
  ASSERT_TRUE(client_->Delete(models_[1].id).ok());
  EXPECT_TRUE(absl::IsNotFound(
      server_->core()->storage().GetMedia(models_[1].id).status()));
  ASSERT_TRUE(Put(models_[1], nullptr).ok());
  EXPECT_TRUE(absl::IsNotFound(client_->GetThumbnail(models_[1].id).status()));
}

TEST_F(IndexerMediaTest, WrongOrOversizedMediaAreRefused) {
  v1::ModelMedia not_png = FakeMedia(10, 'e');
  not_png.set_thumbnail_png("GIF89a....");
  absl::Status s = Put(models_[0], &not_png);
  EXPECT_TRUE(absl::IsInvalidArgument(s)) << s;
  EXPECT_NE(s.message().find("media.thumbnail_png is not a PNG"),
            std::string::npos)
      << s;
  v1::ModelMedia not_ply = FakeMedia(10, 'e');
  not_ply.set_preview_ply("OFF\n3 1 0\n");
  s = Put(models_[0], &not_ply);
  EXPECT_TRUE(absl::IsInvalidArgument(s)) << s;
  EXPECT_NE(s.message().find("media.preview_ply is not a PLY"),
            std::string::npos)
      << s;
  const v1::ModelMedia huge = FakeMedia(indexer::kMaxPreviewBytes, 'f');
  s = Put(models_[0], &huge);
  EXPECT_TRUE(absl::IsResourceExhausted(s)) << s;
  EXPECT_TRUE(absl::IsNotFound(client_->Get(models_[0].id).status()));
}

// Through tpr-gateway over three shards: each model's media come from its
// own shard (the other shards do not hold the id at all).
TEST(GatewayMediaTest, RoutesToTheIdsShard) {
  TempDir dir;
  constexpr int kShards = 3;
  std::vector<std::unique_ptr<InProcessIndexer>> shards;
  gateway::GatewayOptions options;
  for (int s = 0; s < kShards; ++s) {
    shards.push_back(std::make_unique<InProcessIndexer>(
        absl::StrCat(dir.path(), "/shard", s)));
    ASSERT_TRUE(shards.back()->Start().ok());
    options.shards.shards.push_back({shards.back()->address(), {}});
  }
  options.health_interval_ms = 0;
  gateway::GatewayService service(options);
  common::ServerOptions server_options;
  server_options.shutdown_grace_ms = 2000;
  absl::StatusOr<common::StartedServer> started =
      common::StartServer(server_options, {&service});
  ASSERT_TRUE(started.ok()) << started.status();
  absl::StatusOr<client::IndexerClient> gateway =
      client::IndexerClient::Connect(absl::StrCat("127.0.0.1:", started->port));
  ASSERT_TRUE(gateway.ok());

  const std::vector<TestModel> models = MakeModels(12, 3, 9);
  std::vector<int> per_shard(kShards, 0);
  for (size_t i = 0; i < models.size(); ++i) {
    v1::UpsertRequest request = ToRequest(models[i], true);
    *request.mutable_model()->mutable_media() =
        FakeMedia(100000 + i, static_cast<char>('a' + i));
    ASSERT_TRUE(gateway->Upsert(request.model(), true).ok());
    ++per_shard[gateway::ShardOf(models[i].id, kShards)];
  }
  for (int s = 0; s < kShards; ++s) EXPECT_GT(per_shard[s], 0) << s;
  for (size_t i = 0; i < models.size(); ++i) {
    const v1::ModelMedia want =
        FakeMedia(100000 + i, static_cast<char>('a' + i));
    EXPECT_EQ(*gateway->GetThumbnail(models[i].id), want.thumbnail_png());
    EXPECT_EQ(*gateway->GetPreview(models[i].id), want.preview_ply());
    const int owner = gateway::ShardOf(models[i].id, kShards);
    for (int s = 0; s < kShards; ++s) {
      EXPECT_EQ(shards[s]->core()->GetThumbnail(models[i].id).ok(), s == owner)
          << models[i].id << " on shard " << s;
    }
  }
  absl::Status missing = gateway->GetPreview("no/such/id").status();
  EXPECT_TRUE(absl::IsNotFound(missing)) << missing;
  EXPECT_NE(missing.message().find("no model with id"), std::string::npos)
      << missing;
  common::ShutdownGracefully(*started->server, server_options);
}

}  // namespace
}  // namespace tpr
