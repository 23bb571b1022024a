// Little-endian byte encoding for the index's persisted forms (VpTree and
// SignatureIndex bytes): fixed-width writers, a bounds-checked reader and
// the FNV-1a checksum. Bytes are the same on every platform.
//
//   std::string out;  PutU(&out, version, 2);  PutF(&out, radius);
//   ByteReader r(bytes);  uint64_t v;  if (!r.U(2, &v)) return Corrupt(...);
#ifndef TPR_INDEXER_LIB_BYTE_CODEC_H_
#define TPR_INDEXER_LIB_BYTE_CODEC_H_

#include <cstdint>
#include <cstring>
#include <string>

#include "absl/strings/string_view.h"

namespace tpr::index {

// Fnv1a hashes n bytes, continuing from `h` (the FNV offset basis by
// default). Not cryptographic: it detects corruption, not tampering.
inline uint64_t Fnv1a(const void* data, size_t n,
                      uint64_t h = 0xcbf29ce484222325ull) {
  const unsigned char* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

// PutU appends the low `bytes` bytes of v, least significant first.
inline void PutU(std::string* out, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) {
    out->push_back(static_cast<char>(v >> (8 * i)));
  }
}

// PutF appends a double's IEEE-754 bits as 8 bytes.
inline void PutF(std::string* out, double v) {
  uint64_t bits;
  std::memcpy(&bits, &v, sizeof bits);
  PutU(out, bits, 8);
}

// ByteReader reads what PutU/PutF wrote; every read returns false instead of
// reading past the end, so corrupt input cannot overrun.
class ByteReader {
 public:
  explicit ByteReader(absl::string_view bytes) : bytes_(bytes) {}
  bool U(int bytes, uint64_t* v) {
    if (bytes_.size() - pos_ < static_cast<size_t>(bytes)) return false;
    *v = 0;
    for (int i = 0; i < bytes; ++i) {
      *v |= static_cast<uint64_t>(static_cast<unsigned char>(bytes_[pos_ + i]))
            << (8 * i);
    }
    pos_ += bytes;
    return true;
  }
  bool U32(uint32_t* v) {
    uint64_t w;
    if (!U(4, &w)) return false;
    *v = static_cast<uint32_t>(w);
    return true;
  }
  bool F(double* v) {
    uint64_t bits;
    if (!U(8, &bits)) return false;
    std::memcpy(v, &bits, sizeof bits);
    return true;
  }
  bool Bytes(uint64_t n, absl::string_view* out) {
    if (bytes_.size() - pos_ < n) return false;
    *out = bytes_.substr(pos_, n);
    pos_ += n;
    return true;
  }
  size_t remaining() const { return bytes_.size() - pos_; }

 private:
  absl::string_view bytes_;
  size_t pos_ = 0;
};

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_BYTE_CODEC_H_
