// CentroidTable: the centroids of many prepared signatures in one flat,
// slot-indexed array of compact rows, so that the centroid lower bound of
// the EMD (Rubner et al. [22], used by Tam & Lau 2007 section 6.2 to prune
// the VP-tree search) reads one short contiguous row per item instead of
// chasing a pointer to the item's PreparedSignature. The table is the only
// copy of an index item's centroid (PreparedSignature keeps none).
//
//   CentroidTable table = CentroidTable::Build(
//       items.size(), [&](uint32_t i) { return &items[i]; });
//   std::vector<double> q = Centroid(query);             // once per query
//   double lb = table.LowerBound(q.data(), query.bands(), i);
//   // lb <= EmdLowerBound(query, items[i]) <= Emd(query, items[i])
#ifndef TPR_INDEXER_LIB_CENTROID_TABLE_H_
#define TPR_INDEXER_LIB_CENTROID_TABLE_H_

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
  // and (20 + 6 B) n bytes, B the largest bands() of the items; no EMD.
  static CentroidTable Build(
      size_t n, const std::function<const PreparedSignature*(uint32_t)>& item);

  // size returns the number of slots.
  size_t size() const {
    return row_bytes_ == 0 ? 0 : rows_.size() / row_bytes_;
  }
  // MemoryBytes returns the heap bytes this table holds.
  size_t MemoryBytes() const { return rows_.capacity(); }

  // LowerBound returns a lower bound of EmdLowerBound(query, s) (emd.h),
  // hence of Emd(query, s), for the signature s of slot i, given the
  // query's centroid `query_centroid` (Centroid(query), emd.h) and bands;
  // 0.0 when the slot is absent (no bound known). With c the centroid of s
  // and c~ its stored, quantized form (centroid_table.cc), it is
  //   max(0, N(q - c~) - e),  e >= N(c - c~),
  // so by the triangle inequality of the norm N it never exceeds
  // N(q - c) = EmdLowerBound, and it is below it by at most 2e; e is about
  // 1e-4 N(c) (16-bit values per band block). Precondition: i < size().
  // Cost O(bands), no allocation; thread-safe.
  double LowerBound(const double* query_centroid, int query_bands,
                    uint32_t i) const;

  // Prefetch asks the CPU to start loading row i (LowerBound's only read)
  // into cache, without waiting (QuerySpec::prefetch). Precondition: i <
  // size(). No effect on any result; thread-safe.
  void Prefetch(uint32_t i) const;

 private:
  int bands_ = 0;         // largest bands() over present items
  size_t row_bytes_ = 0;  // kHeaderBytes + 3 bands_ int16 values
  // Row i (row_bytes_ bytes): float32 e (the radius above, rounded up; NaN
  // for an absent slot), float32 g (row 0 of the centroid, rounded to
  // float32), float32 scales s_K, s_A, s_H, then the K, A and H blocks of
  // the centroid as int16 multiples of their block's scale, each
  // zero-padded to bands_ values. 140 bytes at 20 bands, against 488 for
  // the centroid in double.
  std::vector<unsigned char> rows_;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_CENTROID_TABLE_H_
