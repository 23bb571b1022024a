#include "web/recent_searches.h"

#include <algorithm>
#include <vector>

namespace tpr::web {
namespace {

// Nearest-rank quantile of sorted values (q in [0, 1]).
double Quantile(const std::vector<float>& sorted, double q) {
  if (sorted.empty()) return 0;
  size_t rank = static_cast<size_t>(q * static_cast<double>(sorted.size()));
  if (rank >= sorted.size()) rank = sorted.size() - 1;
  return sorted[rank];
}

}  // namespace

void RecentSearches::Trim(Clock::time_point now) {
  const Clock::time_point oldest =
      now - std::chrono::duration_cast<Clock::duration>(
                std::chrono::duration<double>(window_s_));
  while (!entries_.empty() &&
         (entries_.front().at < oldest || entries_.size() > kMaxKept)) {
    entries_.pop_front();
  }
}

void RecentSearches::Add(Clock::time_point at, double total_ms,
                         double indexer_ms) {
  std::lock_guard<std::mutex> lock(mu_);
  entries_.push_back(
      {at, static_cast<float>(total_ms), static_cast<float>(indexer_ms)});
  ++total_;
  Trim(at);
}

RecentSearches::Summary RecentSearches::Summarize(Clock::time_point now) {
  std::vector<float> total;
  std::vector<float> indexer;
  Summary summary;
  {
    std::lock_guard<std::mutex> lock(mu_);
    Trim(now);
    summary.total = total_;
    for (const Entry& e : entries_) {
      total.push_back(e.total_ms);
      indexer.push_back(e.indexer_ms);
    }
  }
  std::sort(total.begin(), total.end());
  std::sort(indexer.begin(), indexer.end());
  summary.in_window = static_cast<int64_t>(total.size());
  summary.window_s = window_s_;
  summary.per_second = static_cast<double>(total.size()) / window_s_;
  summary.total_p50_ms = Quantile(total, 0.5);
  summary.total_p95_ms = Quantile(total, 0.95);
  summary.indexer_p50_ms = Quantile(indexer, 0.5);
  summary.indexer_p95_ms = Quantile(indexer, 0.95);
  return summary;
}

}  // namespace tpr::web
