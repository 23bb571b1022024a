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
//   double ls = table.SpectralLowerBound(query.spectral(),
//                                        query.spectral_size(), i);
//   // ls <= SpectralDistance(query, items[i]) (metric.h), so
//   // lb + ls <= DistanceLowerBound(query, items[i]) <= Distance(...)
//
// The row also keeps the item's spectral embedding (quantized the same
// way), so that the level-1 bound of the default metric (centroid bound
// plus spectral term, metric.h) reads no signature at all. The heat-trace
// embedding is kept likewise in a second array of its own (HeatLowerBound),
// read only by searches that weigh the heat-trace term.
#ifndef TPR_INDEXER_LIB_CENTROID_TABLE_H_
#define TPR_INDEXER_LIB_CENTROID_TABLE_H_

#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/huge_pages.h"

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
  // slot order, from the calling thread. The spectral embeddings are kept
  // when every present item has the same spectral_size() > 0 (items of one
  // index are prepared with the same options); otherwise none is (then
  // spectral_size() is 0); the heat-trace embeddings likewise
  // (heat_size()). Cost O(n x features x bands) time and
  // (28 + 6 B + 2 S + 2 M) n bytes, B the largest bands() of the items, S
  // their spectral_size() and M their heat_size(); no EMD.
  static CentroidTable Build(
      size_t n, const std::function<const PreparedSignature*(uint32_t)>& item);

  // size returns the number of slots.
  size_t size() const {
    return row_bytes_ == 0 ? 0 : rows_.size() / row_bytes_;
  }
  // spectral_size returns the length of the spectral embeddings the rows
  // keep: the items' common spectral_size(), or 0 (none kept).
  int spectral_size() const { return spectral_size_; }
  // heat_size returns the length of the heat-trace embeddings kept: the
  // items' common heat_size(), or 0 (none kept).
  int heat_size() const { return heat_.size; }
  // MemoryBytes returns the heap bytes this table holds.
  size_t MemoryBytes() const {
    return rows_.capacity() + heat_.rows.capacity();
  }

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

  // SpectralLowerBound returns a lower bound of the spectral term
  // SpectralDistance(query, s) = ||E(query) - E(s)||_2 (metric.h; both
  // embeddings as PreparedSignature stores them, in float32) for the
  // signature s of slot i, given the query's stored embedding
  // `query_spectral` of `query_spectral_size` values; 0.0 when the slot is
  // absent or the sizes differ from spectral_size() (no bound known, which
  // includes a table that keeps no embeddings). With E~ the row's quantized
  // embedding and e_s >= ||E(s) - E~|| its stored radius (centroid_table.cc)
  // it is
  //   max(0, ||E(query) - E~||_2 - e_s),
  // which by the triangle inequality of the Euclidean norm never exceeds
  // ||E(query) - E(s)||_2, and is below it by at most 2 e_s (about 1e-4
  // of the largest embedding value of the table times sqrt(S)).
  // Precondition: i < size(). Cost O(spectral_size()), no allocation;
  // thread-safe.
  double SpectralLowerBound(const float* query_spectral,
                            int query_spectral_size, uint32_t i) const;

  // HeatLowerBound is SpectralLowerBound for the heat-trace term
  // HeatDistance(query, s) (metric.h), from the second array: a lower
  // bound, below it by at most twice the stored radius; 0.0 when the slot
  // is absent or the sizes differ from heat_size(). Precondition: i <
  // size(). Cost O(heat_size()), no allocation; thread-safe.
  double HeatLowerBound(const float* query_heat, int query_heat_size,
                        uint32_t i) const;

  // Prefetch asks the CPU to start loading row i (the only read of
  // LowerBound and SpectralLowerBound)
  // into cache, without waiting (QuerySpec::prefetch). Precondition: i <
  // size(). No effect on any result; thread-safe.
  void Prefetch(uint32_t i) const;
  // PrefetchHeat does the same for row i of the heat-trace array (the only
  // read of HeatLowerBound besides the slot's presence).
  void PrefetchHeat(uint32_t i) const;

  // QuantizedEmbeddings: one embedding per slot, each row a float32 radius
  // (rounded up) then size int16 multiples of one step (see Build).
  struct QuantizedEmbeddings {
    int size = 0;
    double step = 0.0;
    size_t row_bytes = 0;
    HugeVector<unsigned char> rows;
  };

 private:
  int bands_ = 0;          // largest bands() over present items
  int spectral_size_ = 0;  // see spectral_size()
  // The step of every row's quantized spectral embedding (one for the
  // table: the embeddings' values are of one size by construction,
  // spectral.h).
  double spectral_scale_ = 0.0;
  // kHeaderBytes + (3 bands_ + spectral_size_) int16 values
  size_t row_bytes_ = 0;
  // Row i (row_bytes_ bytes): float32 e (the radius above, rounded up; NaN
  // for an absent slot), float32 g (row 0 of the centroid, rounded to
  // float32), float32 scales s_K, s_A, s_H, float32 e_s (the spectral
  // radius, rounded up), then the K, A and H blocks of the centroid as
  // int16 multiples of their block's scale, each zero-padded to bands_
  // values, then the spectral embedding as int16 multiples of
  // spectral_scale_. 184 bytes at 20 bands and 20 eigenvalues, against 488
  // + 80 for the centroid in double and the embedding in float32.
  // Huge-page advised (huge_pages.h): 184 MB at 1M rows, one random row
  // read per level-1 bound.
  HugeVector<unsigned char> rows_;
  // The heat-trace embeddings, apart from rows_ so that a search that does
  // not weigh the term reads nothing more per row.
  QuantizedEmbeddings heat_;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_CENTROID_TABLE_H_
