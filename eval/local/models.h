// The evaluation set of tpr-eval-local and how each model is described:
// the models of a manifest or of the generator (extractor/synth), the
// paper's invariance copies, and one extraction per model (or its cached
// description, eval/lib/signature_cache.h) turned into the prepared forms
// the distances compare.
//
//   absl::StatusOr<std::vector<Model>> models = ManifestModels(manifest);
//   std::vector<Described> d = DescribeAll(*models, config, /*threads=*/2);
#ifndef TPR_EVAL_LOCAL_MODELS_H_
#define TPR_EVAL_LOCAL_MODELS_H_

#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "eval/lib/d2.h"
#include "extractor/lib/extract.h"
#include "extractor/synth/synth.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/signature.h"

namespace tpr::eval::local {

// MillisecondsSince returns the wall time since `start`, in ms.
double MillisecondsSince(std::chrono::steady_clock::time_point start);

// A model of the evaluation set: where it came from and its class.
struct Model {
  std::string name;
  std::string label;
  std::string path;  // empty for synthetic models
  int synthetic_pose = -1;
  int identity_body = -1;  // identity mode (synth.h): label is the body
  int copy = 0;            // 0 original; 1..3 the paper's invariance copies
};

// What one model contributes to each descriptor.
struct Described {
  bool ok = false;
  std::string error;
  index::Signature raw;
  index::PreparedSignature tpr;
  int points = 0, rings = 0;
  int64_t vertices = 0, faces = 0;
  std::vector<double> d2;
  double extract_ms = 0.0;
  std::map<std::string, double> stage_ms;
};

// Config: every setting a description and a distance depend on.
struct Config {
  extract::Options extract;
  index::GroundDistanceOptions ground;
  // w_s: the spectral term's factor in the TPR column (the EMD's is 1).
  double spectral_weight = 1.0;
  D2Options d2;
  int synthetic_vertices = 5000;
  // Identity mode's surfaces (synth.h, IdentitySurface).
  synth::IdentitySurface identity_surface = synth::IdentitySurface::kSkinned;
  uint64_t seed = 1;
  std::string cache_dir;  // empty: no cache
};

// ManifestModels returns the models of a manifest (eval::ReadDataset: file
// order kept, since the copies' seeds derive from a model's position).
// Errors: those of ReadDataset.
absl::StatusOr<std::vector<Model>> ManifestModels(const std::string& manifest);

// SyntheticModels returns the generated models of `spec`, CLASSESxPOSES or
// identity:BODIESxPOSES. INVALID_ARGUMENT for another spec.
absl::StatusOr<std::vector<Model>> SyntheticModels(const std::string& spec);

// Describe extracts `model` (the index-th of the set: its copy's seed) or
// reads its cached description, and prepares its signature. Never fails:
// a failure is Described::error. Thread-safe.
Described Describe(const Model& model, const Config& config, size_t index);

// DescribeAll describes every model on `threads` threads, reporting
// progress on stderr.
std::vector<Described> DescribeAll(const std::vector<Model>& models,
                                   const Config& config, int threads);

}  // namespace tpr::eval::local

#endif  // TPR_EVAL_LOCAL_MODELS_H_
