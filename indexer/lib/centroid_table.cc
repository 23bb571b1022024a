// CentroidTable: why a flat copy. A k-NN over 100k signatures evaluates
// about 5k centroid bounds per query; reading each through the stored
// PreparedSignature costs two dependent cache misses (the object, then its
// centroid vector), a measurable share of the query. One row per slot in
// one array leaves a single, prefetch-friendly access.
#include "indexer/lib/centroid_table.h"

#include <limits>

namespace tpr::index {

CentroidTable CentroidTable::Build(
    size_t n, const std::function<const PreparedSignature*(uint32_t)>& item) {
  CentroidTable t;
  std::vector<const PreparedSignature*> items(n);
  for (size_t i = 0; i < n; ++i) {
    items[i] = item(static_cast<uint32_t>(i));
    if (items[i] != nullptr) t.bands_ = std::max(t.bands_, items[i]->bands());
  }
  t.width_ = 1 + 3 * static_cast<size_t>(t.bands_);
  t.rows_.assign(n * t.width_, 0.0);
  for (size_t i = 0; i < n; ++i) {
    double* row = t.rows_.data() + i * t.width_;
    const PreparedSignature* p = items[i];
    if (p == nullptr) {
      row[0] = std::numeric_limits<double>::quiet_NaN();
      continue;
    }
    const double* c = p->centroid();
    const size_t b = static_cast<size_t>(p->bands());
    row[0] = c[0];
    for (size_t block = 0; block < 3; ++block) {
      std::copy(c + 1 + block * b, c + 1 + (block + 1) * b,
                row + 1 + block * static_cast<size_t>(t.bands_));
    }
  }
  return t;
}

}  // namespace tpr::index
