#include "indexer/service/ack_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "indexer/lib/byte_codec.h"

namespace tpr::indexer {
namespace {

constexpr char kMagic[] = "TPRACK01";
constexpr size_t kSlotBytes = 32;

std::string EncodeSlot(const Acknowledged& state) {
  std::string out(kMagic, 8);
  tpr::index::PutU(&out, state.writes, 8);
  tpr::index::PutU(&out, state.models, 8);
  tpr::index::PutU(&out, tpr::index::Fnv1a(out.data(), out.size()), 8);
  return out;
}

std::optional<Acknowledged> DecodeSlot(absl::string_view bytes) {
  if (bytes.size() < kSlotBytes ||
      bytes.substr(0, 8) != absl::string_view(kMagic, 8)) {
    return std::nullopt;
  }
  tpr::index::ByteReader reader(bytes.substr(8, kSlotBytes - 8));
  Acknowledged state;
  uint64_t sum = 0;
  if (!reader.U(8, &state.writes) || !reader.U(8, &state.models) ||
      !reader.U(8, &sum) || sum != tpr::index::Fnv1a(bytes.data(), 24)) {
    return std::nullopt;
  }
  return state;
}

absl::Status IoError(absl::string_view what) {
  if (errno == ENOSPC) {
    return absl::ResourceExhaustedError(
        absl::StrCat(what, " ", AckFile::kName, ": the disk is full"));
  }
  return absl::UnavailableError(
      absl::StrCat(what, " ", AckFile::kName, ": ", std::strerror(errno)));
}

}  // namespace

absl::StatusOr<std::unique_ptr<AckFile>> AckFile::Open(const std::string& dir,
                                                       bool create) {
  const std::string path = dir + "/" + kName;
  int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0 && errno == ENOENT) {
    if (!create) return absl::NotFoundError(absl::StrCat(kName, " is missing"));
    fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) return IoError("cannot create");
    // The new, empty file and its directory entry are made durable before
    // any write is acknowledged against it.
    const int dir_fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    const bool synced = ::fsync(fd) == 0 && dir_fd >= 0 && ::fsync(dir_fd) == 0;
    if (dir_fd >= 0) ::close(dir_fd);
    if (!synced) {
      ::close(fd);
      return IoError("cannot sync");
    }
    return std::unique_ptr<AckFile>(new AckFile(fd, std::nullopt, 0));
  }
  if (fd < 0) return IoError("cannot open");
  char bytes[2 * kSlotBytes];
  const ssize_t n = ::pread(fd, bytes, sizeof bytes, 0);
  if (n < 0) {
    ::close(fd);
    return IoError("cannot read");
  }
  const absl::string_view all(bytes, static_cast<size_t>(n));
  std::optional<Acknowledged> slots[2] = {
      DecodeSlot(all.substr(0, kSlotBytes)),
      all.size() > kSlotBytes ? DecodeSlot(all.substr(kSlotBytes))
                              : std::nullopt};
  if (n == 0) return std::unique_ptr<AckFile>(new AckFile(fd, std::nullopt, 0));
  if (!slots[0] && !slots[1]) {
    ::close(fd);
    return absl::DataLossError(absl::StrCat(
        kName, " is damaged (", n,
        " bytes, no valid record): what was acknowledged is unknown"));
  }
  const int latest =
      !slots[1] || (slots[0] && slots[0]->writes >= slots[1]->writes) ? 0 : 1;
  return std::unique_ptr<AckFile>(new AckFile(fd, slots[latest], 1 - latest));
}

AckFile::~AckFile() { ::close(fd_); }

absl::Status AckFile::Record(const Acknowledged& state) {
  const std::string slot = EncodeSlot(state);
  const off_t offset = static_cast<off_t>(next_slot_ * kSlotBytes);
  if (::pwrite(fd_, slot.data(), slot.size(), offset) !=
      static_cast<ssize_t>(slot.size())) {
    return IoError("cannot write");
  }
  if (::fdatasync(fd_) != 0) return IoError("cannot sync");
  next_slot_ = 1 - next_slot_;
  return absl::OkStatus();
}

}  // namespace tpr::indexer
