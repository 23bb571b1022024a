// libFuzzer target: VpTree::Deserialize (indexer/lib/vp_tree.h) on arbitrary
// bytes, framed as loader_input.h describes.
//
// Oracle: a refusal is INVALID_ARGUMENT or DATA_LOSS with a message; a tree
// it accepts serializes back to the same bytes, and a search over it (with
// a stand-in metric on item numbers; the stored distances need not fit it)
// returns at most k distinct items, each < size(), in ascending distance,
// without crashing or reading out of bounds.
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
  absl::StatusOr<tpr::index::VpTree> tree = tpr::index::VpTree::Deserialize(in.bytes);
  if (!tree.ok()) {
    const absl::StatusCode code = tree.status().code();
    FUZZ_CHECK(code == absl::StatusCode::kInvalidArgument ||
                   code == absl::StatusCode::kDataLoss,
               "a refusal is INVALID_ARGUMENT or DATA_LOSS");
    FUZZ_CHECK(!tree.status().message().empty(), "a refusal says why");
    return 0;
  }
  FUZZ_CHECK(tree->Serialize() == in.bytes, "an accepted tree serializes back to its bytes");
  const size_t n = tree->size();
  tpr::index::QuerySpec spec;
  spec.distance = [](uint32_t item) {
    return static_cast<double>((item * 2654435761u) % 1000u) / 10.0;
  };
  const size_t k = std::min<size_t>(n, 64);
  const std::vector<tpr::index::ItemNeighbor> hits = tree->Knn(spec, k);
  FUZZ_CHECK(hits.size() <= k, "at most k results");
  std::set<uint32_t> seen;
  for (size_t i = 0; i < hits.size(); ++i) {
    FUZZ_CHECK(hits[i].item < n, "result item in range");
    FUZZ_CHECK(seen.insert(hits[i].item).second, "results distinct");
    FUZZ_CHECK(i == 0 || hits[i - 1].distance <= hits[i].distance, "results ascending");
  }
  return 0;
}
