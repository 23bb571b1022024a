// A dev set's leave-one-out material saved once by `tpr-eval-local
// --save-matrices` and combined offline by `tpr-tune-intents` (the intents'
// weightings are chosen by cross-validation over every dev set together,
// from the EMD and spectra computed ONCE): every model's name, class and
// Laplace-Beltrami spectrum, the paper's EMD matrix (w_s = 0) and the D2
// matrix.
//
//   SavedSet s = ...;  SaveSet("/tmp/shrec11.mat", s);
//   absl::StatusOr<SavedSet> t = LoadSet("/tmp/shrec11.mat");
//
// File format (text, one item per line, numbers in shortest round-trip
// form): "tpr-eval-matrices v1", the model count N, N lines
// "name<TAB>label", N lines "count v1 ... vcount" (spectra), then the EMD
// and the D2 matrix, each as N - 1 lines holding row i's entries j > i.
#ifndef TPR_EVAL_LIB_SAVED_SET_H_
#define TPR_EVAL_LIB_SAVED_SET_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "eval/lib/distance_matrix.h"

namespace tpr::eval {

// SavedSet: position i is one model in every member.
struct SavedSet {
  std::vector<std::string> names;   // no tab or newline
  std::vector<std::string> labels;  // no tab or newline
  std::vector<std::vector<double>> spectra;
  DistanceMatrix emd, d2;
};

// SaveSet writes `set` to `path`. Errors: INVALID_ARGUMENT when the members'
// sizes disagree or a name or label holds a tab or newline; the file errors
// of WriteTextFile (report.h). Cost O(N^2) text. Thread-compatible.
absl::Status SaveSet(const std::string& path, const SavedSet& set);

// LoadSet reads a file SaveSet wrote. Errors: NOT_FOUND for a missing file,
// INVALID_ARGUMENT naming the line for anything malformed (wrong magic,
// counts, non-numeric or non-finite values). Cost O(N^2). Thread-safe.
absl::StatusOr<SavedSet> LoadSet(const std::string& path);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_SAVED_SET_H_
