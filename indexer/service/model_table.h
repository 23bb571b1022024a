// ModelTable: the live table of stored ids in id order, with each model's
// label and time added, and the number of models per label. It answers
// List and Stats without touching RocksDB, and tells a write whether an id
// exists (and since when).
//
//   ModelTable table;
//   table.Put({{"cat/1", {"cat", now}}});
//   std::vector<std::string> page = table.Page("", "cat", 100, &more);
//
// The table follows the store: IndexerCore updates it after each durable
// write, under its writer lock, so writers see a table that matches the
// store; readers may see a write's effect before or after, never half.
#ifndef TPR_INDEXER_SERVICE_MODEL_TABLE_H_
#define TPR_INDEXER_SERVICE_MODEL_TABLE_H_

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/mutex.h"

namespace tpr::indexer {

// ModelInfo: what the table keeps of one model.
struct ModelInfo {
  std::string label;
  // When the model was first added, microseconds since the Unix epoch.
  int64_t added_unix_micros = 0;
};

// ModelTable: see the file comment. Thread-safe.
class ModelTable {
 public:
  // AddedTime returns when `id` was first added, or nullopt when it is not
  // stored. Cost: O(log n).
  std::optional<int64_t> AddedTime(const std::string& id) const;

  // Put adds or replaces each (id, info), keeping the label counts. Cost:
  // O(m log n).
  void Put(const std::vector<std::pair<std::string, ModelInfo>>& models);

  // Erase removes `id`; returns whether it was present. Cost: O(log n).
  bool Erase(const std::string& id);

  // Page returns up to `page_size` ids in ascending order, all greater than
  // `after` (empty: from the first), only those labelled `label` when it is
  // non-empty. *more is set when further matching ids follow. Cost:
  // O(log n + page) plus the ids skipped by the label filter.
  std::vector<std::string> Page(const std::string& after,
                                const std::string& label, size_t page_size,
                                bool* more) const;

  // size returns the number of models. Cost: O(1).
  size_t size() const;

  // TopLabels returns the number of models per label for the `max` labels
  // holding the most models (ties: the smaller label first), most populous
  // first. Cost: O(labels log max).
  std::vector<std::pair<std::string, int64_t>> TopLabels(size_t max) const;

  // IdLabels returns every (id, label) pair, in id order. Cost: O(n).
  std::vector<std::pair<std::string, std::string>> IdLabels() const;

 private:
  mutable tpr::common::Mutex mu_;
  std::map<std::string, ModelInfo> models_ ABSL_GUARDED_BY(mu_);
  std::map<std::string, int64_t> label_counts_ ABSL_GUARDED_BY(mu_);
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_MODEL_TABLE_H_
