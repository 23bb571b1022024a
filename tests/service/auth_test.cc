// API keys and roles (common/auth.h) through the real binaries: the whole
// matrix of caller (no key, malformed header, unknown key, read, write,
// admin) x RPC (every Indexer and Extractor method, health, reflection)
// against an expected table written here independently of the server's;
// reload when the keys file changes and on SIGHUP; bad keys files refused at
// start naming the line; the keys file format and hashing against OpenSSL's
// command-line tool; a server keeps its keys alive after its options are
// gone.
#include "common/auth.h"

#include <fcntl.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/impl/codegen/sync_stream.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <fstream>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/ascii.h"
#include "common/metrics.h"
#include "common/server_lifecycle.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/ops_testing.h"
#include "tpr/v1/extractor.grpc.pb.h"
#include "tpr/v1/indexer.grpc.pb.h"

namespace tpr::testing {
namespace {

using common::Role;

// The RPCs of the matrix, each with the role the contract gives it
// (README, "API keys and roles"); kNone means open to all.
struct Rpc {
  std::string name;
  Role needs;
};
const std::vector<Rpc>& Rpcs() {
  static const auto* const rpcs = new std::vector<Rpc>{
      {"Search", Role::kRead},       {"Get", Role::kRead},
      {"List", Role::kRead},         {"Stats", Role::kRead},
      {"Extract", Role::kRead},      {"Upsert", Role::kWrite},
      {"BatchUpsert", Role::kWrite}, {"Delete", Role::kWrite},
      {"Health", Role::kNone},       {"Reflection", Role::kNone},
      {"GetThumbnail", Role::kRead}, {"GetPreview", Role::kRead},
  };
  return *rpcs;
}

void Authorize(grpc::ClientContext* context, const std::string& header) {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::seconds(20));
  if (!header.empty()) context->AddMetadata("authorization", header);
}

// Calls `rpc` with the authorization header `header` ("" = none); returns
// the status code. Requests are harmless (unknown ids, empty batches), so
// an authorized call ends OK or with a validation code, never an auth one.
grpc::StatusCode Call(const std::string& rpc, const std::string& header,
                      const std::shared_ptr<grpc::Channel>& indexer,
                      const std::shared_ptr<grpc::Channel>& extractor) {
  auto index = tpr::v1::Indexer::NewStub(indexer);
  grpc::ClientContext context;
  Authorize(&context, header);
  if (rpc == "Search") {
    tpr::v1::SearchRequest request;
    request.set_id("no/such/id");
    request.set_k(1);
    auto reader = index->Search(&context, request);
    tpr::v1::SearchResponse response;
    while (reader->Read(&response)) {
    }
    return reader->Finish().error_code();
  }
  if (rpc == "Get") {
    tpr::v1::GetRequest request;
    request.set_id("no/such/id");
    tpr::v1::Model model;
    return index->Get(&context, request, &model).error_code();
  }
  if (rpc == "GetThumbnail") {
    tpr::v1::GetThumbnailRequest request;
    request.set_id("no/such/id");  // NOT_FOUND once past auth
    tpr::v1::Thumbnail thumbnail;
    return index->GetThumbnail(&context, request, &thumbnail).error_code();
  }
  if (rpc == "GetPreview") {
    tpr::v1::GetPreviewRequest request;
    request.set_id("no/such/id");
    auto reader = index->GetPreview(&context, request);
    tpr::v1::PreviewChunk chunk;
    while (reader->Read(&chunk)) {
    }
    return reader->Finish().error_code();
  }
  if (rpc == "List") {
    tpr::v1::ListResponse response;
    return index->List(&context, tpr::v1::ListRequest(), &response)
        .error_code();
  }
  if (rpc == "Stats") {
    tpr::v1::StatsResponse response;
    return index->Stats(&context, tpr::v1::StatsRequest(), &response)
        .error_code();
  }
  if (rpc == "Upsert") {
    tpr::v1::UpsertRequest
        request;  // No model: INVALID_ARGUMENT once past auth.
    tpr::v1::UpsertResponse response;
    return index->Upsert(&context, request, &response).error_code();
  }
  if (rpc == "BatchUpsert") {
    tpr::v1::BatchUpsertResponse response;
    auto writer = index->BatchUpsert(&context, &response);
    writer->WritesDone();
    return writer->Finish().error_code();
  }
  if (rpc == "Delete") {
    tpr::v1::DeleteRequest request;
    request.set_id("no/such/id");
    tpr::v1::DeleteResponse response;
    return index->Delete(&context, request, &response).error_code();
  }
  if (rpc == "Extract") {
    auto stub = tpr::v1::Extractor::NewStub(extractor);
    tpr::v1::ExtractResponse response;
    auto writer = stub->Extract(&context, &response);
    writer->WritesDone();  // No mesh: INVALID_ARGUMENT once past auth.
    return writer->Finish().error_code();
  }
  if (rpc == "Health") {
    absl::StatusOr<int> status = HealthStatus(indexer, "tpr.v1.Indexer");
    return status.ok() ? grpc::StatusCode::OK
                       : static_cast<grpc::StatusCode>(status.status().code());
  }
  if (rpc == "Reflection") {
    // ServerReflectionRequest{list_services = ""} (field 7, a string).
    const grpc::internal::RpcMethod method(
        "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo",
        grpc::internal::RpcMethod::BIDI_STREAMING);
    std::unique_ptr<
        grpc::ClientReaderWriter<grpc::ByteBuffer, grpc::ByteBuffer>>
        stream(grpc::internal::ClientReaderWriterFactory<
               grpc::ByteBuffer, grpc::ByteBuffer>::Create(indexer.get(),
                                                           method, &context));
    const std::string bytes("\x3a\x00", 2);
    grpc::Slice slice(bytes);
    grpc::ByteBuffer request(&slice, 1);
    stream->Write(request);
    stream->WritesDone();
    grpc::ByteBuffer response;
    const bool answered = stream->Read(&response);
    const grpc::Status status = stream->Finish();
    if (status.ok() && !answered) return grpc::StatusCode::INTERNAL;
    return status.error_code();
  }
  ADD_FAILURE() << "unknown rpc " << rpc;
  return grpc::StatusCode::UNKNOWN;
}

class AuthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    keys_path_ = dir_.path() + "/keys";
    for (Role role : {Role::kRead, Role::kWrite, Role::kAdmin}) {
      absl::StatusOr<std::string> key = common::NewApiKey();
      ASSERT_TRUE(key.ok());
      keys_[role] = *key;
    }
    WriteKeys({Role::kRead, Role::kWrite, Role::kAdmin});
  }

  void WriteKeys(const std::vector<Role>& roles) {
    std::string text = "# test keys\n\n";
    for (Role role : roles) {
      absl::StrAppend(&text, common::KeyFileLine(keys_[role], role, "test-key"),
                      "\n");
    }
    WriteFile(keys_path_, text);
  }

  void StartServers() {
    ASSERT_TRUE(indexer_
                    .Start(BinaryPath("tpr-indexer"),
                           {"--data-dir", dir_.path() + "/data", "--api-keys",
                            keys_path_},
                           dir_.path() + "/indexer.log")
                    .ok());
    ASSERT_TRUE(extractor_
                    .Start(BinaryPath("tpr-extractor"),
                           {"--api-keys", keys_path_},
                           dir_.path() + "/extractor.log")
                    .ok());
    indexer_channel_ = grpc::CreateChannel(indexer_.address(),
                                           grpc::InsecureChannelCredentials());
    extractor_channel_ = grpc::CreateChannel(
        extractor_.address(), grpc::InsecureChannelCredentials());
  }

  grpc::StatusCode StatsWith(Role role) {
    return Call("Stats", "Bearer " + keys_[role], indexer_channel_,
                extractor_channel_);
  }

  // Waits up to 10 s for Stats with `role`'s key to return `want`.
  bool EventuallyStats(Role role, grpc::StatusCode want) {
    for (int i = 0; i < 200; ++i) {
      if (StatsWith(role) == want) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  }

  TempDir dir_;
  std::string keys_path_;
  std::map<Role, std::string> keys_;
  ServiceProcess indexer_;
  ServiceProcess extractor_;
  std::shared_ptr<grpc::Channel> indexer_channel_;
  std::shared_ptr<grpc::Channel> extractor_channel_;
};

TEST_F(AuthTest, EveryCallerAgainstEveryRpc) {
  StartServers();
  struct Caller {
    std::string name;
    std::string header;
    Role role;           // kNone: not a valid key.
    bool authenticated;  // false: expect UNAUTHENTICATED for closed RPCs.
  };
  absl::StatusOr<std::string> stranger = common::NewApiKey();
  ASSERT_TRUE(stranger.ok());
  const std::vector<Caller> callers = {
      {"no key", "", Role::kNone, false},
      {"basic scheme", "Basic " + keys_[Role::kAdmin], Role::kNone, false},
      {"unknown key", "Bearer " + *stranger, Role::kNone, false},
      {"read", "Bearer " + keys_[Role::kRead], Role::kRead, true},
      {"write", "Bearer " + keys_[Role::kWrite], Role::kWrite, true},
      {"admin", "Bearer " + keys_[Role::kAdmin], Role::kAdmin, true},
  };
  int checked = 0;
  for (const Caller& caller : callers) {
    for (const Rpc& rpc : Rpcs()) {
      const grpc::StatusCode got =
          Call(rpc.name, caller.header, indexer_channel_, extractor_channel_);
      std::string where =
          absl::StrCat(caller.name, " x ", rpc.name, ": code ", got);
      if (rpc.needs == Role::kNone) {
        EXPECT_EQ(got, grpc::StatusCode::OK) << where;
      } else if (!caller.authenticated) {
        EXPECT_EQ(got, grpc::StatusCode::UNAUTHENTICATED) << where;
      } else if (caller.role < rpc.needs) {
        EXPECT_EQ(got, grpc::StatusCode::PERMISSION_DENIED) << where;
      } else {
        EXPECT_NE(got, grpc::StatusCode::UNAUTHENTICATED) << where;
        EXPECT_NE(got, grpc::StatusCode::PERMISSION_DENIED) << where;
        EXPECT_NE(got, grpc::StatusCode::UNAVAILABLE) << where;
      }
      ++checked;
    }
  }
  EXPECT_EQ(checked, 72);
  // The logs name refusals but never a key.
  ASSERT_EQ(indexer_.Stop(SIGTERM), 0);
  const std::string log = ReadText(indexer_.log_path());
  EXPECT_NE(log.find("PERMISSION_DENIED"), std::string::npos) << log;
  for (const auto& [role, key] : keys_) {
    EXPECT_EQ(log.find(key.substr(4)), std::string::npos)
        << "key of " << RoleName(role);
  }
  EXPECT_EQ(log.find(stranger->substr(4)), std::string::npos);
}

TEST_F(AuthTest, ReloadsWhenTheFileChangesAndOnSighup) {
  WriteKeys({Role::kRead});
  StartServers();
  EXPECT_EQ(StatsWith(Role::kRead), grpc::StatusCode::OK);
  EXPECT_EQ(StatsWith(Role::kWrite), grpc::StatusCode::UNAUTHENTICATED);

  // A changed file is picked up by the watcher.
  WriteKeys({Role::kWrite});
  EXPECT_TRUE(EventuallyStats(Role::kWrite, grpc::StatusCode::OK));
  EXPECT_EQ(StatsWith(Role::kRead), grpc::StatusCode::UNAUTHENTICATED);

  // Same size and the old modification time: only SIGHUP notices.
  struct stat before;
  ASSERT_EQ(stat(keys_path_.c_str(), &before), 0);
  WriteKeys({Role::kAdmin});
  const struct timespec times[2] = {before.st_atim, before.st_mtim};
  ASSERT_EQ(utimensat(AT_FDCWD, keys_path_.c_str(), times, 0), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  EXPECT_EQ(StatsWith(Role::kAdmin), grpc::StatusCode::UNAUTHENTICATED)
      << "watcher fooled";
  ASSERT_EQ(indexer_.Signal(SIGHUP), 0);
  EXPECT_TRUE(EventuallyStats(Role::kAdmin, grpc::StatusCode::OK));
  EXPECT_EQ(StatsWith(Role::kWrite), grpc::StatusCode::UNAUTHENTICATED);

  // A broken file on reload keeps the keys in force.
  WriteFile(keys_path_, "sha256:nothex admin\n");
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  EXPECT_EQ(StatsWith(Role::kAdmin), grpc::StatusCode::OK);
  ASSERT_EQ(indexer_.Stop(SIGTERM), 0);
  EXPECT_NE(ReadText(indexer_.log_path()).find("keeping the current keys"),
            std::string::npos);
}

TEST_F(AuthTest, BadKeysFileRefusedAtStartNamingTheLine) {
  WriteFile(keys_path_, "# ok\n" +
                            common::KeyFileLine("tpr_x", Role::kRead, "") +
                            "\nsha256:abc reader\n");
  const ShellResult r =
      RunShell(absl::StrCat(BinaryPath("tpr-indexer"), " --data-dir ",
                            dir_.path(), "/data --api-keys ", keys_path_));
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("line 3"), std::string::npos) << r.out;
  const ShellResult missing =
      RunShell(absl::StrCat(BinaryPath("tpr-extractor"), " --api-keys ",
                            dir_.path(), "/absent-keys"));
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  EXPECT_NE(missing.out.find("absent-keys"), std::string::npos) << missing.out;
}

TEST_F(AuthTest, TprKeyNewAndTheCommandsKeyFlags) {
  WriteKeys({Role::kRead});
  StartServers();
  // `tpr key new` appends a line and prints the key once.
  const std::string tpr = BinaryPath("tpr");
  const ShellResult made =
      RunShell(absl::StrCat("(", tpr, " key new --role write --keys ",
                            keys_path_, " --name ci 2>/dev/null)"));
  ASSERT_EQ(made.exit_code, 0) << made.out;
  const std::string key(absl::StripAsciiWhitespace(made.out));
  ASSERT_EQ(key.size(), 68u) << made.out;
  const std::string file = ReadText(keys_path_);
  EXPECT_NE(file.find(common::HashApiKey(key) + " write ci"), std::string::npos)
      << file;
  EXPECT_EQ(file.find(key), std::string::npos)
      << "the file holds only the hash";
  EXPECT_NE(
      RunShell(absl::StrCat(tpr, " key new --role root --keys ", keys_path_))
          .exit_code,
      0);

  const std::string at = absl::StrCat(" --indexer ", indexer_.address(), " ");
  // No key: refused, and the message says how to give one.
  ShellResult r = RunShell(tpr + at + "stats");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.out.find("UNAUTHENTICATED"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("TPR_API_KEY"), std::string::npos) << r.out;
  // The new key works from the environment once the watcher reloaded, and
  // -v prints the request id.
  bool ok = false;
  for (int i = 0; i < 100 && !ok; ++i) {
    r = RunShell(absl::StrCat("TPR_API_KEY=", key, " ", tpr, at, "-v stats"));
    ok = r.exit_code == 0;
    if (!ok) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_TRUE(ok) << r.out;
  EXPECT_NE(r.out.find("/tpr.v1.Indexer/Stats: OK request_id="),
            std::string::npos)
      << r.out;
  // A read key from the flag cannot delete.
  r = RunShell(absl::StrCat(tpr, at, "--api-key ", keys_[Role::kRead],
                            " remove some/id"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.out.find("PERMISSION_DENIED"), std::string::npos) << r.out;
  r = RunShell(absl::StrCat(tpr, at, "--api-key ", key, " remove some/id"));
  EXPECT_NE(r.out.find("NOT_FOUND"), std::string::npos) << r.out;

  // The help texts show the security flags: the top level and every
  // subcommand (whose footer lists the global flags).
  for (const char* help :
       {" --help", " query --help", " add --help", " remove --help"}) {
    r = RunShell(tpr + help);
    EXPECT_EQ(r.exit_code, 0) << help;
    for (const char* flag : {"--api-key", "TPR_API_KEY", "--tls", "--tls-ca",
                             "--tls-cert", "--tls-key", "--verbose"}) {
      EXPECT_NE(r.out.find(flag), std::string::npos)
          << help << " lacks " << flag << "\n"
          << r.out;
    }
  }
}

TEST(AuthFormatTest, HashMatchesOpensslAndLinesParse) {
  // Oracle: OpenSSL's command-line digest of the same bytes.
  const ShellResult r = RunShell("printf %s tpr_abc | openssl dgst -sha256 -r");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(common::HashApiKey("tpr_abc"), "sha256:" + r.out.substr(0, 64));

  absl::StatusOr<std::string> key = common::NewApiKey();
  ASSERT_TRUE(key.ok());
  EXPECT_EQ(key->size(), 4u + 64u);
  EXPECT_EQ(key->substr(0, 4), "tpr_");
  absl::StatusOr<std::string> other = common::NewApiKey();
  ASSERT_TRUE(other.ok());
  EXPECT_NE(*key, *other);

  absl::StatusOr<common::KeyTable> table = common::ParseKeyFile(
      "# c\n\n" + common::KeyFileLine(*key, Role::kWrite, "ci job") + "\n");
  ASSERT_TRUE(table.ok()) << table.status();
  ASSERT_EQ(table->size(), 1u);
  EXPECT_EQ(table->at(common::HashApiKey(*key)), Role::kWrite);
  EXPECT_EQ(
      common::ParseKeyFile(common::KeyFileLine(*key, Role::kRead, "") + "\n" +
                           common::KeyFileLine(*key, Role::kAdmin, ""))
          .status()
          .message(),
      "line 2: duplicate key");
  EXPECT_FALSE(
      common::ParseKeyFile("sha256:" + std::string(64, 'a') + " root\n").ok());
  EXPECT_FALSE(
      common::ParseKeyFile("sha256:" + std::string(64, 'A') + " read\n").ok());
  EXPECT_FALSE(
      common::ParseKeyFile("sha256:" + std::string(64, 'a') + "\n").ok());
}

// The auth filter points into the authenticator: a server must keep it
// alive whatever happens to the ServerOptions it was started with (the
// overhead benchmark once crashed on a freed one).
TEST(AuthLifetimeTest, ServerKeepsItsKeysAliveAfterItsOptionsAreGone) {
  TempDir dir;
  absl::StatusOr<std::string> key = common::NewApiKey();
  ASSERT_TRUE(key.ok());
  WriteFile(dir.path() + "/keys",
            common::KeyFileLine(*key, Role::kRead, "") + "\n");
  absl::StatusOr<common::StartedServer> started;
  {
    common::ServerOptions options;
    absl::StatusOr<std::shared_ptr<common::ApiKeyAuthenticator>> keys =
        common::ApiKeyAuthenticator::Open(dir.path() + "/keys", "lifetime-test",
                                          0);
    ASSERT_TRUE(keys.ok()) << keys.status();
    options.api_keys = *keys;
    started = common::StartServer(options, {});
    ASSERT_TRUE(started.ok()) << started.status();
  }
  auto channel = grpc::CreateChannel(absl::StrCat("127.0.0.1:", started->port),
                                     grpc::InsecureChannelCredentials());
  for (const std::string& header :
       {"Bearer " + *key, std::string("Bearer tpr_wrong")}) {
    grpc::ClientContext context;
    context.AddMetadata("authorization", header);
    tpr::v1::StatsResponse stats;
    const grpc::Status status = tpr::v1::Indexer::NewStub(channel)->Stats(
        &context, tpr::v1::StatsRequest(), &stats);
    // The right key passes the filter (no Indexer service here: UNIMPLEMENTED).
    EXPECT_EQ(status.error_code(), header == "Bearer " + *key
                                       ? grpc::StatusCode::UNIMPLEMENTED
                                       : grpc::StatusCode::UNAUTHENTICATED)
        << status.error_message();
  }
  started->server->Shutdown();
}

// Calls the key check refuses never reach a handler or an interceptor;
// they are counted in tpr_rpc_requests_total with their code all the same.
TEST(AuthMetricsTest, RefusedCallsAreCountedWithTheirCode) {
  TempDir dir;
  absl::StatusOr<std::string> key = common::NewApiKey();
  ASSERT_TRUE(key.ok());
  WriteFile(dir.path() + "/keys",
            common::KeyFileLine(*key, Role::kRead, "") + "\n");
  common::ServerOptions options;
  absl::StatusOr<std::shared_ptr<common::ApiKeyAuthenticator>> keys =
      common::ApiKeyAuthenticator::Open(dir.path() + "/keys", "metrics-test",
                                        0);
  ASSERT_TRUE(keys.ok()) << keys.status();
  options.api_keys = *keys;
  options.metrics = std::make_shared<common::Metrics>();
  absl::StatusOr<common::StartedServer> started =
      common::StartServer(options, {});
  ASSERT_TRUE(started.ok()) << started.status();
  auto stub = tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(absl::StrCat("127.0.0.1:", started->port),
                          grpc::InsecureChannelCredentials()));
  for (int i = 0; i < 3; ++i) {
    grpc::ClientContext context;
    tpr::v1::StatsResponse stats;
    EXPECT_EQ(stub->Stats(&context, {}, &stats).error_code(),
              grpc::StatusCode::UNAUTHENTICATED);
  }
  {
    grpc::ClientContext context;
    context.AddMetadata("authorization", "Bearer " + *key);
    tpr::v1::DeleteRequest request;
    tpr::v1::DeleteResponse response;
    EXPECT_EQ(stub->Delete(&context, request, &response).error_code(),
              grpc::StatusCode::PERMISSION_DENIED);
  }
  const std::string scrape = options.metrics->Scrape();
  EXPECT_EQ(
      Sample(scrape, "tpr_rpc_requests_total",
             {"method=\"/tpr.v1.Indexer/Stats\"", "code=\"UNAUTHENTICATED\""}),
      3)
      << scrape;
  EXPECT_EQ(Sample(scrape, "tpr_rpc_requests_total",
                   {"method=\"/tpr.v1.Indexer/Delete\"",
                    "code=\"PERMISSION_DENIED\""}),
            1)
      << scrape;
  common::ShutdownGracefully(*started, options);
}

}  // namespace
}  // namespace tpr::testing