// Backups and followers of tpr-indexer (indexer/service/replication.h,
// follower.h, admin_service.h), in process on loopback. The oracle of every
// check is the primary itself: a restored or following indexer must answer
// every search byte for byte as the primary does (serialized neighbours),
// and Stats must count the same models.
#include "indexer/service/replication.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "common/server_lifecycle.h"
#include "common/status_macros.h"
#include "indexer/service/admin_service.h"
#include "indexer/service/follower.h"
#include "tests/service/extsvc_test_util.h"
#include "tests/service/indexer_testing.h"

namespace tpr::indexer {
namespace {

using ::tpr::indexer::testing::MakeModels;
using ::tpr::indexer::testing::RunSearch;
using ::tpr::indexer::testing::TestModel;
using ::tpr::indexer::testing::ToRequest;
using ::tpr::indexer::testing::ToWire;
using ::tpr::testing::TempDir;

// One tpr-indexer in process: core, Indexer and IndexerAdmin services, and
// a follower when core.follow is set.
class Node {
 public:
  Node(std::string dir, std::string follow = "", StorageOptions storage = {}) {
    core_options_.data_dir = std::move(dir);
    core_options_.follow = std::move(follow);
    core_options_.storage = storage;
    core_options_.persist_interval_ms = 0;
  }
  ~Node() { Stop(); }

  absl::Status Start() {
    if (!core_options_.follow.empty()) {
      follower_options_.primary = core_options_.follow;
      follower_options_.data_dir = core_options_.data_dir;
      TPR_RETURN_IF_ERROR(PrepareFollowerDir(follower_options_));
    }
    TPR_ASSIGN_OR_RETURN(core_, IndexerCore::Open(core_options_));
    service_ = std::make_unique<IndexerService>(core_.get(), ServiceOptions{});
    if (!core_options_.follow.empty()) {
      follower_ = std::make_unique<Follower>(core_.get(), follower_options_);
    }
    AdminOptions admin_options;
    admin_options.backup_root = "/";  // any path: the tests' temp dirs
    admin_ = std::make_unique<IndexerAdminService>(core_.get(), follower_.get(),
                                                   admin_options);
    server_options_.shutdown_grace_ms = 2000;
    TPR_ASSIGN_OR_RETURN(tpr::common::StartedServer started,
                         tpr::common::StartServer(
                             server_options_, {service_.get(), admin_.get()}));
    server_ = std::move(started.server);
    port_ = started.port;
    auto channel =
        grpc::CreateChannel(address(), grpc::InsecureChannelCredentials());
    stub_ = tpr::v1::Indexer::NewStub(channel);
    admin_stub_ = tpr::v1::IndexerAdmin::NewStub(channel);
    if (follower_ != nullptr) follower_->Start([this] { resync_ = true; });
    return absl::OkStatus();
  }

  void Stop() {
    if (admin_) admin_->Stop();
    if (follower_) follower_->Stop();
    if (server_) tpr::common::ShutdownGracefully(*server_, server_options_);
    server_.reset();
    admin_.reset();
    follower_.reset();
    service_.reset();
    core_.reset();
  }

  std::string address() const { return absl::StrCat("127.0.0.1:", port_); }
  tpr::v1::Indexer::Stub* stub() { return stub_.get(); }
  tpr::v1::IndexerAdmin::Stub* admin() { return admin_stub_.get(); }
  IndexerCore* core() { return core_.get(); }
  Follower* follower() { return follower_.get(); }
  bool resync() const { return resync_; }

 private:
  CoreOptions core_options_;
  FollowerOptions follower_options_;
  tpr::common::ServerOptions server_options_;
  std::unique_ptr<IndexerCore> core_;
  std::unique_ptr<IndexerService> service_;
  std::unique_ptr<Follower> follower_;
  std::unique_ptr<IndexerAdminService> admin_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::unique_ptr<tpr::v1::Indexer::Stub> stub_;
  std::unique_ptr<tpr::v1::IndexerAdmin::Stub> admin_stub_;
  std::atomic<bool> resync_{false};
};

void Ingest(IndexerCore* core, const std::vector<TestModel>& models) {
  for (const TestModel& m : models)
    ASSERT_TRUE(core->Upsert(ToRequest(m, true)).ok()) << m.id;
}

// Every answer of `node` to a fixed set of queries (by signature, by id with
// exclude_self, with a label filter and a radius), serialized: neighbours
// byte for byte, in order.
std::vector<std::string> Answers(Node& node,
                                 const std::vector<TestModel>& queries) {
  std::vector<std::string> out;
  for (size_t i = 0; i < queries.size(); ++i) {
    tpr::v1::SearchRequest by_signature;
    *by_signature.mutable_signature() = ToWire(queries[i].signature);
    by_signature.set_k(7);
    tpr::v1::SearchRequest by_id;
    by_id.set_id(queries[i].id);
    by_id.set_k(5);
    by_id.set_exclude_self(true);
    by_id.set_label(i % 2 == 0 ? "class0" : "");
    for (const auto& request : {by_signature, by_id}) {
      testing::SearchResult r = RunSearch(node.stub(), request);
      std::string answer =
          r.status.ok() ? "" : absl::StrCat("error ", r.status.error_code());
      for (const tpr::v1::Neighbor& n : r.neighbors)
        answer += n.SerializeAsString() + "|";
      out.push_back(answer);
    }
  }
  return out;
}

grpc::Status Call(Node& node, const tpr::v1::BackupRequest& request,
                  tpr::v1::BackupResponse* response) {
  grpc::ClientContext context;
  return node.admin()->Backup(&context, request, response);
}

grpc::Status Call(Node& node, const tpr::v1::RestoreRequest& request,
                  tpr::v1::RestoreResponse* response) {
  grpc::ClientContext context;
  return node.admin()->Restore(&context, request, response);
}

// Storage options that keep no closed write-ahead log: deleted at once.
StorageOptions NoArchive() {
  StorageOptions options;
  options.wal_keep_seconds = 0;
  options.wal_keep_mb = 0;
  return options;
}

template <typename Pred>
bool WaitFor(Pred pred, int seconds = 30) {
  const auto give_up =
      std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
  while (std::chrono::steady_clock::now() < give_up) {
    if (pred()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return pred();
}

TEST(BackupTest, RestoreAnswersByteIdenticallyAndRefusesANonEmptyDirectory) {
  TempDir tmp;
  const std::string backups = tmp.path() + "/backups";
  Node primary(tmp.path() + "/primary");
  ASSERT_TRUE(primary.Start().ok());
  const std::vector<TestModel> models = MakeModels(120, 4, 11);
  Ingest(primary.core(), {models.begin(), models.begin() + 100});

  tpr::v1::BackupRequest request;
  request.set_backup_dir(backups);
  tpr::v1::BackupResponse first;
  ASSERT_TRUE(Call(primary, request, &first).ok());
  EXPECT_EQ(first.backup_id(), 1u);
  EXPECT_EQ(first.models(), 100);
  EXPECT_TRUE(first.verified());
  EXPECT_GT(first.copied_bytes(), 0u);
  const std::vector<TestModel> queries(models.begin(), models.begin() + 12);
  const std::vector<std::string> at_first = Answers(primary, queries);

  // Incremental: a few more models, then a second backup copies only the
  // new files, far less than the first.
  Ingest(primary.core(), {models.begin() + 100, models.end()});
  ASSERT_TRUE(primary.core()->Delete(models[3].id).ok());
  tpr::v1::BackupResponse second;
  ASSERT_TRUE(Call(primary, request, &second).ok());
  EXPECT_EQ(second.backup_id(), 2u);
  EXPECT_EQ(second.models(), 119);
  EXPECT_LT(second.copied_bytes(), first.copied_bytes());
  const std::vector<std::string> at_second = Answers(primary, queries);
  ASSERT_NE(at_first, at_second);  // the two backups differ

  // Restore each into an empty directory: same answers as when taken.
  for (uint32_t id : {1u, 2u}) {
    const std::string into = absl::StrCat(tmp.path(), "/restored", id);
    tpr::v1::RestoreRequest restore;
    restore.set_backup_dir(backups);
    restore.set_backup_id(id);
    restore.set_data_dir(into);
    tpr::v1::RestoreResponse restored;
    grpc::Status s = Call(primary, restore, &restored);
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(restored.models(), id == 1 ? 100 : 119);
    Node copy(into);
    ASSERT_TRUE(copy.Start().ok());
    EXPECT_EQ(Answers(copy, queries), id == 1 ? at_first : at_second)
        << "backup " << id;
  }

  // Refused: a non-empty directory (nothing touched), the indexer's own
  // directory, a missing backup id, a missing set.
  const std::string busy = tmp.path() + "/busy";
  std::filesystem::create_directories(busy);
  std::ofstream(busy + "/keep.txt") << "data";
  tpr::v1::RestoreRequest restore;
  restore.set_backup_dir(backups);
  restore.set_data_dir(busy);
  tpr::v1::RestoreResponse ignored;
  grpc::Status s = Call(primary, restore, &ignored);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_NE(s.error_message().find("not empty"), std::string::npos)
      << s.error_message();
  EXPECT_NE(s.error_message().find(busy), std::string::npos)
      << s.error_message();
  EXPECT_TRUE(std::filesystem::exists(busy + "/keep.txt"));
  restore.set_data_dir(tmp.path() + "/primary");
  EXPECT_EQ(Call(primary, restore, &ignored).error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  restore.set_data_dir(tmp.path() + "/fresh");
  restore.set_backup_id(9);
  EXPECT_EQ(Call(primary, restore, &ignored).error_code(),
            grpc::StatusCode::NOT_FOUND);
  restore.set_backup_dir(tmp.path() + "/nothing");
  restore.set_backup_id(0);
  EXPECT_EQ(Call(primary, restore, &ignored).error_code(),
            grpc::StatusCode::NOT_FOUND);

  // keep_last prunes the set.
  request.set_keep_last(1);
  tpr::v1::BackupResponse third;
  ASSERT_TRUE(Call(primary, request, &third).ok());
  restore.set_backup_dir(backups);
  restore.set_backup_id(1);
  restore.set_data_dir(tmp.path() + "/gone");
  EXPECT_EQ(Call(primary, restore, &ignored).error_code(),
            grpc::StatusCode::NOT_FOUND);
}

TEST(FollowerTest, CopiesTailsRefusesWritesAndPromotes) {
  TempDir tmp;
  Node primary(tmp.path() + "/primary");
  ASSERT_TRUE(primary.Start().ok());
  const std::vector<TestModel> models = MakeModels(150, 5, 23);
  Ingest(primary.core(), {models.begin(), models.begin() + 60});

  Node follower(tmp.path() + "/follower", primary.address());
  {
    absl::Status started = follower.Start();
    ASSERT_TRUE(started.ok()) << started;
  }
  ASSERT_TRUE(
      WaitFor([&] { return follower.follower()->Readiness().empty(); }));
  const std::vector<TestModel> queries(models.begin(), models.begin() + 10);
  EXPECT_EQ(Answers(follower, queries), Answers(primary, queries));

  // Writes on the primary (batch, single, replace, delete) reach it.
  std::vector<tpr::v1::UpsertRequest> batch;
  std::vector<tpr::index::Signature> sigs;
  for (int i = 60; i < 140; ++i) {
    batch.push_back(ToRequest(models[i], true));
    sigs.push_back(models[i].signature);
  }
  ASSERT_TRUE(primary.core()->WriteGroup(batch, sigs).ok());
  tpr::v1::UpsertRequest relabel = ToRequest(models[5], true);
  relabel.mutable_model()->set_label("class0");
  ASSERT_TRUE(primary.core()->Upsert(relabel).ok());
  ASSERT_TRUE(primary.core()->Delete(models[7].id).ok());
  ASSERT_TRUE(WaitFor([&] {
    return follower.follower()->Status().applied_sequence() >=
           LatestSequence(primary.core()->storage());
  }));
  EXPECT_EQ(follower.core()->Stats().models(),
            primary.core()->Stats().models());
  EXPECT_EQ(Answers(follower, queries), Answers(primary, queries));

  // Read-only: writes fail naming the primary.
  absl::StatusOr<bool> refused =
      follower.core()->Upsert(ToRequest(models[140], true));
  EXPECT_TRUE(absl::IsFailedPrecondition(refused.status())) << refused.status();
  EXPECT_NE(refused.status().message().find(primary.address()),
            std::string::npos);
  EXPECT_TRUE(
      absl::IsFailedPrecondition(follower.core()->Delete(models[0].id)));

  // Restarted (its store holds the applied sequence): it resumes, catches
  // up with what was written meanwhile, and is not ready before.
  follower.Stop();
  Ingest(primary.core(), {models.begin() + 140, models.end()});
  {
    absl::Status started = follower.Start();
    ASSERT_TRUE(started.ok()) << started;
  }
  ASSERT_TRUE(
      WaitFor([&] { return follower.follower()->Readiness().empty(); }));
  EXPECT_EQ(Answers(follower, queries), Answers(primary, queries));
  EXPECT_EQ(follower.core()->Stats().models(), 149);

  // Promotion: writes accepted; the directory is a primary's from now on,
  // so --follow refuses it.
  grpc::ClientContext context;
  tpr::v1::PromoteResponse promoted;
  ASSERT_TRUE(follower.admin()->Promote(&context, {}, &promoted).ok());
  EXPECT_EQ(promoted.former_primary(), primary.address());
  EXPECT_TRUE(follower.core()->Upsert(ToRequest(models[7], true)).ok());
  follower.Stop();
  FollowerOptions again;
  again.primary = primary.address();
  again.data_dir = tmp.path() + "/follower";
  absl::Status refused_dir = PrepareFollowerDir(again);
  EXPECT_TRUE(absl::IsFailedPrecondition(refused_dir)) << refused_dir;
}

// Media live in their own column family: a backup restores them, a
// follower's checkpoint copies them and its log tailing brings in later
// ones, replacements and deletes, byte for byte as the primary serves them.
tpr::v1::ModelMedia MediaFor(int i) {
  tpr::v1::ModelMedia media;
  media.set_thumbnail_png(
      std::string("\x89PNG\r\n\x1a\n", 8) +
      std::string(500 + i, static_cast<char>('a' + i % 26)));
  media.set_preview_ply(
      "ply\n" + std::string(70000 + i, static_cast<char>('A' + i % 26)));
  return media;
}

void IngestWithMedia(IndexerCore* core, const std::vector<TestModel>& models,
                     int first, int last) {
  for (int i = first; i < last; ++i) {
    tpr::v1::UpsertRequest request = ToRequest(models[i], true);
    *request.mutable_model()->mutable_media() = MediaFor(i);
    ASSERT_TRUE(core->Upsert(request).ok()) << models[i].id;
  }
}

// What `node` serves of each model's media: "thumbnail|preview", or the
// error code.
std::vector<std::string> MediaAnswers(Node& node,
                                      const std::vector<TestModel>& models) {
  std::vector<std::string> out;
  for (const TestModel& m : models) {
    absl::StatusOr<std::string> png = node.core()->GetThumbnail(m.id);
    absl::StatusOr<std::string> ply = node.core()->GetPreview(m.id);
    out.push_back(absl::StrCat(
        png.ok() ? *png : absl::StrCat("error ", png.status().code()), "|",
        ply.ok() ? *ply : absl::StrCat("error ", ply.status().code())));
  }
  return out;
}

// Backups and restores go only under the configured root (--backup-root),
// and nowhere without one.
TEST(BackupTest, PathsOutsideTheBackupRootAreRefused) {
  TempDir tmp;
  CoreOptions core_options;
  core_options.data_dir = tmp.path() + "/data";
  core_options.persist_interval_ms = 0;
  absl::StatusOr<std::unique_ptr<IndexerCore>> core =
      IndexerCore::Open(core_options);
  ASSERT_TRUE(core.ok()) << core.status();
  const std::string root = tmp.path() + "/backups";
  std::filesystem::create_directories(root);
  auto backup = [&](const std::string& backup_root, const std::string& dir) {
    AdminOptions options;
    options.backup_root = backup_root;
    IndexerAdminService admin(core->get(), nullptr, options);
    tpr::v1::BackupRequest request;
    request.set_backup_dir(dir);
    tpr::v1::BackupResponse response;
    return admin.Backup(nullptr, &request, &response);
  };
  EXPECT_TRUE(backup(root, root + "/set").ok());
  EXPECT_EQ(backup("", root + "/set").error_code(),
            grpc::StatusCode::FAILED_PRECONDITION);
  for (const std::string& outside :
       {tmp.path() + "/elsewhere", root + "/../escaped", std::string("/etc")}) {
    const grpc::Status refused = backup(root, outside);
    EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT)
        << outside;
    EXPECT_NE(refused.error_message().find("backup_dir '" + outside + "'"),
              std::string::npos)
        << refused.error_message();
  }
  AdminOptions options;
  options.backup_root = root;
  IndexerAdminService admin(core->get(), nullptr, options);
  tpr::v1::RestoreRequest restore;
  restore.set_backup_dir(root + "/set");
  restore.set_data_dir(tmp.path() + "/restored");
  tpr::v1::RestoreResponse restored;
  const grpc::Status refused = admin.Restore(nullptr, &restore, &restored);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(refused.error_message().find("data_dir"), std::string::npos)
      << refused.error_message();
  restore.set_data_dir(root + "/restored");
  EXPECT_TRUE(admin.Restore(nullptr, &restore, &restored).ok());
}

TEST(BackupTest, RestoreCarriesMedia) {
  TempDir tmp;
  Node primary(tmp.path() + "/primary");
  ASSERT_TRUE(primary.Start().ok());
  const std::vector<TestModel> models = MakeModels(20, 2, 31);
  IngestWithMedia(primary.core(), models, 0, 15);
  Ingest(primary.core(), {models.begin() + 15, models.end()});  // none
  const std::vector<std::string> before = MediaAnswers(primary, models);
  ASSERT_EQ(before[0], absl::StrCat(MediaFor(0).thumbnail_png(), "|",
                                    MediaFor(0).preview_ply()));

  tpr::v1::BackupRequest request;
  request.set_backup_dir(tmp.path() + "/backups");
  tpr::v1::BackupResponse backup;
  ASSERT_TRUE(Call(primary, request, &backup).ok());
  // Changed after the backup: the restore must not see these.
  ASSERT_TRUE(primary.core()->Delete(models[1].id).ok());
  IngestWithMedia(primary.core(), models, 16, 17);

  tpr::v1::RestoreRequest restore;
  restore.set_backup_dir(tmp.path() + "/backups");
  restore.set_data_dir(tmp.path() + "/restored");
  tpr::v1::RestoreResponse restored;
  grpc::Status s = Call(primary, restore, &restored);
  ASSERT_TRUE(s.ok()) << s.error_message();
  Node copy(tmp.path() + "/restored");
  ASSERT_TRUE(copy.Start().ok());
  EXPECT_EQ(MediaAnswers(copy, models), before);
  EXPECT_TRUE(copy.core()->Get(models[0].id)->media_stored());
  EXPECT_FALSE(copy.core()->Get(models[16].id)->media_stored());
}

TEST(FollowerTest, CarriesMediaFromTheCheckpointAndTheLog) {
  TempDir tmp;
  Node primary(tmp.path() + "/primary");
  ASSERT_TRUE(primary.Start().ok());
  const std::vector<TestModel> models = MakeModels(30, 3, 37);
  IngestWithMedia(primary.core(), models, 0, 10);  // in the checkpoint

  Node follower(tmp.path() + "/follower", primary.address());
  {
    absl::Status started = follower.Start();
    ASSERT_TRUE(started.ok()) << started;
  }
  ASSERT_TRUE(
      WaitFor([&] { return follower.follower()->Readiness().empty(); }));
  EXPECT_EQ(MediaAnswers(follower, models), MediaAnswers(primary, models));

  // Tailed: new media, a replacement without media, a delete.
  IngestWithMedia(primary.core(), models, 10, 30);
  ASSERT_TRUE(primary.core()->Upsert(ToRequest(models[2], true)).ok());
  ASSERT_TRUE(primary.core()->Delete(models[3].id).ok());
  ASSERT_TRUE(WaitFor([&] {
    return follower.follower()->Status().applied_sequence() >=
           LatestSequence(primary.core()->storage());
  }));
  const std::vector<std::string> want = MediaAnswers(primary, models);
  EXPECT_EQ(MediaAnswers(follower, models), want);
  EXPECT_NE(want[2].find("error"), std::string::npos);
  EXPECT_EQ(want[20], absl::StrCat(MediaFor(20).thumbnail_png(), "|",
                                   MediaFor(20).preview_ply()));
  EXPECT_FALSE(follower.core()->Get(models[2].id)->media_stored());
  EXPECT_TRUE(follower.core()->Get(models[20].id)->media_stored());
}

TEST(FollowerTest, FallenBehindTheKeptLogStartsAgainFromACheckpoint) {
  TempDir tmp;
  Node primary(tmp.path() + "/primary", "", NoArchive());
  ASSERT_TRUE(primary.Start().ok());
  const std::vector<TestModel> models = MakeModels(80, 4, 31);
  Ingest(primary.core(), {models.begin(), models.begin() + 20});
  {
    Node follower(tmp.path() + "/follower", primary.address());
    {
      absl::Status started = follower.Start();
      ASSERT_TRUE(started.ok()) << started;
    }
    ASSERT_TRUE(
        WaitFor([&] { return follower.follower()->Readiness().empty(); }));
  }
  // While it is down the primary writes and flushes (a backup flushes), so
  // the log the follower needs is deleted.
  Ingest(primary.core(), {models.begin() + 20, models.end()});
  tpr::v1::BackupRequest request;
  request.set_backup_dir(tmp.path() + "/backups");
  tpr::v1::BackupResponse ignored;
  ASSERT_TRUE(Call(primary, request, &ignored).ok());
  {
    Node follower(tmp.path() + "/follower", primary.address());
    {
      absl::Status started = follower.Start();
      ASSERT_TRUE(started.ok()) << started;
    }
    ASSERT_TRUE(WaitFor([&] { return follower.resync(); }));
    EXPECT_FALSE(follower.follower()->Readiness().empty());
  }
  std::ifstream marker(tmp.path() + "/follower/" + kFollowerMarker);
  std::string text((std::istreambuf_iterator<char>(marker)), {});
  EXPECT_NE(text.find("state resync"), std::string::npos) << text;
  // The restart copies afresh and matches the primary.
  Node follower(tmp.path() + "/follower", primary.address());
  {
    absl::Status started = follower.Start();
    ASSERT_TRUE(started.ok()) << started;
  }
  ASSERT_TRUE(
      WaitFor([&] { return follower.follower()->Readiness().empty(); }));
  EXPECT_FALSE(follower.resync());
  const std::vector<TestModel> queries(models.begin(), models.begin() + 8);
  EXPECT_EQ(Answers(follower, queries), Answers(primary, queries));
  EXPECT_EQ(follower.core()->Stats().models(), 80);
}

// The log cursor a TailLog stream keeps open: what it returns while writes
// go on (and across a new log file, which a flush starts) must be the log
// exactly: the oracle is a fresh cursor reading everything at the end.
TEST(LogCursorTest, ReadsOnlyWhatIsNewAcrossPollsAndLogFiles) {
  TempDir tmp;
  Node primary(tmp.path() + "/primary");
  ASSERT_TRUE(primary.Start().ok());
  Storage& storage = primary.core()->storage();
  const std::vector<TestModel> models = MakeModels(40, 4, 17);
  LogCursor cursor(storage, LatestSequence(storage) + 1);
  std::vector<LoggedBatch> seen;
  auto poll = [&](size_t max_bytes) {
    absl::StatusOr<std::vector<LoggedBatch>> got = cursor.Read(max_bytes);
    EXPECT_TRUE(got.ok()) << got.status();
    if (!got.ok()) return size_t{0};
    seen.insert(seen.end(), got->begin(), got->end());
    return got->size();
  };
  const uint64_t first = LatestSequence(storage) + 1;
  EXPECT_EQ(poll(1 << 20), 0u);  // nothing written yet
  Ingest(primary.core(), {models.begin(), models.begin() + 5});
  EXPECT_EQ(poll(1 << 20), 5u);  // one batch per upsert
  EXPECT_EQ(poll(1 << 20), 0u);
  Ingest(primary.core(), {models.begin() + 5, models.begin() + 8});
  EXPECT_EQ(poll(1), 1u);  // max_bytes: one batch at least, then stop
  EXPECT_EQ(poll(1 << 20), 2u);
  // A checkpoint flushes: the writes after it go to a new log file, which
  // the open iterator cannot see; the cursor opens a new one.
  ASSERT_TRUE(CreateCheckpoint(storage, tmp.path() + "/checkpoint").ok());
  Ingest(primary.core(), {models.begin() + 8, models.begin() + 12});
  EXPECT_EQ(poll(1 << 20), 4u);
  ASSERT_TRUE(primary.core()->Delete(models[2].id).ok());
  EXPECT_EQ(poll(1 << 20), 1u);
  EXPECT_EQ(cursor.next(), LatestSequence(storage) + 1);

  LogCursor oracle(storage, first);
  absl::StatusOr<std::vector<LoggedBatch>> all = oracle.Read(64 << 20);
  ASSERT_TRUE(all.ok()) << all.status();
  ASSERT_EQ(all->size(), seen.size());
  for (size_t i = 0; i < seen.size(); ++i) {
    EXPECT_EQ(seen[i].sequence, (*all)[i].sequence) << i;
    EXPECT_EQ(seen[i].count, (*all)[i].count) << i;
    EXPECT_EQ(seen[i].data, (*all)[i].data) << i;
    if (i > 0) {
      EXPECT_EQ(seen[i].sequence, seen[i - 1].sequence + seen[i - 1].count)
          << i;
    }
  }
}

TEST(LogCursorTest, ASequenceNoLongerKeptIsOutOfRange) {
  TempDir tmp;
  Node primary(tmp.path() + "/primary", "", NoArchive());
  ASSERT_TRUE(primary.Start().ok());
  Storage& storage = primary.core()->storage();
  const std::vector<TestModel> models = MakeModels(6, 2, 19);
  Ingest(primary.core(), {models.begin(), models.begin() + 3});
  ASSERT_TRUE(
      CreateCheckpoint(storage, tmp.path() + "/checkpoint").ok());  // flushes
  Ingest(primary.core(), {models.begin() + 3, models.end()});
  LogCursor cursor(storage, 1);
  absl::StatusOr<std::vector<LoggedBatch>> got = cursor.Read(1 << 20);
  EXPECT_TRUE(absl::IsOutOfRange(got.status())) << got.status();
  EXPECT_NE(got.status().message().find("sequence 1 is no longer"),
            std::string::npos)
      << got.status();
}

// A follower's store records the identity of the database it copied; a
// primary that is another database (restored from a backup, or the wrong
// address) is refused: nothing applied, NOT_SERVING with both identities
// named, the copy kept.
TEST(FollowerTest, RefusesToTailAnotherDatabase) {
  TempDir tmp;
  const std::vector<TestModel> models = MakeModels(60, 3, 41);
  auto primary = std::make_unique<Node>(tmp.path() + "/primary");
  ASSERT_TRUE(primary->Start().ok());
  Ingest(primary->core(), {models.begin(), models.begin() + 20});
  tpr::v1::BackupRequest backup;
  backup.set_backup_dir(tmp.path() + "/backups");
  tpr::v1::BackupResponse ignored;
  ASSERT_TRUE(Call(*primary, backup, &ignored).ok());
  Ingest(primary->core(), {models.begin() + 20, models.begin() + 30});
  absl::StatusOr<std::string> primary_id =
      DatabaseIdentity(primary->core()->storage());
  ASSERT_TRUE(primary_id.ok() && !primary_id->empty());

  const std::string follower_dir = tmp.path() + "/follower";
  uint64_t applied = 0;
  {
    Node follower(follower_dir, primary->address());
    {
      absl::Status started = follower.Start();
      ASSERT_TRUE(started.ok()) << started;
    }
    ASSERT_TRUE(
        WaitFor([&] { return follower.follower()->Readiness().empty(); }));
    const tpr::v1::ReplicationStatusResponse status =
        follower.follower()->Status();
    EXPECT_EQ(status.db_identity(), *primary_id);
    EXPECT_EQ(status.error(), "");
    // The copy is a database of its own (a promoted follower is not its
    // former primary).
    absl::StatusOr<std::string> own =
        DatabaseIdentity(follower.core()->storage());
    ASSERT_TRUE(own.ok());
    EXPECT_NE(*own, *primary_id);
    applied = status.applied_sequence();
  }

  // The primary is restored from its backup (fewer models, a new history)
  // and written to beyond the follower's sequence; then a wholly different
  // primary. Both are refused.
  const std::string restored_dir = tmp.path() + "/restored";
  tpr::v1::RestoreRequest restore;
  restore.set_backup_dir(tmp.path() + "/backups");
  restore.set_data_dir(restored_dir);
  tpr::v1::RestoreResponse restored;
  ASSERT_TRUE(Call(*primary, restore, &restored).ok());
  primary.reset();
  Node restored_primary(restored_dir);
  ASSERT_TRUE(restored_primary.Start().ok());
  Ingest(restored_primary.core(), {models.begin() + 30, models.end()});
  ASSERT_GT(LatestSequence(restored_primary.core()->storage()), applied);
  absl::StatusOr<std::string> restored_id =
      DatabaseIdentity(restored_primary.core()->storage());
  ASSERT_TRUE(restored_id.ok());
  EXPECT_NE(*restored_id, *primary_id);

  Node other(tmp.path() + "/other");
  ASSERT_TRUE(other.Start().ok());
  Ingest(other.core(), MakeModels(80, 2, 43));

  for (Node* wrong : {&restored_primary, &other}) {
    Node follower(follower_dir, wrong->address());
    {
      absl::Status started = follower.Start();
      ASSERT_TRUE(started.ok()) << started;
    }
    ASSERT_TRUE(WaitFor(
        [&] { return !follower.follower()->Status().error().empty(); }));
    const std::string reason = follower.follower()->Readiness();
    EXPECT_NE(reason.find("refuses to be tailed"), std::string::npos) << reason;
    EXPECT_NE(reason.find(*primary_id), std::string::npos) << reason;
    absl::StatusOr<std::string> wrong_id =
        DatabaseIdentity(wrong->core()->storage());
    ASSERT_TRUE(wrong_id.ok());
    EXPECT_NE(reason.find(*wrong_id), std::string::npos) << reason;
    // Nothing applied: the copy of the original is intact.
    EXPECT_EQ(follower.follower()->Status().applied_sequence(), applied);
    EXPECT_EQ(follower.core()->Stats().models(), 30);
    EXPECT_FALSE(follower.resync());
  }
}

TEST(FollowerTest, RefusesADirectoryHoldingAPrimarysData) {
  TempDir tmp;
  {
    Node primary(tmp.path() + "/data");
    ASSERT_TRUE(primary.Start().ok());
    Ingest(primary.core(), MakeModels(3, 1, 5));
  }
  FollowerOptions options;
  options.primary = "127.0.0.1:1";
  options.data_dir = tmp.path() + "/data";
  absl::Status st = PrepareFollowerDir(options);
  EXPECT_TRUE(absl::IsFailedPrecondition(st)) << st;
  EXPECT_NE(st.message().find("never wipes a primary"), std::string::npos)
      << st;
  EXPECT_TRUE(std::filesystem::exists(tmp.path() + "/data/CURRENT"));
}

}  // namespace
}  // namespace tpr::indexer
