// Little-endian byte encoding for the index's persisted forms (VpTree and
// SignatureIndex bytes): fixed-width writers, a bounds-checked reader, the
// FNV-1a checksum and the frame both forms share (magic, 2-byte format
// version, payload, checksum of all before it). Bytes are the same on every
// platform.
//
//   std::string out = BeginFrame(kFrame);  PutF(&out, radius);
//   EndFrame(&out);
//   absl::StatusOr<absl::string_view> payload = OpenFrame(bytes, kFrame);
//   ByteReader r(*payload);  uint64_t v;  if (!r.U(2, &v)) return ...;
#ifndef TPR_INDEXER_LIB_BYTE_CODEC_H_
#define TPR_INDEXER_LIB_BYTE_CODEC_H_

#include <cstdint>
#include <cstring>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
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

// Frame names a persisted form: its magic bytes, the one format version
// this build reads and writes, and the words its errors use.
struct Frame {
  absl::string_view magic;    // first bytes, e.g. "TPRVPT"
  uint16_t version;           // the format version this build reads
  absl::string_view kind;     // "VP-tree": "not VP-tree bytes (bad magic)"
  absl::string_view corrupt;  // "corrupt VP-tree bytes: truncated"
};

// CorruptFrame is DATA_LOSS "<frame.corrupt>: <what>", for a frame that
// opened but whose payload does not decode.
inline absl::Status CorruptFrame(const Frame& frame, absl::string_view what) {
  return absl::DataLossError(absl::StrCat(frame.corrupt, ": ", what));
}

// BeginFrame returns the magic and version that start a frame.
inline std::string BeginFrame(const Frame& frame) {
  std::string out(frame.magic);
  PutU(&out, frame.version, 2);
  return out;
}

// EndFrame appends the checksum of everything in *out.
inline void EndFrame(std::string* out) {
  PutU(out, Fnv1a(out->data(), out->size()), 8);
}

// OpenFrame checks magic, version and checksum, and returns the payload
// between the version and the checksum (a view into `bytes`).
// Errors: INVALID_ARGUMENT when the magic differs (not this form at all) or
// the version is not frame.version (bytes of another build); DATA_LOSS
// ("truncated", "checksum mismatch") otherwise. Cost: one pass over bytes.
inline absl::StatusOr<absl::string_view> OpenFrame(absl::string_view bytes,
                                                   const Frame& frame) {
  const size_t head = frame.magic.size() + 2;
  if (bytes.size() < head ||
      bytes.substr(0, frame.magic.size()) != frame.magic) {
    return absl::InvalidArgumentError(
        absl::StrCat("not ", frame.kind, " bytes (bad magic)"));
  }
  uint64_t version = 0;
  ByteReader(bytes.substr(frame.magic.size())).U(2, &version);
  if (version != frame.version) {
    return absl::InvalidArgumentError(
        absl::StrCat(frame.kind, " bytes of version ", version,
                     "; this build reads ", frame.version));
  }
  if (bytes.size() < head + 8) return CorruptFrame(frame, "truncated");
  const size_t body = bytes.size() - 8;
  uint64_t checksum = 0;
  ByteReader(bytes.substr(body)).U(8, &checksum);
  if (checksum != Fnv1a(bytes.data(), body)) {
    return CorruptFrame(frame, "checksum mismatch");
  }
  return bytes.substr(head, body - head);
}

}  // namespace tpr::index

#endif  // TPR_INDEXER_LIB_BYTE_CODEC_H_
