// tpr-indexer on a full disk: writes fail with
// RESOURCE_EXHAUSTED (which the SDK does not retry), readiness reports the
// reason meanwhile, and once space is freed the indexer accepts writes again
// by itself, without a restart; no acknowledged model is lost. The disk is a
// small tmpfs mounted for the test; where mounting is not permitted (not
// root, no CAP_SYS_ADMIN) the test is skipped.
//
// Why RESOURCE_EXHAUSTED and not UNAVAILABLE: the SDK (client/src/client.cc,
// WithRetries) retries only UNAVAILABLE, so a full disk answers at once
// instead of being hammered by retries; the error reaches the caller.
#include <sys/mount.h>

#include <filesystem>
#include <fstream>
#include <thread>

#include "gtest/gtest.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"

namespace tpr::indexer::testing {
namespace {

using ::tpr::testing::TempDir;

constexpr int kServing = 1;
constexpr int kNotServing = 2;

// The readiness (grpc.health.v1 status of "tpr.v1.Indexer") once it equals
// `want` or 20 s passed; the last status seen (-1 on a failed call).
int WaitForReadiness(InProcessIndexer& server, int want) {
  const auto give_up =
      std::chrono::steady_clock::now() + std::chrono::seconds(20);
  int last = -1;
  while (std::chrono::steady_clock::now() < give_up) {
    absl::StatusOr<int> s =
        ::tpr::testing::HealthStatus(server.channel(), "tpr.v1.Indexer");
    last = s.ok() ? *s : -1;
    if (last == want) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return last;
}

// A tmpfs of `bytes` mounted on `dir` for the object's life.
class SmallDisk {
 public:
  SmallDisk(const std::string& dir, size_t bytes) : dir_(dir) {
    const std::string options = "size=" + std::to_string(bytes);
    mounted_ = ::mount("tmpfs", dir.c_str(), "tmpfs", 0, options.c_str()) == 0;
  }
  ~SmallDisk() {
    if (mounted_) ::umount2(dir_.c_str(), MNT_DETACH);
  }
  bool mounted() const { return mounted_; }

 private:
  std::string dir_;
  bool mounted_ = false;
};

TEST(IndexerDiskFullTest,
     WritesFailWithResourceExhaustedAndResumeOnceSpaceIsFreed) {
  TempDir dir;
  const std::string disk = dir.path() + "/disk";
  std::filesystem::create_directories(disk);
  // 200 MiB, mostly filler: RocksDB's SstFileManager clears a hard error
  // (and DB::Resume succeeds) only once the free space exceeds its reserve,
  // about the write buffers' size (64 MiB), so a smaller disk never recovers.
  SmallDisk small(disk, 200 << 20);
  if (!small.mounted())
    GTEST_SKIP() << "cannot mount a tmpfs here (needs root)";
  // Filler that is freed later: "space returns".
  const std::string filler = disk + "/filler";
  {
    std::ofstream f(filler, std::ios::binary);
    const std::string block(1 << 20, 'f');
    for (int i = 0; i < 194; ++i)
      f.write(block.data(), static_cast<std::streamsize>(block.size()));
  }
  // Large signatures (150 features x 8 bands, ~29 KB a model) fill the
  // disk in a few hundred writes.
  tpr::index::testing::SignatureGeneratorOptions options;
  options.seed = 97;
  options.features = 150;
  options.bands = 8;
  options.classes = 3;
  tpr::index::testing::SignatureGenerator gen(options);
  CoreOptions core;
  core.persist_interval_ms = 0;
  InProcessIndexer server(disk + "/data", core);
  ASSERT_TRUE(server.Start().ok());
  ASSERT_EQ(WaitForReadiness(server, kServing), kServing);

  std::vector<TestModel> acked;
  grpc::Status failed;
  for (int i = 0; i < 2000; ++i) {
    TestModel m{absl::StrCat("m", i), absl::StrCat("c", i % 3),
                gen.Member(i % 3)};
    grpc::ClientContext c;
    tpr::v1::UpsertResponse resp;
    grpc::Status s = server.stub()->Upsert(&c, ToRequest(m), &resp);
    if (!s.ok()) {
      failed = s;
      break;
    }
    acked.push_back(std::move(m));
  }
  ASSERT_FALSE(failed.ok()) << "the disk never filled";
  EXPECT_EQ(failed.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
      << failed.error_message();
  EXPECT_NE(failed.error_message().find("disk is full"), std::string::npos)
      << failed.error_message();
  EXPECT_EQ(failed.error_message().find(disk), std::string::npos)
      << "names the server path: " << failed.error_message();
  // Meanwhile: readiness is NOT_SERVING and says why, further writes fail
  // fast the same way, reads and searches work.
  EXPECT_EQ(WaitForReadiness(server, kNotServing), kNotServing);
  EXPECT_NE(server.core()->WriteReadiness().find("space is freed"),
            std::string::npos)
      << server.core()->WriteReadiness();
  {
    TestModel m{"later", "c0", gen.Member(0)};
    grpc::ClientContext c;
    tpr::v1::UpsertResponse resp;
    grpc::Status s = server.stub()->Upsert(&c, ToRequest(m), &resp);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
        << s.error_message();
    EXPECT_NE(s.error_message().find("disk is full"), std::string::npos)
        << s.error_message();
  }
  EXPECT_EQ(WaitForReadiness(server, kNotServing), kNotServing);
  SearchResult r = RunSearch(server.stub(), [&] {
    tpr::v1::SearchRequest q;
    *q.mutable_signature() = ToWire(acked[0].signature);
    q.set_k(3);
    return q;
  }());
  ASSERT_TRUE(r.status.ok()) << r.status.error_message();
  TPR_EXPECT_SAME_RANKING(r.neighbors,
                          BruteForce(acked[0].signature, acked, 3));

  // Space returns: within a few seconds (one Resume attempt a second)
  // readiness is SERVING again and writes are accepted, no restart.
  std::filesystem::remove(filler);
  EXPECT_EQ(WaitForReadiness(server, kServing), kServing);
  EXPECT_EQ(server.core()->WriteReadiness(), "");
  for (int i = 0; i < 3; ++i) {
    TestModel m{absl::StrCat("after", i), "c1", gen.Member(1)};
    grpc::ClientContext c;
    tpr::v1::UpsertResponse resp;
    grpc::Status s = server.stub()->Upsert(&c, ToRequest(m), &resp);
    ASSERT_TRUE(s.ok()) << s.error_message();
    acked.push_back(std::move(m));
  }

  // Nothing acknowledged was lost and the refused ones were not stored,
  // across a restart too: every acknowledged id is there, the count is
  // exactly theirs.
  server.Stop();
  ASSERT_TRUE(server.Start().ok());
  EXPECT_EQ(WaitForReadiness(server, kServing), kServing);
  grpc::ClientContext c;
  tpr::v1::StatsResponse stats;
  ASSERT_TRUE(server.stub()->Stats(&c, tpr::v1::StatsRequest(), &stats).ok());
  EXPECT_EQ(stats.models(), static_cast<int64_t>(acked.size()));
  int missing = 0;
  for (const TestModel& m : acked) {
    grpc::ClientContext g;
    tpr::v1::GetRequest get;
    get.set_id(m.id);
    tpr::v1::Model got;
    grpc::Status s = server.stub()->Get(&g, get, &got);
    if (!s.ok() || got.label() != m.label) ++missing;
  }
  EXPECT_EQ(missing, 0) << "of " << acked.size() << " acknowledged models";
  {
    grpc::ClientContext g;
    tpr::v1::GetRequest get;
    get.set_id("later");
    tpr::v1::Model got;
    EXPECT_EQ(server.stub()->Get(&g, get, &got).error_code(),
              grpc::StatusCode::NOT_FOUND);
  }
  server.Stop();
}

}  // namespace
}  // namespace tpr::indexer::testing
