// tpr-gateway's operations part through the real binaries on
// loopback: two tpr-indexer shards that demand TLS and API keys, a
// tpr-gateway that serves TLS and checks keys itself and reaches the shards
// with its own client TLS options and key (--shard-tls, --shard-tls-ca,
// TPR_GATEWAY_SHARD_API_KEY). Checked: the caller's key codes at the gateway
// (none, unknown, too low a role, enough), a plaintext caller refused, a
// gateway without a shard key getting the shards' UNAUTHENTICATED; the
// request id of a call (the caller's or a generated one) returned in the
// gateway's trailing metadata and found in the JSON log lines of the
// gateway and of the shards that served it; and the gateway's /metrics
// after known calls (per-shard latency counts equal to the calls each shard
// got, per-shard errors with their code). Also a follower tpr-indexer
// reaching its TLS primary with its own TLS options and key.
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <map>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "common/auth.h"
#include "indexer/gateway/shard_map.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"
#include "tests/service/ops_testing.h"
#include "tpr/client.h"

namespace tpr::testing {
namespace {

using common::Role;

constexpr int kShards = 2;

std::string TrailingRequestId(const grpc::ClientContext& context) {
  auto it = context.GetServerTrailingMetadata().find("x-request-id");
  if (it == context.GetServerTrailingMetadata().end()) return "";
  return std::string(it->second.data(), it->second.size());
}

// The JSON log lines of `log` that carry `request_id`.
std::vector<std::string> LinesWith(const std::string& log,
                                   const std::string& request_id) {
  std::vector<std::string> out;
  for (absl::string_view line : absl::StrSplit(log, '\n')) {
    if (line.find(absl::StrCat("\"request_id\":\"", request_id, "\"")) !=
        absl::string_view::npos) {
      out.emplace_back(line);
    }
  }
  return out;
}

class GatewayOpsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(MakeCertificates(dir_.path())) << "openssl failed";
    for (Role role : {Role::kRead, Role::kWrite, Role::kAdmin}) {
      absl::StatusOr<std::string> key = common::NewApiKey();
      ASSERT_TRUE(key.ok());
      keys_[role] = *key;
    }
    std::string text;
    for (const auto& [role, key] : keys_) {
      absl::StrAppend(&text, common::KeyFileLine(key, role, "test"), "\n");
    }
    WriteFile(Path("keys"), text);
    for (int s = 0; s < kShards; ++s) {
      ASSERT_TRUE(shards_[s]
                      .Start(BinaryPath("tpr-indexer"),
                             {"--data-dir", Path(absl::StrCat("shard", s)),
                              "--api-keys", Path("keys"), "--tls-cert",
                              Path("server1.pem"), "--tls-key",
                              Path("server1.key"), "--log-format", "json"},
                             ShardLog(s))
                      .ok())
          << ReadText(ShardLog(s));
    }
  }

  std::string Path(const std::string& name) const {
    return dir_.path() + "/" + name;
  }
  std::string ShardLog(int s) const {
    return Path(absl::StrCat("shard", s, ".log"));
  }

  // Starts a gateway over the shards with `shard_key` (none when empty) in
  // its environment; TLS and keys on its own port, metrics on a free port.
  void StartGateway(ServiceProcess* gateway, const std::string& name,
                    const std::string& shard_key) {
    std::vector<std::string> args;
    for (int s = 0; s < kShards; ++s) {
      args.push_back("--shard");
      args.push_back(shards_[s].address());
    }
    for (const char* a :
         {"--shard-tls", "--log-format", "json", "--metrics-listen",
          "127.0.0.1:0", "--health-interval-ms", "200"}) {
      args.emplace_back(a);
    }
    for (const std::string& a :
         {std::string("--shard-tls-ca"), Path("ca1.pem"),
          std::string("--api-keys"), Path("keys"), std::string("--tls-cert"),
          Path("server1.pem"), std::string("--tls-key"), Path("server1.key")}) {
      args.push_back(a);
    }
    // The key reaches the child through its environment, as in production
    // (a flag would show in ps).
    if (shard_key.empty()) {
      unsetenv("TPR_GATEWAY_SHARD_API_KEY");
    } else {
      setenv("TPR_GATEWAY_SHARD_API_KEY", shard_key.c_str(), 1);
    }
    const std::string log = Path(name + ".log");
    absl::Status started = gateway->Start(BinaryPath("tpr-gateway"), args, log);
    unsetenv("TPR_GATEWAY_SHARD_API_KEY");
    ASSERT_TRUE(started.ok()) << started << ReadText(log);
    logs_[gateway] = log;
  }

  // An SDK client of `gateway` over TLS with `key` (none when empty).
  client::IndexerClient Client(const ServiceProcess& gateway,
                               const std::string& key) {
    client::ConnectionOptions connection;
    connection.tls = true;
    connection.tls_ca_file = Path("ca1.pem");
    connection.api_key = key;
    client::CallOptions defaults;
    defaults.max_attempts = 1;
    absl::StatusOr<client::IndexerClient> c =
        client::IndexerClient::Connect(gateway.address(), connection, defaults);
    EXPECT_TRUE(c.ok()) << c.status();
    return *c;
  }

  // A raw stub of `gateway` over TLS (for metadata of our own).
  std::unique_ptr<v1::Indexer::Stub> Stub(const ServiceProcess& gateway) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = ReadText(Path("ca1.pem"));
    return v1::Indexer::NewStub(
        grpc::CreateChannel(gateway.address(), grpc::SslCredentials(ssl)));
  }

  std::vector<v1::Model> Models(int n) {
    std::vector<v1::Model> out;
    for (const indexer::testing::TestModel& m :
         indexer::testing::MakeModels(n, 3, 5)) {
      out.push_back(indexer::testing::ToRequest(m).model());
    }
    return out;
  }

  TempDir dir_;
  std::map<Role, std::string> keys_;
  ServiceProcess shards_[kShards];
  std::map<const ServiceProcess*, std::string> logs_;
};

TEST_F(GatewayOpsTest, KeysAreCheckedAtTheGatewayAndItsOwnKeyAtTheShards) {
  ServiceProcess gateway;
  StartGateway(&gateway, "gateway", keys_[Role::kWrite]);
  const std::vector<v1::Model> models = Models(8);

  // The caller's key, checked by the gateway itself.
  EXPECT_EQ(Client(gateway, "").Stats().status().code(),
            absl::StatusCode::kUnauthenticated);
  absl::StatusOr<std::string> stranger = common::NewApiKey();
  ASSERT_TRUE(stranger.ok());
  EXPECT_EQ(Client(gateway, *stranger).Stats().status().code(),
            absl::StatusCode::kUnauthenticated);
  client::IndexerClient reader = Client(gateway, keys_[Role::kRead]);
  EXPECT_EQ(reader.Upsert(models[0], true).status().code(),
            absl::StatusCode::kPermissionDenied);
  EXPECT_EQ(reader.Delete(models[0].id()).code(),
            absl::StatusCode::kPermissionDenied);
  client::IndexerClient writer = Client(gateway, keys_[Role::kWrite]);
  for (const v1::Model& m : models) {
    absl::StatusOr<bool> created = writer.Upsert(m, true);
    ASSERT_TRUE(created.ok()) << created.status();
  }
  absl::StatusOr<v1::StatsResponse> stats = reader.Stats();
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->models(), static_cast<int64_t>(models.size()));
  ASSERT_EQ(stats->shards_size(), kShards);
  for (int s = 0; s < kShards; ++s) {
    int64_t want = 0;
    for (const v1::Model& m : models)
      want += gateway::ShardOf(m.id(), kShards) == s;
    EXPECT_EQ(stats->shards(s).stats().models(), want) << "shard " << s;
  }

  // A plaintext caller against the TLS gateway: refused, no hang.
  client::CallOptions once;
  once.max_attempts = 1;
  absl::StatusOr<client::IndexerClient> plain = client::IndexerClient::Connect(
      gateway.address(), client::ConnectionOptions{}, once);
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(plain->Stats().status().code(), absl::StatusCode::kUnavailable);

  // A gateway without a key of its own: the shards refuse it, and the
  // caller learns which shard said what.
  ServiceProcess keyless;
  StartGateway(&keyless, "keyless", "");
  absl::StatusOr<v1::StatsResponse> refused =
      Client(keyless, keys_[Role::kAdmin]).Stats();
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kUnauthenticated)
      << refused.status();
  EXPECT_NE(refused.status().message().find("shard 0"), absl::string_view::npos)
      << refused.status();
  // Its metrics count the shard's refusals per shard and code: the call's
  // and the start-up check's (each shard's place, indexer/gateway/main.cc).
  const int port = MetricsPort(ReadText(logs_[&keyless]));
  ASSERT_GT(port, 0);
  const ShellResult m = ScrapeMetrics(port);
  ASSERT_EQ(m.exit_code, 0) << m.out;
  EXPECT_EQ(Sample(m.out, "tpr_gateway_shard_errors_total",
                   {"shard=\"0\"", "method=\"/tpr.v1.Indexer/Stats\"",
                    "code=\"UNAUTHENTICATED\""}),
            2)
      << m.out;
}

// A follower reaches a primary that demands TLS and keys with the same
// options as every other client (--follow-tls, --follow-tls-ca, the key in
// TPR_INDEXER_FOLLOW_API_KEY): with an admin key it copies and tails it;
// with too low a role it stops with the primary's PERMISSION_DENIED in its
// log, never copying anything.
TEST_F(GatewayOpsTest, AFollowerReachesItsTlsPrimaryWithItsKey) {
  const std::vector<v1::Model> models = Models(10);
  client::IndexerClient primary = Client(shards_[0], keys_[Role::kWrite]);
  for (size_t i = 0; i < 6; ++i)
    ASSERT_TRUE(primary.Upsert(models[i], true).ok());

  auto start_follower = [&](ServiceProcess* follower, const std::string& name,
                            Role role) {
    setenv("TPR_INDEXER_FOLLOW_API_KEY", keys_[role].c_str(), 1);
    absl::Status started = follower->Start(
        BinaryPath("tpr-indexer"),
        {"--data-dir", Path(name), "--follow", shards_[0].address(),
         "--follow-tls", "--follow-tls-ca", Path("ca1.pem"),
         "--follow-tls-server-name", "localhost"},
        Path(name + ".log"));
    unsetenv("TPR_INDEXER_FOLLOW_API_KEY");
    return started;
  };
  ServiceProcess follower;
  absl::Status started = start_follower(&follower, "follower", Role::kAdmin);
  ASSERT_TRUE(started.ok()) << started << ReadText(Path("follower.log"));
  std::shared_ptr<grpc::Channel> channel = grpc::CreateChannel(
      follower.address(), grpc::InsecureChannelCredentials());
  auto follower_models = [&]() -> int64_t {
    absl::StatusOr<client::IndexerClient> c = client::IndexerClient::Connect(
        follower.address(), client::ConnectionOptions{});
    if (!c.ok()) return -1;
    absl::StatusOr<v1::StatsResponse> stats = c->Stats();
    return stats.ok() ? stats->models() : -1;
  };
  auto wait_for = [](auto pred) {
    const auto give_up =
        std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (std::chrono::steady_clock::now() < give_up && !pred()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return pred();
  };
  ASSERT_TRUE(wait_for([&] {
    absl::StatusOr<int> health = HealthStatus(channel, "tpr.v1.Indexer");
    return health.ok() && *health == 1;  // SERVING: copied and caught up
  })) << ReadText(Path("follower.log"));
  EXPECT_EQ(follower_models(), 6);
  for (size_t i = 6; i < models.size(); ++i)
    ASSERT_TRUE(primary.Upsert(models[i], true).ok());
  EXPECT_TRUE(wait_for([&] { return follower_models() == 10; }))
      << ReadText(Path("follower.log"));
  EXPECT_EQ(follower.Stop(SIGTERM), 0);

  // A write key is not enough to copy a primary.
  ServiceProcess refused;
  started = start_follower(&refused, "refused", Role::kWrite);
  if (started.ok()) {  // it may exit before or after reporting its port
    EXPECT_NE(refused.Stop(0, std::chrono::seconds(30)), 0);
  }
  const std::string log = ReadText(Path("refused.log"));
  EXPECT_NE(log.find("PERMISSION_DENIED"), std::string::npos) << log;
  EXPECT_NE(log.find("cannot copy a checkpoint"), std::string::npos) << log;
}

// Readiness through the real binary: a follower that has not copied its
// primary yet (here none listens at the address, so it keeps retrying) is
// alive ("" SERVING) but not ready (tpr.v1.Indexer NOT_SERVING), so a load
// balancer or the gateway sends it nothing; AFollowerReachesItsTlsPrimary...
// above sees it turn SERVING once it has copied and caught up.
TEST_F(GatewayOpsTest, AFollowerIsAliveButNotReadyUntilItHasCopiedItsPrimary) {
  const std::string nowhere =
      absl::StrCat("127.0.0.1:", ::tpr::testing::FreePort());
  const std::string listen =
      absl::StrCat("127.0.0.1:", ::tpr::testing::FreePort());
  ServiceProcess follower;
  // The real server, and its "(port N)" line, come only after the copy;
  // meanwhile the loading server answers probes on `listen`.
  ASSERT_TRUE(follower
                  .Launch(BinaryPath("tpr-indexer"),
                          {"--data-dir", Path("lonely"), "--follow", nowhere},
                          Path("lonely.log"), listen)
                  .ok());
  std::shared_ptr<grpc::Channel> channel =
      grpc::CreateChannel(listen, grpc::InsecureChannelCredentials());
  // Bounded wait for the loading server to listen.
  absl::StatusOr<int> ready = absl::UnavailableError("not asked yet");
  for (int i = 0; i < 300 && !ready.ok(); ++i) {
    ready = HealthStatus(channel, "tpr.v1.Indexer");
    if (!ready.ok())
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(ready.ok()) << ready.status() << ReadText(Path("lonely.log"));
  for (int i = 0; i < 5; ++i) {  // over a second: several copy attempts
    absl::StatusOr<int> live = HealthStatus(channel, "");
    ready = HealthStatus(channel, "tpr.v1.Indexer");
    ASSERT_TRUE(live.ok()) << live.status();
    ASSERT_TRUE(ready.ok()) << ready.status();
    EXPECT_EQ(*live, 1) << "liveness: SERVING";
    EXPECT_EQ(*ready, 2) << "readiness: NOT_SERVING before the copy";
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
  }
  const std::string log = ReadText(Path("lonely.log"));
  EXPECT_NE(log.find("cannot copy a checkpoint of " + nowhere),
            std::string::npos)
      << log;
  EXPECT_EQ(log.find("(port "), std::string::npos)
      << "no real server before the copy";
  follower.Stop(SIGTERM);
}

TEST_F(GatewayOpsTest, RequestIdTravelsToTheShardsAndBack) {
  ServiceProcess gateway;
  StartGateway(&gateway, "gateway", keys_[Role::kWrite]);
  const std::vector<v1::Model> models = Models(6);
  client::IndexerClient writer = Client(gateway, keys_[Role::kWrite]);
  for (const v1::Model& m : models) ASSERT_TRUE(writer.Upsert(m, true).ok());
  std::unique_ptr<v1::Indexer::Stub> stub = Stub(gateway);

  // The caller's id, on a search (every shard gets a stream).
  const std::string id = "gw-ops-test-1234";
  {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + keys_[Role::kRead]);
    context.AddMetadata("x-request-id", id);
    v1::SearchRequest request;
    request.set_id(models[0].id());
    request.set_k(3);
    auto reader = stub->Search(&context, request);
    v1::SearchResponse item;
    int neighbours = 0;
    while (reader->Read(&item)) neighbours += item.has_neighbor();
    const grpc::Status status = reader->Finish();
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(neighbours, 3);
    EXPECT_EQ(TrailingRequestId(context), id);
  }
  // A generated id, on a Get (one shard: the owner).
  std::string generated;
  const int owner = gateway::ShardOf(models[1].id(), kShards);
  {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + keys_[Role::kRead]);
    v1::GetRequest request;
    request.set_id(models[1].id());
    v1::Model model;
    const grpc::Status status = stub->Get(&context, request, &model);
    ASSERT_TRUE(status.ok()) << status.error_message();
    generated = TrailingRequestId(context);
    EXPECT_FALSE(generated.empty());
    EXPECT_NE(generated, id);
  }

  // Log lines are written when calls end; the shards' streams end before
  // the gateway's answer, but allow the files a moment.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const std::vector<std::string> at_gateway =
      LinesWith(ReadText(logs_[&gateway]), id);
  ASSERT_EQ(at_gateway.size(), 1u) << ReadText(logs_[&gateway]);
  EXPECT_NE(at_gateway[0].find("\"rpc\":\"/tpr.v1.Indexer/Search\""),
            std::string::npos)
      << at_gateway[0];
  // The search by id: a Get on the owner, then a Search on every shard.
  int searches = 0;
  for (int s = 0; s < kShards; ++s) {
    for (const std::string& line : LinesWith(ReadText(ShardLog(s)), id)) {
      searches +=
          line.find("\"rpc\":\"/tpr.v1.Indexer/Search\"") != std::string::npos;
    }
    EXPECT_FALSE(LinesWith(ReadText(ShardLog(s)), id).empty()) << "shard " << s;
  }
  EXPECT_EQ(searches, kShards);
  EXPECT_EQ(LinesWith(ReadText(logs_[&gateway]), generated).size(), 1u);
  EXPECT_EQ(LinesWith(ReadText(ShardLog(owner)), generated).size(), 1u)
      << ReadText(ShardLog(owner));
  EXPECT_TRUE(LinesWith(ReadText(ShardLog(1 - owner)), generated).empty());
  // No key ever reaches a log.
  for (const std::string& log :
       {ReadText(logs_[&gateway]), ReadText(ShardLog(0))}) {
    for (const auto& [role, key] : keys_)
      EXPECT_EQ(log.find(key), std::string::npos);
  }
}

TEST_F(GatewayOpsTest, MetricsCountEachShardsCalls) {
  ServiceProcess gateway;
  StartGateway(&gateway, "gateway", keys_[Role::kWrite]);
  const std::vector<v1::Model> models = Models(10);
  client::IndexerClient writer = Client(gateway, keys_[Role::kWrite]);
  std::vector<int> upserts(kShards, 0);
  for (const v1::Model& m : models) {
    const auto upserted = writer.Upsert(m, true);
    ASSERT_TRUE(upserted.ok()) << upserted.status();
    ++upserts[static_cast<size_t>(gateway::ShardOf(m.id(), kShards))];
  }
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(writer.Stats().ok());
  EXPECT_EQ(writer.Get("no/such/model").status().code(),
            absl::StatusCode::kNotFound);

  const int port = MetricsPort(ReadText(logs_[&gateway]));
  ASSERT_GT(port, 0) << ReadText(logs_[&gateway]);
  const ShellResult m = ScrapeMetrics(port);
  ASSERT_EQ(m.exit_code, 0) << m.out;
  for (int s = 0; s < kShards; ++s) {
    const std::string shard = absl::StrCat("shard=\"", s, "\"");
    EXPECT_EQ(Sample(m.out, "tpr_gateway_shard_duration_seconds_count",
                     {shard, "method=\"/tpr.v1.Indexer/Upsert\""}),
              upserts[static_cast<size_t>(s)])
        << m.out;
    // The three calls and the start-up check of the shard's place.
    EXPECT_EQ(Sample(m.out, "tpr_gateway_shard_duration_seconds_count",
                     {shard, "method=\"/tpr.v1.Indexer/Stats\""}),
              4);
    EXPECT_GT(Sample(m.out, "tpr_gateway_shard_duration_seconds_sum",
                     {shard, "method=\"/tpr.v1.Indexer/Stats\""}),
              0);
  }
  const int owner = gateway::ShardOf("no/such/model", kShards);
  EXPECT_EQ(
      Sample(m.out, "tpr_gateway_shard_errors_total",
             {absl::StrCat("shard=\"", owner, "\""), "code=\"NOT_FOUND\""}),
      1);
  EXPECT_TRUE(std::isnan(Sample(m.out, "tpr_gateway_shard_errors_total",
                                {"code=\"UNAUTHENTICATED\""})));
  // The gateway's own calls, as every service counts them.
  EXPECT_EQ(Sample(m.out, "tpr_rpc_requests_total",
                   {"method=\"/tpr.v1.Indexer/Upsert\"", "code=\"OK\""}),
            static_cast<double>(models.size()));
  EXPECT_EQ(m.out.find("no/such/model"), std::string::npos)
      << "no per-id labels";
}

}  // namespace
}  // namespace tpr::testing
