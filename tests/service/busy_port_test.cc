// Every server refuses an address another process listens on, through the
// real binaries on loopback: a second tpr-extractor, tpr-indexer (with its
// own data directory), tpr-gateway and tpr-web started on the first one's
// port exits non-zero with a message naming the address and the cause, and
// the first keeps serving; likewise a second --metrics-listen on a busy
// metrics port.
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/ops_testing.h"

namespace tpr::testing {
namespace {

// One server binary and the arguments it is started with (twice).
struct ServerCase {
  std::string binary;
  std::vector<std::string> first_args;
  std::vector<std::string> second_args;
};

class BusyPortTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_FALSE(dir_.path().empty());
    ASSERT_TRUE(indexer_
                    .Start(BinaryPath("tpr-indexer"),
                           {"--data-dir", dir_.path() + "/data"},
                           dir_.path() + "/indexer.log")
                    .ok());
    ASSERT_TRUE(extractor_
                    .Start(BinaryPath("tpr-extractor"), {"--threads", "1"},
                           dir_.path() + "/extractor.log")
                    .ok());
  }

  // Starts `second` on `first`'s address and expects it to exit non-zero
  // with "cannot listen on ADDRESS: address already in use", while `first`
  // still answers health checks.
  void ExpectRefused(ServiceProcess& first, const std::string& binary,
                     std::vector<std::string> args, const std::string& name) {
    ServiceProcess second;
    const std::string log = absl::StrCat(dir_.path(), "/", name, ".log");
    ASSERT_TRUE(second.Launch(binary, args, log, first.address()).ok());
    const int code = second.Stop(0, std::chrono::seconds(30));  // waits
    EXPECT_NE(code, 0) << name << ": " << ReadText(log);
    EXPECT_NE(code, -1) << name << " still running: " << ReadText(log);
    EXPECT_NE(
        ReadText(log).find(absl::StrCat("cannot listen on ", first.address(),
                                        ": address already in use")),
        std::string::npos)
        << name << ": " << ReadText(log);
    auto channel = grpc::CreateChannel(first.address(),
                                       grpc::InsecureChannelCredentials());
    if (binary.find("tpr-web") == std::string::npos) {
      EXPECT_EQ(HealthCheck(channel).value_or(-1), 1) << name;
    } else {
      EXPECT_EQ(RunShell(absl::StrCat("curl -sf http://", first.address(),
                                      "/healthz"))
                    .exit_code,
                0)
          << name;
    }
  }

  TempDir dir_;
  ServiceProcess indexer_;
  ServiceProcess extractor_;
};

TEST_F(BusyPortTest, SecondIndexerOnTheSamePortExitsAndTheFirstServes) {
  ExpectRefused(indexer_, BinaryPath("tpr-indexer"),
                {"--data-dir", dir_.path() + "/other"}, "indexer2");
}

TEST_F(BusyPortTest, SecondExtractorOnTheSamePortExitsAndTheFirstServes) {
  ExpectRefused(extractor_, BinaryPath("tpr-extractor"), {"--threads", "1"},
                "extractor2");
}

TEST_F(BusyPortTest, SecondGatewayOnTheSamePortExitsAndTheFirstServes) {
  ServiceProcess gateway;
  ASSERT_TRUE(gateway
                  .Start(BinaryPath("tpr-gateway"),
                         {"--shard", indexer_.address()},
                         dir_.path() + "/gateway.log")
                  .ok());
  ExpectRefused(gateway, BinaryPath("tpr-gateway"),
                {"--shard", indexer_.address()}, "gateway2");
}

TEST_F(BusyPortTest, SecondWebOnTheSamePortExitsAndTheFirstServes) {
  const std::vector<std::string> args = {"--extractor", extractor_.address(),
                                         "--indexer", indexer_.address()};
  ServiceProcess web;
  ASSERT_TRUE(
      web.Start(BinaryPath("tpr-web"), args, dir_.path() + "/web.log").ok());
  ExpectRefused(web, BinaryPath("tpr-web"), args, "web2");
}

TEST_F(BusyPortTest, SecondMetricsListenOnTheSamePortExits) {
  ServiceProcess first;
  ASSERT_TRUE(first
                  .Start(BinaryPath("tpr-extractor"),
                         {"--threads", "1", "--metrics-listen", "127.0.0.1:0"},
                         dir_.path() + "/metrics1.log")
                  .ok());
  const int metrics_port = MetricsPort(ReadText(first.log_path()));
  ASSERT_GT(metrics_port, 0);
  const std::string metrics = absl::StrCat("127.0.0.1:", metrics_port);
  ServiceProcess second;
  const std::string log = dir_.path() + "/metrics2.log";
  ASSERT_TRUE(second
                  .Launch(BinaryPath("tpr-extractor"),
                          {"--threads", "1", "--metrics-listen", metrics}, log,
                          "127.0.0.1:0")
                  .ok());
  const int code = second.Stop(0, std::chrono::seconds(30));
  EXPECT_NE(code, 0) << ReadText(log);
  EXPECT_NE(code, -1) << ReadText(log);
  EXPECT_NE(ReadText(log).find(metrics), std::string::npos) << ReadText(log);
  EXPECT_EQ(ScrapeMetrics(metrics_port).exit_code, 0);
}

}  // namespace
}  // namespace tpr::testing
