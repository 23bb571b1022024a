#include "indexer/lib/intent.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace tpr::index {

TermWeights IntentWeights(Intent intent) {
  switch (intent) {
    case Intent::kBalanced:
      return {1.0, 1.0, 0.0};
    case Intent::kIdentity:
      return {0.25, 1.0, 0.0};
    case Intent::kKind:
      return {1.0, 0.1, 0.0};
  }
  return {1.0, 1.0, 0.0};
}

const char* IntentName(Intent intent) {
  switch (intent) {
    case Intent::kBalanced:
      return "balanced";
    case Intent::kIdentity:
      return "identity";
    case Intent::kKind:
      return "kind";
  }
  return "?";
}

absl::StatusOr<Intent> ParseIntent(absl::string_view name) {
  for (Intent i : {Intent::kBalanced, Intent::kIdentity, Intent::kKind}) {
    if (name == IntentName(i)) return i;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "intent '", name, "' is not one of balanced, identity, kind"));
}

absl::Status ValidateTermWeights(const TermWeights& w) {
  const struct {
    const char* name;
    double value;
  } terms[] = {{"emd", w.emd}, {"spectral", w.spectral}, {"heat", w.heat}};
  bool any = false;
  for (const auto& t : terms) {
    if (!std::isfinite(t.value) || t.value < 0.0) {
      return absl::InvalidArgumentError(
          absl::StrCat("weight of the ", t.name, " term is ", t.value,
                       "; it must be finite and >= 0"));
    }
    any = any || t.value > 0.0;
  }
  if (!any) {
    return absl::InvalidArgumentError("every term weight is 0");
  }
  return absl::OkStatus();
}

}  // namespace tpr::index
