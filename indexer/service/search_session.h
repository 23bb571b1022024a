// SearchSession: one running ranked search of tpr-indexer, streaming the
// neighbours of an index snapshot in ascending EMD (Tam & Lau 2007,
// section 6.2) with the labels of the same moment.
//
//   absl::StatusOr<std::unique_ptr<SearchSession>> s =
//       core->StartSearch(request, cancelled);
//   while (std::optional<tpr::v1::Neighbor> n = (*s)->Next()) Send(*n);
//   tpr::v1::SearchStats stats = (*s)->Stats();
#ifndef TPR_INDEXER_SERVICE_SEARCH_SESSION_H_
#define TPR_INDEXER_SERVICE_SEARCH_SESSION_H_

#include <functional>
#include <memory>
#include <optional>

#include "indexer/lib/signature_index.h"
#include "indexer/service/label_map.h"
#include "tpr/v1/indexer.pb.h"

namespace tpr::indexer {

// SearchSession: one running ranked search. Not thread-safe: one caller.
class SearchSession {
 public:
  virtual ~SearchSession() = default;
  // Next returns the next neighbour (rank, id, label, distance) in ascending
  // distance, or nullopt when k were returned, none is left, or the search
  // was cancelled. Cost: a few EMDs per call, amortized.
  virtual std::optional<tpr::v1::Neighbor> Next() = 0;
  // Stats returns the work done so far and the elapsed time.
  virtual tpr::v1::SearchStats Stats() const = 0;
};

// MakeSearchSession returns a session returning at most `k` neighbours of
// `cursor`, labelled from `labels` (the snapshot taken with the cursor's
// index snapshot). `cancelled`, when set, is polled before each neighbour;
// once it returns true Next() returns nullopt. Cost: O(1).
std::unique_ptr<SearchSession> MakeSearchSession(
    std::unique_ptr<tpr::index::SignatureIndex::Cursor> cursor, int k,
    std::function<bool()> cancelled,
    std::shared_ptr<const LabelSnapshot> labels);

}  // namespace tpr::indexer

#endif  // TPR_INDEXER_SERVICE_SEARCH_SESSION_H_
