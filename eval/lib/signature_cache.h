// A disk cache of extracted TPR signatures for tpr-eval-local, so that
// re-running the evaluation with other matching parameters (W1..W4 of Eq. 7,
// the L2norm scales) does not re-extract every mesh. One small text file per
// model, named by a hash of a key string the caller builds from everything
// the extraction depends on (mesh file, copy, seed, extraction options and a
// feature-code version).
//
//   CachedDescription d;
//   if (!LoadCached(dir, key, &d)) {
//     d = ...extract...;
//     StoreCached(dir, key, d);
//   }
//   index::Signature s = d.signature;
#ifndef TPR_EVAL_LIB_SIGNATURE_CACHE_H_
#define TPR_EVAL_LIB_SIGNATURE_CACHE_H_

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "indexer/lib/signature.h"

namespace tpr::eval {

// CachedDescription: what the evaluation keeps of one extraction.
struct CachedDescription {
  // The signature in the indexer's form; feature i is a point when
  // i < points, a ring otherwise.
  index::Signature signature;
  int points = 0;
  int rings = 0;
  // The mesh's vertex and face counts.
  int64_t vertices = 0;
  int64_t faces = 0;
  // D2 histogram of the same mesh (the baseline).
  std::vector<double> d2;
  // Extraction wall time and per-stage times in ms (as first measured).
  double extract_ms = 0.0;
  std::map<std::string, double> stage_ms;
};

// CacheFileName returns the file name (no directory) for `key`: a 64-bit
// FNV-1a hash in hex plus ".sig". Pure.
std::string CacheFileName(const std::string& key);

// LoadCached reads dir/CacheFileName(key) into *out and returns true when it
// exists, is well formed and records exactly `key` (hash collisions and
// truncated files read as a miss). Thread-safe for distinct keys.
bool LoadCached(const std::string& dir, const std::string& key,
                CachedDescription* out);

// StoreCached writes `d` under `key` (write to a temporary file, then
// rename, so that a concurrent or interrupted run never leaves a partial
// entry). Returns false when the file cannot be written. Thread-safe for
// distinct keys.
bool StoreCached(const std::string& dir, const std::string& key,
                 const CachedDescription& d);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_SIGNATURE_CACHE_H_
