// TreePersister: saves the index's VP-tree to the store when it changed, so
// that a restart loads the tree instead of rebuilding it (Storage::SaveTree,
// SignatureIndex::Load). A background thread checks every interval; Stop()
// saves once more.
//
//   TreePersister persister(storage, index,
//                           {.interval_ms = 10000, .log = log});
//   persister.MarkSaved(bytes);        // the tree the index was loaded from
//   persister.Start();  ...  persister.NoteWrites(n);  ...  persister.Stop();
#ifndef TPR_INDEXER_SERVICE_TREE_PERSISTER_H_
#define TPR_INDEXER_SERVICE_TREE_PERSISTER_H_

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>

#include "absl/base/thread_annotations.h"
#include "absl/status/status.h"
#include "common/mutex.h"
#include "indexer/lib/signature_index.h"
#include "indexer/service/storage.h"

namespace tpr::indexer {

// TreePersisterOptions: when the tree is saved.
struct TreePersisterOptions {
  // How often the background thread checks whether the tree changed and
  // saves it, in milliseconds; 0 means no thread (the tree is then saved
  // only by PersistNow and Stop). Default 10000.
  int interval_ms = 10000;
  // Receives one line per save and per failed save. Default: none.
  std::function<void(const std::string&)> log;
};

// TreePersister: see the file comment. Thread-safe. `storage` and `index`
// must outlive it.
class TreePersister {
 public:
  TreePersister(Storage* storage, const tpr::index::SignatureIndex* index,
                TreePersisterOptions options);
  // The destructor calls Stop().
  ~TreePersister();
  TreePersister(const TreePersister&) = delete;
  TreePersister& operator=(const TreePersister&) = delete;

  // MarkSaved records `bytes` as the tree the store already holds (the one
  // the index was loaded from), so an unchanged tree is not saved again.
  // Call before Start. Cost: O(bytes) (a hash).
  void MarkSaved(const std::string& bytes);

  // Start starts the background thread (when options.interval_ms > 0).
  // Call once.
  void Start();

  // NoteWrites records that `n` writes reached the index since the last
  // save. Cost: O(1), lock-free.
  void NoteWrites(size_t n) { writes_since_save_ += n; }

  // PersistNow saves the index's current tree when it changed since the
  // last save. Returns the store's error (see Storage::SaveTree). Cost:
  // O(n log n) bytes serialized + one fsync when changed; O(1) otherwise.
  absl::Status PersistNow();

  // Stop stops the background thread and saves the tree once more (a
  // failure is logged). Idempotent.
  void Stop();

 private:
  void Loop();

  Storage* const storage_;
  const tpr::index::SignatureIndex* const index_;
  const TreePersisterOptions options_;
  std::atomic<uint64_t> writes_since_save_{0};

  // Serializes saves; remembers what the last one saved.
  tpr::common::Mutex save_mu_;
  size_t saved_hash_ ABSL_GUARDED_BY(save_mu_) = 0;
  size_t saved_indexed_ ABSL_GUARDED_BY(save_mu_) = 0;
  size_t saved_buffered_ ABSL_GUARDED_BY(save_mu_) = 0;

  // Wakes and stops the background thread.
  tpr::common::Mutex stop_mu_;
  bool stopping_ ABSL_GUARDED_BY(stop_mu_) = false;
  bool stopped_ ABSL_GUARDED_BY(stop_mu_) = false;
  std::thread thread_;
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_TREE_PERSISTER_H_
