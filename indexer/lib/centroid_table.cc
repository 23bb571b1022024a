// CentroidTable: why a flat, quantized copy. A k-NN over 100k signatures
// evaluates about 5k centroid bounds per query; reading each through the
// stored PreparedSignature costs dependent cache misses and the
// O(features x bands) sum of the centroid. One row per slot in one array
// leaves a single, prefetch-friendly access. At 1M models the bounds are
// cache misses, not arithmetic (docs/search-cost.md), so a row is kept
// short: 16 bits per band value, with one scale per band block, and the
// quantization error subtracted from the bound so that it stays a lower
// bound (the triangle inequality of N, centroid_table.h). The bound loses
// about 1e-4 of N(c) of pruning power; the centroid costs 140 bytes at 20
// bands instead of 488, and a model about 3.9 KB instead of 4.3 KB.
//
// The spectral embedding (metric.h) rides in the same row, 16 bits per
// value with one step for the whole table, its radius subtracted likewise:
// with the default metric the level-1 bound is the centroid bound plus the
// spectral term, and reading the embedding through the item's signature
// cost a dependent cache miss per bounded item (a third of the 1M 10-NN's
// bounds, docs/search-cost.md). 44 bytes more per row at 20 eigenvalues.
#include "indexer/lib/centroid_table.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

namespace tpr::index {

namespace {

// e, g, s_K, s_A, s_H, e_s
constexpr size_t kHeaderBytes = 6 * sizeof(float);
constexpr size_t kSpectralRadiusAt = 5 * sizeof(float);  // e_s
constexpr double kLevels = 32767.0;                      // int16 magnitude

float LoadFloat(const unsigned char* p) {
  float x;
  std::memcpy(&x, p, sizeof x);
  return x;
}

void StoreFloat(unsigned char* p, float x) { std::memcpy(p, &x, sizeof x); }

int16_t LoadInt16(const unsigned char* p) {
  int16_t x;
  std::memcpy(&x, p, sizeof x);
  return x;
}

// RoundUp returns the smallest float32 >= x (x >= 0, finite).
float RoundUp(double x) {
  float up = static_cast<float>(x);
  if (static_cast<double>(up) < x) {
    up = std::nextafter(up, std::numeric_limits<float>::infinity());
  }
  return up;
}

// Quantize writes x (n float32 values) as int16 multiples of `step` at
// `values` and returns the rounded-up radius ||x - x~||_2 (inflated by a
// relative 1e-12 for the roundings of its sum): each x~_k = step x int16 is
// exact in double.
float Quantize(const float* x, int n, double step, unsigned char* values) {
  double s = 0.0;
  for (int k = 0; k < n; ++k) {
    const double v = static_cast<double>(x[k]);
    double level = step > 0.0 ? std::nearbyint(v / step) : 0.0;
    level = std::clamp(level, -kLevels, kLevels);
    const int16_t q = static_cast<int16_t>(level);
    std::memcpy(values + static_cast<size_t>(k) * sizeof q, &q, sizeof q);
    const double diff = v - step * q;
    s += diff * diff;
  }
  return RoundUp(std::sqrt(s) * (1.0 + 1e-12));
}

// QuantizedBound returns ||query - x~||_2 - radius, at least 0, for a
// row written by Quantize (radius first, then the values).
double QuantizedBound(const float* query, int n, double step,
                      const unsigned char* row) {
  const double radius = static_cast<double>(LoadFloat(row));
  const unsigned char* values = row + sizeof(float);
  double s = 0.0;
  for (int k = 0; k < n; ++k) {
    const double diff =
        static_cast<double>(query[k]) -
        step * LoadInt16(values + static_cast<size_t>(k) * sizeof(int16_t));
    s += diff * diff;
  }
  const double bound = std::sqrt(s) - radius;
  return bound > 0.0 ? bound : 0.0;
}

// BuildHeat returns the heat-trace array of the present items.
CentroidTable::QuantizedEmbeddings BuildHeat(
    const std::vector<const PreparedSignature*>& items) {
  CentroidTable::QuantizedEmbeddings h;
  int size = -1;
  for (const PreparedSignature* p : items) {
    if (p == nullptr) continue;
    if (size == -1) size = p->heat_size();
    if (p->heat_size() != size) size = 0;  // mixed: keep none
  }
  h.size = std::max(size, 0);
  if (h.size == 0) return h;
  double largest = 0.0;
  for (const PreparedSignature* p : items) {
    if (p == nullptr) continue;
    for (int k = 0; k < h.size; ++k) {
      largest = std::max(largest, std::abs(static_cast<double>(p->heat()[k])));
    }
  }
  h.step = RoundUp(largest / kLevels);
  h.row_bytes = sizeof(float) + static_cast<size_t>(h.size) * sizeof(int16_t);
  h.rows.assign(items.size() * h.row_bytes, 0);
  for (size_t i = 0; i < items.size(); ++i) {
    if (items[i] == nullptr) continue;
    unsigned char* row = h.rows.data() + i * h.row_bytes;
    StoreFloat(row,
               Quantize(items[i]->heat(), h.size, h.step, row + sizeof(float)));
  }
  return h;
}

}  // namespace

CentroidTable CentroidTable::Build(
    size_t n, const std::function<const PreparedSignature*(uint32_t)>& item) {
  CentroidTable t;
  std::vector<const PreparedSignature*> items(n);
  int spectral = -1;  // the common spectral_size() so far; -1: none seen
  double largest_spectral = 0.0;
  for (size_t i = 0; i < n; ++i) {
    items[i] = item(static_cast<uint32_t>(i));
    const PreparedSignature* p = items[i];
    if (p == nullptr) continue;
    t.bands_ = std::max(t.bands_, p->bands());
    if (spectral == -1) spectral = p->spectral_size();
    if (p->spectral_size() != spectral) spectral = 0;  // mixed: keep none
    for (int k = 0; k < std::min(spectral, p->spectral_size()); ++k) {
      largest_spectral = std::max(
          largest_spectral, std::abs(static_cast<double>(p->spectral()[k])));
    }
  }
  t.spectral_size_ = std::max(spectral, 0);
  t.spectral_scale_ = RoundUp(largest_spectral / kLevels);
  const size_t table_bands = static_cast<size_t>(t.bands_);
  const size_t spectral_at =
      kHeaderBytes + 3 * table_bands * sizeof(int16_t);  // its int16 values
  t.row_bytes_ =
      spectral_at + static_cast<size_t>(t.spectral_size_) * sizeof(int16_t);
  t.rows_.assign(n * t.row_bytes_, 0);
  for (size_t i = 0; i < n; ++i) {
    unsigned char* row = t.rows_.data() + i * t.row_bytes_;
    const PreparedSignature* p = items[i];
    if (p == nullptr) {
      StoreFloat(row, std::numeric_limits<float>::quiet_NaN());
      continue;
    }
    const std::vector<double> c = Centroid(*p);
    const size_t b = static_cast<size_t>(p->bands());
    // e = N(c - c~), in double, then inflated by a relative 1e-12 for the
    // roundings of this sum and rounded up to float32. Each stored value
    // c~ is exactly what LowerBound reads: double(g32) and
    // double(scale32) * q (a 24-bit by 16-bit product, exact in double).
    const float g = static_cast<float>(c[0]);
    StoreFloat(row + sizeof(float), g);
    double e = std::abs(c[0] - static_cast<double>(g));
    for (size_t block = 0; block < 3; ++block) {
      const double* x = c.data() + 1 + block * b;
      double largest = 0.0;
      for (size_t d = 0; d < b; ++d)
        largest = std::max(largest, std::abs(x[d]));
      const float scale = RoundUp(largest / kLevels);  // |x / scale| <= 32767
      StoreFloat(row + (2 + block) * sizeof(float), scale);
      unsigned char* q =
          row + kHeaderBytes + block * table_bands * sizeof(int16_t);
      double s = 0.0;
      for (size_t d = 0; d < b; ++d) {
        double level = scale > 0.0f ? std::nearbyint(x[d] / scale) : 0.0;
        level = std::clamp(level, -kLevels, kLevels);
        const int16_t v = static_cast<int16_t>(level);
        std::memcpy(q + d * sizeof(int16_t), &v, sizeof v);
        const double diff = x[d] - static_cast<double>(scale) * v;
        s += diff * diff;
      }
      e += std::sqrt(s);
    }
    StoreFloat(row, RoundUp(e * (1.0 + 1e-12)));
    // The spectral embedding: E~_k = spectral_scale_ x int16, exact in
    // double like the centroid's values; e_s = ||E - E~||_2 of the stored
    // float32 embedding E, inflated and rounded up as e is.
    double s = 0.0;
    for (int k = 0; k < t.spectral_size_; ++k) {
      const double x = static_cast<double>(p->spectral()[k]);
      double level =
          t.spectral_scale_ > 0.0 ? std::nearbyint(x / t.spectral_scale_) : 0.0;
      level = std::clamp(level, -kLevels, kLevels);
      const int16_t v = static_cast<int16_t>(level);
      std::memcpy(row + spectral_at + static_cast<size_t>(k) * sizeof v, &v,
                  sizeof v);
      const double diff = x - t.spectral_scale_ * v;
      s += diff * diff;
    }
    StoreFloat(row + kSpectralRadiusAt, RoundUp(std::sqrt(s) * (1.0 + 1e-12)));
  }
  t.heat_ = BuildHeat(items);
  return t;
}

void CentroidTable::PrefetchHeat(uint32_t i) const {
#if defined(__GNUC__)
  if (heat_.row_bytes == 0) return;
  const unsigned char* row =
      heat_.rows.data() + static_cast<size_t>(i) * heat_.row_bytes;
  __builtin_prefetch(row);
  __builtin_prefetch(row + heat_.row_bytes - 1);
#else
  (void)i;
#endif
}

double CentroidTable::HeatLowerBound(const float* query_heat,
                                     int query_heat_size, uint32_t i) const {
  if (heat_.size == 0 || query_heat_size != heat_.size) return 0.0;
  if (std::isnan(LoadFloat(rows_.data() + static_cast<size_t>(i) * row_bytes_)))
    return 0.0;  // absent slot
  return QuantizedBound(
      query_heat, heat_.size, heat_.step,
      heat_.rows.data() + static_cast<size_t>(i) * heat_.row_bytes);
}

void CentroidTable::Prefetch(uint32_t i) const {
#if defined(__GNUC__)
  const unsigned char* row = rows_.data() + static_cast<size_t>(i) * row_bytes_;
  for (size_t at = 0; at < row_bytes_; at += 64) __builtin_prefetch(row + at);
  __builtin_prefetch(row + row_bytes_ - 1);
#else
  (void)i;
#endif
}

double CentroidTable::LowerBound(const double* query_centroid, int query_bands,
                                 uint32_t i) const {
  const unsigned char* row = rows_.data() + static_cast<size_t>(i) * row_bytes_;
  const float e = LoadFloat(row);
  if (std::isnan(e)) return 0.0;  // absent slot
  // N(q - c~) by the arithmetic of CentroidBound (emd.h): a row is
  // zero-padded to bands_ per block, and a zero band contributes exactly
  // what a missing one does. Each stored value reads as scale x int16, a
  // 24-bit by 16-bit product, exact in double.
  const double g = static_cast<double>(LoadFloat(row + sizeof(float)));
  double scale[3];
  for (int block = 0; block < 3; ++block) {
    scale[block] =
        static_cast<double>(LoadFloat(row + (2 + block) * sizeof(float)));
  }
  const unsigned char* values = row + kHeaderBytes;
  const size_t bands = static_cast<size_t>(bands_);
  const double result = internal::CentroidNorm(
      [query_centroid, query_bands](int block, int d) {
        return query_centroid[block < 0 ? 0 : 1 + block * query_bands + d];
      },
      query_bands,
      [g, &scale, values, bands](int block, int d) {
        if (block < 0) return g;
        const size_t at = static_cast<size_t>(block) * bands + d;
        return scale[block] * LoadInt16(values + at * sizeof(int16_t));
      },
      bands_);
  const double bound = result - static_cast<double>(e);
  return bound > 0.0 ? bound : 0.0;
}

double CentroidTable::SpectralLowerBound(const float* query_spectral,
                                         int query_spectral_size,
                                         uint32_t i) const {
  if (spectral_size_ == 0 || query_spectral_size != spectral_size_) return 0.0;
  const unsigned char* row = rows_.data() + static_cast<size_t>(i) * row_bytes_;
  if (std::isnan(LoadFloat(row))) return 0.0;  // absent slot
  const double e_s = static_cast<double>(LoadFloat(row + kSpectralRadiusAt));
  const unsigned char* values =
      row + row_bytes_ - static_cast<size_t>(spectral_size_) * sizeof(int16_t);
  // ||q - E~||_2 in double; each E~_k = spectral_scale_ x int16 is exact.
  double s = 0.0;
  for (int k = 0; k < spectral_size_; ++k) {
    const double diff =
        static_cast<double>(query_spectral[k]) -
        spectral_scale_ *
            LoadInt16(values + static_cast<size_t>(k) * sizeof(int16_t));
    s += diff * diff;
  }
  const double bound = std::sqrt(s) - e_s;
  return bound > 0.0 ? bound : 0.0;
}

}  // namespace tpr::index
