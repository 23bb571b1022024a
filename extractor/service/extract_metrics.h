// The extractor's metrics read from its Extract calls' messages, fed by the
// shared metrics interceptor (common/metrics.h MessageObserver):
//   tpr_extractor_stage_duration_seconds{stage}  histogram (StageTiming)
//   tpr_extractor_mesh_bytes                     histogram (upload size)
//
//   AddExtractMetrics(*server_options.metrics);  // before the server starts
#ifndef TPR_EXTRACTOR_SERVICE_EXTRACT_METRICS_H_
#define TPR_EXTRACTOR_SERVICE_EXTRACT_METRICS_H_

#include "common/metrics.h"

namespace tpr::extractor {

// AddExtractMetrics registers both families in `metrics` and observes
// "/tpr.v1.Extractor/Extract": each call's upload size (the bytes of its
// chunks' `data` fields, read from the wire form without copying) and its
// response's stage timings. Call once, before the server starts.
void AddExtractMetrics(common::Metrics& metrics);

}  // namespace tpr::extractor

#endif  // TPR_EXTRACTOR_SERVICE_EXTRACT_METRICS_H_
