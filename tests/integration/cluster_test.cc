// The scaled-out topology as real processes on 127.0.0.1 (free ports, PIDs
// kept, every wait bounded, everything stopped on exit): 2 tpr-extractor
// behind haproxy, 3 tpr-indexer shards (shard 0 with a follower, which the
// gateway reads from too), 1 tpr-gateway, and one more tpr-indexer holding
// the same corpus alone as the reference. Checks:
// - exactness: every query answers the same (id, distance) list through the
//   gateway as from the single indexer, bit for bit (ties, radius, label
//   filter, exclude_self, k above the corpus, after deletes), with models
//   extracted through haproxy as well as generated signatures; `tpr eval`
//   through the gateway reports what it reports against the single indexer;
// - a killed shard makes queries fail with UNAVAILABLE naming it, never
//   return fewer neighbours;
// - kill -9 of a shard primary during batch ingest through the gateway loses
//   no acknowledged write (the shard restarts on its port and has them);
// - SIGTERM drains each service: an in-flight search through the gateway
//   completes, and every process (the follower too) exits 0;
// - kill -9 of the follower during ingest: restarted, it catches up by
//   itself and answers as its primary does;
// - backup of every shard (`tpr backup`) and restore into empty directories
//   (`tpr restore`): a gateway over the restored shards answers as before.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <fstream>
#include <regex>
#include <set>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "indexer/gateway/shard_map.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"
#include "tpr/client.h"

namespace tpr::gateway {
namespace {

using ::tpr::indexer::testing::MakeModels;
using ::tpr::indexer::testing::RunSearch;
using ::tpr::indexer::testing::SearchResult;
using ::tpr::indexer::testing::TestModel;
using ::tpr::indexer::testing::ToRequest;
using ::tpr::testing::BinaryPath;
using ::tpr::testing::FreePort;
using ::tpr::testing::ServiceProcess;
using ::tpr::testing::TempDir;

constexpr int kShards = 3;

std::string FindHaproxy() {
  for (const char* path :
       {"/usr/sbin/haproxy", "/usr/bin/haproxy", "/usr/local/sbin/haproxy"}) {
    if (access(path, X_OK) == 0) return path;
  }
  return "";
}

std::unique_ptr<v1::Indexer::Stub> Stub(const std::string& address) {
  return v1::Indexer::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
}

// haproxy in the foreground (-db), started and stopped by PID.
class Haproxy {
 public:
  ~Haproxy() { Stop(SIGKILL); }
  absl::Status Start(const std::string& binary, const std::string& config,
                     const std::string& log_path) {
    pid_ = fork();
    if (pid_ < 0) return absl::InternalError("fork failed");
    if (pid_ == 0) {
      FILE* log = std::fopen(log_path.c_str(), "w");
      if (log != nullptr) {
        dup2(fileno(log), STDERR_FILENO);
        dup2(fileno(log), STDOUT_FILENO);
      }
      execl(binary.c_str(), binary.c_str(), "-db", "-f", config.c_str(),
            nullptr);
      _exit(127);
    }
    return absl::OkStatus();
  }
  int Stop(int signo) {
    if (pid_ <= 0) return -1;
    kill(pid_, signo);
    int status = 0;
    for (int i = 0; i < 3000; ++i) {
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
    return -1;
  }

 private:
  pid_t pid_ = -1;
};

class ClusterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    haproxy_binary_ = FindHaproxy();
    if (haproxy_binary_.empty())
      GTEST_SKIP() << "haproxy is not installed (scripts/setup)";
    ASSERT_FALSE(dir_.path().empty());
    std::string servers;
    for (int i = 0; i < 2; ++i) {
      ASSERT_TRUE(extractors_[i]
                      .Start(BinaryPath("tpr-extractor"), {"--threads", "1"},
                             Path(absl::StrCat("extractor", i, ".log")))
                      .ok());
      absl::StrAppend(&servers, "  server e", i, " ", extractors_[i].address(),
                      " proto h2 check check-proto h2\n");
    }
    front_port_ = FreePort();
    std::ofstream(Path("haproxy.cfg"))
        << "global\n  maxconn 256\ndefaults\n  mode http\n  timeout connect "
           "2s\n"
        << "  timeout client 60s\n  timeout server 60s\n  retries 2\n  option "
           "redispatch 1\n"
        << "frontend f\n  bind 127.0.0.1:" << front_port_
        << " proto h2\n  default_backend e\n"
        << "backend e\n  balance roundrobin\n  option httpchk\n"
        << "  http-check send meth POST uri /grpc.health.v1.Health/Check ver "
           "HTTP/2 hdr "
           "content-type application/grpc hdr te trailers\n"
        << "  http-check expect status 200\n  default-server inter 500ms fall "
           "2 rise 1\n"
        << servers;
    ASSERT_TRUE(
        haproxy_
            .Start(haproxy_binary_, Path("haproxy.cfg"), Path("haproxy.log"))
            .ok());
    std::vector<std::string> shard_flags;
    for (int s = 0; s < kShards; ++s) {
      ASSERT_TRUE(StartShard(s, "127.0.0.1:0").ok());
      shard_flags.push_back("--shard");
      shard_flags.push_back(shards_[s].address());
    }
    ASSERT_TRUE(StartFollower("127.0.0.1:0").ok());
    shard_flags[1] += "," + follower_.address();
    shard_flags.push_back("--health-interval-ms");
    shard_flags.push_back("200");
    ASSERT_TRUE(
        gateway_
            .Start(BinaryPath("tpr-gateway"), shard_flags, Path("gateway.log"))
            .ok());
    ASSERT_TRUE(reference_
                    .Start(BinaryPath("tpr-indexer"),
                           {"--data-dir", Path("reference")},
                           Path("reference.log"))
                    .ok());
    gateway_stub_ = Stub(gateway_.address());
    reference_stub_ = Stub(reference_.address());
  }

  absl::Status StartShard(int s, const std::string& listen) {
    return shards_[s].Start(BinaryPath("tpr-indexer"),
                            {"--data-dir", Path(absl::StrCat("shard", s)),
                             "--backup-root", Path("")},
                            Path(absl::StrCat("shard", s, ".log")), listen);
  }

  // The follower of shard 0 (tpr-indexer --follow).
  absl::Status StartFollower(const std::string& listen) {
    return follower_.Start(
        BinaryPath("tpr-indexer"),
        {"--data-dir", Path("follower0"), "--follow", shards_[0].address()},
        Path("follower0.log"), listen);
  }

  // Waits (bounded) until the follower has applied everything shard 0 has
  // and reports SERVING; false on timeout.
  bool WaitForFollower() {
    auto primary = v1::IndexerAdmin::NewStub(grpc::CreateChannel(
        shards_[0].address(), grpc::InsecureChannelCredentials()));
    auto follower = v1::IndexerAdmin::NewStub(grpc::CreateChannel(
        follower_.address(), grpc::InsecureChannelCredentials()));
    for (int i = 0; i < 1500; ++i) {
      grpc::ClientContext c1, c2;
      v1::ReplicationStatusResponse p, f;
      if (primary->ReplicationStatus(&c1, {}, &p).ok() &&
          follower->ReplicationStatus(&c2, {}, &f).ok() && f.caught_up() &&
          f.applied_sequence() >= p.applied_sequence()) {
        // The gateway's health checker must have seen it SERVING too.
        std::this_thread::sleep_for(std::chrono::milliseconds(300));
        return true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }

  // Runs `tpr ARGS...` and returns its exit code and standard output.
  std::pair<int, std::string> Tpr(const std::string& args) const {
    const std::string command =
        absl::StrCat(BinaryPath("tpr"), " ", args, " 2>", Path("tpr.err"));
    std::string out;
    FILE* pipe = popen(command.c_str(), "r");
    if (pipe == nullptr) return {-1, ""};
    char buffer[4096];
    for (size_t n; (n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0;)
      out.append(buffer, n);
    const int status = pclose(pipe);
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
  }

  std::string Path(const std::string& name) const {
    return dir_.path() + "/" + name;
  }

  // Upserts `models` in batches of `batch` through `stub`; returns how many
  // were acknowledged (all models of batches answered OK).
  static grpc::Status Batch(v1::Indexer::Stub* stub,
                            const std::vector<v1::UpsertRequest>& requests,
                            v1::BatchUpsertResponse* response) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::seconds(60));
    auto writer = stub->BatchUpsert(&context, response);
    for (const v1::UpsertRequest& r : requests) {
      if (!writer->Write(r)) break;
    }
    writer->WritesDone();
    return writer->Finish();
  }

  void ExpectSame(const v1::SearchRequest& request) {
    SearchResult want = RunSearch(reference_stub_.get(), request);
    SearchResult got = RunSearch(gateway_stub_.get(), request);
    ASSERT_TRUE(want.status.ok()) << want.status.error_message();
    ASSERT_TRUE(got.status.ok()) << got.status.error_message();
    ASSERT_EQ(got.neighbors.size(), want.neighbors.size())
        << request.ShortDebugString();
    for (size_t i = 0; i < want.neighbors.size(); ++i) {
      EXPECT_EQ(got.neighbors[i].id(), want.neighbors[i].id()) << i;
      EXPECT_EQ(got.neighbors[i].distance(), want.neighbors[i].distance()) << i;
      EXPECT_EQ(got.neighbors[i].rank(), static_cast<int>(i + 1));
    }
    ++queries_;
  }

  TempDir dir_;
  std::string haproxy_binary_;
  ServiceProcess extractors_[2];
  Haproxy haproxy_;
  int front_port_ = 0;
  ServiceProcess shards_[kShards];
  ServiceProcess follower_;
  ServiceProcess gateway_;
  ServiceProcess reference_;
  std::unique_ptr<v1::Indexer::Stub> gateway_stub_;
  std::unique_ptr<v1::Indexer::Stub> reference_stub_;
  int queries_ = 0;
};

TEST_F(ClusterTest, ShardedAnswersEqualOneIndexer) {
  // Models extracted from synthetic meshes through haproxy (both
  // extractors serve), plus generated signatures with exact copies (ties).
  absl::StatusOr<std::vector<testing::GeneratedFile>> files =
      testing::GenerateSet(Path("meshes"), 4, 2, 800);
  ASSERT_TRUE(files.ok()) << files.status();
  absl::StatusOr<client::ExtractorClient> extractor =
      client::ExtractorClient::Connect(absl::StrCat("127.0.0.1:", front_port_));
  ASSERT_TRUE(extractor.ok()) << extractor.status();
  std::vector<v1::UpsertRequest> requests;
  for (const testing::GeneratedFile& f : *files) {
    absl::StatusOr<v1::ExtractResponse> r =
        extractor->ExtractFile(Path("meshes/" + f.relative_path));
    ASSERT_TRUE(r.ok()) << f.relative_path << ": " << r.status();
    v1::UpsertRequest request;
    request.mutable_model()->set_id(f.relative_path);
    request.mutable_model()->set_label(f.label);
    *request.mutable_model()->mutable_signature() = r->signature();
    requests.push_back(request);
  }
  // Generated models with the extractor's band count (one index holds one
  // band count), ids m00000..m00399.
  std::vector<TestModel> models;
  {
    index::testing::SignatureGeneratorOptions options;
    options.seed = 23;
    options.features = 12;
    options.bands = requests[0].model().signature().options().bands();
    options.classes = 8;
    index::testing::SignatureGenerator gen(options);
    for (int i = 0; i < 400; ++i) {
      models.push_back({absl::StrFormat("m%05d", i),
                        absl::StrCat("class", i % 8), gen.Member(i % 8)});
    }
  }
  for (int i = 0; i < 40; i += 4) {
    for (const char* suffix : {"-x", "-y"}) {
      TestModel copy = models[static_cast<size_t>(i)];
      copy.id = absl::StrCat(copy.id, suffix);
      models.push_back(copy);
    }
  }
  for (const TestModel& m : models) requests.push_back(ToRequest(m));
  v1::BatchUpsertResponse single, sharded;
  ASSERT_TRUE(Batch(reference_stub_.get(), requests, &single).ok());
  grpc::Status status = Batch(gateway_stub_.get(), requests, &sharded);
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_EQ(sharded.written(), static_cast<int64_t>(requests.size()));
  // Replicas are asynchronous: the gateway may read shard 0 from its
  // follower, which must have caught up for the answers to be complete.
  ASSERT_TRUE(WaitForFollower());

  // The caller's request id reaches the shard's log through the gateway.
  {
    grpc::ClientContext context;
    context.AddMetadata("x-request-id", "scale-gw-req-7");
    v1::GetRequest get;
    get.set_id("m00007");
    v1::Model model;
    ASSERT_TRUE(gateway_stub_->Get(&context, get, &model).ok());
    std::ifstream in(shards_[gateway::ShardOf("m00007", kShards)].log_path());
    const std::string log((std::istreambuf_iterator<char>(in)),
                          std::istreambuf_iterator<char>());
    EXPECT_NE(log.find("scale-gw-req-7"), std::string::npos) << log;
  }
  const int n = static_cast<int>(requests.size());
  auto run_all = [&] {
    for (const char* id :
         {"m00000", "m00004-y", "m00133", "m00399", "biped_adult/pose_1.off"}) {
      for (int k : {1, 10, n + 5}) {
        for (bool exclude_self : {false, true}) {
          for (const char* label : {"", "class5", "biped_child"}) {
            v1::SearchRequest request;
            request.set_id(id);
            request.set_k(k);
            request.set_exclude_self(exclude_self);
            request.set_label(label);
            ExpectSame(request);
          }
        }
      }
    }
    for (const v1::UpsertRequest& query :
         {requests[0], requests[3], requests[20]}) {
      SearchResult tenth = RunSearch(reference_stub_.get(), [&] {
        v1::SearchRequest r;
        *r.mutable_signature() = query.model().signature();
        r.set_k(10);
        return r;
      }());
      ASSERT_EQ(tenth.neighbors.size(), 10u);
      v1::SearchRequest within;
      *within.mutable_signature() = query.model().signature();
      within.set_k(n);
      within.set_radius(tenth.neighbors.back().distance());
      ExpectSame(within);
    }
  };
  run_all();
  // Deletes through the gateway and in the reference, then everything again.
  for (const char* id : {"m00000", "m00004", "m00004-x",
                         "quadruped_slender/pose_0.off", "m00200"}) {
    for (v1::Indexer::Stub* stub :
         {reference_stub_.get(), gateway_stub_.get()}) {
      grpc::ClientContext context;
      v1::DeleteRequest request;
      request.set_id(id);
      v1::DeleteResponse response;
      ASSERT_TRUE(stub->Delete(&context, request, &response).ok()) << id;
    }
  }
  ASSERT_TRUE(WaitForFollower());
  v1::SearchRequest deleted;
  deleted.set_id("m00000");
  deleted.set_k(3);
  EXPECT_EQ(RunSearch(gateway_stub_.get(), deleted).status.error_code(),
            grpc::StatusCode::NOT_FOUND);
  for (const char* id : {"m00004-y", "m00133", "biped_adult/pose_1.off"}) {
    v1::SearchRequest request;
    request.set_id(id);
    request.set_k(n);
    request.set_exclude_self(true);
    ExpectSame(request);
  }
  EXPECT_GT(queries_, 90);
}

// `tpr eval` works unchanged through the gateway: the same labelled set,
// extracted through haproxy, evaluated once against the gateway over the
// shards and once against the single indexer, reports the same metrics
// (every number of the JSON report but the timings and the output folder).
TEST_F(ClusterTest, TprEvalThroughTheGatewayReportsAsOneIndexer) {
  const std::string synth =
      absl::StrCat(BinaryPath("tpr-synth"), " --out ", Path("set"),
                   " --classes 3 --poses 3 --vertices 1200 --seed 5",
                   " --jobs 2 > /dev/null 2>&1");
  ASSERT_EQ(std::system(synth.c_str()), 0) << synth;
  auto eval = [&](const std::string& indexer, const std::string& out) {
    auto [code, json] = Tpr(absl::StrCat(
        "--json --extractor 127.0.0.1:", front_port_, " --indexer ", indexer,
        " eval --jobs 2 --out ", Path(out), " ", Path("set")));
    EXPECT_EQ(code, 0) << json << tpr::testing::ReadText(Path("tpr.err"));
    // What may differ: where the pictures went and how long it took.
    for (const char* pattern :
         {"\"out\":\"[^\"]*\",?", "\"(extract|query)_seconds\":[0-9.e+-]+,?"}) {
      json = std::regex_replace(json, std::regex(pattern), "");
    }
    return json;
  };
  // The set is added through the gateway first, and the follower of shard
  // 0 (which the gateway reads from) given time to apply it: replicas are
  // asynchronous, and an eval's searches right after its own uploads may
  // reach a follower that has not applied them yet (seen: first tier 0.94
  // against 1). The single indexer gets the very models stored (an
  // extraction run twice may differ in the last bits of a distance), so
  // both evals use them as they are instead of extracting again.
  auto [added, add_out] =
      Tpr(absl::StrCat("--extractor 127.0.0.1:", front_port_, " --indexer ",
                       gateway_.address(), " add ", Path("set")));
  ASSERT_EQ(added, 0) << add_out << tpr::testing::ReadText(Path("tpr.err"));
  ASSERT_TRUE(WaitForFollower());
  const std::string through_gateway = eval(gateway_.address(), "out-gateway");
  std::ifstream manifest(Path("set/MANIFEST.txt"));
  int copied = 0;
  for (std::string id, label; manifest >> id >> label; ++copied) {
    grpc::ClientContext get_context, put_context;
    v1::GetRequest get;
    get.set_id(id);
    v1::UpsertRequest put;
    ASSERT_TRUE(gateway_stub_->Get(&get_context, get, put.mutable_model()).ok())
        << id;
    put.set_overwrite(true);
    v1::UpsertResponse ignored;
    ASSERT_TRUE(reference_stub_->Upsert(&put_context, put, &ignored).ok())
        << id;
  }
  ASSERT_EQ(copied, 9);
  std::string one_indexer = eval(reference_.address(), "out-single");
  const std::string& through = through_gateway;
  EXPECT_NE(through_gateway.find("\"added\":0"), std::string::npos)
      << through_gateway;
  EXPECT_NE(through_gateway.find("\"models\":9"), std::string::npos)
      << through_gateway;
  EXPECT_NE(through_gateway.find("\"per_class\""), std::string::npos)
      << through_gateway;
  EXPECT_EQ(through, one_indexer);
}

TEST_F(ClusterTest, AKilledShardFailsQueriesNeverShortensThem) {
  std::vector<v1::UpsertRequest> requests;
  for (const TestModel& m : MakeModels(90, 3, 4))
    requests.push_back(ToRequest(m));
  v1::BatchUpsertResponse response;
  grpc::Status ingested = Batch(gateway_stub_.get(), requests, &response);
  ASSERT_TRUE(ingested.ok()) << ingested.error_message();
  EXPECT_EQ(shards_[2].Stop(SIGKILL), 128 + SIGKILL);
  // Right after the kill and after the health checker noticed: both fail.
  for (int round = 0; round < 2; ++round) {
    v1::SearchRequest request;
    *request.mutable_signature() = requests[0].model().signature();
    request.set_k(50);
    SearchResult got = RunSearch(gateway_stub_.get(), request);
    EXPECT_EQ(got.status.error_code(), grpc::StatusCode::UNAVAILABLE);
    EXPECT_NE(got.status.error_message().find("shard 2"), std::string::npos)
        << got.status.error_message();
    EXPECT_LT(got.neighbors.size(),
              50u);  // what came before the error is not an answer
    std::this_thread::sleep_for(std::chrono::milliseconds(600));
  }
}

TEST_F(ClusterTest, KillNineOfAPrimaryDuringIngestLosesNoAcknowledgedWrite) {
  const std::vector<TestModel> models = MakeModels(3000, 10, 8, "ingest");
  std::vector<bool> acknowledged(models.size(), false);
  std::atomic<int> batches_done{0};
  std::atomic<int> failures{0};
  constexpr size_t kBatch = 50;
  std::thread ingest([&] {
    auto stub = Stub(gateway_.address());
    for (size_t start = 0; start < models.size(); start += kBatch) {
      std::vector<v1::UpsertRequest> requests;
      for (size_t i = start; i < std::min(models.size(), start + kBatch); ++i) {
        requests.push_back(ToRequest(models[i], /*overwrite=*/true));
      }
      v1::BatchUpsertResponse response;
      if (Batch(stub.get(), requests, &response).ok()) {
        for (size_t i = start; i < start + requests.size(); ++i)
          acknowledged[i] = true;
      } else {
        ++failures;
      }
      ++batches_done;
    }
  });
  const int shard_port = shards_[1].port();
  for (int i = 0; i < 3000 && batches_done.load() < 12; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  EXPECT_EQ(shards_[1].Stop(SIGKILL), 128 + SIGKILL);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  ASSERT_TRUE(StartShard(1, absl::StrCat("127.0.0.1:", shard_port)).ok());
  ingest.join();
  EXPECT_GT(failures.load(), 0);  // the kill hit the ingest
  // The gateway reaches the restarted shard again (bounded wait).
  for (int i = 0; i < 100; ++i) {
    grpc::ClientContext context;
    v1::StatsResponse stats;
    if (gateway_stub_->Stats(&context, {}, &stats).ok()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(WaitForFollower());  // reads of shard 0 may go to its follower
  int acked = 0;
  for (size_t i = 0; i < models.size(); ++i) {
    if (!acknowledged[i]) continue;
    ++acked;
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() +
                         std::chrono::seconds(10));
    v1::GetRequest get;
    get.set_id(models[i].id);
    v1::Model model;
    grpc::Status status = gateway_stub_->Get(&context, get, &model);
    EXPECT_TRUE(status.ok())
        << models[i].id << " was acknowledged: " << status.error_message();
  }
  EXPECT_GT(acked, 12 * static_cast<int>(kBatch) - 1);
  // The restarted shard takes writes again.
  v1::BatchUpsertResponse response;
  std::vector<v1::UpsertRequest> again;
  for (const TestModel& m : models) again.push_back(ToRequest(m, true));
  grpc::Status status;
  for (int attempt = 0; attempt < 50; ++attempt) {
    status = Batch(gateway_stub_.get(), again, &response);
    if (status.ok()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  ASSERT_TRUE(status.ok()) << status.error_message();
  ASSERT_TRUE(WaitForFollower());
  grpc::ClientContext context;
  v1::StatsResponse stats;
  ASSERT_TRUE(gateway_stub_->Stats(&context, {}, &stats).ok());
  EXPECT_EQ(stats.models(), static_cast<int64_t>(models.size()));
}

TEST_F(ClusterTest, SigtermDrainsEveryService) {
  std::vector<v1::UpsertRequest> requests;
  for (const TestModel& m : MakeModels(600, 6, 9))
    requests.push_back(ToRequest(m));
  v1::BatchUpsertResponse response;
  grpc::Status ingested = Batch(gateway_stub_.get(), requests, &response);
  ASSERT_TRUE(ingested.ok()) << ingested.error_message();
  // A search through the gateway in flight when the gateway gets SIGTERM:
  // it runs to its end.
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(60));
  v1::SearchRequest request;
  request.set_id("m00001");
  request.set_k(600);
  auto reader = gateway_stub_->Search(&context, request);
  v1::SearchResponse item;
  ASSERT_TRUE(reader->Read(&item));
  std::thread term([&] { EXPECT_EQ(gateway_.Stop(SIGTERM), 0); });
  int neighbors = 1;
  bool stats = false;
  while (reader->Read(&item)) {
    if (item.has_neighbor()) ++neighbors;
    stats = stats || item.has_stats();
  }
  grpc::Status status = reader->Finish();
  term.join();
  EXPECT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(neighbors, 600);
  EXPECT_TRUE(stats);
  for (int s = 0; s < kShards; ++s) {
    EXPECT_EQ(shards_[s].Stop(SIGTERM), 0) << "shard " << s;
    std::ifstream in(shards_[s].log_path());
    std::string log((std::istreambuf_iterator<char>(in)),
                    std::istreambuf_iterator<char>());
    EXPECT_NE(log.find("data directory closed"), std::string::npos) << log;
  }
  EXPECT_EQ(follower_.Stop(SIGTERM), 0) << "follower";
  for (ServiceProcess& e : extractors_) EXPECT_EQ(e.Stop(SIGTERM), 0);
  EXPECT_EQ(reference_.Stop(SIGTERM), 0);
  // haproxy stops on SIGTERM too ("hard stop": 0 is its exit code then).
  EXPECT_EQ(haproxy_.Stop(SIGUSR1), 0);
}

// Every answer of `stub` to `queries` (by id, k 10 and k 40 with a label),
// serialized byte for byte.
std::vector<std::string> Answers(v1::Indexer::Stub* stub,
                                 const std::vector<std::string>& ids) {
  std::vector<std::string> out;
  for (const std::string& id : ids) {
    for (int k : {10, 40}) {
      v1::SearchRequest request;
      request.set_id(id);
      request.set_k(k);
      if (k == 40) request.set_label("class1");
      SearchResult r = RunSearch(stub, request);
      std::string answer =
          r.status.ok() ? "" : absl::StrCat("error ", r.status.error_code());
      for (const v1::Neighbor& n : r.neighbors)
        answer += n.SerializeAsString() + "|";
      out.push_back(answer);
    }
  }
  return out;
}

TEST_F(ClusterTest, KillNineOfAFollowerCatchesUpByItself) {
  const std::vector<TestModel> models = MakeModels(900, 6, 12, "f");
  std::vector<v1::UpsertRequest> first, second;
  for (size_t i = 0; i < models.size(); ++i) {
    (i < 400 ? first : second).push_back(ToRequest(models[i], true));
  }
  v1::BatchUpsertResponse response;
  ASSERT_TRUE(Batch(gateway_stub_.get(), first, &response).ok());
  ASSERT_TRUE(WaitForFollower());
  // kill -9 while the primary takes more writes; restart on the same port.
  const int port = follower_.port();
  std::thread ingest([&] {
    v1::BatchUpsertResponse r;
    EXPECT_TRUE(Batch(Stub(gateway_.address()).get(), second, &r).ok());
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(follower_.Stop(SIGKILL), 128 + SIGKILL);
  ingest.join();
  ASSERT_TRUE(StartFollower(absl::StrCat("127.0.0.1:", port)).ok());
  ASSERT_TRUE(WaitForFollower());
  std::ifstream in(follower_.log_path());
  const std::string log((std::istreambuf_iterator<char>(in)),
                        std::istreambuf_iterator<char>());
  EXPECT_EQ(log.find("copied a checkpoint"), std::string::npos)
      << "it should resume from its own store, not copy again: " << log;
  auto primary = Stub(shards_[0].address());
  auto follower = Stub(follower_.address());
  grpc::ClientContext c1, c2;
  v1::StatsResponse p, f;
  ASSERT_TRUE(primary->Stats(&c1, {}, &p).ok());
  ASSERT_TRUE(follower->Stats(&c2, {}, &f).ok());
  EXPECT_EQ(f.models(), p.models());
  EXPECT_GT(p.models(), 200);
  std::vector<std::string> ids;
  for (int i = 0; i < 900; i += 97) {
    if (gateway::ShardOf(models[i].id, kShards) == 0)
      ids.push_back(models[i].id);
  }
  ASSERT_FALSE(ids.empty());
  EXPECT_EQ(Answers(follower.get(), ids), Answers(primary.get(), ids));
  // Read-only: a write to the follower names its primary.
  grpc::ClientContext c3;
  v1::UpsertResponse ignored;
  grpc::Status refused =
      follower->Upsert(&c3, ToRequest(models[0], true), &ignored);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(refused.error_message().find(shards_[0].address()),
            std::string::npos);
}

TEST_F(ClusterTest, BackupAndRestoreOfEveryShardAnswerIdentically) {
  const std::vector<TestModel> models = MakeModels(600, 5, 17, "b");
  std::vector<v1::UpsertRequest> requests;
  for (const TestModel& m : models) requests.push_back(ToRequest(m, true));
  v1::BatchUpsertResponse response;
  ASSERT_TRUE(Batch(gateway_stub_.get(), requests, &response).ok());
  ASSERT_TRUE(WaitForFollower());
  std::vector<std::string> ids;
  for (int i = 0; i < 600; i += 50) ids.push_back(models[i].id);
  const std::vector<std::string> before = Answers(gateway_stub_.get(), ids);
  // Per shard: back up its primary with `tpr backup`, restore with `tpr
  // restore` into an empty directory, start an indexer on each copy.
  ServiceProcess restored[kShards];
  std::vector<std::string> flags;
  for (int s = 0; s < kShards; ++s) {
    const std::string set = Path(absl::StrCat("backup", s));
    auto [code, out] = Tpr(
        absl::StrCat("--indexer ", shards_[s].address(), " backup --to ", set));
    ASSERT_EQ(code, 0) << out;
    EXPECT_NE(out.find("verified"), std::string::npos) << out;
    const std::string into = Path(absl::StrCat("restored", s));
    std::tie(code, out) =
        Tpr(absl::StrCat("--indexer ", shards_[s].address(), " restore --from ",
                         set, " --into ", into));
    ASSERT_EQ(code, 0) << out;
    // A second restore into the now non-empty directory is refused.
    EXPECT_EQ(Tpr(absl::StrCat("--indexer ", shards_[s].address(),
                               " restore --from ", set, " --into ", into))
                  .first,
              1);
    ASSERT_TRUE(restored[s]
                    .Start(BinaryPath("tpr-indexer"), {"--data-dir", into},
                           Path(absl::StrCat("restored", s, ".log")))
                    .ok());
    flags.push_back("--shard");
    flags.push_back(restored[s].address());
  }
  ServiceProcess gateway;
  ASSERT_TRUE(
      gateway
          .Start(BinaryPath("tpr-gateway"), flags, Path("gateway-restored.log"))
          .ok());
  auto stub = Stub(gateway.address());
  EXPECT_EQ(Answers(stub.get(), ids), before);
  grpc::ClientContext context;
  v1::StatsResponse stats;
  ASSERT_TRUE(stub->Stats(&context, {}, &stats).ok());
  EXPECT_EQ(stats.models(), 600);
}

}  // namespace
}  // namespace tpr::gateway
