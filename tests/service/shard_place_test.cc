// A shard keeps its place in its gateway's shard map, through the real
// binaries on loopback: two tpr-indexer shards; a tpr-gateway over them in
// one order starts and serves (each shard stores its place on the first
// call); a second gateway over the same shards in the other order refuses
// to start (exit 2, naming the shard's address and its stored place), also
// after a shard restarted; a call claiming another place is
// FAILED_PRECONDITION naming both places; a call without a claim (a client
// of one indexer) is served.
#include <grpcpp/client_context.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "indexer/gateway/shard_map.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"
#include "tests/service/ops_testing.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::testing {
namespace {

// Stats on `address`, claiming `place` (none when empty).
grpc::Status StatsClaiming(const std::string& address,
                           const std::string& place) {
  auto stub = tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(10));
  if (!place.empty()) context.AddMetadata(gateway::kShardPlaceHeader, place);
  tpr::v1::StatsResponse stats;
  return stub->Stats(&context, {}, &stats);
}

class ShardPlaceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_FALSE(dir_.path().empty());
    for (int s = 0; s < 2; ++s) {
      ASSERT_TRUE(StartShard(s).ok());
    }
  }

  // `run` names the log (a fresh one per start: the port is read from it).
  absl::Status StartShard(int s, int run = 0) {
    return shards_[s].Start(
        BinaryPath("tpr-indexer"),
        {"--data-dir", absl::StrCat(dir_.path(), "/d", s)},
        absl::StrCat(dir_.path(), "/shard", s, "-", run, ".log"));
  }

  // Runs a gateway over `order` (indexes into shards_) until it serves or
  // exits; returns its exit code (0 when it served, then stopped).
  int RunGateway(const std::vector<int>& order, const std::string& name,
                 std::string* log_text) {
    std::vector<std::string> args;
    for (int s : order) {
      args.push_back("--shard");
      args.push_back(shards_[s].address());
    }
    ServiceProcess gateway;
    const std::string log = absl::StrCat(dir_.path(), "/", name, ".log");
    const absl::Status started =
        gateway.Start(BinaryPath("tpr-gateway"), args, log);
    int code = 0;
    if (started.ok()) {
      auto stub = tpr::v1::Indexer::NewStub(grpc::CreateChannel(
          gateway.address(), grpc::InsecureChannelCredentials()));
      grpc::ClientContext context;
      tpr::v1::StatsResponse stats;
      const grpc::Status status = stub->Stats(&context, {}, &stats);
      EXPECT_TRUE(status.ok()) << name << ": " << status.error_message();
      code = gateway.Stop(SIGTERM);
      EXPECT_EQ(code, 0) << name;
    } else {
      code = gateway.exit_code();
    }
    *log_text = ReadText(log);
    return code;
  }

  TempDir dir_;
  ServiceProcess shards_[2];
};

TEST_F(ShardPlaceTest, GatewayInTheOtherOrderRefusesToStart) {
  std::string log;
  ASSERT_EQ(RunGateway({0, 1}, "first", &log), 0) << log;
  EXPECT_EQ(RunGateway({0, 1}, "again", &log), 0) << log;
  EXPECT_EQ(RunGateway({1, 0}, "swapped", &log), 2) << log;
  // It names the shard it found first in the wrong place, its address and
  // the place that shard keeps.
  EXPECT_NE(log.find(absl::StrCat("shard 0 (", shards_[1].address(), ")")),
            std::string::npos)
      << log;
  EXPECT_NE(log.find("this indexer is shard 1/2"), std::string::npos) << log;

  // The place is durable: a restarted shard keeps refusing.
  ASSERT_EQ(shards_[1].Stop(SIGTERM), 0);
  ASSERT_TRUE(StartShard(1, /*run=*/1).ok());
  EXPECT_EQ(RunGateway({1, 0}, "swapped_after_restart", &log), 2) << log;
  EXPECT_EQ(RunGateway({0, 1}, "first_after_restart", &log), 0) << log;
}

TEST_F(ShardPlaceTest, ACallClaimingAnotherPlaceIsRefusedNamingBoth) {
  EXPECT_TRUE(StatsClaiming(shards_[0].address(), "0/2").ok());
  const grpc::Status other = StatsClaiming(shards_[0].address(), "1/2");
  EXPECT_EQ(other.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(other.error_message().find("shard 0/2"), std::string::npos)
      << other.error_message();
  EXPECT_NE(other.error_message().find("shard 1/2"), std::string::npos)
      << other.error_message();
  const grpc::Status count = StatsClaiming(shards_[0].address(), "0/3");
  EXPECT_EQ(count.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  // A client of one indexer names no place.
  EXPECT_TRUE(StatsClaiming(shards_[0].address(), "").ok());
  // A malformed claim names the header.
  const grpc::Status bad = StatsClaiming(shards_[1].address(), "2/2");
  EXPECT_EQ(bad.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(bad.error_message().find(gateway::kShardPlaceHeader),
            std::string::npos)
      << bad.error_message();
  // A refused or malformed claim stores nothing: shard 1 takes its first
  // valid one.
  EXPECT_TRUE(StatsClaiming(shards_[1].address(), "1/2").ok());
}

}  // namespace
}  // namespace tpr::testing
