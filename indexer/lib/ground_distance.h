// Ground distance between two topological features (Tam & Lau 2007, Eq. 7)
// and signature preparation for the EMD (section 6.1).
//
// Eq. 7 compares two features by their Normalized Integral Geodesic G'_norm
// and their three geometric surface vectors K, A, H (5.3):
//   Dist(U1, U2) = W1 |G'1 - G'2| + W2 L2norm(K1, K2) + W3 L2norm(A1, A2)
//                + W4 L2norm(H1, H2).
// The paper leaves L2norm undefined. Here it is a FIXED scaling of the
// Euclidean distance, L2norm(X1, X2) = c_X * ||X1 - X2||_2, with c_X an
// option shared by every signature of an index (never a per-pair
// normalization such as dividing by ||X1|| + ||X2||, which breaks the
// triangle inequality). Band vectors of different lengths are compared as
// if the shorter one were padded with zeros.
//
// Why Dist is a metric. Let phi map a feature to the concatenated vector
//   phi(U) = (W1 G', W2 c_K K, W3 c_A A, W4 c_H H)        (zero-padded)
// and let N(v) = |v_G| + ||v_K||_2 + ||v_A||_2 + ||v_H||_2 on that space.
// N is a norm (a sum of norms of the blocks: positive homogeneous,
// subadditive, zero only at v = 0), and Dist(U1, U2) = N(phi(U1) - phi(U2)).
// Hence Dist is non-negative, symmetric and satisfies the triangle
// inequality; Dist(U1, U2) = 0 iff phi(U1) = phi(U2). Two different
// features with equal coordinates (or features differing only in a block
// whose weight is 0) are at distance 0: on features Dist is a pseudometric,
// and a true metric on their images phi(U). That is all the EMD needs:
// Rubner et al. [22] prove that the EMD between signatures of equal total
// mass is a metric whenever the ground distance is a metric; with a
// pseudometric it is a pseudometric on signatures and a metric on the
// images of signatures (two signatures whose features have equal images and
// masses are at EMD 0, which is the right answer for retrieval anyway).
// The norm form is also what makes the centroid lower bound of emd.h valid.
//
//   GroundDistanceOptions options;                       // equal weights
//   absl::StatusOr<PreparedSignature> p = Prepare(signature, options);
//   double d = GroundDistance(*p, 0, *q, 2);             // feature 0 vs 2
#ifndef TPR_INDEXER_LIB_GROUND_DISTANCE_H_
#define TPR_INDEXER_LIB_GROUND_DISTANCE_H_

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "indexer/lib/signature.h"
#include "indexer/lib/spectral.h"

namespace tpr::index {

// GroundDistanceOptions: the weights W1..W4 of Eq. 7 and the fixed scales of
// its L2norm terms. Every signature of one index must be prepared with the
// same options, or distances between them mean nothing.
struct GroundDistanceOptions {
  // W1..W4 of Eq. 7: relative importance of G'_norm, K, A and H. Must be
  // >= 0, finite, and sum to 1 within 1e-6 (section 6.1). The paper gives no
  // values. Defaults (0.2, 0.1, 0.2, 0.5) were chosen by cross-validation
  // on SHREC'07's 11 articulated classes (`tpr-eval-local --tune`, see
  // docs/results.md): every W on the simplex grid of step 0.1 was scored
  // by mean(NN, FT, ST, DCG) on each half of every class (alternate
  // models); this W is best summed over both halves, and each half's own
  // best W, (0.2, 0.1, 0.2, 0.5) and (0.3, 0.1, 0.2, 0.4), scored NN
  // .918/.973, FT .722/.716, ST .813/.832, DCG .892/.899 on the other
  // half (equal weights: NN .891/.936, FT .682/.675). Never tuned per
  // query or per class.
  double w1 = 0.2;
  double w2 = 0.1;
  double w3 = 0.2;
  double w4 = 0.5;
  // c_K: L2norm(K1, K2) = c_K ||K1 - K2||_2. K holds per band the
  // (segment-area-weighted) integrated Gaussian curvature in radians, whose
  // sum over the bands is at most about the total curvature 4 pi of a
  // genus-0 surface; the scale brings it to order 1. Must be > 0 and
  // finite. Default 1/(4 pi).
  double k_scale = 0.07957747154594767;
  // c_A: A holds band area / total area (entries >= 0, summing to at most
  // 1), so ||A1 - A2||_2 <= sqrt(2); the scale maps that range onto [0, 1].
  // Must be > 0 and finite. Default 1/sqrt(2).
  double a_scale = 0.7071067811865476;
  // c_H: H holds segment thickness / sqrt(total area), already of order 1
  // or less. Must be > 0 and finite. Default 1.
  double h_scale = 1.0;
  // The spectral term S and the heat-trace term H that metric.h adds to the
  // EMD (neither is part of Eq. 7; a weighting whose factors of S and H are
  // 0 is the paper's distance). Prepare stores both embeddings.
  SpectralOptions spectral;
  HeatTraceOptions heat;
};

// ValidateOptions returns OK when `options` meets the constraints above
// (spectral and heat-trace ones included, ValidateSpectralOptions and
// ValidateHeatTraceOptions), INVALID_ARGUMENT naming
// the offending field otherwise. O(1); thread-safe.
absl::Status ValidateOptions(const GroundDistanceOptions& options);

// ValidateSignature returns OK when `signature` can be matched:
// INVALID_ARGUMENT if it has no feature, more than kMaxFeatures features, a
// weight that is negative or not finite, weights not summing to 1 within
// 1e-6 (Eq. 6), band vectors K, A, H of unequal lengths (within a feature
// or across the signature's features), any non-finite coordinate, or a
// spectrum longer than kMaxSpectrum or holding a value that is not finite
// and > 0. The message names the feature index (or spectrum entry) at
// fault. O(total size); thread-safe.
absl::Status ValidateSignature(const Signature& signature);

// kMaxFeatures: the largest signature the EMD solver accepts (the paper
// averages 30 features per model; 200 leaves room for detailed meshes).
inline constexpr int kMaxFeatures = 200;

// PreparedSignature: what the index stores for one signature. An immutable,
// flat structure-of-arrays copy holding the scaled coordinates phi(U) of
// every feature (dimension-major), the masses normalized to sum to 1 and
// the spectral and heat-trace embeddings. Copyable and movable; built only by
// Prepare. Thread-safe to read from any number of threads.
//
// Compact storage (at most 4 KB per model). One block per model
// holds the masses in double, then the spectral embedding, the heat-trace
// embedding and the coordinates in float32, unpadded: the coordinates (1 + 3
// bands values per feature) are the bulk of a signature. The index keeps its
// tree's blocks side by side in one SignatureArena (signature_arena.h). The
// centroid sum_i w_i phi(U_i) of the centroid bound is not stored: Centroid
// (emd.h) computes it in O(size x bands) when a query starts, and the index
// keeps its items' centroids once, in its CentroidTable.
//
// Every distance is computed in double from the float32 values, so the
// index's distance is exactly the distance of metric.h between the rounded
// points phi32(U) = fl32(phi(U)) and rounded embeddings fl32(E): still a
// metric (the ground distance is N(phi32(U1) - phi32(U2)), a norm of a
// difference, and the spectral term a Euclidean distance), and its EMD
// differs from the EMD on double coordinates by at most
//   2^-24 (max_i N(phi(a_i)) + max_j N(phi(b_j)))
// (each coordinate moves by at most 2^-24 of itself, so each ground
// distance by at most the norms of the two moves, and an EMD is a convex
// combination of ground distances), its spectral term by at most
// 2^-24 (||E(a)|| + ||E(b)||) and its heat-trace term likewise:
// EmdTest.Float32StorageErrorWithinBound and
// MetricTest.DistanceIsEmdPlusSpectralAndWeightZeroIsThePaper check the
// bounds, ExtractedSignaturesTest that rankings on real signatures do not
// change.
//
// Owning or view. Prepare returns an object that owns its block; CopyInto
// returns a view whose block lives in storage the caller owns (one
// contiguous arena for a whole index, signature_arena.h), which must
// outlive the view. A copy of either owns a copy of the block; a move
// carries the block and its ownership along.
class PreparedSignature {
 public:
  PreparedSignature() = default;
  ~PreparedSignature();
  PreparedSignature(const PreparedSignature& other);
  PreparedSignature& operator=(const PreparedSignature& other);
  PreparedSignature(PreparedSignature&& other) noexcept;
  PreparedSignature& operator=(PreparedSignature&& other) noexcept;

  // CopyInto copies this signature's block (MemoryBytes() bytes) to
  // `storage` and returns a view of it: equal to *this in every value and
  // serial(), owning nothing. Preconditions: storage is aligned to
  // alignof(double), holds at least MemoryBytes() bytes, and outlives the
  // view (and every view moved from it); *this is not default-constructed.
  // Cost O(MemoryBytes()); thread-safe for distinct storage.
  PreparedSignature CopyInto(std::byte* storage) const;
  // owns_block returns whether this object frees its block (false for a
  // view from CopyInto and for a default-constructed object).
  bool owns_block() const { return owns_block_; }

  // size returns the number of features (0 only for a default-constructed
  // object, which no function below accepts).
  int size() const { return size_; }
  // bands returns the length of the K, A and H vectors.
  int bands() const { return bands_; }
  // weight returns the normalized mass of feature i, 0 <= i < size().
  double weight(int i) const { return weights()[i]; }
  // weights returns all masses (size() values summing to 1).
  const double* weights() const {
    return reinterpret_cast<const double*>(block_);
  }
  // MemoryBytes returns the bytes of this object's block (heap bytes it
  // holds when it owns them; arena bytes it refers to when a view).
  size_t MemoryBytes() const { return BlockBytes(); }
  // spectral returns the spectral embedding E(spectrum) (spectral.h),
  // rounded to float32, of spectral_size() values
  // (options.spectral.eigenvalues). metric.h compares it.
  const float* spectral() const {
    return reinterpret_cast<const float*>(block_ +
                                          sizeof(double) * Size(size_));
  }
  int spectral_size() const { return spectral_size_; }
  // heat returns the heat-trace embedding F(spectrum) (spectral.h,
  // HeatTraceEmbedding), rounded to float32, of heat_size() values
  // (options.heat.scales; 0 when the term is absent). metric.h compares it.
  const float* heat() const { return spectral() + spectral_size_; }
  int heat_size() const { return heat_size_; }

  // Layout (for emd.cc and the lower bound; not a stable interface):
  // coords() holds 1 + 3 bands() rows of size() float32 values each
  // (dimension-major, no padding): row 0 holds W1 G'; rows 1 .. bands()
  // hold W2 c_K K; the next bands() rows W3 c_A A; the next bands() rows
  // W4 c_H H. Row r, feature i is coords()[r * size() + i].
  const float* coords() const { return heat() + heat_size_; }
  // stride returns the row length of this signature's ground-distance
  // matrix as the column side (GroundDistanceMatrix's out_stride): size()
  // rounded up to a multiple of 8, so that matrix rows are whole SIMD
  // registers.
  int stride() const { return (size_ + 7) / 8 * 8; }
  // serial returns a process-unique number of the Prepare call that made
  // this object (copies share it, as they share the content): a cache key
  // for work derived from the content (EmdSolver reuses a ground-distance
  // matrix across a bound and the EMD of the same pair).
  uint64_t serial() const { return serial_; }
  // rows returns the number of coordinate rows, 1 + 3 bands(): the length
  // of the centroid (emd.h, Centroid).
  int rows() const { return 1 + 3 * bands_; }

 private:
  friend absl::StatusOr<PreparedSignature> Prepare(
      const Signature& signature, const GroundDistanceOptions& options);
  static size_t Size(int n) { return static_cast<size_t>(n); }
  size_t BlockBytes() const {
    return sizeof(double) * Size(size_) +
           sizeof(float) * (Size(spectral_size_) + Size(heat_size_) +
                            Size(rows()) * Size(size_));
  }

  // Frees block_ when owned; leaves *this default-constructed.
  void Release() noexcept;

  int size_ = 0;
  int bands_ = 0;
  // At most kMaxSpectrum and 256 (ValidateOptions): 16 bits each keep the
  // object at 32 bytes.
  uint16_t spectral_size_ = 0;
  uint16_t heat_size_ = 0;
  // Whether block_ came from new[] here (in the padding before serial_).
  bool owns_block_ = false;
  uint64_t serial_ = 0;
  // BlockBytes() bytes: weights (size_ doubles), then the spectral
  // embedding (spectral_size_ floats), the heat-trace embedding (heat_size_
  // floats), then the coordinates (rows() x size_ floats). operator new[] (or
  // CopyInto's caller) aligns it for double; size_ doubles keep the floats
  // aligned.
  std::byte* block_ = nullptr;
};

// Prepare validates `signature` and `options` (see ValidateSignature and
// ValidateOptions; INVALID_ARGUMENT otherwise) and returns its prepared
// form. Weights are divided by their sum so that they sum to 1 to rounding.
// Cost O(features x bands); thread-safe.
absl::StatusOr<PreparedSignature> Prepare(const Signature& signature,
                                          const GroundDistanceOptions& options);

// GroundDistance returns Dist(U_i of a, U_j of b) of Eq. 7 under the options
// both were prepared with. Preconditions (asserted in debug builds):
// 0 <= i < a.size(), 0 <= j < b.size(). Cost O(bands); thread-safe.
double GroundDistance(const PreparedSignature& a, int i,
                      const PreparedSignature& b, int j);

// GroundDistanceMatrix writes the a.size() x b.size() matrix of ground
// distances into `out`, row i at out[i * out_stride], with
// out_stride >= b.stride(); entries past b.size() in a row (up to
// b.stride()) are written with finite values (the distance to the
// origin). The EMD's kernel, in the variant chosen once per process
// (internal/simd.h: AVX-512F, AVX2 + FMA or scalar; TPR_SIMD forces a
// lower one): the two wide ones write the same values bit for bit, the
// scalar one GroundDistance's; entries equal GroundDistance to rounding
// (about 1e-15 relative) and the matrix of (b, a) is exactly the
// transpose of that of (a, b). Returns an upper bound of the entries (the
// largest value written, padding included), for scaling tolerances. Cost
// O(a.size() x b.size() x bands); thread-safe.
double GroundDistanceMatrix(const PreparedSignature& a,
                            const PreparedSignature& b, double* out,
                            int out_stride);

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_GROUND_DISTANCE_H_
