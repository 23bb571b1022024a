// libFuzzer target: SignatureIndex::Load (indexer/lib/signature_index.h) of
// arbitrary tree bytes (framed as loader_input.h describes) against a fixed
// set of 40 models (fuzz_items.h).
//
// Oracle: a refusal is INVALID_ARGUMENT, DATA_LOSS or FAILED_PRECONDITION
// with a message. An accepted index holds exactly the 40 models, and a
// 10-NN search returns distinct known ids in ascending distance; when the
// checksum came with the input (bytes as SerializeTree wrote them), the
// answer equals brute force (every EMD computed directly).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/signature_index.h"
#include "tests/fuzz/fuzz_check.h"
#include "tests/fuzz/fuzz_items.h"
#include "tests/fuzz/loader_input.h"

namespace {

using Items = std::vector<std::pair<std::string, tpr::index::Signature>>;

// BruteForce returns the k nearest items to `query` by (distance, id).
std::vector<tpr::index::Neighbor> BruteForce(const Items& items,
                                             const tpr::index::Signature& query,
                                             size_t k) {
  const tpr::index::GroundDistanceOptions ground =
      tpr::fuzz::FuzzIndexOptions().ground;
  const tpr::index::PreparedSignature q = *tpr::index::Prepare(query, ground);
  std::vector<tpr::index::Neighbor> all;
  for (const auto& [id, s] : items) {
    all.push_back({id, tpr::index::Emd(q, *tpr::index::Prepare(s, ground))});
  }
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) {
    return a.distance != b.distance ? a.distance < b.distance : a.id < b.id;
  });
  all.resize(std::min(k, all.size()));
  return all;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const Items items = tpr::fuzz::FuzzItems();
  static const std::vector<tpr::index::Neighbor> expected =
      BruteForce(items, items[7].second, 10);
  const tpr::fuzz::LoaderInput in = tpr::fuzz::DecodeLoaderInput(data, size);
  absl::StatusOr<std::unique_ptr<tpr::index::SignatureIndex>> index =
      tpr::index::SignatureIndex::Load(in.bytes, items,
                                       tpr::fuzz::FuzzIndexOptions());
  if (!index.ok()) {
    tpr::fuzz::CheckRefusal(
        index.status(),
        {absl::StatusCode::kInvalidArgument, absl::StatusCode::kDataLoss,
         absl::StatusCode::kFailedPrecondition});
    return 0;
  }
  FUZZ_CHECK((*index)->size() == items.size(),
             "the index holds exactly the given models");
  const std::vector<tpr::index::Neighbor> got =
      (*index)->Knn(items[7].second, 10);
  FUZZ_CHECK(got.size() == expected.size(), "10 results from 40 models");
  std::set<std::string> seen;
  for (size_t i = 0; i < got.size(); ++i) {
    FUZZ_CHECK(seen.insert(got[i].id).second, "results distinct");
    FUZZ_CHECK(
        std::any_of(items.begin(), items.end(),
                    [&](const auto& it) { return it.first == got[i].id; }),
        "results are known ids");
    FUZZ_CHECK(i == 0 || got[i - 1].distance <= got[i].distance,
               "results ascending");
    if (in.checksum_given) {
      FUZZ_CHECK(got[i].id == expected[i].id &&
                     std::abs(got[i].distance - expected[i].distance) <= 1e-9,
                 "intact bytes give the brute-force answer");
    }
  }
  return 0;
}
