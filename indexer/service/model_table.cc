#include "indexer/service/model_table.h"

#include <algorithm>
#include <cstddef>

namespace tpr::indexer {

std::optional<int64_t> ModelTable::AddedTime(const std::string& id) const {
  tpr::common::ReaderMutexLock lock(&mu_);
  auto it = models_.find(id);
  if (it == models_.end()) return std::nullopt;
  return it->second.added_unix_micros;
}

void ModelTable::Put(
    const std::vector<std::pair<std::string, ModelInfo>>& models) {
  tpr::common::MutexLock lock(&mu_);
  for (const auto& [id, info] : models) {
    auto [it, created] = models_.try_emplace(id);
    if (!created) {
      if (--label_counts_[it->second.label] == 0)
        label_counts_.erase(it->second.label);
    }
    it->second = info;
    ++label_counts_[info.label];
  }
}

bool ModelTable::Erase(const std::string& id) {
  tpr::common::MutexLock lock(&mu_);
  auto it = models_.find(id);
  if (it == models_.end()) return false;
  if (--label_counts_[it->second.label] == 0)
    label_counts_.erase(it->second.label);
  models_.erase(it);
  return true;
}

std::vector<std::string> ModelTable::Page(const std::string& after,
                                          const std::string& label,
                                          size_t page_size, bool* more) const {
  std::vector<std::string> ids;
  *more = false;
  tpr::common::ReaderMutexLock lock(&mu_);
  auto it = after.empty() ? models_.begin() : models_.upper_bound(after);
  for (; it != models_.end(); ++it) {
    if (!label.empty() && it->second.label != label) continue;
    if (ids.size() == page_size) {
      *more = true;
      break;
    }
    ids.push_back(it->first);
  }
  return ids;
}

size_t ModelTable::size() const {
  tpr::common::ReaderMutexLock lock(&mu_);
  return models_.size();
}

std::vector<std::pair<std::string, int64_t>> ModelTable::TopLabels(
    size_t max) const {
  std::vector<std::pair<std::string, int64_t>> out;
  {
    tpr::common::ReaderMutexLock lock(&mu_);
    out.assign(label_counts_.begin(), label_counts_.end());
  }
  auto more_models = [](const auto& a, const auto& b) {
    return a.second != b.second ? a.second > b.second : a.first < b.first;
  };
  if (out.size() > max) {
    std::partial_sort(out.begin(),
                      out.begin() + static_cast<std::ptrdiff_t>(max), out.end(),
                      more_models);
    out.resize(max);
  } else {
    std::sort(out.begin(), out.end(), more_models);
  }
  return out;
}

std::vector<std::pair<std::string, std::string>> ModelTable::IdLabels() const {
  tpr::common::ReaderMutexLock lock(&mu_);
  std::vector<std::pair<std::string, std::string>> out;
  out.reserve(models_.size());
  for (const auto& [id, info] : models_) out.emplace_back(id, info.label);
  return out;
}

}  // namespace tpr::indexer
