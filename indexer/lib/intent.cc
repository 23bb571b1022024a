#include "indexer/lib/intent.h"

#include <cmath>

#include "absl/strings/str_cat.h"

namespace tpr::index {

// The weights were chosen by cross-validation over every dev set together
// (tpr-tune-intents, run by scripts/eval-intents; the folds, held-out
// figures and the choice are in docs/results.md, "Intents"), with the
// embeddings spectral.h's defaults give: S = ShapeDNA of 50 eigenvalues
// (by_index), H = the heat trace over t in [0.2, 20]. IDENTITY is the
// spectrum alone: every weighting with the EMD lost on the scape-identity
// sets (the TPR features vary between poses of one body there). KIND adds a
// little spectrum to the EMD, which lifts SHREC'07's FT over the EMD alone.
// BALANCED weighs the identity and the kind sets equally.
TermWeights IntentWeights(Intent intent) {
  switch (intent) {
    case Intent::kBalanced:
      return {1.0, 11.0, 0.12};
    case Intent::kIdentity:
      return {0.0, 1.1, 0.0};
    case Intent::kKind:
      return {1.0, 0.53, 0.0};
  }
  return {1.0, 11.0, 0.12};
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
