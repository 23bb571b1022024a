// tpr-indexer persistence: a restart gives identical answers from the
// persisted VP-tree (no rebuild); kill -9 of the real binary during a batch
// add keeps every acknowledged model and the index stays exact; SIGTERM
// during a search stream ends cleanly with exit code 0. Damaged files (a
// truncated MANIFEST, a flipped byte in the write-ahead log) are refused
// with DATA_LOSS naming the file, never served as a smaller database, and
// the refusal deletes nothing (docs/recovery.md).
#include <signal.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include "gtest/gtest.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"

namespace tpr::indexer::testing {
namespace {

using ::tpr::testing::BinaryPath;
using ::tpr::testing::ServiceProcess;
using ::tpr::testing::TempDir;

tpr::v1::SearchRequest BySignature(const tpr::index::Signature& s, int k) {
  tpr::v1::SearchRequest r;
  *r.mutable_signature() = ToWire(s);
  r.set_k(k);
  return r;
}

// The tpr-indexer binary: CMake puts it under indexer/ of the build dir.
std::string IndexerBinary() {
  for (const char* rel : {"indexer/tpr-indexer", "tpr-indexer"}) {
    const std::string path = BinaryPath(rel);
    if (std::filesystem::exists(path)) return path;
  }
  return BinaryPath("indexer/tpr-indexer");
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

grpc::Status BatchAdd(tpr::v1::Indexer::Stub* stub,
                      const std::vector<TestModel>& models, size_t begin,
                      size_t end) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() +
                       std::chrono::seconds(30));
  tpr::v1::BatchUpsertResponse response;
  auto writer = stub->BatchUpsert(&context, &response);
  for (size_t i = begin; i < end; ++i) {
    if (!writer->Write(ToRequest(models[i]))) break;
  }
  writer->WritesDone();
  grpc::Status s = writer->Finish();
  if (s.ok() && response.written() != static_cast<int64_t>(end - begin)) {
    return grpc::Status(grpc::StatusCode::INTERNAL, "wrong written count");
  }
  return s;
}

std::unique_ptr<tpr::v1::Indexer::Stub> Connect(const std::string& address) {
  return tpr::v1::Indexer::NewStub(
      grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
}

// Every stored model, through List and Get.
std::map<std::string, tpr::v1::Model> Everything(tpr::v1::Indexer::Stub* stub) {
  std::map<std::string, tpr::v1::Model> out;
  std::string token;
  do {
    grpc::ClientContext c;
    tpr::v1::ListRequest l;
    l.set_page_size(1000);
    l.set_page_token(token);
    tpr::v1::ListResponse r;
    EXPECT_TRUE(stub->List(&c, l, &r).ok());
    for (const auto& m : r.models()) {
      grpc::ClientContext g;
      tpr::v1::GetRequest get;
      get.set_id(m.id());
      EXPECT_TRUE(stub->Get(&g, get, &out[m.id()]).ok());
    }
    token = r.next_page_token();
  } while (!token.empty());
  return out;
}

TEST(PersistenceTest, RestartGivesIdenticalAnswersFromThePersistedTree) {
  TempDir dir;
  CoreOptions core;
  core.persist_interval_ms = 0;
  core.index.rebuild_threshold = 32;
  auto lines = std::make_shared<std::vector<std::string>>();
  auto mu = std::make_shared<std::mutex>();
  core.log = [lines, mu](const std::string& line) {
    std::lock_guard<std::mutex> lock(*mu);
    lines->push_back(line);
  };
  InProcessIndexer server(dir.path(), core);
  ASSERT_TRUE(server.Start().ok());
  const std::vector<TestModel> models = MakeModels(200, 4, 5);
  ASSERT_TRUE(BatchAdd(server.stub(), models, 0, models.size()).ok());
  // Let a rebuild fold the buffer in, so most models are in the tree.
  server.core()->WaitForRebuild();
  for (int i : {3, 50, 120}) {
    grpc::ClientContext c;
    tpr::v1::DeleteRequest d;
    d.set_id(models[static_cast<size_t>(i)].id);
    tpr::v1::DeleteResponse r;
    ASSERT_TRUE(server.stub()->Delete(&c, d, &r).ok());
  }
  const std::vector<TestModel> queries = MakeModels(5, 4, 6, "q");
  std::vector<SearchResult> before;
  for (const TestModel& q : queries) {
    tpr::v1::SearchRequest r = BySignature(q.signature, 12);
    r.set_label(q.label == "class1" ? "class1" : "");
    before.push_back(RunSearch(server.stub(), r));
    ASSERT_TRUE(before.back().status.ok());
  }
  grpc::ClientContext c1;
  tpr::v1::StatsResponse stats_before;
  ASSERT_TRUE(
      server.stub()->Stats(&c1, tpr::v1::StatsRequest(), &stats_before).ok());

  server.Stop();
  lines->clear();
  ASSERT_TRUE(server.Start().ok());
  // Reopened from the persisted tree, not rebuilt.
  bool from_tree = false;
  for (const std::string& line : *lines) {
    from_tree |= line.find("from the persisted VP-tree") != std::string::npos;
  }
  EXPECT_TRUE(from_tree);
  EXPECT_GT(server.core()->index().indexed(), 150u);

  grpc::ClientContext c2;
  tpr::v1::StatsResponse stats_after;
  ASSERT_TRUE(
      server.stub()->Stats(&c2, tpr::v1::StatsRequest(), &stats_after).ok());
  EXPECT_EQ(stats_after.models(), 197);
  EXPECT_EQ(stats_after.models(), stats_before.models());
  EXPECT_EQ(stats_after.labels().size(), stats_before.labels().size());
  for (size_t i = 0; i < queries.size(); ++i) {
    tpr::v1::SearchRequest r = BySignature(queries[i].signature, 12);
    r.set_label(queries[i].label == "class1" ? "class1" : "");
    SearchResult after = RunSearch(server.stub(), r);
    ASSERT_TRUE(after.status.ok());
    ASSERT_EQ(after.neighbors.size(), before[i].neighbors.size());
    for (size_t j = 0; j < after.neighbors.size(); ++j) {
      EXPECT_EQ(after.neighbors[j].SerializeAsString(),
                before[i].neighbors[j].SerializeAsString());
    }
  }
}

// Phase 1 adds and stops with SIGTERM (tree persisted); phase 2 adds in
// acknowledged batches and is killed with SIGKILL mid-way; phase 3 finds
// every acknowledged model, with the models written after the persisted tree
// in the index's buffer, and answers exactly.
TEST(PersistenceTest, KillDashNineDuringBatchAddKeepsEveryAcknowledgedModel) {
  const std::string binary = IndexerBinary();
  if (!std::filesystem::exists(binary)) GTEST_SKIP() << "no " << binary;
  TempDir dir;
  const std::string data = dir.path() + "/data";
  const std::vector<TestModel> first = MakeModels(120, 3, 7, "a");
  const std::vector<TestModel> second = MakeModels(600, 3, 8, "b");

  {
    ServiceProcess p;
    ASSERT_TRUE(
        p.Start(binary, {"--data-dir", data}, dir.path() + "/log1").ok());
    auto stub = Connect(p.address());
    ASSERT_TRUE(BatchAdd(stub.get(), first, 0, first.size()).ok());
    // An idle C++ channel has no thread to answer the server's shutdown
    // ping, which would stretch the graceful stop by seconds: close it first.
    stub.reset();
    EXPECT_EQ(p.Stop(SIGTERM), 0);
  }

  std::vector<std::string> acked;
  {
    ServiceProcess p;
    ASSERT_TRUE(
        p.Start(binary, {"--data-dir", data}, dir.path() + "/log2").ok());
    auto stub = Connect(p.address());
    std::mutex mu;
    std::atomic<size_t> acked_count{0};
    std::thread writer([&] {
      for (size_t begin = 0; begin < second.size(); begin += 20) {
        if (!BatchAdd(stub.get(), second, begin, begin + 20).ok()) return;
        std::lock_guard<std::mutex> lock(mu);
        for (size_t i = begin; i < begin + 20; ++i)
          acked.push_back(second[i].id);
        acked_count = acked.size();
      }
    });
    const auto give_up =
        std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (acked_count.load() < 100 &&
           std::chrono::steady_clock::now() < give_up) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    EXPECT_EQ(p.Stop(SIGKILL), 128 + SIGKILL);
    writer.join();
  }
  ASSERT_GE(acked.size(), 100u);
  EXPECT_LT(acked.size(), second.size())
      << "the kill came after the last batch";

  ServiceProcess p;
  ASSERT_TRUE(p.Start(binary, {"--data-dir", data}, dir.path() + "/log3").ok());
  auto stub = Connect(p.address());
  const std::map<std::string, tpr::v1::Model> stored = Everything(stub.get());
  for (const std::string& id : acked) EXPECT_EQ(stored.count(id), 1u) << id;
  for (const TestModel& m : first) EXPECT_EQ(stored.count(m.id), 1u) << m.id;
  // Whatever is stored is exactly what was sent (no torn records).
  std::vector<TestModel> present;
  for (const std::vector<TestModel>* set : {&first, &second}) {
    for (const TestModel& m : *set) {
      auto it = stored.find(m.id);
      if (it == stored.end()) continue;
      EXPECT_EQ(it->second.signature().SerializeAsString(),
                ToWire(m.signature).SerializeAsString());
      present.push_back(m);
    }
  }
  EXPECT_EQ(present.size(), stored.size());
  // Reopened from phase 1's tree; phase 2's models went to the buffer.
  const std::string log = ReadText(dir.path() + "/log3");
  EXPECT_NE(log.find("from the persisted VP-tree"), std::string::npos) << log;
  for (const TestModel& q : MakeModels(4, 3, 9, "q")) {
    SearchResult r = RunSearch(stub.get(), BySignature(q.signature, 15));
    ASSERT_TRUE(r.status.ok());
    TPR_EXPECT_SAME_RANKING(r.neighbors, BruteForce(q.signature, present, 15));
  }
  stub.reset();
  EXPECT_EQ(p.Stop(SIGTERM), 0);
}

TEST(PersistenceTest, SigtermDuringASearchStreamExitsCleanly) {
  const std::string binary = IndexerBinary();
  if (!std::filesystem::exists(binary)) GTEST_SKIP() << "no " << binary;
  TempDir dir;
  ServiceProcess p;
  ASSERT_TRUE(
      p.Start(binary, {"--data-dir", dir.path() + "/data"}, dir.path() + "/log")
          .ok());
  auto stub = Connect(p.address());
  const std::vector<TestModel> models = MakeModels(300, 3, 10);
  ASSERT_TRUE(BatchAdd(stub.get(), models, 0, models.size()).ok());

  grpc::ClientContext context;
  auto reader = stub->Search(&context, BySignature(models[0].signature, 300));
  tpr::v1::SearchResponse response;
  ASSERT_TRUE(reader->Read(&response));
  std::vector<tpr::v1::Neighbor> got = {response.neighbor()};
  std::atomic<int> exit_code{-2};
  std::thread stopper([&] { exit_code = p.Stop(SIGTERM); });
  while (reader->Read(&response)) {
    if (response.has_neighbor()) got.push_back(response.neighbor());
  }
  const grpc::Status status = reader->Finish();
  stopper.join();
  EXPECT_EQ(exit_code.load(), 0);
  // Either the stream completed before the server stopped, and then it is
  // exact, or it was cut by the shutdown with a gRPC error; never a crash.
  if (status.ok()) {
    TPR_EXPECT_SAME_RANKING(got, BruteForce(models[0].signature, models, 300));
  } else {
    EXPECT_LT(got.size(), 300u);
  }
  const std::string log = ReadText(dir.path() + "/log");
  EXPECT_NE(log.find("shutting down"), std::string::npos) << log;
  EXPECT_NE(log.find("stopped"), std::string::npos) << log;
}

// The files of a RocksDB directory with names ending in `suffix`.
std::set<std::string> FilesEndingIn(const std::string& dir,
                                    const std::string& suffix) {
  std::set<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (name.size() >= suffix.size() &&
        name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0) {
      out.insert(name);
    }
  }
  return out;
}

// The MANIFEST the directory's CURRENT file names.
std::string CurrentManifest(const std::string& dir) {
  std::string name = ReadText(dir + "/CURRENT");
  while (!name.empty() && (name.back() == '\n' || name.back() == '\r'))
    name.pop_back();
  return dir + "/" + name;
}

// Writes 200 models in two sessions (so the MANIFEST records several
// flushes), then applies `damage` to the closed directory and checks that
// reopening is refused with DATA_LOSS naming the MANIFEST, and that the
// refused open deleted no table file.
void ExpectManifestDamageRefused(
    const std::function<void(const std::string&)>& damage,
    size_t kSessions = 1) {
  TempDir dir;
  const std::string data = dir.path() + "/data";
  const std::vector<TestModel> models = MakeModels(200, 4, 21);
  for (size_t session = 0; session < kSessions; ++session) {
    CoreOptions core;
    core.persist_interval_ms = 0;
    InProcessIndexer server(data, core);
    ASSERT_TRUE(server.Start().ok());
    for (size_t begin = session * 200 / kSessions;
         begin < (session + 1) * 200 / kSessions; begin += 20) {
      ASSERT_TRUE(BatchAdd(server.stub(), models, begin, begin + 20).ok());
    }
  }  // Stop: memtables flushed, write-ahead logs obsolete.
  const std::set<std::string> tables = FilesEndingIn(data, ".sst");
  damage(CurrentManifest(data));

  CoreOptions core;
  core.data_dir = data;
  absl::StatusOr<std::unique_ptr<IndexerCore>> opened = IndexerCore::Open(core);
  ASSERT_FALSE(opened.ok()) << "served " << (*opened)->Stats().models()
                            << " models of 200 acknowledged";
  EXPECT_EQ(opened.status().code(), absl::StatusCode::kDataLoss)
      << opened.status();
  EXPECT_NE(opened.status().message().find("MANIFEST-"), std::string::npos)
      << opened.status();
  EXPECT_EQ(FilesEndingIn(data, ".sst"), tables)
      << "the refused open deleted table files";
  // Refused again: the first refusal changed nothing that would let a
  // second open through.
  opened = IndexerCore::Open(core);
  EXPECT_EQ(opened.status().code(), absl::StatusCode::kDataLoss)
      << opened.status();
}

TEST(PersistenceTest, ManifestTruncatedBy100BytesIsRefusedWithDataLoss) {
  ExpectManifestDamageRefused([](const std::string& manifest) {
    std::filesystem::resize_file(manifest,
                                 std::filesystem::file_size(manifest) - 100);
  });
}

TEST(PersistenceTest, ManifestTruncatedTo300BytesIsRefusedWithDataLoss) {
  ExpectManifestDamageRefused([](const std::string& manifest) {
    std::filesystem::resize_file(manifest, 300);
  });
}

// kill -9 of the real binary after 50 acknowledged models (in five batches),
// then one byte flipped in the write-ahead log, at several places in turn
// (each on a fresh copy of the killed directory): the open is refused with
// DATA_LOSS naming the log, and the binary exits instead of serving.
TEST(PersistenceTest, FlippedByteInTheWriteAheadLogIsRefusedWithDataLoss) {
  const std::string binary = IndexerBinary();
  if (!std::filesystem::exists(binary)) GTEST_SKIP() << "no " << binary;
  TempDir dir;
  const std::string killed = dir.path() + "/killed";
  const std::vector<TestModel> models = MakeModels(50, 3, 22);
  {
    ServiceProcess p;
    ASSERT_TRUE(
        p.Start(binary, {"--data-dir", killed}, dir.path() + "/log").ok());
    auto stub = Connect(p.address());
    for (size_t begin = 0; begin < models.size(); begin += 10) {
      ASSERT_TRUE(BatchAdd(stub.get(), models, begin, begin + 10).ok());
    }
    EXPECT_EQ(p.Stop(SIGKILL), 128 + SIGKILL);
  }
  const std::set<std::string> logs = FilesEndingIn(killed, ".log");
  std::string wal;
  uintmax_t wal_size = 0;
  for (const std::string& name : logs) {
    const uintmax_t size = std::filesystem::file_size(killed + "/" + name);
    if (size > wal_size) {
      wal = name;
      wal_size = size;
    }
  }
  ASSERT_GT(wal_size, 1000u)
      << "the acknowledged writes are not in a write-ahead log";

  // Undamaged, the killed directory opens with every acknowledged model.
  {
    const std::string copy = dir.path() + "/intact";
    std::filesystem::copy(killed, copy);
    CoreOptions core;
    core.data_dir = copy;
    auto opened = IndexerCore::Open(core);
    ASSERT_TRUE(opened.ok()) << opened.status();
    EXPECT_EQ((*opened)->Stats().models(), 50);
  }
  for (double at : {0.25, 0.5, 0.75, 0.98}) {
    SCOPED_TRACE(absl::StrCat("byte flipped at ", at, " of ", wal, " (",
                              wal_size, " bytes)"));
    const std::string copy =
        absl::StrCat(dir.path(), "/flipped", static_cast<int>(at * 100));
    std::filesystem::copy(killed, copy);
    {
      std::fstream f(copy + "/" + wal,
                     std::ios::in | std::ios::out | std::ios::binary);
      const std::streamoff offset = static_cast<std::streamoff>(wal_size * at);
      f.seekg(offset);
      char byte = 0;
      f.read(&byte, 1);
      byte = static_cast<char>(byte ^ 0x5a);
      f.seekp(offset);
      f.write(&byte, 1);
    }
    CoreOptions core;
    core.data_dir = copy;
    absl::StatusOr<std::unique_ptr<IndexerCore>> opened =
        IndexerCore::Open(core);
    ASSERT_FALSE(opened.ok()) << "served " << (*opened)->Stats().models()
                              << " models of 50 acknowledged";
    EXPECT_EQ(opened.status().code(), absl::StatusCode::kDataLoss)
        << opened.status();
    EXPECT_NE(opened.status().message().find(wal), std::string::npos)
        << opened.status();
    if (at == 0.5) {
      // The binary refuses to serve: it exits, saying why.
      ServiceProcess p;
      absl::Status started =
          p.Start(binary, {"--data-dir", copy}, dir.path() + "/log_flipped");
      EXPECT_FALSE(started.ok());
      EXPECT_NE(ReadText(dir.path() + "/log_flipped").find("DATA_LOSS"),
                std::string::npos);
    }
  }
}

}  // namespace
}  // namespace tpr::indexer::testing
