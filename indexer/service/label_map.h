// LabelMap: the id -> label map that searches filter and annotate by, kept
// copy-on-write so that a search holds, for its whole life, the labels that
// went with the index snapshot it ranks (IndexerCore takes both together).
//
//   LabelMap labels({{"cat/1", "cat"}});
//   std::shared_ptr<const LabelSnapshot> s = labels.snapshot();   // O(1)
//   labels.Apply({{"cat/1", std::nullopt}});  // s unchanged
//
// The map is split into kLabelShards hash shards, each immutable once
// published: a write copies only the shards it touches (plus the vector of
// shard pointers), a search start copies one shared pointer.
#ifndef TPR_INDEXER_SERVICE_LABEL_MAP_H_
#define TPR_INDEXER_SERVICE_LABEL_MAP_H_

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

namespace tpr::indexer {

// LabelSnapshot: one published, immutable state of a LabelMap.
// Thread-safe (immutable).
class LabelSnapshot {
 public:
  // Find returns the label of `id`, or nullptr when `id` is absent. The
  // pointer lives as long as this snapshot. Cost: one hash lookup.
  const std::string* Find(const std::string& id) const;

 private:
  friend class LabelMap;
  using Shard = std::unordered_map<std::string, std::string>;
  std::vector<std::shared_ptr<const Shard>> shards_;
};

// LabelChange: one update of LabelMap::Apply: the id's new label, or nullopt
// to remove the id.
using LabelChange = std::pair<std::string, std::optional<std::string>>;

// LabelMap: see the file comment. Not thread-safe: the owner serializes
// Apply and snapshot() (IndexerCore holds its view mutex over both); the
// snapshots it hands out may be used from any thread.
class LabelMap {
 public:
  // Number of hash shards; a write copies about labels / kLabelShards
  // entries per shard it touches.
  static constexpr size_t kLabelShards = 4096;

  // LabelMap builds the map holding `labels` (id, label); ids are unique.
  // Cost: O(n).
  explicit LabelMap(
      const std::vector<std::pair<std::string, std::string>>& labels = {});

  // snapshot returns the current state. Cost: O(1).
  std::shared_ptr<const LabelSnapshot> snapshot() const { return current_; }

  // Apply publishes a new state with `changes` applied in order. Snapshots
  // taken before keep the old state. Cost: O(changes + size of the shards
  // touched).
  void Apply(const std::vector<LabelChange>& changes);

 private:
  static size_t ShardOf(const std::string& id) {
    return std::hash<std::string>()(id) % kLabelShards;
  }
  friend class LabelSnapshot;
  std::shared_ptr<const LabelSnapshot> current_;
};

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_LABEL_MAP_H_
