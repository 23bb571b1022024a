// The spectral term of the combined distance (metric.h): a fixed embedding
// of a signature's Laplace-Beltrami spectrum ("ShapeDNA", Reuter et al.
// 2006) into R^n, compared with the Euclidean norm. The spectrum
// values are lambda_i A / (4 pi) (indexer/lib/signature.h), which Weyl's law
// makes grow like i: lambda_i ~ 4 pi i / A for a closed surface of area A.
//
// Embedding. For n = options.eigenvalues and s_1 <= s_2 <= ... the stored
// values (a spectrum shorter than n is padded with its Weyl asymptote
// s_i = i, so every signature has an image), coordinate i is
//   E_i(s) = phi_i(s_i) / sqrt(n),        i = 1..n,
// with phi_i one fixed per-coordinate map chosen by options.transform:
//   kRaw      phi_i(x) = x                (ShapeDNA's plain Euclidean form)
//   kByIndex  phi_i(x) = x / i            (normalized by index: every
//                                          coordinate is about 1 by Weyl)
//   kLog      phi_i(x) = log(x)           (relative differences)
// The 1/sqrt(n) makes the term's size independent of n. The spectral
// distance is ||E(s) - E(t)||_2. phi does not depend on the other signature
// or on any data, which is what keeps the sum with the EMD a metric
// (metric.h).
//
//   SpectralOptions o;                              // defaults, see below
//   std::vector<double> e = SpectralEmbedding(spectrum, o);
//   double d = SpectralDistance(e.data(), f.data(), e.size());
#ifndef TPR_INDEXER_LIB_SPECTRAL_H_
#define TPR_INDEXER_LIB_SPECTRAL_H_

#include <cstddef>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "common/signature_limits.h"

namespace tpr::index {

// SpectralTransform: the per-coordinate map phi of the file comment.
enum class SpectralTransform { kRaw, kByIndex, kLog };

// SpectralTransformName returns "raw", "by_index" or "log".
const char* SpectralTransformName(SpectralTransform t);
// ParseSpectralTransform is its inverse; INVALID_ARGUMENT for another name.
absl::StatusOr<SpectralTransform> ParseSpectralTransform(
    absl::string_view name);

// kMaxSpectrum: the longest spectrum a signature may carry and the largest
// options.eigenvalues: the contract's (common/signature_limits.h).
inline constexpr int kMaxSpectrum = common::kMaxSpectrumEigenvalues;

// SpectralOptions: the spectral term of the combined distance. Every
// signature of one index is prepared with the same options.
struct SpectralOptions {
  // The term's factor in a distance is not an option of the embedding: it
  // is the spectral factor of the search's TermWeights (intent.h).
  // phi. Default kByIndex: x_i / i, the 1/i weighting of ShapeDNA's
  // reference form; chosen by cross-validation with n over every dev set
  // (tpr-tune-intents, docs/results.md: IDENTITY's best over phi in
  // {by_index, log} x n in {20, 30, 50}).
  SpectralTransform transform = SpectralTransform::kByIndex;
  // n: eigenvalues compared (the first n). Range 1..kMaxSpectrum. Default
  // 50, see transform (the extractor stores 50 by default; a longer
  // spectrum is truncated, a shorter one padded).
  int eigenvalues = 50;
};

// ValidateSpectralOptions returns OK when `options` meets the constraints
// above, INVALID_ARGUMENT naming the field otherwise. O(1); thread-safe.
absl::Status ValidateSpectralOptions(const SpectralOptions& options);

// HeatTraceOptions: the heat-trace term H of the distance, a second fixed
// embedding of the same spectrum. With s_1 <= ... <= s_n the stored values
// (padded with the Weyl asymptote s_i = i like the spectral term), the heat
// trace is Z(t) = sum_{i=1..n} exp(-s_i t) (Sun et al. 2009; the trace of
// the heat kernel, scale-free because s is), and coordinate j of the
// embedding is
//   F_j(s) = log(t_j Z(t_j)) / sqrt(m),   j = 1..m,
// at m times t_j spaced evenly in log between t_min and t_max. t Z(t) tends
// to 1 for small t on every surface (Weyl's law), so each coordinate is of
// order 1. H(A, B) = ||F(s_A) - F(s_B)||_2 is a pseudometric (a Euclidean
// distance between images of one fixed map).
struct HeatTraceOptions {
  // m: diffusion times; 0 means the term is absent (empty embedding).
  // Range 0..256. Default 16.
  int scales = 16;
  // t_1 and t_m, dimensionless (the unit of 1 / s_i). 0 < t_min < t_max.
  // Defaults 0.2 and 20, with eigenvalues 20: chosen by cross-validation
  // over every dev set (tpr-tune-intents, docs/results.md) among [0.01, 1],
  // [0.05, 5] and [0.2, 20] x n in {20, 50}. Long times weigh the first
  // eigenvalues (the coarse build); only BALANCED uses the term, and it
  // gains little from it.
  double t_min = 0.2;
  double t_max = 20.0;
  // n: eigenvalues summed (the first n). Range 1..kMaxSpectrum. Default 20,
  // see t_min.
  int eigenvalues = 20;
};

// ValidateHeatTraceOptions returns OK when `options` meets the constraints
// above, INVALID_ARGUMENT naming the field otherwise. O(1); thread-safe.
absl::Status ValidateHeatTraceOptions(const HeatTraceOptions& options);

// HeatTraceEmbedding returns F(spectrum) of HeatTraceOptions: options.scales
// values (none when scales is 0). Preconditions: `options` valid and every
// value of `spectrum` finite and > 0. O(n m); thread-safe.
std::vector<double> HeatTraceEmbedding(const std::vector<double>& spectrum,
                                       const HeatTraceOptions& options);

// SpectralEmbedding returns E(spectrum) of the file comment: options.
// eigenvalues values. Preconditions: `options` valid and every value of
// `spectrum` finite and > 0 (ValidateSignature checks both); values past
// the first n are ignored. O(n); thread-safe.
std::vector<double> SpectralEmbedding(const std::vector<double>& spectrum,
                                      const SpectralOptions& options);

// SpectralDistance returns ||a - b||_2 over n coordinates (0 for n = 0),
// computed in double; the float32 form reads PreparedSignature's stored
// embeddings. O(n); thread-safe.
double SpectralDistance(const double* a, const double* b, size_t n);
double SpectralDistance(const float* a, const float* b, size_t n);

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_SPECTRAL_H_
