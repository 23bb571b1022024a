// tpr-web's API keys (the services' keys file and roles) and TLS, through
// the real binary: every API route per role, keys checked by tpr-web
// itself, and keys passed on to services that check them.
#include <gtest/gtest.h>
#include <signal.h>

#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "common/auth.h"
#include "tests/web/web_test_util.h"

namespace tpr::testing {
namespace {

struct Keys {
  std::string read, write, admin;
};

Keys WriteKeys(const std::string& path) {
  Keys keys;
  std::string text;
  for (auto [key, role] :
       {std::pair<std::string*, common::Role>{&keys.read, common::Role::kRead},
        {&keys.write, common::Role::kWrite},
        {&keys.admin, common::Role::kAdmin}}) {
    *key = *common::NewApiKey();
    absl::StrAppend(&text, common::KeyFileLine(*key, role, "test"), "\n");
  }
  WriteFile(path, text);
  return keys;
}

// One request of each API route; `write` marks the routes needing the
// write role.
struct Call {
  std::string method, path;
  bool write;
};

std::vector<Call> EveryRoute() {
  return {{"GET", "/api/v1/search?id=a.off", false},
          {"POST", "/api/v1/search?file_name=a.off", false},
          {"GET", "/api/v1/models", false},
          {"POST", "/api/v1/models?id=new.off&file_name=a.off", true},
          {"GET", "/api/v1/models/a.off", false},
          {"DELETE", "/api/v1/models/gone.off", true},
          {"GET", "/api/v1/stats", false},
          {"GET", "/api/v1/status", false},
          {"GET", "/api/v1/thumbnails/a.off", false},
          {"GET", "/api/v1/previews/a.off", false}};
}

httplib::Result Send(httplib::Client& c, const Call& call,
                     const std::string& key, const std::string& body) {
  httplib::Headers headers;
  if (!key.empty()) headers.emplace("Authorization", "Bearer " + key);
  if (call.method == "GET") return c.Get(call.path, headers);
  if (call.method == "DELETE") return c.Delete(call.path, headers);
  return c.Post(call.path, headers, body, "application/octet-stream");
}

class WebAuthTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(cluster_.Start().ok());
    synth::ShapeOptions options;
    options.target_vertices = 1000;
    absl::StatusOr<extract::Mesh> mesh =
        synth::GenerateShape(synth::ClassNames()[0], 0, options);
    ASSERT_TRUE(mesh.ok());
    mesh_ = ToOff(*mesh);
    keys_ = WriteKeys(cluster_.dir() + "/keys.txt");
  }

  // Checks every route with no key, an unknown key and each role's key
  // against `web`; `status_of` says what an allowed call answers.
  void CheckRoles(int port) {
    httplib::Client c("127.0.0.1", port);
    c.set_read_timeout(60, 0);
    for (const Call& call : EveryRoute()) {
      const std::string what = call.method + " " + call.path;
      httplib::Result r = Send(c, call, "", mesh_);
      ASSERT_TRUE(r) << what;
      EXPECT_EQ(r->status, 401) << what << ": " << r->body;
      EXPECT_EQ(ErrorCode(r->body), "UNAUTHENTICATED") << what;
      r = Send(c, call, "tpr_" + std::string(64, '0'), mesh_);
      ASSERT_TRUE(r) << what;
      EXPECT_EQ(r->status, 401) << what;
      EXPECT_EQ(Field(ParseJson(r->body), "message").string_value(),
                "unknown API key")
          << what;
      r = Send(c, call, keys_.read, mesh_);
      ASSERT_TRUE(r) << what;
      if (call.write) {
        EXPECT_EQ(r->status, 403) << what << ": " << r->body;
        EXPECT_EQ(ErrorCode(r->body), "PERMISSION_DENIED") << what;
        EXPECT_TRUE(absl::StrContains(r->body, "write role")) << r->body;
      } else {
        EXPECT_NE(r->status, 401) << what << ": " << r->body;
        EXPECT_NE(r->status, 403) << what << ": " << r->body;
      }
      for (const std::string& key : {keys_.write, keys_.admin}) {
        r = Send(c, call, key, mesh_);
        ASSERT_TRUE(r) << what;
        EXPECT_NE(r->status, 401) << what << ": " << r->body;
        EXPECT_NE(r->status, 403) << what << ": " << r->body;
      }
    }
    // Health, readiness and the console stay open.
    for (const char* open : {"/healthz", "/readyz", "/"}) {
      httplib::Result r = c.Get(open);
      ASSERT_TRUE(r) << open;
      EXPECT_EQ(r->status, 200) << open << ": " << r->body;
    }
    // A write key really writes, and a read key reads it back.
    httplib::Result r =
        Send(c, {"POST", "/api/v1/models?id=written.off&file_name=a.off", true},
             keys_.write, mesh_);
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 201) << r->body;
    r = Send(c, {"GET", "/api/v1/models/written.off", false}, keys_.read, "");
    ASSERT_TRUE(r);
    EXPECT_EQ(r->status, 200) << r->body;
  }

  Cluster cluster_;
  std::string mesh_;
  Keys keys_;
};

// tpr-web checks the keys itself (--api-keys); the services are open.
TEST_F(WebAuthTest, WebChecksKeysPerRole) {
  ServiceProcess web;
  ASSERT_TRUE(StartWeb(&web, cluster_.dir(), "web",
                       {"--extractor", cluster_.extractor_addresses(),
                        "--indexer", cluster_.indexer().address(), "--api-keys",
                        cluster_.dir() + "/keys.txt"})
                  .ok());
  CheckRoles(web.port());
}

// The services check the keys; tpr-web has none of its own and passes
// each caller's Authorization on.
TEST_F(WebAuthTest, CallerKeysArePassedToTheServices) {
  ServiceProcess indexer;
  ASSERT_TRUE(indexer
                  .Start(BinaryPath("tpr-indexer"),
                         {"--data-dir", cluster_.dir() + "/data2", "--api-keys",
                          cluster_.dir() + "/keys.txt"},
                         cluster_.dir() + "/indexer2.log")
                  .ok());
  ServiceProcess extractor;
  ASSERT_TRUE(extractor
                  .Start(BinaryPath("tpr-extractor"),
                         {"--api-keys", cluster_.dir() + "/keys.txt"},
                         cluster_.dir() + "/extractor2.log")
                  .ok());
  ServiceProcess web;
  ASSERT_TRUE(StartWeb(&web, cluster_.dir(), "web",
                       {"--extractor", extractor.address(), "--indexer",
                        indexer.address()})
                  .ok());
  CheckRoles(web.port());

  // With its own key (--api-key / TPR_API_KEY) tpr-web needs none from
  // callers: the services see tpr-web's role.
  ServiceProcess keyed;
  ASSERT_TRUE(StartWeb(&keyed, cluster_.dir(), "keyed",
                       {"--extractor", extractor.address(), "--indexer",
                        indexer.address(), "--api-key", keys_.read})
                  .ok());
  httplib::Client c("127.0.0.1", keyed.port());
  httplib::Result r = c.Get("/api/v1/stats");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200) << r->body;
  r = c.Delete("/api/v1/models/new.off");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 403) << r->body;
}

TEST(WebTlsTest, ServesHttpsWithTheServicesTlsFlags) {
  // A refused handshake closes the socket under the client's write.
  signal(SIGPIPE, SIG_IGN);
  TempDir dir;
  ASSERT_TRUE(MakeCertificates(dir.path()));
  ServiceProcess web;
  const std::string dead = absl::StrCat("127.0.0.1:", FreePort());
  ASSERT_TRUE(StartWeb(&web, dir.path(), "web",
                       {"--extractor", dead, "--indexer", dead, "--tls-cert",
                        dir.path() + "/server1.pem", "--tls-key",
                        dir.path() + "/server1.key"})
                  .ok());
  httplib::SSLClient tls("127.0.0.1", web.port());
  tls.set_ca_cert_path((dir.path() + "/ca1.pem").c_str());
  tls.enable_server_certificate_verification(true);
  httplib::Result r = tls.Get("/healthz");
  ASSERT_TRUE(r) << httplib::to_string(r.error());
  EXPECT_EQ(r->status, 200);
  // The wrong authority is refused, and so is plaintext.
  httplib::SSLClient wrong("127.0.0.1", web.port());
  wrong.set_ca_cert_path((dir.path() + "/ca2.pem").c_str());
  wrong.enable_server_certificate_verification(true);
  EXPECT_FALSE(wrong.Get("/healthz"));
  httplib::Client plain("127.0.0.1", web.port());
  httplib::Result p = plain.Get("/healthz");
  EXPECT_TRUE(!p || p->status != 200);

  // Mutual TLS: a client certificate of the named authority is required.
  ServiceProcess mutual;
  ASSERT_TRUE(StartWeb(&mutual, dir.path(), "mutual",
                       {"--extractor", dead, "--indexer", dead, "--tls-cert",
                        dir.path() + "/server1.pem", "--tls-key",
                        dir.path() + "/server1.key", "--tls-client-ca",
                        dir.path() + "/ca1.pem"})
                  .ok());
  httplib::SSLClient anonymous("127.0.0.1", mutual.port());
  anonymous.set_ca_cert_path((dir.path() + "/ca1.pem").c_str());
  anonymous.enable_server_certificate_verification(true);
  EXPECT_FALSE(anonymous.Get("/healthz"));
  httplib::SSLClient known("127.0.0.1", mutual.port(),
                           dir.path() + "/client1.pem",
                           dir.path() + "/client1.key");
  known.set_ca_cert_path((dir.path() + "/ca1.pem").c_str());
  known.enable_server_certificate_verification(true);
  r = known.Get("/healthz");
  ASSERT_TRUE(r) << httplib::to_string(r.error());
  EXPECT_EQ(r->status, 200);

  // A missing certificate file is refused at start, naming it.
  ServiceProcess bad;
  EXPECT_FALSE(StartWeb(&bad, dir.path(), "bad",
                        {"--tls-cert", dir.path() + "/none.pem", "--tls-key",
                         dir.path() + "/server1.key"})
                   .ok());
  EXPECT_TRUE(absl::StrContains(ReadText(dir.path() + "/bad.log"), "none.pem"));
}

}  // namespace
}  // namespace tpr::testing
