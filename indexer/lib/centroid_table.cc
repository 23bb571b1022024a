// CentroidTable: why a flat float32 copy. A k-NN over 100k signatures
// evaluates about 5k centroid bounds per query; reading each through the
// stored PreparedSignature costs dependent cache misses and the
// O(features x bands) sum of the centroid. One row per slot in one array
// leaves a single, prefetch-friendly access, and float32 halves the cache
// lines a row spans (at 1M models the bounds are cache misses, not
// arithmetic: docs/search-cost.md) and the bytes per model.
#include "indexer/lib/centroid_table.h"

#include <cmath>
#include <limits>

namespace tpr::index {

namespace {

// RoundingRadius returns a float32 e >= N(c - fl32(c)) for the centroid c
// of `rows` values with `bands` bands (N of emd.h: |x_0| plus the L2 norm
// of each band block). The norm of the differences is computed in double
// (the differences themselves are exact: c - fl32(c) is representable), then
// inflated by a relative 1e-12 to cover the few roundings of that sum and
// rounded up to float32.
float RoundingRadius(const std::vector<double>& c, int bands) {
  double e = std::abs(c[0] - static_cast<double>(static_cast<float>(c[0])));
  for (int block = 0; block < 3; ++block) {
    double s = 0.0;
    for (int d = 0; d < bands; ++d) {
      const double x = c[static_cast<size_t>(1 + block * bands + d)];
      const double diff = x - static_cast<double>(static_cast<float>(x));
      s += diff * diff;
    }
    e += std::sqrt(s);
  }
  e *= 1.0 + 1e-12;
  float up = static_cast<float>(e);
  if (static_cast<double>(up) < e) {
    up = std::nextafter(up, std::numeric_limits<float>::infinity());
  }
  return up;
}

}  // namespace

CentroidTable CentroidTable::Build(
    size_t n, const std::function<const PreparedSignature*(uint32_t)>& item) {
  CentroidTable t;
  std::vector<const PreparedSignature*> items(n);
  for (size_t i = 0; i < n; ++i) {
    items[i] = item(static_cast<uint32_t>(i));
    if (items[i] != nullptr) t.bands_ = std::max(t.bands_, items[i]->bands());
  }
  t.width_ = 2 + 3 * static_cast<size_t>(t.bands_);
  t.rows_.assign(n * t.width_, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    float* row = t.rows_.data() + i * t.width_;
    const PreparedSignature* p = items[i];
    if (p == nullptr) {
      row[0] = std::numeric_limits<float>::quiet_NaN();
      continue;
    }
    const std::vector<double> c = Centroid(*p);
    const size_t b = static_cast<size_t>(p->bands());
    row[0] = RoundingRadius(c, p->bands());
    row[1] = static_cast<float>(c[0]);
    for (size_t block = 0; block < 3; ++block) {
      for (size_t d = 0; d < b; ++d) {
        row[2 + block * static_cast<size_t>(t.bands_) + d] =
            static_cast<float>(c[1 + block * b + d]);
      }
    }
  }
  return t;
}

}  // namespace tpr::index
