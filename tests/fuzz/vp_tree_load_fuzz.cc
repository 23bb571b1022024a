// libFuzzer target: VpTree::Deserialize (indexer/lib/vp_tree.h) on arbitrary
// bytes, framed as loader_input.h describes.
//
// Oracle: a refusal is INVALID_ARGUMENT or DATA_LOSS with a message; a tree
// it accepts serializes back to the same bytes, and an 8-NN search over it
// returns min(8, size()) distinct items, each < size(), without crashing or
// reading out of bounds. Patched-up bytes may store distances that do not fit
// the metric, so order and exactness are checked only on intact bytes (the
// seeds), against brute force.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <set>
#include <vector>

#include "absl/status/status.h"
#include "indexer/lib/vp_tree.h"
#include "tests/fuzz/fuzz_check.h"
#include "tests/fuzz/loader_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const tpr::fuzz::LoaderInput in = tpr::fuzz::DecodeLoaderInput(data, size);
  absl::StatusOr<tpr::index::VpTree> tree =
      tpr::index::VpTree::Deserialize(in.bytes);
  if (!tree.ok()) {
    tpr::fuzz::CheckRefusal(tree.status(), {absl::StatusCode::kInvalidArgument,
                                            absl::StatusCode::kDataLoss});
    return 0;
  }
  FUZZ_CHECK(tree->Serialize() == in.bytes,
             "an accepted tree serializes back to its bytes");
  // The seeds are trees over items on a line, d(i, j) = |i - j|
  // (make_seeds.cc); the query is the point 2.5 on that line.
  const size_t n = tree->size();
  tpr::index::QuerySpec spec;
  auto line = [](uint32_t item) {
    return std::abs(static_cast<double>(item) - 2.5);
  };
  // A tree of several terms (forged bytes) reads the same line per term.
  spec.distance = [line](uint32_t item, double* d) {
    for (size_t t = 0; t < tpr::index::kMaxTerms; ++t) d[t] = line(item);
  };
  const size_t k = std::min<size_t>(n, 8);
  const std::vector<tpr::index::ItemNeighbor> hits = tree->Knn(spec, k);
  FUZZ_CHECK(hits.size() == k, "k results from a tree of >= k items");
  std::vector<double> expected;
  if (in.checksum_given) {
    for (size_t i = 0; i < n; ++i)
      expected.push_back(line(static_cast<uint32_t>(i)));
    std::sort(expected.begin(), expected.end());
  }
  std::set<uint32_t> seen;
  for (size_t i = 0; i < hits.size(); ++i) {
    FUZZ_CHECK(hits[i].item < n, "result item in range");
    FUZZ_CHECK(seen.insert(hits[i].item).second, "results distinct");
    if (in.checksum_given) {
      // Intact bytes of a line tree: the stored distances fit the metric,
      // so the answer is exact (brute force over items 0..n-1).
      FUZZ_CHECK(hits[i].distance == expected[i],
                 "intact bytes give the brute-force answer");
    }
  }
  return 0;
}
