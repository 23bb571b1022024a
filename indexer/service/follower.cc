#include "indexer/service/follower.h"

#include <fcntl.h>
#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include "absl/strings/str_cat.h"
#include "common/grpc_status.h"
#include "common/status_macros.h"
#include "indexer/service/replication.h"

namespace tpr::indexer {
namespace {

namespace fs = std::filesystem;

int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

absl::Status FsyncPath(const std::string& path, bool directory) {
  const int fd =
      open(path.c_str(), directory ? O_RDONLY | O_DIRECTORY : O_RDONLY);
  if (fd < 0)
    return absl::UnavailableError(
        absl::StrCat("cannot open ", path, " to sync"));
  const int rc = fsync(fd);
  close(fd);
  if (rc != 0)
    return absl::UnavailableError(absl::StrCat("cannot sync ", path));
  return absl::OkStatus();
}

// The marker: "primary ADDR\nstate STATE\n", replaced atomically (write,
// sync, rename, sync the directory).
absl::Status WriteMarker(const std::string& dir, const std::string& primary,
                         const std::string& state) {
  const std::string path = dir + "/" + kFollowerMarker;
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << "primary " << primary << "\nstate " << state << "\n";
    if (!out.flush())
      return absl::UnavailableError(absl::StrCat("cannot write ", tmp));
  }
  TPR_RETURN_IF_ERROR(FsyncPath(tmp, false));
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec)
    return absl::UnavailableError(
        absl::StrCat("cannot rename ", tmp, ": ", ec.message()));
  return FsyncPath(dir, true);
}

// The marker's state ("" when there is no marker).
std::string ReadMarkerState(const std::string& dir) {
  std::ifstream in(dir + "/" + kFollowerMarker);
  std::string key, value, state;
  while (in >> key >> value) {
    if (key == "state") state = value;
  }
  return in.eof() || !state.empty() ? state : "";
}

grpc::ClientContext* Prepare(grpc::ClientContext* context,
                             const std::string& api_key) {
  if (!api_key.empty())
    context->AddMetadata("authorization", absl::StrCat("Bearer ", api_key));
  return context;
}

std::unique_ptr<tpr::v1::IndexerAdmin::Stub> MakeStub(
    const FollowerOptions& options) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  if (options.credentials != nullptr && !options.tls_server_name.empty()) {
    args.SetSslTargetNameOverride(options.tls_server_name);
  }
  return tpr::v1::IndexerAdmin::NewStub(grpc::CreateCustomChannel(
      options.primary,
      options.credentials != nullptr ? options.credentials
                                     : grpc::InsecureChannelCredentials(),
      args));
}

// A checkpoint copied: the primary sequence it reflects and the primary's
// database identity.
struct Copied {
  uint64_t sequence = 0;
  std::string identity;
};

// Streams the primary's checkpoint into `dir` (empty).
absl::StatusOr<Copied> FetchCheckpoint(tpr::v1::IndexerAdmin::Stub& stub,
                                       const FollowerOptions& options) {
  grpc::ClientContext context;
  Prepare(&context, options.api_key);
  std::unique_ptr<grpc::ClientReader<tpr::v1::CheckpointChunk>> reader =
      stub.Checkpoint(&context, tpr::v1::CheckpointRequest());
  tpr::v1::CheckpointChunk chunk;
  std::string open_name;
  std::FILE* file = nullptr;
  std::vector<std::string> files;
  Copied copied;
  bool done = false;
  absl::Status failed;
  auto close_file = [&]() -> absl::Status {
    if (file == nullptr) return absl::OkStatus();
    const bool ok = std::fflush(file) == 0 && fsync(fileno(file)) == 0;
    std::fclose(file);
    file = nullptr;
    return ok ? absl::OkStatus()
              : absl::UnavailableError(
                    absl::StrCat("cannot write ", open_name));
  };
  while (failed.ok() && reader->Read(&chunk)) {
    if (chunk.done()) {
      copied.sequence = chunk.sequence();
      copied.identity = chunk.db_identity();
      done = true;
      continue;
    }
    const std::string& name = chunk.file();
    if (name.empty() || name.find('/') != std::string::npos || name == "." ||
        name == "..") {
      failed = absl::InvalidArgumentError(absl::StrCat(
          "the primary sent a bad checkpoint file name '", name, "'"));
      break;
    }
    if (name != open_name) {
      failed = close_file();
      if (!failed.ok()) break;
      open_name = name;
      file = std::fopen((options.data_dir + "/" + name).c_str(), "wb");
      if (file == nullptr) {
        failed = absl::UnavailableError(absl::StrCat("cannot create ", name));
        break;
      }
      files.push_back(name);
    }
    if (!chunk.data().empty() &&
        std::fwrite(chunk.data().data(), 1, chunk.data().size(), file) !=
            chunk.data().size()) {
      failed = absl::UnavailableError(absl::StrCat("cannot write ", name));
    }
  }
  if (absl::Status st = close_file(); failed.ok()) failed = st;
  if (!failed.ok()) {
    context.TryCancel();
    reader->Finish().ok();
    return failed;
  }
  grpc::Status finished = reader->Finish();
  if (!finished.ok()) return tpr::common::FromGrpcStatus(finished);
  if (!done) return absl::UnavailableError("the checkpoint stream ended early");
  TPR_RETURN_IF_ERROR(FsyncPath(options.data_dir, true));
  return copied;
}

// Empties `dir` (a follower's own copy).
absl::Status EmptyDir(const std::string& dir) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    fs::remove_all(entry.path(), ec);
    if (ec)
      return absl::UnavailableError(
          absl::StrCat("cannot empty ", dir, ": ", ec.message()));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status PrepareFollowerDir(const FollowerOptions& options) {
  const std::string& dir = options.data_dir;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec)
    return absl::UnavailableError(
        absl::StrCat("cannot create ", dir, ": ", ec.message()));
  const std::string state = ReadMarkerState(dir);
  if (state == "ready") return absl::OkStatus();
  if (state.empty() && !fs::is_empty(dir, ec)) {
    return absl::FailedPreconditionError(absl::StrCat(
        "data directory '", dir, "' holds data that is not a follower's (no ",
        kFollowerMarker,
        " file: a primary's or a promoted follower's); --follow needs an empty "
        "directory or a "
        "follower's, and never wipes a primary"));
  }
  auto log = [&](const std::string& line) {
    if (options.log) options.log(line);
  };
  std::unique_ptr<tpr::v1::IndexerAdmin::Stub> stub = MakeStub(options);
  int wait_ms = options.retry_min_ms;
  for (;;) {
    TPR_RETURN_IF_ERROR(EmptyDir(dir));
    TPR_RETURN_IF_ERROR(WriteMarker(dir, options.primary, "copying"));
    const auto start = std::chrono::steady_clock::now();
    absl::StatusOr<Copied> sequence = FetchCheckpoint(*stub, options);
    if (sequence.ok()) {
      {
        // The copy is a database of its own (a promoted follower must not
        // pass for its former primary): a new identity when first opened.
        TPR_RETURN_IF_ERROR(ForgetDatabaseIdentity(dir));
        // Record where tailing starts, and whose log it is, in the copied
        // store itself. The database is there; Open makes its ACKNOWLEDGED
        // record.
        StorageOptions storage_options;
        TPR_ASSIGN_OR_RETURN(std::unique_ptr<Storage> storage,
                             Storage::Open(dir, storage_options));
        TPR_RETURN_IF_ERROR(SetPrimaryIdentity(*storage, sequence->identity));
        TPR_RETURN_IF_ERROR(SetAppliedSequence(*storage, sequence->sequence));
      }
      TPR_RETURN_IF_ERROR(WriteMarker(dir, options.primary, "ready"));
      const double ms = std::chrono::duration<double, std::milli>(
                            std::chrono::steady_clock::now() - start)
                            .count();
      log(absl::StrCat("copied a checkpoint of ", options.primary,
                       " (database ", sequence->identity, ") at sequence ",
                       sequence->sequence, " in ", static_cast<int64_t>(ms),
                       " ms"));
      return absl::OkStatus();
    }
    if (!absl::IsUnavailable(sequence.status()) &&
        !absl::IsDeadlineExceeded(sequence.status())) {
      return absl::Status(
          sequence.status().code(),
          absl::StrCat("cannot copy a checkpoint of ", options.primary, ": ",
                       sequence.status().message()));
    }
    log(absl::StrCat("cannot copy a checkpoint of ", options.primary, " (",
                     sequence.status().ToString(), "); retrying in ", wait_ms,
                     " ms"));
    std::this_thread::sleep_for(std::chrono::milliseconds(wait_ms));
    wait_ms = std::min(wait_ms * 2, options.retry_max_ms);
  }
}

Follower::Follower(IndexerCore* core, FollowerOptions options)
    : core_(core), options_(std::move(options)), stub_(MakeStub(options_)) {}

Follower::~Follower() { Stop(); }

void Follower::Start(std::function<void()> on_resync) {
  thread_ =
      std::thread([this, on_resync = std::move(on_resync)] { Run(on_resync); });
}

void Follower::Stop() {
  {
    absl::MutexLock lock(&mu_);
    stopping_ = true;
    if (context_ != nullptr) context_->TryCancel();
  }
  if (thread_.joinable()) thread_.join();
}

std::string Follower::Readiness() const {
  if (promoted_) return "";
  {
    absl::MutexLock lock(&state_mu_);
    if (!refused_.empty()) {
      return absl::StrCat("the primary ", options_.primary,
                          " refuses to be tailed: ", refused_);
    }
  }
  if (caught_up_) return "";
  return absl::StrCat("catching up with ", options_.primary, ": applied ",
                      applied_.load(), ", primary at ", primary_seq_.load());
}

tpr::v1::ReplicationStatusResponse Follower::Status() const {
  tpr::v1::ReplicationStatusResponse status;
  if (promoted_) {
    status.set_role("primary");
    status.set_applied_sequence(LatestSequence(core_->storage()));
    absl::StatusOr<std::string> identity = DatabaseIdentity(core_->storage());
    if (identity.ok()) status.set_db_identity(*identity);
    return status;
  }
  status.set_role("follower");
  status.set_primary(options_.primary);
  {
    absl::MutexLock lock(&state_mu_);
    status.set_db_identity(primary_identity_);
    status.set_error(refused_);
  }
  const uint64_t applied = applied_.load();
  const uint64_t primary = primary_seq_.load();
  status.set_applied_sequence(applied);
  status.set_primary_sequence(primary);
  status.set_behind(primary > applied ? primary - applied : 0);
  status.set_caught_up(caught_up_.load());
  const int64_t heard = last_heard_ms_.load();
  status.set_last_heard_ms(heard < 0 ? -1 : NowMs() - heard);
  return status;
}

absl::StatusOr<tpr::v1::PromoteResponse> Follower::Promote() {
  Stop();
  TPR_ASSIGN_OR_RETURN(std::string former, core_->Promote());
  std::error_code ec;
  fs::remove(options_.data_dir + "/" + kFollowerMarker, ec);
  if (ec) {
    return absl::UnavailableError(absl::StrCat(
        "promoted, but cannot remove the follower marker: ", ec.message()));
  }
  TPR_RETURN_IF_ERROR(FsyncPath(options_.data_dir, true));
  promoted_ = true;
  tpr::v1::PromoteResponse response;
  response.set_former_primary(former);
  response.set_applied_sequence(applied_.load());
  if (options_.log && !former.empty()) {
    options_.log(absl::StrCat("promoted to primary (was following ", former,
                              ", applied sequence ", applied_.load(), ")"));
  }
  return response;
}

void Follower::Run(std::function<void()> on_resync) {
  auto log = [this](const std::string& line) {
    if (options_.log) options_.log(line);
  };
  absl::StatusOr<std::optional<uint64_t>> applied =
      AppliedSequence(core_->storage());
  if (!applied.ok() || !applied->has_value()) {
    log(absl::StrCat("no applied sequence in the store (",
                     applied.ok() ? "missing" : applied.status().ToString(),
                     "); starting again from a fresh copy"));
    WriteMarker(options_.data_dir, options_.primary, "resync").IgnoreError();
    if (on_resync) on_resync();
    return;
  }
  applied_ = **applied;
  absl::StatusOr<std::string> identity = PrimaryIdentity(core_->storage());
  if (!identity.ok()) {
    log(absl::StrCat("cannot read the primary's identity (",
                     identity.status().ToString(), "); not tailing"));
    absl::MutexLock lock(&state_mu_);
    refused_ = identity.status().ToString();
    return;
  }
  {
    absl::MutexLock lock(&state_mu_);
    primary_identity_ = *identity;
  }
  int wait_ms = options_.retry_min_ms;
  std::string last_error;
  for (;;) {
    grpc::ClientContext context;
    Prepare(&context, options_.api_key);
    {
      absl::MutexLock lock(&mu_);
      if (stopping_) return;
      context_ = &context;
    }
    tpr::v1::TailLogRequest request;
    request.set_from_sequence(applied_.load() + 1);
    request.set_db_identity(*identity);
    std::unique_ptr<grpc::ClientReader<tpr::v1::LogBatch>> reader =
        stub_->TailLog(&context, request);
    tpr::v1::LogBatch batch;
    absl::Status failed;
    bool heard = false;
    while (reader->Read(&batch)) {
      last_heard_ms_ = NowMs();
      if (!heard) {
        heard = true;
        absl::MutexLock lock(&state_mu_);
        if (!refused_.empty())
          log(absl::StrCat("the primary ", options_.primary,
                           " accepts us again"));
        refused_.clear();
      }
      if (!batch.batch().empty()) {
        absl::StatusOr<uint64_t> now =
            core_->ApplyReplicated(batch.batch(), batch.sequence());
        if (!now.ok()) {
          failed = now.status();
          break;
        }
        applied_ = std::max(applied_.load(), *now);
      }
      primary_seq_ = std::max(primary_seq_.load(), batch.primary_sequence());
      if (applied_.load() >= batch.primary_sequence() && !caught_up_) {
        caught_up_ = true;
        log(absl::StrCat("caught up with ", options_.primary, " at sequence ",
                         applied_.load()));
      }
      wait_ms = options_.retry_min_ms;
    }
    if (!failed.ok()) context.TryCancel();
    grpc::Status finished = reader->Finish();
    {
      absl::MutexLock lock(&mu_);
      context_ = nullptr;
      if (stopping_) return;
    }
    absl::Status status =
        failed.ok() ? tpr::common::FromGrpcStatus(finished) : failed;
    if (absl::IsOutOfRange(status)) {
      log(absl::StrCat("fell behind the log ", options_.primary, " keeps (",
                       status.message(),
                       "); starting again from a fresh copy"));
      WriteMarker(options_.data_dir, options_.primary, "resync").IgnoreError();
      if (on_resync) on_resync();
      return;
    }
    if (!failed.ok() && absl::IsFailedPrecondition(failed)) return;  // promoted
    const std::string error = status.ToString();
    if (failed.ok() && absl::IsFailedPrecondition(status)) {
      // The primary refuses (another database, not a primary, or it lost
      // writes): apply nothing, be NOT_SERVING with the reason, ask again
      // at the slowest pace. The copy stays as it is for the operator.
      caught_up_ = false;
      {
        absl::MutexLock lock(&state_mu_);
        refused_ = std::string(status.message());
      }
      wait_ms = options_.retry_max_ms;
    }
    if (error != last_error) {
      log(absl::StrCat("tailing ", options_.primary, " stopped (", error,
                       "); retrying"));
      last_error = error;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(wait_ms));
    wait_ms = std::min(wait_ms * 2, options_.retry_max_ms);
  }
}

}  // namespace tpr::indexer
