#include "indexer/service/label_map.h"

namespace tpr::indexer {

const std::string* LabelSnapshot::Find(const std::string& id) const {
  const Shard& shard = *shards_[LabelMap::ShardOf(id)];
  auto it = shard.find(id);
  return it == shard.end() ? nullptr : &it->second;
}

LabelMap::LabelMap(
    const std::vector<std::pair<std::string, std::string>>& labels) {
  std::vector<LabelSnapshot::Shard> shards(kLabelShards);
  for (const auto& [id, label] : labels) shards[ShardOf(id)].emplace(id, label);
  auto snapshot = std::make_shared<LabelSnapshot>();
  snapshot->shards_.reserve(kLabelShards);
  for (LabelSnapshot::Shard& shard : shards) {
    snapshot->shards_.push_back(
        std::make_shared<const LabelSnapshot::Shard>(std::move(shard)));
  }
  current_ = std::move(snapshot);
}

void LabelMap::Apply(const std::vector<LabelChange>& changes) {
  // Copy-on-write: only the shards touched are copied; the others are
  // shared with the previous state, which running searches may still hold.
  auto next = std::make_shared<LabelSnapshot>(*current_);
  std::unordered_map<size_t, LabelSnapshot::Shard*> copied;
  for (const auto& [id, label] : changes) {
    const size_t at = ShardOf(id);
    LabelSnapshot::Shard*& shard = copied[at];
    if (shard == nullptr) {
      auto copy = std::make_shared<LabelSnapshot::Shard>(*next->shards_[at]);
      shard = copy.get();
      next->shards_[at] = std::move(copy);
    }
    if (label.has_value()) {
      (*shard)[id] = *label;
    } else {
      shard->erase(id);
    }
  }
  current_ = std::move(next);
}

}  // namespace tpr::indexer
