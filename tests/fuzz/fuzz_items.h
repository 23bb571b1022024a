// The fixed model set the index-loader fuzz target loads tree bytes against,
// and make_seeds.cc builds its seed trees from: 40 generated signatures
// (tests/indexer/signature_testing.h, 3 classes, 6 features x 4 bands),
// ids "m00".."m39".
#ifndef TPR_TESTS_FUZZ_FUZZ_ITEMS_H_
#define TPR_TESTS_FUZZ_FUZZ_ITEMS_H_

#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "indexer/lib/signature.h"
#include "indexer/lib/signature_index.h"
#include "tests/indexer/signature_testing.h"

namespace tpr::fuzz {

inline std::vector<std::pair<std::string, tpr::index::Signature>> FuzzItems() {
  tpr::index::testing::SignatureGeneratorOptions options;
  options.seed = 11;
  options.classes = 3;
  options.features = 6;
  options.bands = 4;
  tpr::index::testing::SignatureGenerator gen(options);
  std::vector<std::pair<std::string, tpr::index::Signature>> items;
  for (int i = 0; i < 40; ++i) {
    char id[8];
    std::snprintf(id, sizeof id, "m%02d", i);
    items.emplace_back(id, gen.Member(i % options.classes));
  }
  return items;
}

// FuzzIndexOptions: small leaves so that 40 items make a tree with levels;
// no background thread (the fuzz target stays single-threaded).
inline tpr::index::IndexOptions FuzzIndexOptions() {
  tpr::index::IndexOptions options;
  options.tree.leaf_size = 4;
  options.background_rebuild = false;
  return options;
}

}  // namespace tpr::fuzz

#endif  // TPR_TESTS_FUZZ_FUZZ_ITEMS_H_
