// Configuration of the services (common/config.h) through the real
// binaries: --config FILE.toml, TPR_INDEXER_* / TPR_EXTRACTOR_* environment
// variables, the precedence flag > environment > file > default, the error
// for a misspelt key, --print-config (and that its output reads back), and
// the masking of secrets.
#include "common/config.h"

#include <gtest/gtest.h>

#include <map>
#include <string>

#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "common/server_flags.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/ops_testing.h"

namespace tpr::testing {
namespace {

// Parses --print-config output: name -> value as written (comments cut).
std::map<std::string, std::string> ParseConfig(const std::string& text) {
  std::map<std::string, std::string> out;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    if (line.empty() || line[0] == '#') continue;
    const size_t eq = line.find(" = ");
    if (eq == absl::string_view::npos) continue;
    absl::string_view value = line.substr(eq + 3);
    const size_t comment = value.find("  #");
    if (comment != absl::string_view::npos) value = value.substr(0, comment);
    out[std::string(line.substr(0, eq))] = std::string(value);
  }
  return out;
}

TEST(ConfigTest, EnvNameIsPrefixPlusUpperSnake) {
  EXPECT_EQ(common::EnvName("TPR_INDEXER_", "max-k"), "TPR_INDEXER_MAX_K");
  EXPECT_EQ(common::EnvName("TPR_EXTRACTOR_", "max-mesh-bytes"),
            "TPR_EXTRACTOR_MAX_MESH_BYTES");
}

TEST(ConfigTest, IndexerPrecedenceFlagOverEnvOverFileOverDefault) {
  TempDir dir;
  const std::string file = dir.path() + "/tpr-indexer.toml";
  WriteFile(file,
            "# settings\n"
            "listen = \"127.0.0.1:9123\"\n"
            "max-k = 50\n"
            "threads = 3\n"
            "max-concurrent-searches = 7\n"
            "log-format = \"json\"\n");
  const ShellResult r = RunShell(
      absl::StrCat("TPR_INDEXER_MAX_K=77 TPR_INDEXER_THREADS=4 ",
                   BinaryPath("tpr-indexer"), " --data-dir ", dir.path(),
                   "/data --config ", file, " --threads 5 --print-config"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  std::map<std::string, std::string> config = ParseConfig(r.out);
  EXPECT_EQ(config["threads"], "5") << "flag beats environment and file\n"
                                    << r.out;
  EXPECT_EQ(config["max-k"], "77") << "environment beats file\n" << r.out;
  EXPECT_EQ(config["max-concurrent-searches"], "7") << "file beats default\n"
                                                    << r.out;
  EXPECT_EQ(config["listen"], "\"127.0.0.1:9123\"") << r.out;
  EXPECT_EQ(config["log-format"], "\"json\"") << r.out;
  EXPECT_EQ(config["shutdown-grace-ms"], "10000") << "default\n" << r.out;
  EXPECT_EQ(config["log-calls"], "true") << r.out;
}

TEST(ConfigTest, PrintedConfigReadsBackToTheSameConfig) {
  TempDir dir;
  const std::string first = dir.path() + "/first.toml";
  ShellResult r = RunShell(absl::StrCat(
      "TPR_EXTRACTOR_THREADS=3 ", BinaryPath("tpr-extractor"),
      " --max-vertices 12345 --no-log-calls --log-format json --print-config"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  WriteFile(first, r.out);
  std::map<std::string, std::string> config = ParseConfig(r.out);
  EXPECT_EQ(config["threads"], "3");
  EXPECT_EQ(config["max-vertices"], "12345");
  EXPECT_EQ(config["log-calls"], "false");
  const ShellResult again = RunShell(absl::StrCat(
      BinaryPath("tpr-extractor"), " --config ", first, " --print-config"));
  ASSERT_EQ(again.exit_code, 0) << again.out;
  std::map<std::string, std::string> reread = ParseConfig(again.out);
  EXPECT_EQ(reread, config) << again.out;
}

TEST(ConfigTest, MisspeltKeyIsAnErrorNamingIt) {
  TempDir dir;
  const std::string file = dir.path() + "/bad.toml";
  WriteFile(file, "max-kk = 5\n");
  const ShellResult r =
      RunShell(absl::StrCat(BinaryPath("tpr-indexer"), " --data-dir ",
                            dir.path(), " --config ", file));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.out.find("max-kk"), std::string::npos) << r.out;
}

TEST(ConfigTest, MissingFileAndBadValueAreErrors) {
  TempDir dir;
  ShellResult r = RunShell(
      absl::StrCat(BinaryPath("tpr-indexer"), " --data-dir ", dir.path(),
                   " --config ", dir.path(), "/absent.toml"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.out.find("absent.toml"), std::string::npos) << r.out;
  r = RunShell(absl::StrCat(BinaryPath("tpr-indexer"), " --data-dir ",
                            dir.path(), " --log-format xml"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.out.find("log-format"), std::string::npos) << r.out;
  r = RunShell(absl::StrCat("TPR_INDEXER_MAX_K=many ",
                            BinaryPath("tpr-indexer"), " --data-dir ",
                            dir.path(), " --print-config"));
  EXPECT_NE(r.exit_code, 0) << r.out;
}

TEST(ConfigTest, DeployExamplesLoad) {
  const std::string deploy =
      std::string(TPR_TEST_DATA_DIR) + "/../../deploy/config/";
  ShellResult r =
      RunShell(absl::StrCat(BinaryPath("tpr-indexer"), " --config ", deploy,
                            "tpr-indexer.toml --print-config"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(ParseConfig(r.out)["data-dir"], "\"/var/lib/tpr\"") << r.out;
  r = RunShell(absl::StrCat(BinaryPath("tpr-extractor"), " --config ", deploy,
                            "tpr-extractor.toml --print-config"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(ParseConfig(r.out)["listen"], "\"0.0.0.0:7001\"") << r.out;
  r = RunShell(absl::StrCat(BinaryPath("tpr-gateway"), " --config ", deploy,
                            "tpr-gateway.toml --print-config"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(ParseConfig(r.out)["shard-map"], "\"/etc/tpr/shards.txt\"")
      << r.out;
  EXPECT_EQ(ParseConfig(r.out)["metrics-listen"], "\"127.0.0.1:9103\"")
      << r.out;
}

// The examples listen beyond loopback, so they must carry TLS and keys (or
// the server refuses to start: common/server_flags.h, CheckOpenDefaults).
TEST(ConfigTest, DeployExamplesAreNotOpen) {
  const std::string deploy =
      std::string(TPR_TEST_DATA_DIR) + "/../../deploy/config/";
  auto unquote = [](std::string v) {
    return v.size() >= 2 && v.front() == '"' ? v.substr(1, v.size() - 2) : v;
  };
  for (const char* service : {"tpr-indexer", "tpr-extractor", "tpr-gateway"}) {
    const ShellResult r =
        RunShell(absl::StrCat(BinaryPath(service), " --config ", deploy,
                              service, ".toml --print-config"));
    ASSERT_EQ(r.exit_code, 0) << r.out;
    std::map<std::string, std::string> config = ParseConfig(r.out);
    common::ServerFlags flags;
    flags.tls.cert_file = unquote(config["tls-cert"]);
    flags.api_keys = unquote(config["api-keys"]);
    flags.metrics_listen = unquote(config["metrics-listen"]);
    EXPECT_TRUE(
        common::CheckOpenDefaults(flags, unquote(config["listen"])).ok())
        << service << ": "
        << common::CheckOpenDefaults(flags, unquote(config["listen"]));
  }
}

TEST(ConfigTest, GatewayTakesEnvironmentAndMasksItsShardKey) {
  // The shard key from the environment, masked; a flag beats the
  // environment, which beats the default.
  const ShellResult r = RunShell(
      absl::StrCat("TPR_GATEWAY_SHARD_API_KEY=tpr_verysecret "
                   "TPR_GATEWAY_HEALTH_INTERVAL_MS=250 "
                   "TPR_GATEWAY_LOG_FORMAT=json ",
                   BinaryPath("tpr-gateway"),
                   " --shard 127.0.0.1:1 --log-format text --print-config"));
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out.find("verysecret"), std::string::npos) << r.out;
  std::map<std::string, std::string> config = ParseConfig(r.out);
  EXPECT_EQ(config["shard-api-key"], "\"***\"") << r.out;
  EXPECT_EQ(config["health-interval-ms"], "250") << r.out;
  EXPECT_EQ(config["log-format"], "\"text\"") << r.out;
}

TEST(ConfigTest, PrintConfigMasksSecrets) {
  CLI::App app{"test"};
  std::string key;
  std::string address = "127.0.0.1:1";
  app.add_option("--api-key", key, "a secret");
  app.add_option("--address", address, "not a secret")->capture_default_str();
  common::ConfigSupport config =
      common::AddConfigSupport(app, "TPR_TEST_", {"api-key"});
  const char* argv[] = {"test", "--api-key", "tpr_supersecret",
                        "--print-config"};
  ASSERT_NO_THROW(app.parse(4, const_cast<char**>(argv)));
  ASSERT_TRUE(config.print_requested());
  const std::string printed = config.Effective();
  EXPECT_EQ(printed.find("supersecret"), std::string::npos) << printed;
  EXPECT_NE(printed.find("api-key = \"***\""), std::string::npos) << printed;
  EXPECT_NE(printed.find("address = \"127.0.0.1:1\""), std::string::npos)
      << printed;
}

}  // namespace
}  // namespace tpr::testing
