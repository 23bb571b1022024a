// Open defaults are refused (common/server_flags.h, CheckOpenDefaults):
// the rule itself, and through the real binaries: a server asked to listen
// beyond loopback without TLS and API keys, or to serve /metrics beyond
// loopback, exits 2 saying how to fix it; with --insecure it starts and
// logs that it is insecure; on loopback nothing is asked.
#include <gtest/gtest.h>
#include <signal.h>

#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/listen_address.h"
#include "common/server_flags.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/ops_testing.h"

namespace tpr::testing {
namespace {

TEST(OpenDefaultsTest, LoopbackAddresses) {
  for (const char* a : {"127.0.0.1:7002", "127.1.2.3:1", "localhost:80",
                        "[::1]:7002", "unix:/tmp/socket"}) {
    EXPECT_TRUE(common::IsLoopbackAddress(a)) << a;
  }
  for (const char* a : {"0.0.0.0:7002", "[::]:7002", ":7002", "10.0.0.1:7002",
                        "example.com:7002", "127.0.0.1.example.com:1"}) {
    EXPECT_FALSE(common::IsLoopbackAddress(a)) << a;
  }
}

TEST(OpenDefaultsTest, BeyondLoopbackNeedsTlsAndKeysOrInsecure) {
  common::ServerFlags flags;
  EXPECT_TRUE(common::CheckOpenDefaults(flags, "127.0.0.1:7002").ok());
  const absl::Status open = common::CheckOpenDefaults(flags, "0.0.0.0:7002");
  EXPECT_TRUE(absl::IsFailedPrecondition(open)) << open;
  EXPECT_NE(open.message().find("--insecure"), absl::string_view::npos);
  EXPECT_NE(open.message().find("TLS and API keys"), absl::string_view::npos);
  flags.tls.cert_file = "server.pem";
  EXPECT_NE(common::CheckOpenDefaults(flags, "0.0.0.0:7002")
                .message()
                .find("without API keys"),
            absl::string_view::npos);
  flags.api_keys = "keys";
  EXPECT_TRUE(common::CheckOpenDefaults(flags, "0.0.0.0:7002").ok());
  flags.metrics_listen = "0.0.0.0:9102";
  EXPECT_TRUE(absl::IsFailedPrecondition(
      common::CheckOpenDefaults(flags, "0.0.0.0:7002")));
  flags.metrics_listen = "127.0.0.1:9102";
  EXPECT_TRUE(common::CheckOpenDefaults(flags, "0.0.0.0:7002").ok());
  common::ServerFlags insecure;
  insecure.insecure = true;
  insecure.metrics_listen = "0.0.0.0:9102";
  EXPECT_TRUE(common::CheckOpenDefaults(insecure, "0.0.0.0:7002").ok());
}

// Starts `binary` with `args` on `listen`; returns its exit code once it
// exited (it must refuse), -1 when it served instead.
int ExitCodeOf(const std::string& binary, const std::vector<std::string>& args,
               const std::string& listen, const std::string& log) {
  ServiceProcess p;
  if (!p.Launch(binary, args, log, listen).ok()) return -2;
  return p.Stop(0, std::chrono::seconds(20));
}

TEST(OpenDefaultsTest, ServersRefuseToListenOpenly) {
  TempDir dir;
  const std::vector<std::pair<std::string, std::vector<std::string>>> servers =
      {{"tpr-extractor", {"--threads", "1"}},
       {"tpr-indexer", {"--data-dir", dir.path() + "/data"}},
       {"tpr-gateway", {"--shard", "127.0.0.1:1"}},
       {"tpr-web", {"--extractor", "127.0.0.1:1", "--indexer", "127.0.0.1:2"}}};
  for (const auto& [name, args] : servers) {
    const std::string log = absl::StrCat(dir.path(), "/", name, ".log");
    EXPECT_EQ(ExitCodeOf(BinaryPath(name), args, "0.0.0.0:0", log), 2)
        << name << ": " << ReadText(log);
    EXPECT_NE(ReadText(log).find("--insecure"), std::string::npos)
        << name << ": " << ReadText(log);
    std::vector<std::string> metrics = args;
    metrics.insert(metrics.end(), {"--metrics-listen", "0.0.0.0:0"});
    EXPECT_EQ(ExitCodeOf(BinaryPath(name), metrics, "127.0.0.1:0", log), 2)
        << name << ": " << ReadText(log);
    EXPECT_NE(ReadText(log).find("--metrics-listen 0.0.0.0:0"),
              std::string::npos)
        << name << ": " << ReadText(log);
  }
  // Told explicitly, it serves, and says so.
  ServiceProcess insecure;
  const std::string log = dir.path() + "/insecure.log";
  ASSERT_TRUE(insecure
                  .Start(BinaryPath("tpr-extractor"),
                         {"--threads", "1", "--insecure"}, log, "0.0.0.0:0")
                  .ok());
  EXPECT_NE(ReadText(log).find("--insecure: serving 0.0.0.0:0 beyond "
                               "loopback, without TLS, without API keys"),
            std::string::npos)
      << ReadText(log);
  EXPECT_EQ(insecure.Stop(SIGTERM), 0);
}

}  // namespace
}  // namespace tpr::testing
