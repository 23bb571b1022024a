// Storage (RocksDB) of tpr-indexer: round trips, order, tree marker,
// sequence numbers across reopen, exclusive open, and the acknowledged-state
// check (ACKNOWLEDGED): a database behind it is DATA_LOSS, one ahead of it
// (a crash between a write and its record) opens. A fresh temp dir per test.
#include "indexer/service/storage.h"

#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <string>
#include <utility>

#include "gtest/gtest.h"
#include "indexer/service/ack_file.h"
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
  for (size_t i = protos.size(); i-- > 0;)
    writes.push_back({protos[i].id(), &protos[i]});
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
  EXPECT_EQ(ids, (std::vector<std::string>{models[0].id, models[2].id,
                                           models[3].id, models[4].id}));
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
  ASSERT_TRUE(
      (*storage)
          ->ForEachModel(
              [&](uint64_t seq, tpr::v1::Model&& m) {
                std::lock_guard<std::mutex> lock(mu);
                if (!parallel
                         .emplace(m.id(),
                                  std::make_pair(seq, m.SerializeAsString()))
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
        return m.id() == bad ? absl::DataLossError("bad " + bad)
                             : absl::OkStatus();
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
    ASSERT_TRUE((*storage)
                    ->Write({{protos[0].id(), &protos[0]},
                             {protos[1].id(), &protos[1]}})
                    .ok());
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

// Writes three models and deletes one (four write batches), then closes.
void WriteFourBatches(const std::string& dir) {
  const std::vector<TestModel> models = MakeModels(3, 1, 3);
  std::vector<tpr::v1::Model> protos;
  for (const TestModel& m : models) protos.push_back(ModelOf(m));
  auto storage = Storage::Open(dir);
  ASSERT_TRUE(storage.ok()) << storage.status();
  for (const tpr::v1::Model& m : protos)
    ASSERT_TRUE((*storage)->Write({{m.id(), &m}}).ok());
  ASSERT_TRUE(
      (*storage)->Write({{protos[1].id(), nullptr}, {"absent", nullptr}}).ok());
  EXPECT_EQ((*storage)->model_count(), 2u);
}

TEST(StorageTest, ModelCountSurvivesReopenAndMatchesTheScan) {
  TempDir dir;
  WriteFourBatches(dir.path());
  auto storage = Storage::Open(dir.path());
  ASSERT_TRUE(storage.ok()) << storage.status();
  EXPECT_EQ((*storage)->model_count(), 2u);
  uint64_t scanned = 0;
  ASSERT_TRUE((*storage)
                  ->ForEachModel([&](uint64_t, tpr::v1::Model&&) {
                    ++scanned;
                    return absl::OkStatus();
                  })
                  .ok());
  EXPECT_EQ(scanned, 2u);
  EXPECT_TRUE((*storage)->CheckScanned(2).ok());
  absl::Status short_scan = (*storage)->CheckScanned(1);
  EXPECT_TRUE(absl::IsDataLoss(short_scan)) << short_scan;
  EXPECT_NE(short_scan.message().find("MANIFEST-"), std::string::npos)
      << short_scan;
}

// ACKNOWLEDGED claiming more than the database holds (what a lost MANIFEST
// edit or write-ahead log record leaves) is refused, naming the file, and
// the refused open changes no file of the directory.
TEST(StorageTest, DatabaseBehindWhatWasAcknowledgedIsDataLoss) {
  TempDir dir;
  WriteFourBatches(dir.path());
  {
    auto ack = AckFile::Open(dir.path(), /*create=*/false);
    ASSERT_TRUE(ack.ok()) << ack.status();
    ASSERT_TRUE((*ack)->recorded().has_value());
    EXPECT_EQ((*ack)->recorded()->writes, 4u);
    EXPECT_EQ((*ack)->recorded()->models, 2u);
    ASSERT_TRUE((*ack)->Record({5, 3}).ok());
  }
  std::map<std::string, uintmax_t> files;
  // Every file, the archived write-ahead logs kept for followers included.
  for (const auto& e :
       std::filesystem::recursive_directory_iterator(dir.path())) {
    if (e.is_regular_file())
      files[e.path().lexically_relative(dir.path()).string()] = e.file_size();
  }
  absl::StatusOr<std::unique_ptr<Storage>> storage = Storage::Open(dir.path());
  ASSERT_FALSE(storage.ok());
  EXPECT_TRUE(absl::IsDataLoss(storage.status())) << storage.status();
  EXPECT_NE(storage.status().message().find("ACKNOWLEDGED"), std::string::npos);
  EXPECT_NE(storage.status().message().find("MANIFEST-"), std::string::npos);
  EXPECT_EQ(storage.status().message().find(dir.path()), std::string::npos)
      << "names the server path: " << storage.status();
  std::map<std::string, uintmax_t> after;
  // Every file, the archived write-ahead logs kept for followers included.
  for (const auto& e :
       std::filesystem::recursive_directory_iterator(dir.path())) {
    if (e.is_regular_file())
      after[e.path().lexically_relative(dir.path()).string()] = e.file_size();
  }
  EXPECT_EQ(after, files);

  // Same number of writes, fewer models than acknowledged: also a loss.
  {
    auto ack = AckFile::Open(dir.path(), /*create=*/false);
    ASSERT_TRUE(ack.ok());
    ASSERT_TRUE((*ack)->Record({4, 3}).ok());
  }
  EXPECT_TRUE(absl::IsDataLoss(Storage::Open(dir.path()).status()));
}

// A crash after the database write but before its ACKNOWLEDGED record
// leaves the database one write ahead: not a loss; the open catches the
// record up.
TEST(StorageTest, DatabaseAheadOfTheRecordOpens) {
  TempDir dir;
  WriteFourBatches(dir.path());
  {
    auto ack = AckFile::Open(dir.path(), /*create=*/false);
    ASSERT_TRUE(ack.ok());
    ASSERT_TRUE((*ack)->Record({3, 3}).ok());  // before the delete batch
  }
  {
    auto storage = Storage::Open(dir.path());
    ASSERT_TRUE(storage.ok()) << storage.status();
    EXPECT_EQ((*storage)->model_count(), 2u);
  }
  auto ack = AckFile::Open(dir.path(), /*create=*/false);
  ASSERT_TRUE(ack.ok());
  EXPECT_EQ((*ack)->recorded()->writes, 4u);
  EXPECT_EQ((*ack)->recorded()->models, 2u);
}

// A torn record leaves the other slot; garbage in both is DATA_LOSS.
TEST(StorageTest, DamagedAcknowledgedFileIsDataLoss) {
  TempDir dir;
  WriteFourBatches(dir.path());
  const std::string path = dir.path() + "/" + AckFile::kName;
  {
    // Tear the latest record (the slot written last): the previous stands.
    auto ack = AckFile::Open(dir.path(), /*create=*/false);
    ASSERT_TRUE(ack.ok());
    const uint64_t writes = (*ack)->recorded()->writes;
    ack->reset();
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    char bytes[64];
    f.read(bytes, 64);
    // The slot holding `writes` (little-endian at offset 8 of its slot).
    const int latest = static_cast<unsigned char>(bytes[8]) == writes ? 0 : 1;
    f.seekp(latest * 32 + 12);
    f.write("XX", 2);
  }
  {
    auto ack = AckFile::Open(dir.path(), /*create=*/false);
    ASSERT_TRUE(ack.ok()) << ack.status();
    EXPECT_EQ((*ack)->recorded()->writes, 3u);
  }
  EXPECT_TRUE(Storage::Open(dir.path()).ok());
  {
    std::ofstream f(path, std::ios::binary | std::ios::trunc);
    f << std::string(64, 'x');
  }
  absl::Status st = Storage::Open(dir.path()).status();
  EXPECT_TRUE(absl::IsDataLoss(st)) << st;
  EXPECT_NE(st.message().find("ACKNOWLEDGED"), std::string::npos) << st;
}

}  // namespace
}  // namespace tpr::indexer::testing
