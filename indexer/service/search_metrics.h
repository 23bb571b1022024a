// The metrics of a tpr.v1.Indexer Search, read from the stream's final
// SearchStats by the shared metrics interceptor (common/metrics.h
// MessageObserver); the indexer and the gateway both serve Search and both
// record them:
//   tpr_indexer_search_emd_computations  histogram per search
//   tpr_indexer_search_lower_bounds      histogram per search
//   tpr_indexer_search_duration_seconds  histogram (server time)
// Header-only: it needs prometheus-cpp and tpr_proto, not the indexer.
//
//   tpr::indexer::AddSearchMetrics(*server_options.metrics);
#ifndef TPR_INDEXER_SERVICE_SEARCH_METRICS_H_
#define TPR_INDEXER_SERVICE_SEARCH_METRICS_H_

#include <memory>

#include "common/metrics.h"
#include "tpr/v1/indexer.pb.h"

namespace tpr::indexer {
namespace search_metrics_internal {

// SearchObserver records the SearchStats a Search stream sends.
class SearchObserver final : public common::MessageObserver {
 public:
  SearchObserver(prometheus::Histogram* emds,
                 prometheus::Histogram* lower_bounds,
                 prometheus::Histogram* seconds)
      : emds_(emds), lower_bounds_(lower_bounds), seconds_(seconds) {}

  void OnSend(const void* message) override {
    const auto* response = static_cast<const v1::SearchResponse*>(message);
    if (!response->has_stats()) return;
    emds_->Observe(static_cast<double>(response->stats().emd_computations()));
    lower_bounds_->Observe(
        static_cast<double>(response->stats().lower_bounds()));
    seconds_->Observe(response->stats().milliseconds() / 1000);
  }

 private:
  prometheus::Histogram* emds_;
  prometheus::Histogram* lower_bounds_;
  prometheus::Histogram* seconds_;
};

}  // namespace search_metrics_internal

// AddSearchMetrics registers the three histograms in `metrics` and observes
// "/tpr.v1.Indexer/Search". Call once, before the server starts.
inline void AddSearchMetrics(common::Metrics& metrics) {
  prometheus::Registry& r = metrics.registry();
  prometheus::Histogram* emds =
      &prometheus::BuildHistogram()
           .Name("tpr_indexer_search_emd_computations")
           .Help("Full EMD computations per search (SearchStats)")
           .Register(r)
           .Add({}, common::CountBuckets());
  prometheus::Histogram* lower_bounds =
      &prometheus::BuildHistogram()
           .Name("tpr_indexer_search_lower_bounds")
           .Help("Lower bounds computed per search (SearchStats)")
           .Register(r)
           .Add({}, common::CountBuckets());
  prometheus::Histogram* seconds =
      &prometheus::BuildHistogram()
           .Name("tpr_indexer_search_duration_seconds")
           .Help("Server-side time of each search (SearchStats)")
           .Register(r)
           .Add({}, common::SecondsBuckets());
  metrics.ObserveMethod(
      "/tpr.v1.Indexer/Search", [emds, lower_bounds, seconds] {
        return std::make_unique<search_metrics_internal::SearchObserver>(
            emds, lower_bounds, seconds);
      });
}

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_SEARCH_METRICS_H_
