// tpr-extractor over the wire: an in-process ExtractorService on a loopback
// port (and the real binary for signals), checked against the library called
// directly on the same bytes (the oracle: the service must only transport
// and convert).
#include "extractor/service/extractor_service.h"

#include <signal.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <grpcpp/client_context.h>
#include <grpcpp/create_channel.h>
#include <gtest/gtest.h>

#include "common/server_lifecycle.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/service/convert.h"
#include "extractor/synth/synth.h"
#include "tests/service/extsvc_test_util.h"
#include "tpr/client.h"

namespace tpr::extractor_service {
namespace {

using ::tpr::testing::ToOff;

std::string GeneratedOff(const std::string& cls, int pose, int vertices) {
  synth::ShapeOptions options;
  options.target_vertices = vertices;
  options.seed = 7;
  absl::StatusOr<extract::Mesh> mesh = synth::GenerateShape(cls, pose, options);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? ToOff(*mesh) : std::string();
}

class ExtractorServiceTest : public ::testing::Test {
 protected:
  void StartWith(const ServiceOptions& options) {
    service_ = std::make_unique<ExtractorService>(options);
    common::ServerOptions server_options;
    server_options.listen_address = "127.0.0.1:0";
    absl::StatusOr<common::StartedServer> started =
        common::StartServer(server_options, {service_.get()});
    ASSERT_TRUE(started.ok()) << started.status();
    server_ = std::move(started->server);
    address_ = absl::StrCat("127.0.0.1:", started->port);
    absl::StatusOr<client::ExtractorClient> c = client::ExtractorClient::Connect(address_);
    ASSERT_TRUE(c.ok()) << c.status();
    client_ = std::make_unique<client::ExtractorClient>(*c);
  }
  void SetUp() override { StartWith(ServiceOptions{}); }
  void TearDown() override {
    if (server_) {
      server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
      server_->Wait();
    }
    server_.reset();
    service_.reset();
  }

  std::unique_ptr<ExtractorService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::string address_;
  std::unique_ptr<client::ExtractorClient> client_;
};

TEST_F(ExtractorServiceTest, ReturnsTheLibrarySignatureForAGeneratedMesh) {
  const std::string off = GeneratedOff("biped_adult", 1, 3000);
  ASSERT_FALSE(off.empty());
  v1::ExtractOptions options;
  options.set_explain(true);
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes(off, "biped.off", options);
  ASSERT_TRUE(r.ok()) << r.status();

  // Oracle: the library on the same bytes.
  absl::StatusOr<extract::LoadedMesh> loaded =
      extract::LoadMeshFromBuffer(off, extract::MeshFormat::kOff, "biped.off", {});
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  extract::Options lib_options;
  lib_options.explain = true;
  absl::StatusOr<extract::ExtractResult> expected =
      extract::ExtractSignature(loaded->mesh, loaded->stats, lib_options);
  ASSERT_TRUE(expected.ok()) << expected.status();

  const v1::Signature& s = r->signature();
  ASSERT_EQ(s.features_size(), static_cast<int>(expected->signature.features.size()));
  ASSERT_GT(s.features_size(), 0);
  for (int i = 0; i < s.features_size(); ++i) {
    const extract::Feature& e = expected->signature.features[i];
    EXPECT_EQ(s.features(i).kind() == v1::FEATURE_KIND_POINT,
              e.kind == extract::FeatureKind::kPoint);
    EXPECT_DOUBLE_EQ(s.features(i).weight(), e.weight);
    EXPECT_DOUBLE_EQ(s.features(i).integral_geodesic(), e.integral_geodesic);
    ASSERT_EQ(s.features(i).curvature_size(), static_cast<int>(e.curvature.size()));
    for (size_t b = 0; b < e.curvature.size(); ++b) {
      EXPECT_DOUBLE_EQ(s.features(i).curvature(b), e.curvature[b]);
      EXPECT_DOUBLE_EQ(s.features(i).area(b), e.area[b]);
      EXPECT_DOUBLE_EQ(s.features(i).distance(b), e.distance[b]);
    }
  }
  // Mesh stats are intake's; options come back with every default filled.
  EXPECT_EQ(s.mesh().vertices(), loaded->stats.vertices);
  EXPECT_EQ(s.mesh().faces(), loaded->stats.faces);
  EXPECT_DOUBLE_EQ(s.mesh().area(), loaded->stats.area);
  EXPECT_EQ(s.mesh().genus(), 0);
  EXPECT_EQ(s.extractor_version(), kExtractorVersion);
  EXPECT_FALSE(s.extractor_version().empty());
  EXPECT_EQ(s.options().bands(), extract::Options{}.bands);
  EXPECT_EQ(s.options().cycle_min_vertices(), extract::Options{}.cycle_min_vertices);
  EXPECT_DOUBLE_EQ(s.options().ring_length_threshold(),
                   extract::Options{}.ring_length_threshold);
  EXPECT_GE(s.options().threads(), 1);
  // Timings: intake first, then the library's stages in order.
  ASSERT_EQ(r->timings_size(), static_cast<int>(expected->timings.size()) + 1);
  EXPECT_EQ(r->timings(0).stage(), "intake");
  for (size_t i = 0; i < expected->timings.size(); ++i) {
    EXPECT_EQ(r->timings(i + 1).stage(), expected->timings[i].stage);
  }
  // Explanation as asked: one region per vertex, one vertex list per feature.
  ASSERT_TRUE(r->has_explanation());
  EXPECT_EQ(r->explanation().vertex_region_size(), loaded->stats.vertices);
  EXPECT_EQ(r->explanation().feature_vertices_size(), s.features_size());
  ASSERT_TRUE(expected->explanation.has_value());
  EXPECT_TRUE(std::equal(r->explanation().vertex_region().begin(),
                         r->explanation().vertex_region().end(),
                         expected->explanation->vertex_region.begin()));
}

TEST_F(ExtractorServiceTest, NoExplanationUnlessAskedAndMultiChunkUploadsAgree) {
  // 60k vertices of OFF text is several MiB: several 1 MiB chunks.
  const std::string off = GeneratedOff("quadruped_slender", 0, 60000);
  ASSERT_GT(off.size(), 3 * client::kChunkBytes);
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes(off, "dog.off");
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_FALSE(r->has_explanation());
  absl::StatusOr<extract::LoadedMesh> loaded =
      extract::LoadMeshFromBuffer(off, extract::MeshFormat::kUnknown, "dog.off", {});
  ASSERT_TRUE(loaded.ok());
  EXPECT_EQ(r->signature().mesh().vertices(), loaded->stats.vertices);
}

TEST_F(ExtractorServiceTest, EachMalformedMeshOfTheCorpusIsInvalidArgumentWithItsReason) {
  const std::filesystem::path dir = std::filesystem::path(TPR_TEST_DATA_DIR) / "meshes" / "bad";
  if (!std::filesystem::is_directory(dir)) GTEST_SKIP() << "no corpus at " << dir;
  int checked = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (!entry.is_regular_file() || entry.path().extension() == ".txt" ||
        entry.path().extension() == ".md") {
      continue;
    }
    std::ifstream in(entry.path(), std::ios::binary);
    std::stringstream bytes;
    bytes << in.rdbuf();
    const std::string name = entry.path().filename().string();
    absl::StatusOr<extract::LoadedMesh> local = extract::LoadMeshFromBuffer(
        bytes.str(), extract::MeshFormat::kUnknown, name, {});
    if (local.ok()) continue;  // a "bad" file intake accepts with warnings
    if (!absl::IsInvalidArgument(local.status())) continue;
    absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes(bytes.str(), name);
    ASSERT_FALSE(r.ok()) << name;
    EXPECT_TRUE(absl::IsInvalidArgument(r.status())) << name << ": " << r.status();
    // An empty file never reaches intake: the service itself says so.
    if (!bytes.str().empty()) {
      EXPECT_EQ(r.status().message(), local.status().message()) << name;
    }
    ++checked;
  }
  EXPECT_GT(checked, 0) << "the corpus in " << dir << " had no rejected mesh";
  // Still serving.
  absl::StatusOr<v1::ExtractResponse> ok =
      client_->ExtractBytes(GeneratedOff("biped_adult", 0, 1000), "ok.off");
  EXPECT_TRUE(ok.ok()) << ok.status();
}

TEST_F(ExtractorServiceTest, EmptyUploadIsInvalidArgument) {
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes("", "empty.off");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(r.status())) << r.status();
}

TEST_F(ExtractorServiceTest, BadOptionsAreInvalidArgument) {
  v1::ExtractOptions options;
  options.set_bands(1000);
  absl::StatusOr<v1::ExtractResponse> r =
      client_->ExtractBytes(GeneratedOff("biped_adult", 0, 1000), "a.off", options);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(r.status())) << r.status();
  EXPECT_NE(r.status().message().find("bands"), absl::string_view::npos);
}

TEST_F(ExtractorServiceTest, OversizedUploadIsResourceExhaustedAndServiceKeepsServing) {
  TearDown();
  ServiceOptions options;
  options.max_mesh_bytes = 200'000;
  StartWith(options);
  // 5 MiB: the server must refuse after the first chunk that crosses 200 kB.
  const std::string big(5 << 20, 'x');
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes(big, "big.off");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsResourceExhausted(r.status())) << r.status();
  EXPECT_NE(r.status().message().find("200000"), absl::string_view::npos) << r.status();
  const std::string off = GeneratedOff("biped_adult", 0, 1000);
  ASSERT_LT(off.size(), 200'000u);
  absl::StatusOr<v1::ExtractResponse> ok = client_->ExtractBytes(off, "small.off");
  EXPECT_TRUE(ok.ok()) << ok.status();
}

TEST_F(ExtractorServiceTest, TooManyVerticesIsResourceExhausted) {
  TearDown();
  ServiceOptions options;
  options.max_vertices = 500;
  StartWith(options);
  absl::StatusOr<v1::ExtractResponse> r =
      client_->ExtractBytes(GeneratedOff("biped_adult", 0, 2000), "a.off");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsResourceExhausted(r.status())) << r.status();
}

TEST_F(ExtractorServiceTest, CallsBeyondMaxConcurrentAreRefusedAtOnce) {
  TearDown();
  ServiceOptions options;
  options.max_concurrent = 1;
  StartWith(options);
  auto channel = grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
  auto stub = v1::Extractor::NewStub(channel);
  // Call A stays open (upload not finished) and holds the only slot.
  grpc::ClientContext a_context;
  v1::ExtractResponse a_response;
  auto a = stub->Extract(&a_context, &a_response);
  v1::ExtractRequest first;
  first.set_file_name("a.off");
  first.set_data("OFF\n");
  ASSERT_TRUE(a->Write(first));
  for (int i = 0; i < 500 && service_->InFlight() < 1; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(service_->InFlight(), 1);
  absl::StatusOr<v1::ExtractResponse> b =
      client_->ExtractBytes(GeneratedOff("biped_adult", 0, 1000), "b.off");
  ASSERT_FALSE(b.ok());
  EXPECT_TRUE(absl::IsResourceExhausted(b.status())) << b.status();
  // Cancelling A frees the slot; the service serves again.
  a_context.TryCancel();
  a->Finish();
  for (int i = 0; i < 500 && service_->InFlight() > 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(service_->InFlight(), 0);
  EXPECT_TRUE(client_->ExtractBytes(GeneratedOff("biped_adult", 0, 1000), "c.off").ok());
}

TEST_F(ExtractorServiceTest, ExpiredDeadlineIsDeadlineExceeded) {
  client::CallOptions call;
  call.timeout = absl::Milliseconds(1);
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes(
      GeneratedOff("biped_adult", 0, 20000), "a.off", {}, v1::MESH_FORMAT_OFF, &call);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsDeadlineExceeded(r.status())) << r.status();
  for (int i = 0; i < 1000 && service_->InFlight() > 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(service_->InFlight(), 0);
}

TEST_F(ExtractorServiceTest, HealthIsServing) {
  auto channel = grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
  absl::StatusOr<int> health = testing::HealthCheck(channel);
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_EQ(*health, 1);  // SERVING
}

// The real binary: health, then SIGTERM while an upload is open. The open
// call must still complete (graceful shutdown) and the process exit 0.
TEST(ExtractorBinaryTest, SigtermDuringAnUploadFinishesItAndExitsZero) {
  testing::TempDir dir;
  testing::ServiceProcess process;
  ASSERT_TRUE(process
                  .Start(testing::BinaryPath("tpr-extractor"), {"--threads", "1"},
                         dir.path() + "/extractor.log")
                  .ok());
  auto channel = grpc::CreateChannel(process.address(), grpc::InsecureChannelCredentials());
  absl::StatusOr<int> health = testing::HealthCheck(channel);
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_EQ(*health, 1);

  const std::string off = GeneratedOff("biped_adult", 2, 3000);
  auto stub = v1::Extractor::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  v1::ExtractResponse response;
  auto writer = stub->Extract(&context, &response);
  v1::ExtractRequest first;
  first.set_file_name("a.off");
  first.set_data(off.substr(0, off.size() / 2));
  ASSERT_TRUE(writer->Write(first));
  // Give the server time to admit the call before the signal.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  std::thread stopper([&] { EXPECT_EQ(process.Stop(SIGTERM), 0); });
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  v1::ExtractRequest rest;
  rest.set_data(off.substr(off.size() / 2));
  EXPECT_TRUE(writer->Write(rest));
  writer->WritesDone();
  grpc::Status status = writer->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_GT(response.signature().features_size(), 0);
  stopper.join();
}

}  // namespace
}  // namespace tpr::extractor_service
