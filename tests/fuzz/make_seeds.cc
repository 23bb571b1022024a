// make_seeds writes the generated part of the fuzz seed corpus:
//   <out>/signature_convert/  serialized tpr.v1.Signature messages
//   <out>/vp_tree_load/       VpTree::Serialize() bytes (both framings)
//   <out>/index_load/         SignatureIndex::SerializeTree() bytes over
//                             fuzz_items.h's models (both framings)
// The mesh seeds are copies of tests/data/meshes. Run once after a format
// change and commit the output:
//   build-fuzz/tests/fuzz/make_seeds tests/fuzz/corpus
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "indexer/lib/signature_index.h"
#include "indexer/lib/vp_tree.h"
#include "tests/fuzz/fuzz_items.h"
#include "tests/fuzz/loader_input.h"
#include "tests/service/indexer_testing.h"

namespace {

void Write(const std::filesystem::path& path, const std::string& bytes) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) {
    std::fprintf(stderr, "cannot write %s\n", path.c_str());
    std::exit(1);
  }
}

// WriteLoaderSeeds writes `bytes` in both framings of loader_input.h.
void WriteLoaderSeeds(const std::filesystem::path& dir, const std::string& name,
                      const std::string& bytes) {
  Write(dir / (name + "_patched"), tpr::fuzz::EncodeLoaderInput(bytes, false));
  Write(dir / (name + "_intact"), tpr::fuzz::EncodeLoaderInput(bytes, true));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_seeds CORPUS_DIR\n");
    return 2;
  }
  const std::filesystem::path out = argv[1];
  const auto items = tpr::fuzz::FuzzItems();

  for (size_t i = 0; i < 4; ++i) {
    std::string bytes;
    tpr::indexer::testing::ToWire(items[i].second).SerializeToString(&bytes);
    Write(out / "signature_convert" / ("generated_" + std::to_string(i)),
          bytes);
  }

  for (size_t n : {1, 5, 40}) {
    tpr::index::VpTreeOptions options;
    options.leaf_size = 4;
    auto tree = tpr::index::VpTree::Build(
        n,
        [](uint32_t a, uint32_t b) {
          return a > b ? double(a - b) : double(b - a);
        },
        options);
    if (!tree.ok()) return 1;
    WriteLoaderSeeds(out / "vp_tree_load", "line_" + std::to_string(n),
                     tree->Serialize());
  }

  for (size_t n : {items.size(), size_t{30}}) {
    tpr::index::SignatureIndex index(tpr::fuzz::FuzzIndexOptions());
    const std::vector<std::pair<std::string, tpr::index::Signature>> some(
        items.begin(), items.begin() + static_cast<std::ptrdiff_t>(n));
    if (!index.UpsertBatch(some).ok()) return 1;
    index.Rebuild();
    WriteLoaderSeeds(out / "index_load", "items_" + std::to_string(n),
                     index.SerializeTree());
  }
  return 0;
}
