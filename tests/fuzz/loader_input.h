// Input framing shared by the byte-loader fuzz targets (VP-tree, index).
// Both formats end with an FNV-1a checksum of everything before it, so a
// mutated input almost never gets past the checksum. The first input byte
// therefore picks a mode:
//   even: the rest is the bytes WITHOUT their checksum; the target appends
//         the right one, so mutations reach the structural checks behind it;
//   odd:  the rest is passed as is (the checksum path itself).
// tests/fuzz/make_seeds.cc writes seeds in both modes.
#ifndef TPR_TESTS_FUZZ_LOADER_INPUT_H_
#define TPR_TESTS_FUZZ_LOADER_INPUT_H_

#include <cstddef>
#include <cstdint>
#include <string>

#include "indexer/lib/byte_codec.h"

namespace tpr::fuzz {

struct LoaderInput {
  std::string bytes;
  // True when the checksum came from the input (odd mode byte): the bytes
  // are then as a writer produced them, not patched up by the target.
  bool checksum_given = false;
};

inline LoaderInput DecodeLoaderInput(const uint8_t* data, size_t size) {
  LoaderInput in;
  if (size == 0) return in;
  in.checksum_given = (data[0] & 1) != 0;
  in.bytes.assign(reinterpret_cast<const char*>(data) + 1, size - 1);
  if (!in.checksum_given) {
    tpr::index::PutU(&in.bytes,
                     tpr::index::Fnv1a(in.bytes.data(), in.bytes.size()), 8);
  }
  return in;
}

// EncodeLoaderInput is the inverse for a writer's bytes (which end with
// their checksum): the seed in the given mode.
inline std::string EncodeLoaderInput(const std::string& bytes,
                                     bool checksum_given) {
  std::string out(1, checksum_given ? '\x01' : '\x00');
  out += checksum_given ? bytes : bytes.substr(0, bytes.size() - 8);
  return out;
}

}  // namespace tpr::fuzz

#endif  // TPR_TESTS_FUZZ_LOADER_INPUT_H_
