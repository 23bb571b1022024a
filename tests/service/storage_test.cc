// Storage (RocksDB) of tpr-indexer: round trips, order, tree marker,
// sequence numbers across reopen, exclusive open. A fresh temp dir per test.
#include "indexer/service/storage.h"

#include <map>
#include <mutex>
#include <string>
#include <utility>

#include "gtest/gtest.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"

namespace tpr::indexer::testing {
namespace {

using ::tpr::testing::TempDir;

tpr::v1::Model ModelOf(const TestModel& m) { return ToRequest(m).model(); }

TEST(StorageTest, WriteGetDeleteAndScanInIdOrder) {
  TempDir dir;
  auto storage = Storage::Open(dir.path());
  ASSERT_TRUE(storage.ok()) << storage.status();
  const std::vector<TestModel> models = MakeModels(5, 2, 1);
  std::vector<tpr::v1::Model> protos;
  for (const TestModel& m : models) protos.push_back(ModelOf(m));
  // Written in reverse order; the scan returns id order.
  std::vector<ModelWrite> writes;
  for (size_t i = protos.size(); i-- > 0;) writes.push_back({protos[i].id(), &protos[i]});
  ASSERT_TRUE((*storage)->Write(writes).ok());
  EXPECT_EQ((*storage)->last_seq(), 5u);

  absl::StatusOr<tpr::v1::Model> got = (*storage)->GetModel(models[2].id);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->SerializeAsString(), protos[2].SerializeAsString());
  EXPECT_TRUE(absl::IsNotFound((*storage)->GetModel("nope").status()));

  ASSERT_TRUE((*storage)->Write({{models[1].id, nullptr}}).ok());
  EXPECT_TRUE(absl::IsNotFound((*storage)->GetModel(models[1].id).status()));

  std::vector<std::string> ids;
  std::vector<uint64_t> seqs;
  ASSERT_TRUE((*storage)
                  ->ForEachModel([&](uint64_t seq, tpr::v1::Model&& m) {
                    ids.push_back(m.id());
                    seqs.push_back(seq);
                    return absl::OkStatus();
                  })
                  .ok());
  EXPECT_EQ(ids, (std::vector<std::string>{models[0].id, models[2].id, models[3].id,
                                           models[4].id}));
  // Reverse write order: model 0 was written last (seq 5), model 4 first.
  EXPECT_EQ(seqs, (std::vector<uint64_t>{5, 3, 2, 1}));
  EXPECT_GT((*storage)->DiskBytes(), 0);
}

// The parallel scan visits exactly what the sequential one does (the
// oracle), each model once with its sequence number, and stops with the
// callback's error.
TEST(StorageTest, ParallelScanMatchesSequentialScanAndStopsAtAnError) {
  TempDir dir;
  auto storage = Storage::Open(dir.path());
  ASSERT_TRUE(storage.ok()) << storage.status();
  // More than a few chunks of 128 records, so both workers get some.
  const std::vector<TestModel> models = MakeModels(700, 3, 5);
  std::vector<tpr::v1::Model> protos;
  for (const TestModel& m : models) protos.push_back(ModelOf(m));
  std::vector<ModelWrite> writes;
  for (const tpr::v1::Model& p : protos) writes.push_back({p.id(), &p});
  ASSERT_TRUE((*storage)->Write(writes).ok());

  std::map<std::string, std::pair<uint64_t, std::string>> sequential;
  ASSERT_TRUE((*storage)
                  ->ForEachModel([&](uint64_t seq, tpr::v1::Model&& m) {
                    sequential[m.id()] = {seq, m.SerializeAsString()};
                    return absl::OkStatus();
                  })
                  .ok());
  ASSERT_EQ(sequential.size(), models.size());
  std::mutex mu;
  std::map<std::string, std::pair<uint64_t, std::string>> parallel;
  int duplicates = 0;
  ASSERT_TRUE((*storage)
                  ->ForEachModel(
                      [&](uint64_t seq, tpr::v1::Model&& m) {
                        std::lock_guard<std::mutex> lock(mu);
                        if (!parallel.emplace(m.id(), std::make_pair(seq, m.SerializeAsString()))
                                 .second) {
                          ++duplicates;
                        }
                        return absl::OkStatus();
                      },
                      /*threads=*/2)
                  .ok());
  EXPECT_EQ(duplicates, 0);
  EXPECT_EQ(parallel, sequential);

  const std::string bad = models[400].id;
  absl::Status st = (*storage)->ForEachModel(
      [&](uint64_t, tpr::v1::Model&& m) {
        return m.id() == bad ? absl::DataLossError("bad " + bad) : absl::OkStatus();
      },
      /*threads=*/2);
  EXPECT_TRUE(absl::IsDataLoss(st)) << st;
  EXPECT_EQ(st.message(), "bad " + bad);
}

TEST(StorageTest, TreeAndSequenceSurviveReopen) {
  TempDir dir;
  const std::vector<TestModel> models = MakeModels(3, 1, 2);
  std::vector<tpr::v1::Model> protos;
  for (const TestModel& m : models) protos.push_back(ModelOf(m));
  {
    auto storage = Storage::Open(dir.path());
    ASSERT_TRUE(storage.ok());
    EXPECT_TRUE(absl::IsNotFound((*storage)->LoadTree().status()));
    ASSERT_TRUE((*storage)->Write({{protos[0].id(), &protos[0]}, {protos[1].id(), &protos[1]}}).ok());
    ASSERT_TRUE((*storage)->SaveTree(std::string("tree\0bytes", 10), 2).ok());
    ASSERT_TRUE((*storage)->Write({{protos[2].id(), &protos[2]}}).ok());
    ASSERT_TRUE((*storage)->Write({{protos[2].id(), nullptr}}).ok());
  }
  auto storage = Storage::Open(dir.path());
  ASSERT_TRUE(storage.ok());
  absl::StatusOr<PersistedTree> tree = (*storage)->LoadTree();
  ASSERT_TRUE(tree.ok());
  EXPECT_EQ(tree->bytes, std::string("tree\0bytes", 10));
  EXPECT_EQ(tree->seq, 2u);
  // The counter continues after the deleted model's number.
  EXPECT_EQ((*storage)->last_seq(), 3u);
  ASSERT_TRUE((*storage)->Write({{protos[2].id(), &protos[2]}}).ok());
  EXPECT_EQ((*storage)->last_seq(), 4u);
}

TEST(StorageTest, SecondOpenOfALockedDirectoryIsUnavailable) {
  TempDir dir;
  auto first = Storage::Open(dir.path());
  ASSERT_TRUE(first.ok());
  auto second = Storage::Open(dir.path());
  EXPECT_TRUE(absl::IsUnavailable(second.status())) << second.status();
  EXPECT_TRUE(absl::IsInvalidArgument(Storage::Open("").status()));
}

}  // namespace
}  // namespace tpr::indexer::testing
