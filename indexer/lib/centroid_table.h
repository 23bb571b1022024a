// CentroidTable: the centroids of many prepared signatures in one flat,
// slot-indexed float32 array, so that the centroid lower bound of the EMD
// (Rubner et al. [22], used by Tam & Lau 2007 section 6.2 to prune the
// VP-tree search) reads one contiguous row per item instead of chasing a
// pointer to the item's PreparedSignature. The table is the only copy of an
// index item's centroid (PreparedSignature keeps none).
//
//   CentroidTable table = CentroidTable::Build(
//       items.size(), [&](uint32_t i) { return &items[i]; });
//   std::vector<double> q = Centroid(query);             // once per query
//   double lb = table.LowerBound(q.data(), query.bands(), i);
//   // lb <= EmdLowerBound(query, items[i]) <= Emd(query, items[i])
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
  // slot order, from the calling thread. Cost O(n x features x bands) time
  // and 4 (2 + 3 B) n bytes, B the largest bands() of the items; no EMD.
  static CentroidTable Build(
      size_t n, const std::function<const PreparedSignature*(uint32_t)>& item);

  // size returns the number of slots.
  size_t size() const { return width_ == 0 ? 0 : rows_.size() / width_; }
  // MemoryBytes returns the heap bytes this table holds.
  size_t MemoryBytes() const { return rows_.capacity() * sizeof(float); }

  // LowerBound returns a lower bound of EmdLowerBound(query, s) (emd.h),
  // hence of Emd(query, s), for the signature s of slot i, given the
  // query's centroid `query_centroid` (Centroid(query), emd.h) and bands;
  // 0.0 when the slot is absent (no bound known). It is
  //   max(0, N(q - fl32(c)) - e),  e >= N(c - fl32(c)),
  // so by the triangle inequality of the norm N it never exceeds
  // N(q - c) = EmdLowerBound, and it is below it by at most 2e, where
  // e <= 2^-24 N(c) (float32 rounding of each value). Precondition:
  // i < size(). Cost O(bands), no allocation; thread-safe.
  double LowerBound(const double* query_centroid, int query_bands,
                    uint32_t i) const {
    const float* row = rows_.data() + static_cast<size_t>(i) * width_;
    if (std::isnan(row[0])) return 0.0;  // absent slot
    // A row is padded with zeros to bands_ per block, and a zero band
    // contributes to N exactly what a missing one does (emd.h).
    const double bound = CentroidBound(query_centroid, query_bands, row + 1, bands_) -
                         static_cast<double>(row[0]);
    return bound > 0.0 ? bound : 0.0;
  }

 private:
  int bands_ = 0;      // largest bands() over present items
  size_t width_ = 0;   // 2 + 3 bands_ floats per row
  // Row i: e (the rounding radius above, rounded up to float32; NaN for an
  // absent slot), then the centroid in float32: row 0 (g), then the K, A
  // and H blocks each zero-padded to bands_ values.
  std::vector<float> rows_;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_CENTROID_TABLE_H_
