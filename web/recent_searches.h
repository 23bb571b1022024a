// RecentSearches: the searches tpr-web passed to the indexer in the last
// minute, for the console's Status screen (query rate and latency as the
// indexer itself measured them, SearchStats.milliseconds, beside the time
// the whole HTTP request took).
//
//   RecentSearches recent;
//   recent.Add(now, /*total_ms=*/3.1, /*indexer_ms=*/2.2);
//   RecentSearches::Summary s = recent.Summarize(now);  // s.per_second ...
#ifndef TPR_WEB_RECENT_SEARCHES_H_
#define TPR_WEB_RECENT_SEARCHES_H_

#include <chrono>
#include <cstdint>
#include <deque>
#include <mutex>

namespace tpr::web {

// RecentSearches keeps (time, durations) of the searches of the last
// window_s seconds, at most kMaxKept of them. Thread-safe.
class RecentSearches {
 public:
  using Clock = std::chrono::steady_clock;
  // kMaxKept bounds memory (24 bytes per entry): beyond it the oldest are
  // dropped and the rate is computed over the time the kept ones span.
  static constexpr size_t kMaxKept = 100000;

  // window_s: the length of the window, in seconds. Default 60.
  explicit RecentSearches(double window_s = 60) : window_s_(window_s) {}

  // Add records one finished search. O(1) amortized.
  void Add(Clock::time_point at, double total_ms, double indexer_ms);

  // Summary: what the window holds.
  struct Summary {
    int64_t total = 0;        // Searches since start.
    int64_t in_window = 0;    // Searches in the window.
    double window_s = 0;      // The window's length, seconds.
    double per_second = 0;    // in_window / window_s.
    double total_p50_ms = 0;  // Median time of the whole HTTP request.
    double total_p95_ms = 0;
    double indexer_p50_ms = 0;  // Median SearchStats.milliseconds.
    double indexer_p95_ms = 0;
  };
  // Summarize drops entries older than the window and summarizes the rest.
  // O(n log n) in the entries kept.
  Summary Summarize(Clock::time_point now);

 private:
  struct Entry {
    Clock::time_point at;
    float total_ms;
    float indexer_ms;
  };
  void Trim(Clock::time_point now);  // Needs mu_.

  const double window_s_;
  std::mutex mu_;
  std::deque<Entry> entries_;  // Guarded by mu_.
  int64_t total_ = 0;          // Guarded by mu_.
};

}  // namespace tpr::web

#endif  // TPR_WEB_RECENT_SEARCHES_H_
