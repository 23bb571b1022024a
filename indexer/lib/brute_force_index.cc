// Deliberately the simplest correct search: every distance, one sort. It
// shares no code with the VP-tree so that it can serve as its oracle.
#include "indexer/lib/brute_force_index.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace tpr::index {
namespace {

class SortedCursor : public NeighborCursor {
 public:
  SortedCursor(std::vector<ItemNeighbor> results, SearchStats stats)
      : results_(std::move(results)), stats_(stats) {}

  std::optional<ItemNeighbor> Next() override {
    if (next_ >= results_.size()) return std::nullopt;
    return results_[next_++];
  }
  const SearchStats& stats() const override { return stats_; }

 private:
  std::vector<ItemNeighbor> results_;
  size_t next_ = 0;
  SearchStats stats_;
};

}  // namespace

std::unique_ptr<NeighborCursor> BruteForceIndex::Search(QuerySpec spec) const {
  std::vector<uint32_t> items;
  items.reserve(n_ + spec.extra_items.size());
  for (size_t i = 0; i < n_; ++i) items.push_back(static_cast<uint32_t>(i));
  items.insert(items.end(), spec.extra_items.begin(), spec.extra_items.end());
  SearchStats stats;
  std::vector<ItemNeighbor> results;
  for (uint32_t item : items) {
    if (spec.accept && !spec.accept(item)) continue;
    double terms[kMaxTerms] = {};
    spec.distance(item, terms);
    double d = 0.0;
    for (size_t t = 0; t < kMaxTerms; ++t) {
      if (spec.weights[t] > 0.0) d += spec.weights[t] * terms[t];
    }
    ++stats.emd_computations;
    if (std::isnan(d) || d > spec.radius) continue;
    results.push_back({item, d});
  }
  std::sort(results.begin(), results.end(),
            [&spec](const ItemNeighbor& a, const ItemNeighbor& b) {
              if (a.distance != b.distance) return a.distance < b.distance;
              return spec.tie_less ? spec.tie_less(a.item, b.item)
                                   : a.item < b.item;
            });
  return std::make_unique<SortedCursor>(std::move(results), stats);
}

std::vector<ItemNeighbor> BruteForceIndex::Knn(QuerySpec spec, size_t k,
                                               SearchStats* stats) const {
  return TakeNeighbors(*Search(std::move(spec)), k, stats);
}

std::vector<ItemNeighbor> BruteForceIndex::Range(QuerySpec spec,
                                                 SearchStats* stats) const {
  return Knn(std::move(spec), static_cast<size_t>(-1), stats);
}

}  // namespace tpr::index
