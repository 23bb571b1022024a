// The SIMD variants of the search's kernels and the one run-time choice
// among them (library-internal; not part of the public API).
//
//   if (SimdLevelSupported(SimdLevel::kAvx2)) ...   // this CPU can run it
//   const EmdKernels& k = EmdKernelsFor(ChosenSimdLevel());
//
// Every kernel (the EMD's pricing and start, emd_kernels.h; the ground-
// distance matrices, ground_distance_kernels.h) has a scalar version, an
// AVX2 + FMA twin and an AVX-512F twin, each in its own source file
// compiled with that instruction set's flags (indexer/CMakeLists.txt).
// ChosenSimdLevel picks the highest level the CPU supports once per
// process; the environment variable TPR_SIMD=avx512|avx2|scalar caps it
// (a lower level only: a level the CPU lacks is never run), so one
// AVX-512 machine can test and time the AVX2 and scalar paths.
//
// Why hand-written intrinsics rather than Google Highway (Debian
// libhwy-dev 1.0.3): the AVX-512 kernels were already tuned in intrinsics
// (mask blends, masked tail loads, compare-to-bit-set scans) and stay
// unchanged instruction for instruction, so the AVX-512 path cannot get
// slower; the AVX2 twins are about 400 lines in all; and the values must
// equal the scalar oracle's bit for bit, which needs every lane's
// operation order pinned down (Highway would give one source for all
// targets, but a second dependency, a per-target recompile of every kernel
// and a rewrite of the tuned AVX-512 code to re-validate).
#ifndef TPR_INDEXER_LIB_INTERNAL_SIMD_H_
#define TPR_INDEXER_LIB_INTERNAL_SIMD_H_

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace tpr::index::internal {

// SimdLevel: a kernel variant, in increasing order of width.
enum class SimdLevel {
  kScalar = 0,  // portable C++ (SSE2 code from the compiler on x86-64)
  kAvx2 = 1,    // AVX2 + FMA (+ POPCNT), 4 doubles / 8 floats per register
  kAvx512 = 2,  // AVX-512F, 8 doubles / 16 floats per register
};

// kSimdLevels: every level, lowest first, for loops over the variants.
inline constexpr SimdLevel kSimdLevels[] = {
    SimdLevel::kScalar, SimdLevel::kAvx2, SimdLevel::kAvx512};

// SimdLevelName returns "scalar", "avx2" or "avx512" (the TPR_SIMD
// spelling). O(1); thread-safe.
const char* SimdLevelName(SimdLevel level);

// ParseSimdLevel returns the level spelled `name` as SimdLevelName spells
// it, INVALID_ARGUMENT naming the value and the accepted ones otherwise.
// O(1); thread-safe.
absl::StatusOr<SimdLevel> ParseSimdLevel(absl::string_view name);

// SimdLevelSupported returns whether this build and CPU (and OS, which
// must save the wider registers) can run `level`: kScalar always; kAvx2
// needs AVX2, FMA and POPCNT, kAvx512 AVX-512F and POPCNT, in an x86-64
// GCC or Clang build (TPR_HAVE_X86_KERNELS, indexer/CMakeLists.txt). Cost: a
// CPU-feature query; thread-safe.
bool SimdLevelSupported(SimdLevel level);

// HighestSimdLevel returns the highest level SimdLevelSupported accepts.
// Thread-safe.
SimdLevel HighestSimdLevel();

// CappedSimdLevel returns the level a process runs given the value of
// TPR_SIMD (`env`, nullptr or empty when unset) and the highest supported
// level: the lower of the two. INVALID_ARGUMENT (ParseSimdLevel's) for an
// unknown value. O(1); thread-safe.
absl::StatusOr<SimdLevel> CappedSimdLevel(const char* env, SimdLevel highest);

// ChosenSimdLevel returns the level every kernel of this process runs,
// decided on the first call: CappedSimdLevel(getenv("TPR_SIMD"),
// HighestSimdLevel()); an unknown TPR_SIMD value is reported once on
// stderr and ignored (the highest level runs). Thread-safe.
SimdLevel ChosenSimdLevel();

}  // namespace tpr::index::internal

#endif  // TPR_INDEXER_LIB_INTERNAL_SIMD_H_
