// The ground-distance matrix kernels (library-internal): the double
// matrix of GroundDistanceMatrix and the float32 matrix of the search's
// level-2 bound, in scalar, AVX2 + FMA and AVX-512F variants (simd.h),
// and the entry points that tests and emd.cc use to run one of them.
//
// Files: ground_distance.cc (the scalar kernel, the dispatch),
// ground_distance_kernels_avx2.cc (-mavx2 -mfma),
// ground_distance_kernels_avx512.cc (-mavx512f); the wide files follow
// the rule of emd_kernels.h (anonymous namespace, no inline functions
// from other headers).
#ifndef TPR_INDEXER_LIB_INTERNAL_GROUND_DISTANCE_KERNELS_H_
#define TPR_INDEXER_LIB_INTERNAL_GROUND_DISTANCE_KERNELS_H_

#include "indexer/lib/internal/simd.h"

namespace tpr::index {

class PreparedSignature;

namespace internal {

// GroundDistanceMatrixAt runs the double-matrix kernel of `level`,
// whatever the run-time choice, for tests and benchmarks. Returns false,
// writing nothing, when !SimdLevelSupported(level), or for a wide level
// when the band counts differ. Same contract as GroundDistanceMatrix
// (ground_distance.h) otherwise; every level writes the same values bit
// for bit (the wide ones: within about 1e-15 relative of GroundDistance,
// which sums the bands without fused multiply-adds).
bool GroundDistanceMatrixAt(SimdLevel level, const PreparedSignature& a,
                            const PreparedSignature& b, double* out,
                            int out_stride);

// Stride32 returns the row length of GroundDistanceMatrix32's output for
// b as the column side: b.size() rounded up to a multiple of 16 (whole
// 16-lane registers).
int Stride32(const PreparedSignature& b);

// Float32MatrixError returns theta(bands) = (bands + 12) 2^-24, the
// relative error bound of GroundDistanceMatrix32's entries. Why it holds,
// with u = 2^-24 (float32 rounding) and c = |g - g'| + sqrt(S_K) +
// sqrt(S_A) + sqrt(S_H) the entry in exact arithmetic on the stored
// float32 coordinates, S_X the sum of B = bands squared differences: each
// difference is rounded once (t = (x - y)(1 + d), |d| <= u) and each fused
// multiply-add once, so the computed S~ = sum_k t_k^2 prod (1 + d_j) lies
// within (1 + u)^(B + 2) - 1 <= (B + 2) u (1 + 1e-5) of S relatively (all
// terms >= 0); the correctly rounded sqrt halves that and adds u; |g - g'|
// is rounded once; the three additions of non-negative terms add u each.
// So |c~ - c| <= ((B + 2) / 2 + 5) u (1 + 1e-5) c <= theta c. O(1).
inline double Float32MatrixError(int bands) { return (bands + 12) * 0x1p-24; }

// GroundDistanceMatrix32 writes the a.size() x b.size() ground distances,
// computed in float32 arithmetic, into `out`: row i at out[i * out_stride],
// out_stride a multiple of 16 and >= Stride32(b); entries past b.size() in
// a row (up to Stride32(b)) are written with finite values. Each entry c~
// of the exact entry c (Eq. 7 in exact arithmetic on the stored float32
// coordinates; GroundDistance computes it in double, within about 1e-15)
// satisfies |c~ - c| <= Float32MatrixError(a.bands()) c. It runs the
// chosen level's kernel (ChosenSimdLevel): AVX-512F with 16 features of b
// per register, AVX2 with 8 (the same values bit for bit), both reading
// the stored float32 values with no widening, about half the arithmetic
// of GroundDistanceMatrix. Returns false, writing nothing, at the scalar
// level (no float32 kernel: callers use GroundDistanceMatrix, whose
// scalar kernel is as fast) or when the band counts differ. Cost
// O(a.size() x b.size() x bands); thread-safe.
bool GroundDistanceMatrix32(const PreparedSignature& a,
                            const PreparedSignature& b, float* out,
                            int out_stride);

// GroundDistanceMatrix32At runs the float32 kernel of `level` whatever
// the run-time choice, for tests: false, writing nothing, where
// GroundDistanceMatrix32 would return false at that level or when
// !SimdLevelSupported(level).
bool GroundDistanceMatrix32At(SimdLevel level, const PreparedSignature& a,
                              const PreparedSignature& b, float* out,
                              int out_stride);

// KernelCoords: what a wide kernel reads of a signature (its layout is
// PreparedSignature::coords()'s: 1 + 3 bands rows of `size` floats).
struct KernelCoords {
  const float* coords;
  int size;
  int bands;
};

// MatrixFn: a double-matrix kernel for equal band counts. `wide` is
// scratch for b's coordinates widened to double (b.rows x b.stride
// doubles). Returns the largest entry written, padding included.
using MatrixFn = double (*)(const KernelCoords& a, const KernelCoords& b,
                            double* wide, double* out, int out_stride);

// Matrix32Fn: a float32-matrix kernel for equal band counts; writes every
// entry up to `stride32` (Stride32(b)) in each row.
using Matrix32Fn = void (*)(const KernelCoords& a, const KernelCoords& b,
                            int stride32, float* out, int out_stride);

// MatrixKernels: one wide level's matrix kernels.
struct MatrixKernels {
  MatrixFn matrix;
  Matrix32Fn matrix32;
};

// The wide files' tables, for ground_distance.cc's dispatch only (calling
// one runs code of that instruction set: only after SimdLevelSupported).
const MatrixKernels* MatrixKernelsAvx2Table();
const MatrixKernels* MatrixKernelsAvx512Table();

}  // namespace internal
}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_INTERNAL_GROUND_DISTANCE_KERNELS_H_
