// The run-time choice of kernel variant (simd.h). Compiled for the build's
// baseline: it runs before any variant is known to be safe.
#include "indexer/lib/internal/simd.h"

#include <cstdio>
#include <cstdlib>
#include <string>

#include "absl/strings/str_cat.h"

namespace tpr::index::internal {

const char* SimdLevelName(SimdLevel level) {
  switch (level) {
    case SimdLevel::kAvx2:
      return "avx2";
    case SimdLevel::kAvx512:
      return "avx512";
    case SimdLevel::kScalar:
      break;
  }
  return "scalar";
}

absl::StatusOr<SimdLevel> ParseSimdLevel(absl::string_view name) {
  for (SimdLevel level : kSimdLevels) {
    if (name == SimdLevelName(level)) return level;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("TPR_SIMD=\"", name,
                   "\" is not a kernel variant: use avx512, avx2 or scalar"));
}

bool SimdLevelSupported(SimdLevel level) {
  switch (level) {
    case SimdLevel::kScalar:
      return true;
#ifdef TPR_HAVE_X86_KERNELS
    case SimdLevel::kAvx2:
      __builtin_cpu_init();
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
             __builtin_cpu_supports("popcnt");
    case SimdLevel::kAvx512:
      __builtin_cpu_init();
      return __builtin_cpu_supports("avx512f") &&
             __builtin_cpu_supports("popcnt");
#endif
    default:
      return false;
  }
}

SimdLevel HighestSimdLevel() {
  SimdLevel highest = SimdLevel::kScalar;
  for (SimdLevel level : kSimdLevels) {
    if (SimdLevelSupported(level)) highest = level;
  }
  return highest;
}

absl::StatusOr<SimdLevel> CappedSimdLevel(const char* env, SimdLevel highest) {
  if (env == nullptr || *env == '\0') return highest;
  absl::StatusOr<SimdLevel> wanted = ParseSimdLevel(env);
  if (!wanted.ok()) return wanted.status();
  return static_cast<int>(*wanted) < static_cast<int>(highest) ? *wanted
                                                               : highest;
}

SimdLevel ChosenSimdLevel() {
  static const SimdLevel chosen = [] {
    const SimdLevel highest = HighestSimdLevel();
    absl::StatusOr<SimdLevel> level =
        CappedSimdLevel(std::getenv("TPR_SIMD"), highest);
    if (level.ok()) return *level;
    std::fprintf(stderr, "tpr: %s; running %s\n",
                 std::string(level.status().message()).c_str(),
                 SimdLevelName(highest));
    return highest;
  }();
  return chosen;
}

}  // namespace tpr::index::internal
