#include "indexer/service/search_session.h"

#include <chrono>
#include <string>
#include <utility>

namespace tpr::indexer {
namespace {

class Session final : public SearchSession {
 public:
  Session(std::unique_ptr<tpr::index::SignatureIndex::Cursor> cursor, int k,
          std::function<bool()> cancelled,
          std::shared_ptr<const LabelSnapshot> labels)
      : cursor_(std::move(cursor)),
        k_(k),
        cancelled_(std::move(cancelled)),
        labels_(std::move(labels)),
        start_(std::chrono::steady_clock::now()) {}

  std::optional<tpr::v1::Neighbor> Next() override {
    if (returned_ >= k_ || IsCancelled()) return std::nullopt;
    std::optional<tpr::index::Neighbor> n = cursor_->Next();
    // After a cancellation the filter rejected candidates unseen, so what the
    // cursor returns then is no longer the true next neighbour.
    if (!n.has_value() || IsCancelled()) return std::nullopt;
    tpr::v1::Neighbor out;
    out.set_rank(++returned_);
    if (const std::string* label = labels_->Find(n->id)) out.set_label(*label);
    out.set_id(std::move(n->id));
    out.set_distance(n->distance);
    return out;
  }

  tpr::v1::SearchStats Stats() const override {
    tpr::v1::SearchStats stats;
    const tpr::index::SearchStats& s = cursor_->stats();
    stats.set_emd_computations(s.emd_computations);
    stats.set_lower_bounds(s.lower_bounds);
    stats.set_nodes_visited(s.nodes_visited);
    stats.set_milliseconds(std::chrono::duration<double, std::milli>(
                               std::chrono::steady_clock::now() - start_)
                               .count());
    return stats;
  }

 private:
  bool IsCancelled() const { return cancelled_ && cancelled_(); }

  std::unique_ptr<tpr::index::SignatureIndex::Cursor> cursor_;
  const int k_;
  int returned_ = 0;
  std::function<bool()> cancelled_;
  std::shared_ptr<const LabelSnapshot> labels_;
  const std::chrono::steady_clock::time_point start_;
};

}  // namespace

std::unique_ptr<SearchSession> MakeSearchSession(
    std::unique_ptr<tpr::index::SignatureIndex::Cursor> cursor, int k,
    std::function<bool()> cancelled,
    std::shared_ptr<const LabelSnapshot> labels) {
  return std::make_unique<Session>(std::move(cursor), k, std::move(cancelled),
                                   std::move(labels));
}

}  // namespace tpr::indexer
