// PLY reader (mesh_io_readers.h): ASCII and binary, either byte order.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "common/status_macros.h"
#include "extractor/lib/mesh_io_readers.h"
#include "extractor/lib/mesh_io_text.h"

namespace tpr::extract {
namespace {

using absl::string_view;
using mesh_io::Invalid;
using mesh_io::InvalidAt;
using mesh_io::Quote;

enum class PlyEncoding { kAscii, kLittle, kBig };

struct PlyProperty {
  std::string name;
  int size = 0;  // scalar or list entry size in bytes
  bool is_float = false;
  bool is_signed = false;
  bool is_list = false;
  int count_size = 0;  // list count size in bytes
  bool count_signed = false;
  int coordinate = -1;        // 0, 1, 2 for a vertex's x, y, z
  bool role_indices = false;  // face vertex_indices
};

struct PlyElement {
  std::string name;
  int64_t count = 0;
  int64_t line = 0;
  std::vector<PlyProperty> properties;
};

bool PlyType(string_view name, int* size, bool* is_float, bool* is_signed) {
  struct Entry {
    const char* name;
    int size;
    bool is_float, is_signed;
  };
  static constexpr Entry kTypes[] = {
      {"char", 1, false, true},    {"int8", 1, false, true},
      {"uchar", 1, false, false},  {"uint8", 1, false, false},
      {"short", 2, false, true},   {"int16", 2, false, true},
      {"ushort", 2, false, false}, {"uint16", 2, false, false},
      {"int", 4, false, true},     {"int32", 4, false, true},
      {"uint", 4, false, false},   {"uint32", 4, false, false},
      {"float", 4, true, true},    {"float32", 4, true, true},
      {"double", 8, true, true},   {"float64", 8, true, true}};
  for (const Entry& e : kTypes) {
    if (name == e.name) {
      *size = e.size;
      *is_float = e.is_float;
      *is_signed = e.is_signed;
      return true;
    }
  }
  return false;
}

// Reads one binary scalar as double.
double ReadPlyScalar(const char* p, int size, bool is_float, bool is_signed,
                     bool big_endian) {
  unsigned char b[8];
  std::memcpy(b, p, size);
  if (big_endian) std::reverse(b, b + size);
  if (is_float) {
    if (size == 4) {
      float f;
      std::memcpy(&f, b, 4);
      return f;
    }
    double d;
    std::memcpy(&d, b, 8);
    return d;
  }
  uint64_t u = 0;
  for (int i = size - 1; i >= 0; --i) u = (u << 8) | b[i];
  if (is_signed && size < 8 && (u >> (8 * size - 1)) != 0) {
    return static_cast<double>(static_cast<int64_t>(u) -
                               (static_cast<int64_t>(1) << (8 * size)));
  }
  return static_cast<double>(u);
}

constexpr string_view kFmt = "PLY";

// The body's values come from one of two sources with the same methods,
// so that one walk (WalkBody) serves both encodings. Each returns
// OUT_OF_RANGE at the end of the data (the walk reports "truncated"), or
// INVALID_ARGUMENT in its encoding's words (ASCII messages name the line).
//
// AsciiBody: whitespace tokens, any line breaks, numbered from the header.
class AsciiBody {
 public:
  AsciiBody(string_view body, int64_t header_lines)
      : reader_(body), first_line_(header_lines), line_(header_lines) {}

  absl::Status Scalar(const PlyProperty& p, string_view element, int64_t i,
                      double* value) {
    string_view token;
    TPR_RETURN_IF_ERROR(Next(&token));
    if (p.coordinate >= 0 && element == "vertex") {
      return mesh_io::ParseCoordinate(kFmt, line_, i, token, value);
    }
    int64_t n = 0;
    const bool ok = p.is_float ? mesh_io::ParseDouble(token, value)
                               : mesh_io::ParseInt(token, &n);
    if (!ok) {
      return InvalidAt(
          kFmt, line_,
          absl::StrCat(element, " ", i, ": property ", Quote(p.name),
                       ": expected ", p.is_float ? "a number" : "an integer",
                       ", got ", Quote(token)));
    }
    return absl::OkStatus();
  }
  absl::Status Count(const PlyProperty&, int64_t i, int64_t* n) {
    string_view token;
    TPR_RETURN_IF_ERROR(Next(&token));
    if (!mesh_io::ParseInt(token, n) || *n < 3) {
      return InvalidAt(kFmt, line_,
                       absl::StrCat("face ", i, " has vertex count ",
                                    Quote(token), "; at least 3 are needed"));
    }
    return absl::OkStatus();
  }
  // ASCII entries take at least two bytes; the count is checked as read.
  absl::Status Fits(int64_t) { return absl::OkStatus(); }
  absl::Status Index(const PlyProperty&, int64_t i, int64_t* index) {
    string_view token;
    TPR_RETURN_IF_ERROR(Next(&token));
    if (!mesh_io::ParseInt(token, index)) {
      return InvalidAt(
          kFmt, line_,
          absl::StrCat("face ", i, ": expected a vertex index, got ",
                       Quote(token)));
    }
    return absl::OkStatus();
  }
  absl::Status Error(string_view message) const {
    return InvalidAt(kFmt, line_, message);
  }

 private:
  absl::Status Next(string_view* token) {
    while (!cursor_.Next(token)) {
      string_view l;
      if (!reader_.Next(&l)) return absl::OutOfRangeError("eof");
      line_ = first_line_ + reader_.number();
      if (mesh_io::HasBinaryBytes(l)) {
        return InvalidAt(kFmt, line_, "binary data in an ASCII body");
      }
      cursor_ = mesh_io::TokenCursor(l);
    }
    return absl::OkStatus();
  }

  mesh_io::LineReader reader_;
  mesh_io::TokenCursor cursor_{""};
  const int64_t first_line_;
  int64_t line_;
};

// BinaryBody: packed scalars in the file's byte order.
class BinaryBody {
 public:
  BinaryBody(string_view body, bool big_endian)
      : body_(body), big_(big_endian) {}

  absl::Status Scalar(const PlyProperty& p, string_view element, int64_t i,
                      double* value) {
    if (body_.size() - pos_ < static_cast<size_t>(p.size)) {
      return absl::OutOfRangeError("eof");
    }
    *value = ReadPlyScalar(body_.data() + pos_, p.size, p.is_float, p.is_signed,
                           big_);
    pos_ += p.size;
    if (p.coordinate >= 0 && element == "vertex") {
      TPR_RETURN_IF_ERROR(mesh_io::CheckCoordinateValue(
          kFmt, absl::StrCat("vertex ", i), *value));
      // Float precision, as for every format (mesh_io_readers.h).
      *value = static_cast<float>(*value);
    }
    return absl::OkStatus();
  }
  absl::Status Count(const PlyProperty& p, int64_t i, int64_t* n) {
    if (body_.size() - pos_ < static_cast<size_t>(p.count_size)) {
      return absl::OutOfRangeError("eof");
    }
    const double count = ReadPlyScalar(body_.data() + pos_, p.count_size, false,
                                       p.count_signed, big_);
    pos_ += p.count_size;
    if (count < 3) {
      return Invalid(kFmt, absl::StrCat("face ", i, " has ", count,
                                        " vertices; at least 3 are needed"));
    }
    *n = static_cast<int64_t>(count);
    entry_size_ = p.size;
    return absl::OkStatus();
  }
  // Fits: the list's n entries are in the data (checked before the limit,
  // so a lying count is reported as truncation).
  absl::Status Fits(int64_t n) {
    if (static_cast<uint64_t>(n) > (body_.size() - pos_) / entry_size_) {
      return absl::OutOfRangeError("eof");
    }
    return absl::OkStatus();
  }
  absl::Status Index(const PlyProperty& p, int64_t, int64_t* index) {
    const double value =
        ReadPlyScalar(body_.data() + pos_, p.size, false, p.is_signed, big_);
    pos_ += p.size;
    *index = static_cast<int64_t>(value);
    return absl::OkStatus();
  }
  absl::Status Error(string_view message) const {
    return Invalid(kFmt, message);
  }

 private:
  string_view body_;
  bool big_;
  size_t pos_ = 0;
  int entry_size_ = 1;
};

// WalkBody reads the elements up to the faces from `source` into *soup
// (positions already sized to the vertex count).
template <typename Source>
absl::Status WalkBody(const std::vector<PlyElement>& elements,
                      int vertex_element, const IntakeOptions& options,
                      Source* source, PolygonSoup* soup) {
  const int64_t nv = static_cast<int64_t>(soup->positions.size());
  int64_t triangles = 0;
  for (size_t e = 0; e < elements.size(); ++e) {
    const PlyElement& element = elements[e];
    const bool is_vertex = static_cast<int>(e) == vertex_element;
    for (int64_t i = 0; i < element.count; ++i) {
      auto check = [&](absl::Status s) {
        if (!absl::IsOutOfRange(s)) return s;
        return Invalid(kFmt, absl::StrCat("truncated in ", element.name, " ", i,
                                          " of ", element.count));
      };
      for (const PlyProperty& p : element.properties) {
        if (!p.is_list) {
          double value = 0.0;
          TPR_RETURN_IF_ERROR(
              check(source->Scalar(p, element.name, i, &value)));
          if (is_vertex && p.coordinate >= 0) {
            soup->positions[i][p.coordinate] = value;
          }
          continue;
        }
        int64_t n = 0;
        TPR_RETURN_IF_ERROR(check(source->Count(p, i, &n)));
        TPR_RETURN_IF_ERROR(check(source->Fits(n)));
        if (triangles + n - 2 > options.max_faces) {
          return mesh_io::TooManyFaces(triangles + n - 2, options);
        }
        triangles += n - 2;
        for (int64_t k = 0; k < n; ++k) {
          int64_t index = 0;
          TPR_RETURN_IF_ERROR(check(source->Index(p, i, &index)));
          if (index < 0 || index >= nv) {
            return source->Error(absl::StrCat("face ", i, " references vertex ",
                                              index, "; the file has ", nv,
                                              " vertices"));
          }
          soup->corners.push_back(static_cast<int32_t>(index));
        }
        soup->offsets.push_back(static_cast<int64_t>(soup->corners.size()));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<PolygonSoup> ReadPly(string_view bytes,
                                    const IntakeOptions& options) {
  mesh_io::LineReader reader(bytes);
  string_view line;
  std::vector<string_view> tok;
  if (!reader.Next(&line) || absl::StripAsciiWhitespace(line) != "ply") {
    return Invalid(kFmt, "the file does not start with 'ply'");
  }
  PlyEncoding encoding = PlyEncoding::kAscii;
  bool have_format = false, have_end = false;
  std::vector<PlyElement> elements;
  while (reader.Next(&line)) {
    const int64_t at = reader.number();
    if (mesh_io::HasBinaryBytes(line)) {
      return InvalidAt(kFmt, at, "binary data in the header");
    }
    mesh_io::SplitTokens(line, &tok, 6);
    if (tok.empty() || tok[0] == "comment" || tok[0] == "obj_info") continue;
    if (tok[0] == "end_header") {
      have_end = true;
      break;
    }
    if (!have_format && tok[0] != "format") {
      return InvalidAt(kFmt, at, "expected the 'format' line first");
    }
    if (tok[0] == "format") {
      double version = 0;
      if (have_format || tok.size() != 3 ||
          !mesh_io::ParseDouble(tok[2], &version)) {
        return InvalidAt(kFmt, at, "expected 'format <encoding> 1.0'");
      }
      if (tok[1] == "ascii") {
        encoding = PlyEncoding::kAscii;
      } else if (tok[1] == "binary_little_endian") {
        encoding = PlyEncoding::kLittle;
      } else if (tok[1] == "binary_big_endian") {
        encoding = PlyEncoding::kBig;
      } else {
        return InvalidAt(kFmt, at,
                         absl::StrCat("unknown format ", Quote(tok[1])));
      }
      have_format = true;
    } else if (tok[0] == "element") {
      PlyElement element;
      if (tok.size() != 3 || !mesh_io::ParseInt(tok[2], &element.count) ||
          element.count < 0) {
        return InvalidAt(kFmt, at, "expected 'element <name> <count>'");
      }
      element.name = std::string(tok[1]);
      element.line = at;
      elements.push_back(std::move(element));
    } else if (tok[0] == "property") {
      if (elements.empty()) {
        return InvalidAt(kFmt, at, "'property' before any 'element'");
      }
      PlyElement& element = elements.back();
      PlyProperty p;
      if (tok.size() == 5 && tok[1] == "list") {
        p.is_list = true;
        p.name = std::string(tok[4]);
        bool count_float = false;
        if (!PlyType(tok[2], &p.count_size, &count_float, &p.count_signed) ||
            count_float) {
          return InvalidAt(kFmt, at,
                           absl::StrCat("list count type ", Quote(tok[2]),
                                        " is not an integer type"));
        }
        if (!PlyType(tok[3], &p.size, &p.is_float, &p.is_signed) ||
            p.is_float) {
          return InvalidAt(kFmt, at,
                           absl::StrCat("list entry type ", Quote(tok[3]),
                                        " is not an integer type"));
        }
        if (element.name != "face" ||
            (p.name != "vertex_indices" && p.name != "vertex_index")) {
          return InvalidAt(
              kFmt, at,
              absl::StrCat("list property ", Quote(p.name), " of element ",
                           Quote(element.name), " is not supported"));
        }
        p.role_indices = true;
      } else if (tok.size() == 3) {
        p.name = std::string(tok[2]);
        if (!PlyType(tok[1], &p.size, &p.is_float, &p.is_signed)) {
          return InvalidAt(
              kFmt, at, absl::StrCat("unknown property type ", Quote(tok[1])));
        }
        if (element.name == "vertex" && p.name.size() == 1 &&
            p.name[0] >= 'x' && p.name[0] <= 'z') {
          p.coordinate = p.name[0] - 'x';
        }
      } else {
        return InvalidAt(kFmt, at, "malformed 'property' line");
      }
      element.properties.push_back(std::move(p));
    } else {
      return InvalidAt(kFmt, at,
                       absl::StrCat("unknown header keyword ", Quote(tok[0])));
    }
  }
  if (!have_end) return Invalid(kFmt, "the header has no 'end_header' line");
  if (!have_format) return Invalid(kFmt, "the header has no 'format' line");

  int vertex_element = -1, face_element = -1;
  for (size_t e = 0; e < elements.size(); ++e) {
    if (elements[e].name == "vertex" && vertex_element < 0) vertex_element = e;
    if (elements[e].name == "face" && face_element < 0) face_element = e;
  }
  if (vertex_element < 0) return Invalid(kFmt, "no 'vertex' element");
  if (face_element < 0) return Invalid(kFmt, "no 'face' element");
  if (face_element < vertex_element) {
    return Invalid(kFmt, "a 'face' element before 'vertex' is not supported");
  }
  {
    int coords[3] = {0, 0, 0};
    for (const auto& p : elements[vertex_element].properties) {
      if (p.coordinate >= 0) ++coords[p.coordinate];
    }
    if (coords[0] != 1 || coords[1] != 1 || coords[2] != 1) {
      return Invalid(kFmt, "vertex needs x, y and z properties");
    }
    int lists = 0;
    for (const auto& p : elements[face_element].properties) {
      lists += p.role_indices;
    }
    if (lists != 1) {
      return Invalid(kFmt, "face needs a 'vertex_indices' list property");
    }
  }
  // Only elements up to the faces are read; what follows is ignored.
  elements.resize(face_element + 1);
  const int64_t nv = elements[vertex_element].count;
  const int64_t nf = elements[face_element].count;

  // Fail fast on counts the body cannot hold: the smallest record of each
  // element is its scalars plus empty lists (binary) or one byte per value
  // plus a separator (ASCII).
  string_view body = bytes.substr(bytes.size() - reader.remaining());
  for (const auto& element : elements) {
    uint64_t min_record = 0;
    for (const auto& p : element.properties) {
      if (encoding == PlyEncoding::kAscii) {
        min_record += 2;
      } else {
        min_record += p.is_list ? p.count_size : p.size;
      }
    }
    if (min_record > 0 &&
        static_cast<uint64_t>(element.count) > body.size() / min_record) {
      return InvalidAt(
          kFmt, element.line,
          absl::StrCat("header declares ", element.count, " ",
                       Quote(element.name), " elements, but ", body.size(),
                       " bytes of data cannot hold "
                       "them (truncated file or wrong count)"));
    }
  }
  if (nv > options.max_vertices) return mesh_io::TooManyVertices(nv, options);
  if (nf > options.max_faces) return mesh_io::TooManyFaces(nf, options);

  PolygonSoup soup;
  soup.positions.resize(nv);
  soup.offsets.reserve(nf + 1);
  if (encoding == PlyEncoding::kAscii) {
    AsciiBody source(body, reader.number());
    TPR_RETURN_IF_ERROR(
        WalkBody(elements, vertex_element, options, &source, &soup));
  } else {
    BinaryBody source(body, encoding == PlyEncoding::kBig);
    TPR_RETURN_IF_ERROR(
        WalkBody(elements, vertex_element, options, &source, &soup));
  }
  return soup;
}

}  // namespace tpr::extract
