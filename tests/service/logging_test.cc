// Logs, request ids and health (common/logging.h, call_interceptor.h,
// health.h): through the real tpr-indexer with --log-format=json, a client's
// x-request-id comes back in the trailing metadata and appears in the call's
// log line; a missing or malformed one is replaced by a generated id; the
// API key never reaches the log. Liveness ("") and readiness
// ("tpr.v1.Indexer") are SERVING once the binary serves; in-process, the
// readiness check drives the per-service status and draining turns it off;
// while a service loads, a stand-in on its port reports alive-not-ready and
// refuses calls with UNAVAILABLE, and the real server takes the port over
// without closing it.
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>

#include <atomic>
#include <mutex>
#include <string>
#include <thread>

#include "absl/strings/ascii.h"
#include "absl/strings/str_split.h"
#include "common/server_lifecycle.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/ops_testing.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::testing {
namespace {

std::string TrailingRequestId(const grpc::ClientContext& context) {
  auto it = context.GetServerTrailingMetadata().find("x-request-id");
  if (it == context.GetServerTrailingMetadata().end()) return "";
  return std::string(it->second.data(), it->second.size());
}

// The log line (JSON) that carries `request_id`, or "".
std::string LineWith(const std::string& log, const std::string& request_id) {
  for (absl::string_view line : absl::StrSplit(log, '\n')) {
    if (line.find(absl::StrCat("\"request_id\":\"", request_id, "\"")) !=
        absl::string_view::npos) {
      return std::string(line);
    }
  }
  return "";
}

bool IsHexId(const std::string& id) {
  if (id.size() != 16) return false;
  for (char c : id) {
    if (!absl::ascii_isxdigit(static_cast<unsigned char>(c))) return false;
  }
  return true;
}

TEST(LoggingTest, RequestIdsComeBackAndJsonLinesCarryThem) {
  TempDir dir;
  ServiceProcess indexer;
  ASSERT_TRUE(
      indexer
          .Start(BinaryPath("tpr-indexer"),
                 {"--data-dir", dir.path() + "/data", "--log-format", "json"},
                 dir.path() + "/indexer.log")
          .ok());
  auto channel = grpc::CreateChannel(indexer.address(),
                                     grpc::InsecureChannelCredentials());
  auto stub = tpr::v1::Indexer::NewStub(channel);

  // A client id travels back; the API key header never reaches the log.
  grpc::ClientContext stats_context;
  stats_context.AddMetadata("x-request-id", "test-req-42");
  stats_context.AddMetadata("authorization", "Bearer tpr_NEVER_LOGGED");
  tpr::v1::StatsResponse stats;
  ASSERT_TRUE(
      stub->Stats(&stats_context, tpr::v1::StatsRequest(), &stats).ok());
  EXPECT_EQ(TrailingRequestId(stats_context), "test-req-42");

  // No id: one is generated (16 hex digits) and returned.
  grpc::ClientContext get_context;
  tpr::v1::GetRequest get;
  get.set_id("no/such/model");
  tpr::v1::Model model;
  EXPECT_EQ(stub->Get(&get_context, get, &model).error_code(),
            grpc::StatusCode::NOT_FOUND);
  const std::string generated = TrailingRequestId(get_context);
  EXPECT_TRUE(IsHexId(generated)) << generated;

  // A malformed id (a space and a quote could forge log lines) is replaced.
  grpc::ClientContext bad_context;
  bad_context.AddMetadata("x-request-id", "evil\" id");
  ASSERT_TRUE(stub->Stats(&bad_context, tpr::v1::StatsRequest(), &stats).ok());
  const std::string replaced = TrailingRequestId(bad_context);
  EXPECT_TRUE(IsHexId(replaced)) << replaced;

  ASSERT_EQ(indexer.Stop(SIGTERM), 0);
  const std::string log = ReadText(indexer.log_path());
  const std::string stats_line = LineWith(log, "test-req-42");
  ASSERT_FALSE(stats_line.empty()) << log;
  EXPECT_EQ(stats_line.front(), '{');
  EXPECT_EQ(stats_line.back(), '}');
  EXPECT_NE(stats_line.find("\"service\":\"tpr-indexer\""), std::string::npos)
      << stats_line;
  EXPECT_NE(stats_line.find("\"rpc\":\"/tpr.v1.Indexer/Stats\""),
            std::string::npos)
      << stats_line;
  EXPECT_NE(stats_line.find("\"status\":\"OK\""), std::string::npos)
      << stats_line;
  EXPECT_NE(stats_line.find("\"peer\":\"ipv4:127.0.0.1:"), std::string::npos)
      << stats_line;
  EXPECT_NE(stats_line.find("\"duration_ms\":"), std::string::npos)
      << stats_line;
  const std::string get_line = LineWith(log, generated);
  EXPECT_NE(get_line.find("\"status\":\"NOT_FOUND\""), std::string::npos)
      << log;
  EXPECT_NE(get_line.find("\"rpc\":\"/tpr.v1.Indexer/Get\""), std::string::npos)
      << get_line;
  EXPECT_FALSE(LineWith(log, replaced).empty()) << log;
  EXPECT_EQ(log.find("NEVER_LOGGED"), std::string::npos) << log;
  EXPECT_EQ(log.find("evil"), std::string::npos) << log;
  // Every line of the log is one JSON object.
  for (absl::string_view line : absl::StrSplit(log, '\n', absl::SkipEmpty())) {
    EXPECT_TRUE(line.front() == '{' && line.back() == '}') << line;
  }
}

TEST(LoggingTest, BinaryReportsLivenessAndReadiness) {
  TempDir dir;
  ServiceProcess extractor;
  ASSERT_TRUE(extractor
                  .Start(BinaryPath("tpr-extractor"), {"--no-log-calls"},
                         dir.path() + "/e.log")
                  .ok());
  ServiceProcess indexer;
  ASSERT_TRUE(indexer
                  .Start(BinaryPath("tpr-indexer"),
                         {"--data-dir", dir.path() + "/data"},
                         dir.path() + "/i.log")
                  .ok());
  auto e = grpc::CreateChannel(extractor.address(),
                               grpc::InsecureChannelCredentials());
  auto i = grpc::CreateChannel(indexer.address(),
                               grpc::InsecureChannelCredentials());
  EXPECT_EQ(HealthStatus(e, "").value_or(-1), 1);
  EXPECT_EQ(HealthStatus(e, "tpr.v1.Extractor").value_or(-1), 1);
  EXPECT_EQ(HealthStatus(i, "").value_or(-1), 1);
  EXPECT_EQ(HealthStatus(i, "tpr.v1.Indexer").value_or(-1), 1);
  EXPECT_EQ(HealthStatus(i, "tpr.v1.Nothing").status().code(),
            absl::StatusCode::kNotFound);
  // The indexer answered health checks while it loaded, on the same port.
  EXPECT_NE(
      ReadText(dir.path() + "/i.log")
          .find(absl::StrCat(
              "not ready: loading the data directory; health answers on port ",
              indexer.address().substr(indexer.address().rfind(':') + 1))),
      std::string::npos)
      << ReadText(dir.path() + "/i.log");
}

TEST(LoggingTest, WhileLoadingAliveNotReadyAndThePortIsHandedOver) {
  common::ServerOptions options;
  options.readiness_service = "tpr.v1.Indexer";
  options.log_name = "loading-test";
  absl::StatusOr<std::unique_ptr<common::LoadingServer>> loading =
      common::StartLoadingServer(options, "loading the data directory");
  ASSERT_TRUE(loading.ok()) << loading.status();
  const std::string address = absl::StrCat("127.0.0.1:", (*loading)->port);
  auto channel =
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  EXPECT_EQ(HealthStatus(channel, "").value_or(-1), 1) << "alive";
  EXPECT_EQ(HealthStatus(channel, "tpr.v1.Indexer").value_or(-1), 2)
      << "not ready";
  auto stub = tpr::v1::Indexer::NewStub(channel);
  {
    grpc::ClientContext context;
    tpr::v1::StatsResponse stats;
    const grpc::Status status = stub->Stats(&context, {}, &stats);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_EQ(status.error_message(),
              "loading-test is not ready: loading the data directory");
  }
  // The port is exclusive: the real server cannot bind it while the
  // stand-in holds it, and takes it once the stand-in is gone.
  options.listen_address =
      common::ListenAddressWithPort("127.0.0.1:0", (*loading)->port);
  EXPECT_EQ(options.listen_address, address);
  const int port = (*loading)->port;
  absl::StatusOr<common::StartedServer> shared =
      common::StartServer(options, {});
  EXPECT_EQ(shared.status().code(), absl::StatusCode::kUnavailable);
  loading->reset();
  absl::StatusOr<common::StartedServer> started =
      common::StartServer(options, {});
  ASSERT_TRUE(started.ok()) << started.status();
  EXPECT_EQ(started->port, port);
  // From now on the same address (same channel, reconnecting) is ready.
  bool ready = false;
  for (int i = 0; i < 200 && !ready; ++i) {
    ready = HealthStatus(channel, "tpr.v1.Indexer").value_or(-1) == 1;
    if (!ready) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(ready);
  common::ShutdownGracefully(*started, options);
}

TEST(LoggingTest, ReadinessFollowsTheCheckAndDrainingEndsIt) {
  std::mutex mu;
  std::string reason = "loading";
  common::ServerOptions options;
  options.readiness_service = "tpr.v1.Test";
  options.readiness_poll_ms = 10;
  options.readiness_check = [&] {
    std::lock_guard<std::mutex> lock(mu);
    return reason;
  };
  absl::StatusOr<common::StartedServer> started =
      common::StartServer(options, {});
  ASSERT_TRUE(started.ok()) << started.status();
  auto channel = grpc::CreateChannel(absl::StrCat("127.0.0.1:", started->port),
                                     grpc::InsecureChannelCredentials());
  auto wait_for = [&](int want) {
    for (int i = 0; i < 500; ++i) {
      if (HealthStatus(channel, "tpr.v1.Test").value_or(-1) == want)
        return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return false;
  };
  // Not ready from the very first probe (the constructor polls once).
  EXPECT_EQ(HealthStatus(channel, "tpr.v1.Test").value_or(-1), 2);
  EXPECT_EQ(HealthStatus(channel, "").value_or(-1), 1)
      << "liveness stays SERVING";
  {
    std::lock_guard<std::mutex> lock(mu);
    reason = "";
  }
  EXPECT_TRUE(wait_for(1));
  {
    std::lock_guard<std::mutex> lock(mu);
    reason = "disk full";
  }
  EXPECT_TRUE(wait_for(2));
  {
    std::lock_guard<std::mutex> lock(mu);
    reason = "";
  }
  EXPECT_TRUE(wait_for(1));
  // Draining: readiness off at once, liveness still on until shutdown.
  started->readiness->Stop();
  EXPECT_EQ(HealthStatus(channel, "tpr.v1.Test").value_or(-1), 2);
  EXPECT_EQ(HealthStatus(channel, "").value_or(-1), 1);
  common::ShutdownGracefully(*started, options);
}

}  // namespace
}  // namespace tpr::testing
