// TLS (common/tls.h, the SDK's ConnectionOptions) through the real
// tpr-indexer, with certificates made here by the openssl command: the
// handshake (and an API key over it), a plaintext client against a TLS
// server and a TLS client against a plaintext one, a client trusting
// another authority, mutual TLS refusing clients without a certificate or
// with one from another authority, the certificate reloaded when its files
// change, and unusable files refused at start; tpr-extractor serving mutual
// TLS with the same flags.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

#include "common/auth.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/ops_testing.h"
#include "tpr/client.h"

namespace tpr::testing {
namespace {

using client::ConnectionOptions;
using client::IndexerClient;

class TlsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(MakeCertificates(dir_.path())) << "openssl failed";
    // The server reads these two names; the reload test swaps their content.
    Copy("server1.pem", "serving.pem");
    Copy("server1.key", "serving.key");
  }

  void Copy(const std::string& from, const std::string& to) {
    // Write a temporary and rename, as a certificate manager does, so the
    // watcher never sees a half-written pair.
    const std::string tmp = Path(to + ".tmp");
    std::filesystem::copy_file(
        Path(from), tmp, std::filesystem::copy_options::overwrite_existing);
    std::filesystem::rename(tmp, Path(to));
  }

  std::string Path(const std::string& name) const {
    return dir_.path() + "/" + name;
  }

  void StartIndexer(std::vector<std::string> extra) {
    std::vector<std::string> args = {"--data-dir", Path("data")};
    args.insert(args.end(), extra.begin(), extra.end());
    ASSERT_TRUE(
        server_.Start(BinaryPath("tpr-indexer"), args, Path("indexer.log"))
            .ok())
        << ReadText(Path("indexer.log"));
  }

  void StartTlsIndexer(std::vector<std::string> extra = {}) {
    std::vector<std::string> args = {"--tls-cert",      Path("serving.pem"),
                                     "--tls-key",       Path("serving.key"),
                                     "--tls-refresh-s", "1"};
    args.insert(args.end(), extra.begin(), extra.end());
    StartIndexer(args);
  }

  ConnectionOptions Tls(const std::string& ca,
                        const std::string& client = "") const {
    ConnectionOptions c;
    c.tls = true;
    c.tls_ca_file = Path(ca + ".pem");
    if (!client.empty()) {
      c.tls_cert_file = Path(client + ".pem");
      c.tls_key_file = Path(client + ".key");
    }
    return c;
  }

  // Stats over a fresh channel; the status, and the time the call took.
  absl::Status Stats(const ConnectionOptions& connection,
                     double* seconds = nullptr) {
    client::CallOptions call;
    call.timeout = absl::Seconds(20);
    absl::StatusOr<IndexerClient> indexer =
        IndexerClient::Connect(server_.address(), connection, call);
    if (!indexer.ok()) return indexer.status();
    const auto start = std::chrono::steady_clock::now();
    absl::Status status = indexer->Stats().status();
    if (seconds != nullptr) {
      *seconds = std::chrono::duration<double>(
                     std::chrono::steady_clock::now() - start)
                     .count();
    }
    return status;
  }

  TempDir dir_;
  ServiceProcess server_;
};

TEST_F(TlsTest, HandshakeSucceedsAndCarriesAnApiKey) {
  absl::StatusOr<std::string> key = common::NewApiKey();
  ASSERT_TRUE(key.ok());
  WriteFile(Path("keys"),
            common::KeyFileLine(*key, common::Role::kRead, "t") + "\n");
  StartTlsIndexer({"--api-keys", Path("keys")});
  ConnectionOptions connection = Tls("ca1");
  EXPECT_EQ(Stats(connection).code(), absl::StatusCode::kUnauthenticated);
  connection.api_key = *key;
  std::string request_id;
  connection.on_call_done = [&](absl::string_view, absl::string_view id,
                                const grpc::Status&) {
    request_id = std::string(id);
  };
  EXPECT_TRUE(Stats(connection).ok());
  EXPECT_EQ(request_id.size(), 16u) << "the request id comes back over TLS";
  // By host name (the certificate's DNS name) as well as by IP address.
  client::CallOptions call;
  absl::StatusOr<IndexerClient> by_name = IndexerClient::Connect(
      absl::StrCat("localhost:", server_.port()), connection, call);
  ASSERT_TRUE(by_name.ok());
  EXPECT_TRUE(by_name->Stats().ok());
}

TEST_F(TlsTest, PlaintextClientGetsAClearErrorNotAHang) {
  StartTlsIndexer();
  double seconds = 0;
  absl::Status status = Stats(ConnectionOptions(), &seconds);
  EXPECT_EQ(status.code(), absl::StatusCode::kUnavailable) << status;
  EXPECT_NE(status.message().find("does it use TLS?"), absl::string_view::npos)
      << status;
  EXPECT_LT(seconds, 10.0) << "must fail fast, not wait for the 20 s deadline";
}

TEST_F(TlsTest, TlsClientAgainstPlaintextServerFails) {
  StartIndexer({});
  double seconds = 0;
  absl::Status status = Stats(Tls("ca1"), &seconds);
  EXPECT_EQ(status.code(), absl::StatusCode::kUnavailable) << status;
  EXPECT_NE(status.message().find("TLS"), absl::string_view::npos) << status;
  EXPECT_LT(seconds, 10.0);
}

TEST_F(TlsTest, WrongAuthorityIsRefused) {
  StartTlsIndexer();
  double seconds = 0;
  absl::Status status = Stats(Tls("ca2"), &seconds);
  EXPECT_EQ(status.code(), absl::StatusCode::kUnavailable) << status;
  // The SDK names what to check in its own terms (no command-line flag).
  EXPECT_NE(status.message().find("CA certificate"), absl::string_view::npos)
      << status;
  EXPECT_EQ(status.message().find("--tls"), absl::string_view::npos) << status;
  EXPECT_LT(seconds, 10.0);
  EXPECT_TRUE(Stats(Tls("ca1")).ok());
}

TEST_F(TlsTest, MutualTlsRefusesClientsWithoutAGoodCertificate) {
  StartTlsIndexer({"--tls-client-ca", Path("ca1.pem")});
  double seconds = 0;
  absl::Status none = Stats(Tls("ca1"), &seconds);
  EXPECT_EQ(none.code(), absl::StatusCode::kUnavailable) << none;
  EXPECT_LT(seconds, 10.0);
  EXPECT_EQ(Stats(Tls("ca1", "client2")).code(),
            absl::StatusCode::kUnavailable);
  EXPECT_TRUE(Stats(Tls("ca1", "client1")).ok());
  ConnectionOptions half = Tls("ca1", "client1");
  half.tls_key_file.clear();
  EXPECT_EQ(Stats(half).code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(TlsTest, CertificateIsReloadedWhenItsFilesChange) {
  StartTlsIndexer();
  EXPECT_TRUE(Stats(Tls("ca1")).ok());
  EXPECT_FALSE(Stats(Tls("ca2")).ok());
  Copy("server2.key", "serving.key");
  Copy("server2.pem", "serving.pem");
  bool switched = false;
  for (int i = 0; i < 100 && !switched; ++i) {
    switched = Stats(Tls("ca2")).ok();
    if (!switched) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_TRUE(switched) << "the new certificate was not served within 10 s";
  EXPECT_FALSE(Stats(Tls("ca1")).ok()) << "the old certificate is still served";
}

TEST_F(TlsTest, TprCommandTakesTheTlsFlags) {
  StartTlsIndexer({"--tls-client-ca", Path("ca1.pem")});
  const std::string tpr =
      absl::StrCat(BinaryPath("tpr"), " --indexer ", server_.address());
  ShellResult r =
      RunShell(absl::StrCat(tpr, " --tls --tls-ca ", Path("ca1.pem"),
                            " --tls-cert ", Path("client1.pem"), " --tls-key ",
                            Path("client1.key"), " --json stats"));
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("\"models\""), std::string::npos) << r.out;
  r = RunShell(tpr + " stats");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.out.find("does it use TLS?"), std::string::npos) << r.out;
  r = RunShell(absl::StrCat("TPR_TLS=1 TPR_TLS_CA=", Path("ca1.pem"), " ", tpr,
                            " stats"));
  EXPECT_EQ(r.exit_code, 1) << "mutual TLS without a client certificate";
  EXPECT_NE(r.out.find("--tls-cert"), std::string::npos) << r.out;
}

// The same flags serve tpr-extractor (common/server_flags.h): mutual TLS,
// a mesh extracted over it, a plaintext client and a client without a
// certificate refused fast.
TEST_F(TlsTest, ExtractorServesMutualTls) {
  ServiceProcess extractor;
  ASSERT_TRUE(
      extractor
          .Start(BinaryPath("tpr-extractor"),
                 {"--tls-cert", Path("serving.pem"), "--tls-key",
                  Path("serving.key"), "--tls-client-ca", Path("ca1.pem")},
                 Path("extractor.log"))
          .ok())
      << ReadText(Path("extractor.log"));
  absl::StatusOr<std::vector<GeneratedFile>> files =
      GenerateSet(Path("set"), 1, 1, 600);
  ASSERT_TRUE(files.ok()) << files.status();
  auto extract = [&](const ConnectionOptions& connection) {
    client::CallOptions call;
    call.timeout = absl::Seconds(60);
    absl::StatusOr<client::ExtractorClient> ex =
        client::ExtractorClient::Connect(extractor.address(), connection, call);
    if (!ex.ok()) return ex.status();
    return ex->ExtractBytes(files->front().off, "m.off").status();
  };
  const auto start = std::chrono::steady_clock::now();
  absl::Status plain = extract(ConnectionOptions());
  EXPECT_EQ(plain.code(), absl::StatusCode::kUnavailable) << plain;
  EXPECT_NE(plain.message().find("does it use TLS?"), absl::string_view::npos)
      << plain;
  EXPECT_EQ(extract(Tls("ca1")).code(), absl::StatusCode::kUnavailable);
  EXPECT_LT(
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start)
          .count(),
      20.0);
  absl::Status mutual = extract(Tls("ca1", "client1"));
  EXPECT_TRUE(mutual.ok()) << mutual;
}

TEST_F(TlsTest, UnusableFilesAreRefusedAtStart) {
  auto start = [&](const std::string& cert, const std::string& key) {
    return RunShell(absl::StrCat(BinaryPath("tpr-indexer"), " --data-dir ",
                                 Path("data"), " --tls-cert ", Path(cert),
                                 " --tls-key ", Path(key)));
  };
  ShellResult mismatch = start("server1.pem", "server2.key");
  EXPECT_EQ(mismatch.exit_code, 2) << mismatch.out;
  EXPECT_NE(mismatch.out.find("does not match"), std::string::npos)
      << mismatch.out;
  ShellResult missing = start("absent.pem", "server1.key");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  EXPECT_NE(missing.out.find("absent.pem"), std::string::npos) << missing.out;
  ShellResult swapped = start("server1.key", "server1.pem");
  EXPECT_EQ(swapped.exit_code, 2) << swapped.out;
  EXPECT_NE(swapped.out.find("no PEM certificate"), std::string::npos)
      << swapped.out;
}

}  // namespace
}  // namespace tpr::testing
