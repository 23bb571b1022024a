// AckFile: what the indexer has acknowledged (the number of write batches
// and the number of models), kept in a small synced file, ACKNOWLEDGED,
// beside RocksDB's files in the data directory. RocksDB never reads, writes
// or deletes it, so a damaged MANIFEST or write-ahead log cannot silently
// take it back with them: at open, Storage compares the database with it and
// refuses a database that holds less (DATA_LOSS, docs/recovery.md).
//
//   absl::StatusOr<std::unique_ptr<AckFile>> ack = AckFile::Open(dir);
//   std::optional<Acknowledged> before = (*ack)->recorded();
//   TPR_RETURN_IF_ERROR((*ack)->Record({writes, models}));   // synced
//
// Format: two 32-byte slots, each "TPRACK01", writes and models (8-byte
// little-endian) and the FNV-1a of those 24 bytes. Records alternate between
// the slots, so a write torn by a crash leaves the other slot (the previous
// state) intact; the valid slot with more writes wins.
#ifndef TPR_INDEXER_SERVICE_ACK_FILE_H_
#define TPR_INDEXER_SERVICE_ACK_FILE_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace tpr::indexer {

// Acknowledged: the state of the store as of the last acknowledged write.
struct Acknowledged {
  // Write batches applied since the database was created (Storage's write
  // counter: every Write, puts and deletes alike, adds one).
  uint64_t writes = 0;
  // Models stored after it.
  uint64_t models = 0;
};

// AckFile: see the file comment. Not thread-safe (Storage serializes
// Record under its write lock).
class AckFile {
 public:
  // The file's name inside the data directory.
  static constexpr char kName[] = "ACKNOWLEDGED";

  // Open opens dir/ACKNOWLEDGED, creating it (empty, synced) when missing
  // and `create` is set. Returns NOT_FOUND when it is missing and `create`
  // is false, DATA_LOSS when it exists but neither slot is valid,
  // UNAVAILABLE on an I/O error. Cost: one small read (plus two fsyncs when
  // created).
  static absl::StatusOr<std::unique_ptr<AckFile>> Open(const std::string& dir,
                                                       bool create);

  ~AckFile();
  AckFile(const AckFile&) = delete;
  AckFile& operator=(const AckFile&) = delete;

  // recorded returns the state read at open; nullopt for a new file.
  std::optional<Acknowledged> recorded() const { return recorded_; }

  // Record writes `state` into the slot not holding the latest record and
  // syncs it (fdatasync). Returns UNAVAILABLE on an I/O error (the previous
  // record then still stands). Cost: one 32-byte write and one fdatasync.
  absl::Status Record(const Acknowledged& state);

 private:
  AckFile(int fd, std::optional<Acknowledged> recorded, int next_slot)
      : fd_(fd), recorded_(recorded), next_slot_(next_slot) {}
  int fd_;
  std::optional<Acknowledged> recorded_;
  int next_slot_;
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_ACK_FILE_H_
