// CentroidTable: the centroids of many prepared signatures in one flat,
// slot-indexed array, so that the centroid lower bound of the EMD (Rubner
// et al. [22], used by Tam & Lau 2007 section 6.2 to prune the VP-tree
// search) reads one contiguous row per item instead of chasing a pointer to
// the item's PreparedSignature and then to its centroid vector.
//
//   CentroidTable table = CentroidTable::Build(
//       items.size(), [&](uint32_t i) { return &items[i]; });
//   double lb = table.LowerBound(query, i);  // == EmdLowerBound(query, items[i])
#ifndef TPR_INDEXER_LIB_CENTROID_TABLE_H_
#define TPR_INDEXER_LIB_CENTROID_TABLE_H_

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"

namespace tpr::index {

// CentroidTable holds, for slots 0 .. size() - 1, the centroid of the
// signature in that slot (or nothing: an absent slot). Immutable once
// built; copyable and movable; thread-safe to read from any number of
// threads.
class CentroidTable {
 public:
  CentroidTable() = default;

  // Build returns the table of `n` slots; item(i) gives the signature of
  // slot i, or nullptr for an absent slot. item is called once per slot, in
  // slot order, from the calling thread. Cost O(n x bands) time and
  // 8 (1 + 3 B) n bytes, B the largest bands() of the items; no EMD.
  static CentroidTable Build(
      size_t n, const std::function<const PreparedSignature*(uint32_t)>& item);

  // size returns the number of slots.
  size_t size() const { return width_ == 0 ? 0 : rows_.size() / width_; }
  // MemoryBytes returns the heap bytes this table holds.
  size_t MemoryBytes() const { return rows_.capacity() * sizeof(double); }

  // LowerBound returns EmdLowerBound(query, s) (emd.h) for the signature s
  // of slot i, bit for bit, or 0.0 when the slot is absent (no bound
  // known). Precondition: i < size(). Cost O(bands), no allocation;
  // thread-safe.
  double LowerBound(const PreparedSignature& query, uint32_t i) const {
    const double* cb = rows_.data() + static_cast<size_t>(i) * width_;
    if (std::isnan(cb[0])) return 0.0;  // absent slot
    // CentroidBound is EmdLowerBound's own arithmetic, so the value is
    // identical: a row is padded with zeros to bands_ per block,
    // and (x - 0) * (x - 0) == x * x and s + 0 * 0 == s exactly, so where
    // the item has fewer bands than bands_ the padding terms reproduce the
    // "d >= common" tails of EmdLowerBound term for term.
    return CentroidBound(query.centroid(), query.bands(), cb, bands_);
  }

 private:
  int bands_ = 0;      // largest bands() over present items
  size_t width_ = 0;   // 1 + 3 bands_ doubles per row
  // Row i: centroid row 0, then the K, A and H blocks each zero-padded to
  // bands_ values; an absent slot has a NaN in its first value (a present
  // centroid is finite: Prepare rejects non-finite coordinates).
  std::vector<double> rows_;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_CENTROID_TABLE_H_
