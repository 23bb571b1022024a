// tpr-extractor over the wire: an in-process ExtractorService on a loopback
// port (and the real binary for signals), checked against the library called
// directly on the same bytes (the oracle: the service must only transport
// and convert).
#include "extractor/service/extractor_service.h"

#include <fcntl.h>
#include <grpcpp/client_context.h>
#include <grpcpp/create_channel.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "absl/strings/str_format.h"
#include "common/server_lifecycle.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/service/convert.h"
#include "extractor/synth/synth.h"
#include "tests/sanitizers/sanitizer_build.h"
#include "tests/service/extsvc_test_util.h"
#include "tpr/client.h"

namespace tpr::extractor {
namespace {

using ::tpr::testing::kAddressSanitizer;
using ::tpr::testing::kSanitizerSlowdown;
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
    absl::StatusOr<client::ExtractorClient> c =
        client::ExtractorClient::Connect(address_);
    ASSERT_TRUE(c.ok()) << c.status();
    client_ = std::make_unique<client::ExtractorClient>(*c);
  }
  void SetUp() override { StartWith(ServiceOptions{}); }
  void TearDown() override {
    if (server_) {
      server_->Shutdown(std::chrono::system_clock::now() +
                        std::chrono::seconds(5));
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
  absl::StatusOr<v1::ExtractResponse> r =
      client_->ExtractBytes(off, "biped.off", options);
  ASSERT_TRUE(r.ok()) << r.status();

  // Oracle: the library on the same bytes.
  absl::StatusOr<extract::LoadedMesh> loaded = extract::LoadMeshFromBuffer(
      off, extract::MeshFormat::kOff, "biped.off", {});
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  extract::Options lib_options;
  lib_options.explain = true;
  absl::StatusOr<extract::ExtractResult> expected =
      extract::ExtractSignature(loaded->mesh, loaded->stats, lib_options);
  ASSERT_TRUE(expected.ok()) << expected.status();

  const v1::Signature& s = r->signature();
  ASSERT_EQ(s.features_size(),
            static_cast<int>(expected->signature.features.size()));
  ASSERT_GT(s.features_size(), 0);
  for (int i = 0; i < s.features_size(); ++i) {
    const extract::Feature& e = expected->signature.features[i];
    EXPECT_EQ(s.features(i).kind() == v1::FEATURE_KIND_POINT,
              e.kind == extract::FeatureKind::kPoint);
    EXPECT_DOUBLE_EQ(s.features(i).weight(), e.weight);
    EXPECT_DOUBLE_EQ(s.features(i).integral_geodesic(), e.integral_geodesic);
    ASSERT_EQ(s.features(i).curvature_size(),
              static_cast<int>(e.curvature.size()));
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
  EXPECT_EQ(s.options().cycle_min_vertices(),
            extract::Options{}.cycle_min_vertices);
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

TEST_F(ExtractorServiceTest,
       NoExplanationUnlessAskedAndMultiChunkUploadsAgree) {
  // 60k vertices of OFF text is several MiB: several 1 MiB chunks.
  const std::string off = GeneratedOff("quadruped_slender", 0, 60000);
  ASSERT_GT(off.size(), 3 * client::kChunkBytes);
  // The default 60 s deadline is ample in Release; under ASan this
  // extraction alone took longer (scripts/test --sanitize).
  client::CallOptions call;
  call.timeout = absl::Seconds(60 * kSanitizerSlowdown);
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes(
      off, "dog.off", {}, v1::MESH_FORMAT_UNSPECIFIED, &call);
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_FALSE(r->has_explanation());
  absl::StatusOr<extract::LoadedMesh> loaded = extract::LoadMeshFromBuffer(
      off, extract::MeshFormat::kUnknown, "dog.off", {});
  ASSERT_TRUE(loaded.ok());
  EXPECT_EQ(r->signature().mesh().vertices(), loaded->stats.vertices);
}

TEST_F(ExtractorServiceTest,
       EachMalformedMeshOfTheCorpusIsInvalidArgumentWithItsReason) {
  const std::filesystem::path dir =
      std::filesystem::path(TPR_TEST_DATA_DIR) / "meshes" / "bad";
  if (!std::filesystem::is_directory(dir))
    GTEST_SKIP() << "no corpus at " << dir;
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
    absl::StatusOr<v1::ExtractResponse> r =
        client_->ExtractBytes(bytes.str(), name);
    ASSERT_FALSE(r.ok()) << name;
    EXPECT_TRUE(absl::IsInvalidArgument(r.status()))
        << name << ": " << r.status();
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

// Bytes that do not parse in the middle of an upload were taken
// for the end of the stream (gRPC's typed reader reports both the same
// way), so the chunks before them were extracted as if they were the whole
// mesh and the call answered OK. Now it fails with INVALID_ARGUMENT naming
// the message. Raw bytes go on the wire as another client could send them.
TEST_F(ExtractorServiceTest, MalformedMessageInTheUploadIsAnError) {
  v1::ExtractRequest first;
  first.set_file_name("a.off");
  first.set_data(GeneratedOff("biped_adult", 0, 1000));  // a whole mesh
  v1::ExtractRequest more;
  more.set_data("\n");
  const std::string method = "/tpr.v1.Extractor/Extract";
  grpc::Status s = ::tpr::testing::RawClientStream(
      grpc::CreateChannel(address_, grpc::InsecureChannelCredentials()), method,
      {first.SerializeAsString(), std::string("\xff\xff\xff\xff", 4),
       more.SerializeAsString()});
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
      << s.error_message();
  EXPECT_NE(s.error_message().find("Extract: message 2 of the stream"),
            std::string::npos)
      << s.error_message();
  EXPECT_NE(s.error_message().find("tpr.v1.ExtractRequest"), std::string::npos)
      << s.error_message();
  // The same raw path extracts a well-formed upload.
  std::string answer;
  s = ::tpr::testing::RawClientStream(
      grpc::CreateChannel(address_, grpc::InsecureChannelCredentials()), method,
      {first.SerializeAsString(), more.SerializeAsString()}, &answer);
  ASSERT_TRUE(s.ok()) << s.error_message();
  v1::ExtractResponse response;
  ASSERT_TRUE(response.ParseFromString(answer));
  EXPECT_GT(response.signature().mesh().vertices(), 0);
}

TEST_F(ExtractorServiceTest, EmptyUploadIsInvalidArgument) {
  absl::StatusOr<v1::ExtractResponse> r =
      client_->ExtractBytes("", "empty.off");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(r.status())) << r.status();
}

TEST_F(ExtractorServiceTest, BadOptionsAreInvalidArgument) {
  v1::ExtractOptions options;
  options.set_bands(1000);
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes(
      GeneratedOff("biped_adult", 0, 1000), "a.off", options);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsInvalidArgument(r.status())) << r.status();
  EXPECT_NE(r.status().message().find("bands"), absl::string_view::npos);
}

TEST_F(ExtractorServiceTest,
       OversizedUploadIsResourceExhaustedAndServiceKeepsServing) {
  TearDown();
  ServiceOptions options;
  options.max_mesh_bytes = 200'000;
  StartWith(options);
  // 5 MiB: the server must refuse after the first chunk that crosses 200 kB.
  const std::string big(5 << 20, 'x');
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractBytes(big, "big.off");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsResourceExhausted(r.status())) << r.status();
  EXPECT_NE(r.status().message().find("200000"), absl::string_view::npos)
      << r.status();
  const std::string off = GeneratedOff("biped_adult", 0, 1000);
  ASSERT_LT(off.size(), 200'000u);
  absl::StatusOr<v1::ExtractResponse> ok =
      client_->ExtractBytes(off, "small.off");
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
  auto channel =
      grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
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
  EXPECT_TRUE(
      client_->ExtractBytes(GeneratedOff("biped_adult", 0, 1000), "c.off")
          .ok());
}

TEST_F(ExtractorServiceTest, ExpiredDeadlineIsDeadlineExceeded) {
  client::CallOptions call;
  call.timeout = absl::Milliseconds(1);
  absl::StatusOr<v1::ExtractResponse> r =
      client_->ExtractBytes(GeneratedOff("biped_adult", 0, 20000), "a.off", {},
                            v1::MESH_FORMAT_OFF, &call);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(absl::IsDeadlineExceeded(r.status())) << r.status();
  for (int i = 0; i < 1000 && service_->InFlight() > 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(service_->InFlight(), 0);
}

TEST_F(ExtractorServiceTest, HealthIsServing) {
  auto channel =
      grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
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
                  .Start(testing::BinaryPath("tpr-extractor"),
                         {"--threads", "1"}, dir.path() + "/extractor.log")
                  .ok());
  auto channel = grpc::CreateChannel(process.address(),
                                     grpc::InsecureChannelCredentials());
  absl::StatusOr<int> health = testing::HealthCheck(channel);
  ASSERT_TRUE(health.ok()) << health.status();
  EXPECT_EQ(*health, 1);

  const std::string off = GeneratedOff("biped_adult", 2, 3000);
  auto stub = v1::Extractor::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(60));
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

// A client that opens an upload, sends `first` and then (optionally) more
// data at its own pace, over a raw stub so that the test controls timing.
class RawUpload {
 public:
  RawUpload(v1::Extractor::Stub* stub, std::chrono::seconds deadline) {
    context_.set_deadline(std::chrono::system_clock::now() + deadline);
    writer_ = stub->Extract(&context_, &response_);
  }
  bool Write(const std::string& data, const std::string& file_name = "") {
    v1::ExtractRequest request;
    request.set_file_name(file_name);
    request.set_data(data);
    return writer_->Write(request);
  }
  // Waits for the server's status (without closing the upload first when
  // `close` is false: a stalled client never does).
  grpc::Status Finish(bool close = false) {
    if (close) writer_->WritesDone();
    return writer_->Finish();
  }
  const v1::ExtractResponse& response() const { return response_; }

 private:
  grpc::ClientContext context_;
  v1::ExtractResponse response_;
  std::unique_ptr<grpc::ClientWriter<v1::ExtractRequest>> writer_;
};

// Slot starvation, reproduced: as many uploads as there are slots each send
// 4 bytes and wait. While they wait everyone else is refused; after the idle
// timeout they are refused with DEADLINE_EXCEEDED naming the flag, their
// slots are free, and a normal client is served. Under a sanitizer every
// wait and time bound is kSanitizerSlowdown times longer (the four stalled
// calls must all be admitted before the first one's idle timeout ends).
TEST_F(ExtractorServiceTest, StalledUploadsAreRefusedAfterTheIdleTimeout) {
  TearDown();
  ServiceOptions options;
  options.max_concurrent = 4;
  options.upload_idle_timeout_ms = 400 * kSanitizerSlowdown;
  options.min_upload_bytes_per_second = 0;
  StartWith(options);
  // Generated before the uploads start: under ASan generating it took
  // longer than the idle timeout, which then freed the slots early.
  const std::string off = GeneratedOff("biped_adult", 0, 1000);
  auto channel =
      grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
  auto stub = v1::Extractor::NewStub(channel);
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::unique_ptr<RawUpload>> slow;
  for (int i = 0; i < options.max_concurrent; ++i) {
    slow.push_back(
        std::make_unique<RawUpload>(stub.get(), std::chrono::seconds(60)));
    ASSERT_TRUE(slow.back()->Write("OFF\n", "slow.off"));
  }
  // Up to 10 s: on a loaded 2-core machine (a landing build beside it) the
  // four calls took over a second to reach the server.
  for (int i = 0; i < 2000 * kSanitizerSlowdown &&
                  service_->InFlight() < options.max_concurrent;
       ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ(service_->InFlight(), options.max_concurrent);
  absl::StatusOr<v1::ExtractResponse> refused =
      client_->ExtractBytes(off, "b.off");
  EXPECT_TRUE(absl::IsResourceExhausted(refused.status())) << refused.status();

  for (auto& upload : slow) {
    const grpc::Status status = upload->Finish();
    EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED)
        << status.error_message();
    EXPECT_NE(status.error_message().find("--upload-idle-timeout-ms"),
              std::string::npos)
        << status.error_message();
  }
  const double waited =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start)
          .count();
  EXPECT_GE(waited, options.upload_idle_timeout_ms / 1000.0);
  EXPECT_LT(waited, 5.0 * kSanitizerSlowdown)
      << "the idle timeout was not enforced promptly";
  for (int i = 0; i < 2000 * kSanitizerSlowdown && service_->InFlight() > 0;
       ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_EQ(service_->InFlight(), 0);
  absl::StatusOr<v1::ExtractResponse> served =
      client_->ExtractBytes(off, "c.off");
  EXPECT_TRUE(served.ok()) << served.status();
}

// A client that never stalls but trickles (2 KB/s against a 40 KB/s
// minimum) is refused once the grace has passed; a client at loopback
// speed sending many small chunks under the same limits is served.
TEST_F(ExtractorServiceTest, TricklingUploadIsRefusedBelowTheMinimumRate) {
  TearDown();
  ServiceOptions options;
  options.upload_idle_timeout_ms = 300;
  options.min_upload_bytes_per_second = 40'000;
  StartWith(options);
  auto channel =
      grpc::CreateChannel(address_, grpc::InsecureChannelCredentials());
  auto stub = v1::Extractor::NewStub(channel);
  const std::string off = GeneratedOff("biped_adult", 1, 2000);
  ASSERT_GT(off.size(), 40'000u);

  RawUpload trickle(stub.get(), std::chrono::seconds(60));
  const auto start = std::chrono::steady_clock::now();
  size_t sent = 0;
  bool first = true;
  // 100 bytes every 50 ms; Write fails once the server has finished the
  // call. Bounded: at most 10 s of trickling.
  while (sent < off.size() &&
         std::chrono::steady_clock::now() - start < std::chrono::seconds(10)) {
    if (!trickle.Write(off.substr(sent, 100), first ? "trickle.off" : ""))
      break;
    first = false;
    sent += 100;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  const grpc::Status status = trickle.Finish();
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DEADLINE_EXCEEDED)
      << status.error_message();
  EXPECT_NE(status.error_message().find("--min-upload-bytes-per-second"),
            std::string::npos)
      << status.error_message();
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(3));

  RawUpload fast(stub.get(), std::chrono::seconds(60));
  for (size_t at = 0; at < off.size(); at += 1000) {
    ASSERT_TRUE(fast.Write(off.substr(at, 1000), at == 0 ? "fast.off" : ""));
  }
  const grpc::Status fast_status = fast.Finish(/*close=*/true);
  EXPECT_TRUE(fast_status.ok()) << fast_status.error_message();
  EXPECT_GT(fast.response().signature().features_size(), 0);
}

// The slot-starvation reproduction on the real binary with its flags:
// 16 streams that send 4 bytes and wait no longer hold every slot for
// minutes; a normal client is served once the idle timeout has passed.
// Under a sanitizer the idle timeout and every wait and time bound are
// kSanitizerSlowdown times longer.
TEST(ExtractorBinaryTest, SixteenStalledStreamsReleaseTheirSlots) {
  testing::TempDir dir;
  testing::ServiceProcess process;
  const int idle_timeout_ms = 500 * kSanitizerSlowdown;
  ASSERT_TRUE(
      process
          .Start(testing::BinaryPath("tpr-extractor"),
                 {"--threads", "1", "--max-concurrent", "16",
                  "--upload-idle-timeout-ms", std::to_string(idle_timeout_ms)},
                 dir.path() + "/extractor.log")
          .ok());
  // The mesh and the client exist before the uploads start: under ASan
  // generating the mesh took longer than the idle timeout.
  const std::string off = GeneratedOff("biped_adult", 0, 1000);
  absl::StatusOr<client::ExtractorClient> c =
      client::ExtractorClient::Connect(process.address());
  ASSERT_TRUE(c.ok());
  auto channel = grpc::CreateChannel(process.address(),
                                     grpc::InsecureChannelCredentials());
  auto stub = v1::Extractor::NewStub(channel);
  std::vector<std::unique_ptr<RawUpload>> slow;
  for (int i = 0; i < 16; ++i) {
    slow.push_back(
        std::make_unique<RawUpload>(stub.get(), std::chrono::seconds(120)));
    ASSERT_TRUE(slow.back()->Write("OFF\n", "slow.off"));
  }
  // Right away every slot is held (the 16 were admitted first) ...
  std::this_thread::sleep_for(std::chrono::milliseconds(100) *
                              kSanitizerSlowdown);
  absl::StatusOr<v1::ExtractResponse> refused = c->ExtractBytes(off, "a.off");
  EXPECT_TRUE(absl::IsResourceExhausted(refused.status())) << refused.status();
  // ... and a client retrying for a few seconds gets through.
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<v1::ExtractResponse> served = refused;
  while (!served.ok() && absl::IsResourceExhausted(served.status()) &&
         std::chrono::steady_clock::now() - start <
             std::chrono::seconds(10) * kSanitizerSlowdown) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    served = c->ExtractBytes(off, "a.off");
  }
  EXPECT_TRUE(served.ok()) << served.status();
  EXPECT_LT(std::chrono::steady_clock::now() - start,
            std::chrono::seconds(3) * kSanitizerSlowdown);
  for (auto& upload : slow) {
    EXPECT_EQ(upload->Finish().error_code(),
              grpc::StatusCode::DEADLINE_EXCEEDED);
  }
  // Close the connections first: open channels hold up the server's
  // graceful shutdown until its grace period ends.
  slow.clear();
  stub.reset();
  channel.reset();
  c = absl::InternalError("closed");
  EXPECT_EQ(process.Stop(SIGTERM), 0);
}

// VmHWM (peak resident set) of process `pid`, in bytes; -1 if unreadable.
int64_t PeakResidentBytes(pid_t pid) {
  std::ifstream in(absl::StrCat("/proc/", pid, "/status"));
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("VmHWM:", 0) == 0)
      return std::atoll(line.c_str() + 6) * 1024;
  }
  return -1;
}

// Hostile uploads of `bytes` bytes each: an OBJ whose one face lists every
// vertex index again and again (the "one 30M-vertex polygon"), an
// OFF and a PLY whose headers declare far more elements than follow, and
// plain garbage.
std::string HostileUpload(int kind, size_t bytes) {
  std::string out;
  out.reserve(bytes);
  switch (kind % 4) {
    case 0:
      out = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf";
      while (out.size() + 8 < bytes) out += " 1 2 3";
      out += "\n";
      break;
    case 1:
      out = "OFF\n200000000 400000000 0\n";
      while (out.size() + 16 < bytes) out += "0 0 0\n";
      break;
    case 2:
      out =
          "ply\nformat ascii 1.0\nelement vertex 900000000\nproperty float x\n"
          "property float y\nproperty float z\nelement face 900000000\n"
          "property list uchar int vertex_indices\nend_header\n";
      while (out.size() + 16 < bytes) out += "1 2 3\n";
      break;
    default:
      while (out.size() < bytes)
        out += static_cast<char>('a' + out.size() % 26);
  }
  return out;
}

// The documented memory bound (extractor_service.h) on a
// real process. Every slot holds a nearly full hostile upload at once while
// more clients push oversized uploads (chunked, and as one huge message);
// then the held uploads are parsed, two at a time. The growth of VmHWM over
// a warmed-up baseline must stay within max_concurrent x max_mesh_bytes for
// the uploads, plus the intake allowance of the two meshes being parsed.
TEST(ExtractorBinaryTest, PeakMemoryStaysWithinTheBoundUnderHostileUploads) {
  constexpr int kConcurrent = 8;
  constexpr int kThreads = 2;
  constexpr int64_t kMaxMesh = int64_t{8} << 20;
  constexpr int kPushers = 8;
  testing::TempDir dir;
  testing::ServiceProcess process;
  ASSERT_TRUE(process
                  .Start(testing::BinaryPath("tpr-extractor"),
                         {"--threads", std::to_string(kThreads),
                          "--max-concurrent", std::to_string(kConcurrent),
                          "--max-mesh-bytes", std::to_string(kMaxMesh),
                          "--upload-idle-timeout-ms", "30000"},
                         dir.path() + "/extractor.log")
                  .ok());
  {
    absl::StatusOr<client::ExtractorClient> c =
        client::ExtractorClient::Connect(process.address());
    ASSERT_TRUE(c.ok());
    ASSERT_TRUE(
        c->ExtractBytes(GeneratedOff("biped_adult", 0, 3000), "warm.off").ok());
  }
  const int64_t baseline = PeakResidentBytes(process.pid());
  ASSERT_GT(baseline, 0);

  auto channel = grpc::CreateChannel(process.address(),
                                     grpc::InsecureChannelCredentials());
  auto stub = v1::Extractor::NewStub(channel);
  // 1. Every slot fills up to just under the limit, 1 MiB at a time.
  const size_t held_bytes = kMaxMesh - (64 << 10);
  std::vector<std::unique_ptr<RawUpload>> held;
  for (int i = 0; i < kConcurrent; ++i) {
    held.push_back(
        std::make_unique<RawUpload>(stub.get(), std::chrono::seconds(120)));
    const std::string data = HostileUpload(i, held_bytes);
    const char* names[] = {"a.obj", "b.off", "c.ply", "d.off"};
    for (size_t at = 0; at < data.size(); at += 1 << 20) {
      ASSERT_TRUE(held.back()->Write(data.substr(at, 1 << 20),
                                     at == 0 ? names[i % 4] : ""));
    }
  }
  // 2. Meanwhile others push oversized uploads: refused (busy, or over the
  // limit), never buffered beyond it.
  std::vector<std::thread> pushers;
  std::atomic<int> refused{0};
  for (int i = 0; i < kPushers; ++i) {
    pushers.emplace_back([&, i] {
      RawUpload upload(stub.get(), std::chrono::seconds(60));
      if (i % 2 == 0) {
        upload.Write(std::string(size_t{32} << 20, 'x'),
                     "huge.obj");  // one message
      } else {
        for (int mb = 0;
             mb < 12 && upload.Write(std::string(1 << 20, 'y'), "big.off");
             ++mb) {
        }
      }
      const grpc::Status status = upload.Finish(/*close=*/true);
      if (status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED)
        ++refused;
    });
  }
  for (std::thread& t : pushers) t.join();
  EXPECT_EQ(refused.load(), kPushers);
  const int64_t uploads_peak = PeakResidentBytes(process.pid());

  // 3. The held uploads complete and are parsed, one after another.
  for (auto& upload : held) {
    const grpc::Status status = upload->Finish(/*close=*/true);
    EXPECT_FALSE(status.ok());
    EXPECT_TRUE(status.error_code() == grpc::StatusCode::INVALID_ARGUMENT ||
                status.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED)
        << status.error_code() << " " << status.error_message();
  }
  const int64_t parse_peak = PeakResidentBytes(process.pid());
  std::fprintf(stderr,
               "VmHWM baseline %.1f MiB; +%.1f MiB holding %d uploads of %.1f "
               "MiB; +%.1f "
               "MiB after parsing them\n",
               baseline / 1048576.0, (uploads_peak - baseline) / 1048576.0,
               kConcurrent, held_bytes / 1048576.0,
               (parse_peak - baseline) / 1048576.0);
  // Uploads, from the code: each admitted call's buffer is at most
  // kMaxMesh (reserved once, never reallocated), and every call, admitted
  // or refused, holds at most one message gRPC accepted: main.cc caps a
  // message at min(max-mesh-bytes, 4 MiB) + 64 KiB.
  const int64_t max_message =
      std::min<int64_t>(kMaxMesh, int64_t{4} << 20) + (64 << 10);
  const int64_t upload_bound =
      kConcurrent * kMaxMesh + (kConcurrent + kPushers) * max_message;
  const std::string figures = absl::StrFormat(
      "measured VmHWM baseline %.1f MiB, growth %.1f MiB holding the uploads, "
      "%.1f MiB after "
      "parsing; upload bound %.1f MiB",
      baseline / 1048576.0, (uploads_peak - baseline) / 1048576.0,
      (parse_peak - baseline) / 1048576.0, upload_bound / 1048576.0);
  if (kAddressSanitizer) {
    // ASan's allocator keeps freed memory in quarantine and adds redzones
    // and shadow memory, so VmHWM measures ASan, not the server's buffers
    // (seen: 167 MiB growth against a 129 MiB bound). The refusals above
    // are still checked; the bound is checked by the plain build.
    std::fprintf(stderr, "AddressSanitizer: memory bounds not checked; %s\n",
                 figures.c_str());
  } else {
    EXPECT_LE(uploads_peak - baseline, upload_bound) << figures;
    // Parsing: the test finishes the held uploads one after another, so
    // one is parsed while the others are still held. Intake documents no
    // memory multiple of its input (only max_vertices / max_faces), so this
    // is an allowance, not a guarantee: 16x the upload for the mesh being
    // parsed (the issue measured 14x before intake refused lying counts
    // early).
    EXPECT_LE(parse_peak - baseline, upload_bound + 16 * kMaxMesh) << figures;
  }
  held.clear();
  stub.reset();
  channel.reset();
  EXPECT_EQ(process.Stop(SIGTERM), 0);
}

// An out-of-range cycle_min_vertices is refused naming that option (the
// one the caller set) and its range, not the library's internal hop limit.
TEST_F(ExtractorServiceTest, CycleMinVerticesErrorNamesTheProtoOption) {
  const std::string off = GeneratedOff("biped_adult", 0, 1000);
  v1::ExtractOptions options;
  options.set_cycle_min_vertices(10);
  absl::StatusOr<v1::ExtractResponse> r =
      client_->ExtractBytes(off, "a.off", options);
  ASSERT_TRUE(absl::IsInvalidArgument(r.status())) << r.status();
  EXPECT_NE(r.status().message().find("options.cycle_min_vertices"),
            absl::string_view::npos)
      << r.status();
  EXPECT_NE(r.status().message().find("got 10"), absl::string_view::npos)
      << r.status();
  EXPECT_EQ(r.status().message().find("hops must"), absl::string_view::npos)
      << r.status();
  options.set_cycle_min_vertices(5);  // the largest accepted value
  EXPECT_TRUE(client_->ExtractBytes(off, "a.off", options).ok());
}

// ExtractFile streams the file as it reads it: from a FIFO whose writer
// offers 16 MiB, an upload refused at the server's 1.5 MiB limit stops the
// reading after a few chunks. Reading the whole file first would drain all
// 16 MiB before sending anything.
TEST_F(ExtractorServiceTest, ExtractFileStreamsInsteadOfReadingTheWholeFile) {
  TearDown();
  ServiceOptions options;
  options.max_mesh_bytes = 3 << 19;  // 1.5 MiB
  StartWith(options);
  testing::TempDir dir;
  const std::string fifo = dir.path() + "/mesh.off";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  signal(SIGPIPE, SIG_IGN);
  std::atomic<int64_t> written{0};
  std::thread writer([&] {
    const int fd = open(fifo.c_str(), O_WRONLY);
    if (fd < 0) return;
    const std::string block(64 << 10, '0');
    // Stops when the reader closes (EPIPE) or after 16 MiB.
    while (written.load() < (int64_t{16} << 20)) {
      const ssize_t n = write(fd, block.data(), block.size());
      if (n <= 0) break;
      written += n;
    }
    close(fd);
  });
  absl::StatusOr<v1::ExtractResponse> r = client_->ExtractFile(fifo);
  writer.join();
  EXPECT_TRUE(absl::IsResourceExhausted(r.status())) << r.status();
  EXPECT_LT(written.load(), int64_t{8} << 20)
      << "ExtractFile read " << written.load() << " bytes before the refusal";
  // A missing file is NOT_FOUND.
  EXPECT_TRUE(absl::IsNotFound(
      client_->ExtractFile(dir.path() + "/none.off").status()));
}

}  // namespace
}  // namespace tpr::extractor
