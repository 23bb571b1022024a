// Mesh intake. Three layers, each with one job:
//   1. a structural scan of the bytes (ours): OpenMesh's readers trust their
//      headers (a PLY or OFF count of 4e9 makes them loop 4e9 times on a
//      failed stream, a list count of 4e9 makes them push 4e9 indices), read
//      coordinates with `>>` (which silently fails on "nan"), and report no
//      line numbers. The scan rejects anything those readers would misread,
//      before they run, and names the line or element.
//   2. OpenMesh's reader (IOManager) into RecordingImporter, which only
//      records vertices and polygons, so no face is silently dropped by
//      add_face.
//   3. ValidateAndClean (shared with BuildMesh): limits, finiteness, ranges,
//      triangulation, degenerate/duplicate dropping, manifoldness,
//      orientation, compaction.
#include "extractor/lib/mesh_io.h"

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/IO/IOManager.hh>
#include <OpenMesh/Core/IO/importer/BaseImporter.hh>
#include <OpenMesh/Core/System/omstream.hh>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <numeric>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/status_macros.h"
#include "extractor/lib/disjoint_sets.h"

namespace tpr::extract {
namespace {

using absl::string_view;

// OpenMesh's readers convert coordinates to float; a larger magnitude makes
// libstdc++'s `>> float` fail and poison the stream.
constexpr double kMaxFloat = std::numeric_limits<float>::max();

// A triangle whose doubled area is at most this times its longest squared
// edge is degenerate (collinear up to rounding). Scale-free, so it treats a
// millimetre mesh and a kilometre mesh alike.
constexpr double kDegenerateRatio = 1e-12;

absl::Status Invalid(string_view format, string_view message) {
  return absl::InvalidArgumentError(absl::StrCat(format, ": ", message));
}
absl::Status InvalidAt(string_view format, int64_t line, string_view message) {
  return absl::InvalidArgumentError(
      absl::StrCat(format, " line ", line, ": ", message));
}
absl::Status TooManyVertices(int64_t n, const IntakeOptions& options) {
  return absl::ResourceExhaustedError(absl::StrCat(
      "mesh has ", n, " vertices; the limit is ", options.max_vertices,
      " (IntakeOptions::max_vertices)"));
}
absl::Status TooManyFaces(int64_t n, const IntakeOptions& options) {
  return absl::ResourceExhaustedError(absl::StrCat(
      "mesh has at least ", n, " triangles; the limit is ", options.max_faces,
      " (IntakeOptions::max_faces)"));
}

// ---------------------------------------------------------------------------
// RecordingImporter: the target OpenMesh's readers write into. It keeps raw
// positions and polygons and ignores attributes (normals, colours, texture
// coordinates), which the signature does not use.
class RecordingImporter final : public OpenMesh::IO::BaseImporter {
 public:
  std::vector<Eigen::Vector3d> positions;
  std::vector<std::vector<int32_t>> polygons;

  OpenMesh::VertexHandle add_vertex(const OpenMesh::Vec3f& p) override {
    positions.emplace_back(p[0], p[1], p[2]);
    return OpenMesh::VertexHandle(static_cast<int>(positions.size() - 1));
  }
  OpenMesh::VertexHandle add_vertex(const OpenMesh::Vec3d& p) override {
    positions.emplace_back(p[0], p[1], p[2]);
    return OpenMesh::VertexHandle(static_cast<int>(positions.size() - 1));
  }
  OpenMesh::VertexHandle add_vertex() override {
    positions.emplace_back(0.0, 0.0, 0.0);
    return OpenMesh::VertexHandle(static_cast<int>(positions.size() - 1));
  }
  void set_point(OpenMesh::VertexHandle vh, const OpenMesh::Vec3f& p) override {
    if (vh.idx() >= 0 && static_cast<size_t>(vh.idx()) < positions.size()) {
      positions[vh.idx()] = Eigen::Vector3d(p[0], p[1], p[2]);
    }
  }
  OpenMesh::FaceHandle add_face(const VHandles& indices) override {
    std::vector<int32_t> polygon;
    polygon.reserve(indices.size());
    for (const auto& vh : indices) polygon.push_back(vh.idx());
    polygons.push_back(std::move(polygon));
    return OpenMesh::FaceHandle(static_cast<int>(polygons.size() - 1));
  }
  size_t n_vertices() const override { return positions.size(); }
  size_t n_faces() const override { return polygons.size(); }
  size_t n_edges() const override { return 0; }

  // Everything below is deliberately ignored.
  OpenMesh::HalfedgeHandle add_edge(OpenMesh::VertexHandle,
                                    OpenMesh::VertexHandle) override {
    return OpenMesh::HalfedgeHandle();
  }
  OpenMesh::FaceHandle add_face(OpenMesh::HalfedgeHandle) override {
    return OpenMesh::FaceHandle();
  }
  void add_face_texcoords(OpenMesh::FaceHandle, OpenMesh::VertexHandle,
                          const std::vector<OpenMesh::Vec2f>&) override {}
  void add_face_texcoords(OpenMesh::FaceHandle, OpenMesh::VertexHandle,
                          const std::vector<OpenMesh::Vec3f>&) override {}
  void set_face_texindex(OpenMesh::FaceHandle, int) override {}
  void set_halfedge(OpenMesh::VertexHandle, OpenMesh::HalfedgeHandle) override {}
  void set_normal(OpenMesh::VertexHandle, const OpenMesh::Vec3f&) override {}
  void set_normal(OpenMesh::VertexHandle, const OpenMesh::Vec3d&) override {}
  void set_color(OpenMesh::VertexHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(OpenMesh::VertexHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(OpenMesh::VertexHandle, const OpenMesh::Vec3f&) override {}
  void set_color(OpenMesh::VertexHandle, const OpenMesh::Vec4f&) override {}
  void set_texcoord(OpenMesh::VertexHandle, const OpenMesh::Vec2f&) override {}
  void set_status(OpenMesh::VertexHandle,
                  const OpenMesh::Attributes::StatusInfo&) override {}
  void set_next(OpenMesh::HalfedgeHandle, OpenMesh::HalfedgeHandle) override {}
  void set_face(OpenMesh::HalfedgeHandle, OpenMesh::FaceHandle) override {}
  void request_face_texcoords2D() override {}
  void set_texcoord(OpenMesh::HalfedgeHandle, const OpenMesh::Vec2f&) override {}
  void set_texcoord(OpenMesh::VertexHandle, const OpenMesh::Vec3f&) override {}
  void set_texcoord(OpenMesh::HalfedgeHandle, const OpenMesh::Vec3f&) override {}
  void set_status(OpenMesh::HalfedgeHandle,
                  const OpenMesh::Attributes::StatusInfo&) override {}
  void set_color(OpenMesh::EdgeHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(OpenMesh::EdgeHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(OpenMesh::EdgeHandle, const OpenMesh::Vec3f&) override {}
  void set_color(OpenMesh::EdgeHandle, const OpenMesh::Vec4f&) override {}
  void set_status(OpenMesh::EdgeHandle,
                  const OpenMesh::Attributes::StatusInfo&) override {}
  void set_normal(OpenMesh::FaceHandle, const OpenMesh::Vec3f&) override {}
  void set_normal(OpenMesh::FaceHandle, const OpenMesh::Vec3d&) override {}
  void set_color(OpenMesh::FaceHandle, const OpenMesh::Vec3uc&) override {}
  void set_color(OpenMesh::FaceHandle, const OpenMesh::Vec4uc&) override {}
  void set_color(OpenMesh::FaceHandle, const OpenMesh::Vec3f&) override {}
  void set_color(OpenMesh::FaceHandle, const OpenMesh::Vec4f&) override {}
  void set_status(OpenMesh::FaceHandle,
                  const OpenMesh::Attributes::StatusInfo&) override {}
  void add_texture_information(int, std::string) override {}
};

// ---------------------------------------------------------------------------
// Text helpers for the structural scan.

// LineReader splits bytes into lines ('\n', with a trailing '\r' removed) and
// numbers them from 1.
class LineReader {
 public:
  explicit LineReader(string_view bytes) : bytes_(bytes) {}
  bool Next(string_view* line) {
    if (pos_ >= bytes_.size()) return false;
    size_t end = bytes_.find('\n', pos_);
    if (end == string_view::npos) end = bytes_.size();
    *line = bytes_.substr(pos_, end - pos_);
    if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
    pos_ = end + 1;
    ++number_;
    return true;
  }
  int64_t number() const { return number_; }
  size_t remaining() const {
    return pos_ >= bytes_.size() ? 0 : bytes_.size() - pos_;
  }

 private:
  string_view bytes_;
  size_t pos_ = 0;
  int64_t number_ = 0;
};

bool IsSpace(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' ||
         c == '\v';
}

// Control bytes other than whitespace never occur in a text mesh file; they
// mean binary data was handed to a text reader.
bool HasBinaryBytes(string_view line) {
  for (char c : line) {
    const unsigned char u = static_cast<unsigned char>(c);
    if ((u < 0x20 && !IsSpace(c)) || u == 0x7f) return true;
  }
  return false;
}

void SplitTokens(string_view line, std::vector<string_view>* tokens) {
  tokens->clear();
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && IsSpace(line[i])) ++i;
    size_t j = i;
    while (j < line.size() && !IsSpace(line[j])) ++j;
    if (j > i) tokens->push_back(line.substr(i, j - i));
    i = j;
  }
}

string_view StripComment(string_view line) {
  size_t hash = line.find('#');
  return hash == string_view::npos ? line : line.substr(0, hash);
}

// ParseDouble accepts what strtod accepts ("nan" and "inf" included, so that
// they can be reported as non-finite rather than as garbage).
bool ParseDouble(string_view token, double* value) {
  if (!token.empty() && token[0] == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  auto result =
      std::from_chars(token.data(), token.data() + token.size(), *value);
  if (result.ec == std::errc::result_out_of_range) {
    // Overflow or underflow: report overflow as infinite, underflow as 0.
    std::string copy(token);
    *value = std::strtod(copy.c_str(), nullptr);
    return true;
  }
  return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

bool ParseInt(string_view token, int64_t* value) {
  if (!token.empty() && token[0] == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  auto result =
      std::from_chars(token.data(), token.data() + token.size(), *value);
  return result.ec == std::errc() && result.ptr == token.data() + token.size();
}

std::string Quote(string_view token) {
  std::string s(token.substr(0, 40));
  for (char& c : s) {
    if (static_cast<unsigned char>(c) < 0x20 ||
        static_cast<unsigned char>(c) >= 0x7f) {
      c = '?';
    }
  }
  return absl::StrCat("'", s, token.size() > 40 ? "...'" : "'");
}

// Checks one coordinate token of vertex `vertex` on `line`.
absl::Status CheckCoordinate(string_view format, int64_t line, int64_t vertex,
                             string_view token) {
  double value = 0.0;
  if (!ParseDouble(token, &value)) {
    return InvalidAt(format, line,
                     absl::StrCat("vertex ", vertex,
                                  ": expected a coordinate, got ", Quote(token)));
  }
  if (!std::isfinite(value)) {
    return InvalidAt(format, line,
                     absl::StrCat("vertex ", vertex,
                                  " has a non-finite coordinate ", Quote(token)));
  }
  if (std::fabs(value) > kMaxFloat) {
    return InvalidAt(format, line,
                     absl::StrCat("vertex ", vertex, ": coordinate ",
                                  Quote(token), " exceeds the float range"));
  }
  return absl::OkStatus();
}

// What the scan learned; OpenMesh's output is checked against it.
struct Scan {
  int64_t vertices = 0;  // vertex records (STL: 3 per facet, before welding)
  int64_t faces = 0;     // face records
  bool stl_binary = false;
  // OFF and OBJ: a canonical rewrite handed to OpenMesh (plain "OFF" / "v" and
  // "f" lines only), so that comments, header variants, relative indices and
  // "mtllib" (which would make OpenMesh open a file named by the input) never
  // reach the reader.
  std::string canonical;
};

// ---------------------------------------------------------------------------
// OFF.
absl::StatusOr<Scan> ScanOff(string_view bytes, const IntakeOptions& options) {
  constexpr string_view kFmt = "OFF";
  LineReader reader(bytes);
  string_view line;
  std::vector<string_view> tok;
  auto next_content = [&]() -> absl::StatusOr<bool> {
    while (reader.Next(&line)) {
      if (HasBinaryBytes(line)) {
        return InvalidAt(kFmt, reader.number(), "binary data in a text file");
      }
      SplitTokens(StripComment(line), &tok);
      if (!tok.empty()) return true;
    }
    return false;
  };
  TPR_ASSIGN_OR_RETURN(bool have, next_content());
  if (!have) return Invalid(kFmt, "the file is empty");
  if (tok[0] != "OFF") {
    if (absl::EndsWith(tok[0], "OFF")) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("header variant ", Quote(tok[0]),
                                    " is not supported (plain OFF only)"));
    }
    return InvalidAt(kFmt, reader.number(),
                     absl::StrCat("expected the 'OFF' header, got ",
                                  Quote(tok[0])));
  }
  if (tok.size() > 1 && tok[1] == "BINARY") {
    return InvalidAt(kFmt, reader.number(), "binary OFF is not supported");
  }
  std::vector<string_view> counts(tok.begin() + 1, tok.end());
  if (counts.empty()) {
    TPR_ASSIGN_OR_RETURN(have, next_content());
    if (!have) return Invalid(kFmt, "truncated: no vertex and face counts");
    counts = tok;
  }
  int64_t nv = 0, nf = 0;
  if (counts.size() < 2 || !ParseInt(counts[0], &nv) ||
      !ParseInt(counts[1], &nf) || nv < 0 || nf < 0) {
    return InvalidAt(kFmt, reader.number(),
                     "expected vertex, face and edge counts");
  }
  const int64_t counts_line = reader.number();
  // Each vertex line holds at least "0 0 0\n", each face "3 0 1 2\n".
  const uint64_t remaining = reader.remaining();
  if (static_cast<uint64_t>(nv) > remaining / 6 ||
      static_cast<uint64_t>(nf) > remaining / 8 ||
      static_cast<uint64_t>(nv) * 6 + static_cast<uint64_t>(nf) * 8 >
          remaining + 1) {
    return InvalidAt(
        kFmt, counts_line,
        absl::StrCat("header declares ", nv, " vertices and ", nf,
                     " faces, more than the remaining ", remaining,
                     " bytes can hold (truncated file or wrong counts)"));
  }
  if (nv > options.max_vertices) return TooManyVertices(nv, options);
  if (nf > options.max_faces) return TooManyFaces(nf, options);

  Scan scan;
  scan.vertices = nv;
  scan.faces = nf;
  std::string& out = scan.canonical;
  out.reserve(bytes.size());
  absl::StrAppend(&out, "OFF\n", nv, " ", nf, " 0\n");
  for (int64_t v = 0; v < nv; ++v) {
    TPR_ASSIGN_OR_RETURN(have, next_content());
    if (!have) {
      return Invalid(kFmt, absl::StrCat("truncated: header declares ", nv,
                                        " vertices, the file ends after ", v));
    }
    if (tok.size() < 3) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("vertex ", v, " has ", tok.size(),
                                    " values; 3 are needed"));
    }
    for (int k = 0; k < 3; ++k) {
      TPR_RETURN_IF_ERROR(CheckCoordinate(kFmt, reader.number(), v, tok[k]));
    }
    absl::StrAppend(&out, tok[0], " ", tok[1], " ", tok[2], "\n");
  }
  int64_t triangles = 0;
  for (int64_t f = 0; f < nf; ++f) {
    TPR_ASSIGN_OR_RETURN(have, next_content());
    if (!have) {
      return Invalid(kFmt, absl::StrCat("truncated: header declares ", nf,
                                        " faces, the file ends after ", f));
    }
    int64_t n = 0;
    if (!ParseInt(tok[0], &n)) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("face ", f, ": expected a vertex count, got ",
                                    Quote(tok[0])));
    }
    if (n < 3) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("face ", f, " has ", n,
                                    " vertices; at least 3 are needed"));
    }
    if (static_cast<int64_t>(tok.size()) - 1 < n) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("face ", f, " declares ", n,
                                    " vertices but lists ", tok.size() - 1));
    }
    triangles += n - 2;
    if (triangles > options.max_faces) return TooManyFaces(triangles, options);
    absl::StrAppend(&out, n);
    for (int64_t k = 1; k <= n; ++k) {
      int64_t index = 0;
      if (!ParseInt(tok[k], &index)) {
        return InvalidAt(kFmt, reader.number(),
                         absl::StrCat("face ", f, ": expected a vertex index, got ",
                                      Quote(tok[k])));
      }
      if (index < 0 || index >= nv) {
        return InvalidAt(kFmt, reader.number(),
                         absl::StrCat("face ", f, " references vertex ", index,
                                      "; the file has ", nv, " vertices"));
      }
      absl::StrAppend(&out, " ", index);
    }
    out.push_back('\n');
  }
  return scan;
}

// ---------------------------------------------------------------------------
// OBJ: only "v" and "f" matter; every other statement is ignored.
absl::StatusOr<Scan> ScanObj(string_view bytes, const IntakeOptions& options) {
  constexpr string_view kFmt = "OBJ";
  LineReader reader(bytes);
  string_view line;
  std::vector<string_view> tok;
  Scan scan;
  std::string vertices_text;
  std::vector<int64_t> face_indices;   // 1-based, flattened
  std::vector<int64_t> face_offsets{0};
  std::vector<int64_t> face_lines;
  int64_t triangles = 0;
  while (reader.Next(&line)) {
    if (HasBinaryBytes(line)) {
      return InvalidAt(kFmt, reader.number(), "binary data in a text file");
    }
    SplitTokens(StripComment(line), &tok);
    if (tok.empty()) continue;
    if (tok[0] == "v") {
      if (tok.size() < 4) {
        return InvalidAt(kFmt, reader.number(),
                         absl::StrCat("vertex ", scan.vertices, " has ",
                                      tok.size() - 1, " values; 3 are needed"));
      }
      for (int k = 1; k <= 3; ++k) {
        TPR_RETURN_IF_ERROR(
            CheckCoordinate(kFmt, reader.number(), scan.vertices, tok[k]));
      }
      absl::StrAppend(&vertices_text, "v ", tok[1], " ", tok[2], " ", tok[3],
                      "\n");
      if (++scan.vertices > options.max_vertices) {
        return TooManyVertices(scan.vertices, options);
      }
    } else if (tok[0] == "f") {
      const int64_t face = static_cast<int64_t>(face_lines.size());
      if (tok.size() < 4) {
        return InvalidAt(kFmt, reader.number(),
                         absl::StrCat("face ", face, " has ", tok.size() - 1,
                                      " vertices; at least 3 are needed"));
      }
      for (size_t k = 1; k < tok.size(); ++k) {
        string_view ref = tok[k].substr(0, tok[k].find('/'));
        int64_t index = 0;
        if (!ParseInt(ref, &index) || index == 0) {
          return InvalidAt(kFmt, reader.number(),
                           absl::StrCat("face ", face,
                                        ": expected a vertex index (1-based), got ",
                                        Quote(tok[k])));
        }
        // Negative indices count back from the latest vertex (OBJ spec).
        if (index < 0) index = scan.vertices + index + 1;
        if (index < 1) {
          return InvalidAt(kFmt, reader.number(),
                           absl::StrCat("face ", face, " references relative vertex ",
                                        ref, " before vertex 1"));
        }
        face_indices.push_back(index);
      }
      face_offsets.push_back(static_cast<int64_t>(face_indices.size()));
      face_lines.push_back(reader.number());
      triangles += static_cast<int64_t>(tok.size()) - 3;
      if (triangles > options.max_faces) return TooManyFaces(triangles, options);
    }
  }
  scan.faces = static_cast<int64_t>(face_lines.size());
  std::string& out = scan.canonical;
  out = std::move(vertices_text);
  for (int64_t f = 0; f < scan.faces; ++f) {
    out.push_back('f');
    for (int64_t k = face_offsets[f]; k < face_offsets[f + 1]; ++k) {
      if (face_indices[k] > scan.vertices) {
        return InvalidAt(kFmt, face_lines[f],
                         absl::StrCat("face ", f, " references vertex ",
                                      face_indices[k], " (1-based); the file has ",
                                      scan.vertices, " vertices"));
      }
      absl::StrAppend(&out, " ", face_indices[k]);
    }
    out.push_back('\n');
  }
  if (scan.vertices == 0) return Invalid(kFmt, "no vertices ('v' lines) found");
  if (scan.faces == 0) return Invalid(kFmt, "no faces ('f' lines) found");
  return scan;
}

// ---------------------------------------------------------------------------
// STL.
uint32_t LoadLe32(const char* p) {
  const auto* u = reinterpret_cast<const unsigned char*>(p);
  return static_cast<uint32_t>(u[0]) | (static_cast<uint32_t>(u[1]) << 8) |
         (static_cast<uint32_t>(u[2]) << 16) |
         (static_cast<uint32_t>(u[3]) << 24);
}

bool LooksLikeAsciiStl(string_view bytes) {
  size_t i = 0;
  while (i < bytes.size() && IsSpace(bytes[i])) ++i;
  if (!absl::StartsWith(bytes.substr(i), "solid")) return false;
  // Control bytes early on mean binary data behind a "solid" header.
  if (HasBinaryBytes(bytes.substr(0, 4096))) return false;
  // Binary files often start their 80-byte header with "solid" too; a size
  // that matches the binary layout exactly decides for binary.
  if (bytes.size() >= 84) {
    const uint64_t n = LoadLe32(bytes.data() + 80);
    if (84 + 50 * n == bytes.size()) return false;
  }
  return true;
}

absl::StatusOr<Scan> ScanStlBinary(string_view bytes,
                                   const IntakeOptions& options) {
  constexpr string_view kFmt = "STL (binary)";
  if (bytes.size() < 84) {
    return Invalid(kFmt, absl::StrCat("truncated: ", bytes.size(),
                                      " bytes, the header alone is 84"));
  }
  const uint64_t n = LoadLe32(bytes.data() + 80);
  if (84 + 50 * n != bytes.size()) {
    return Invalid(kFmt, absl::StrCat("header declares ", n,
                                      " triangles (", 84 + 50 * n,
                                      " bytes) but the file has ",
                                      bytes.size(), " bytes"));
  }
  if (static_cast<int64_t>(n) > options.max_faces) {
    return TooManyFaces(static_cast<int64_t>(n), options);
  }
  if (n == 0) return Invalid(kFmt, "the file holds no triangles");
  for (uint64_t t = 0; t < n; ++t) {
    for (int corner = 0; corner < 3; ++corner) {
      for (int c = 0; c < 3; ++c) {
        const uint32_t raw =
            LoadLe32(bytes.data() + 84 + 50 * t + 12 + 12 * corner + 4 * c);
        float value;
        std::memcpy(&value, &raw, sizeof(value));
        if (!std::isfinite(value)) {
          return Invalid(kFmt, absl::StrCat("triangle ", t, " corner ", corner,
                                            " has a non-finite coordinate"));
        }
      }
    }
  }
  Scan scan;
  scan.stl_binary = true;
  scan.faces = static_cast<int64_t>(n);
  scan.vertices = 3 * scan.faces;
  return scan;
}

absl::StatusOr<Scan> ScanStlAscii(string_view bytes,
                                  const IntakeOptions& options) {
  constexpr string_view kFmt = "STL (ASCII)";
  LineReader reader(bytes);
  string_view line;
  std::vector<string_view> tok;
  enum class State { kOutside, kSolid, kFacet, kLoopDone, kFacetDone };
  State state = State::kOutside;
  Scan scan;
  while (reader.Next(&line)) {
    if (HasBinaryBytes(line)) {
      return InvalidAt(kFmt, reader.number(), "binary data in a text file");
    }
    SplitTokens(line, &tok);
    if (tok.empty()) continue;
    const int64_t at = reader.number();
    // OpenMesh's reader starts a triangle at any line containing "outer" and
    // then takes the next three raw lines as vertices: only "outer loop"
    // lines may contain it.
    const bool outer_loop = tok.size() == 2 && tok[0] == "outer" &&
                            tok[1] == "loop";
    if (!outer_loop && (absl::StrContains(line, "outer") ||
                        absl::StrContains(line, "OUTER"))) {
      return InvalidAt(kFmt, at,
                       "the word 'outer' outside an 'outer loop' line is not "
                       "supported");
    }
    if (tok[0] == "solid" && state == State::kOutside) {
      state = State::kSolid;
    } else if (tok[0] == "endsolid" && state == State::kSolid) {
      state = State::kOutside;
    } else if (tok[0] == "facet" && state == State::kSolid) {
      if (tok.size() != 5 || tok[1] != "normal") {
        return InvalidAt(kFmt, at, "expected 'facet normal nx ny nz'");
      }
      state = State::kFacet;
    } else if (outer_loop && state == State::kFacet) {
      for (int corner = 0; corner < 3; ++corner) {
        if (!reader.Next(&line)) {
          return Invalid(kFmt, absl::StrCat("truncated inside triangle ",
                                            scan.faces));
        }
        SplitTokens(line, &tok);
        if (tok.size() != 4 || tok[0] != "vertex") {
          return InvalidAt(kFmt, reader.number(),
                           absl::StrCat("triangle ", scan.faces,
                                        ": expected 'vertex x y z'"));
        }
        for (int k = 1; k <= 3; ++k) {
          TPR_RETURN_IF_ERROR(CheckCoordinate(kFmt, reader.number(),
                                              scan.vertices, tok[k]));
        }
        ++scan.vertices;
      }
      state = State::kLoopDone;
    } else if (tok[0] == "endloop" && state == State::kLoopDone) {
      state = State::kFacetDone;
    } else if (tok[0] == "endfacet" && state == State::kFacetDone) {
      state = State::kSolid;
      if (++scan.faces > options.max_faces) {
        return TooManyFaces(scan.faces, options);
      }
    } else {
      return InvalidAt(kFmt, at, absl::StrCat("unexpected ", Quote(tok[0])));
    }
  }
  if (state != State::kOutside && state != State::kSolid) {
    return Invalid(kFmt, absl::StrCat("truncated inside triangle ", scan.faces));
  }
  if (scan.faces == 0) return Invalid(kFmt, "the file holds no triangles");
  return scan;
}

// ---------------------------------------------------------------------------
// PLY.
enum class PlyEncoding { kAscii, kLittle, kBig };

struct PlyProperty {
  std::string name;
  std::string type;        // scalar type, or "<count type> <entry type>"

  int size = 0;          // scalar or list entry size in bytes
  bool is_float = false;
  bool is_signed = false;
  bool is_list = false;
  int count_size = 0;    // list count size in bytes
  bool role_coordinate = false;  // x, y or z of a vertex
  bool role_indices = false;     // face vertex_indices
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

absl::StatusOr<Scan> ScanPly(string_view bytes, const IntakeOptions& options) {
  constexpr string_view kFmt = "PLY";
  LineReader reader(bytes);
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
    if (HasBinaryBytes(line)) return InvalidAt(kFmt, at, "binary data in the header");
    SplitTokens(line, &tok);
    if (tok.empty() || tok[0] == "comment") continue;
    if (tok[0] == "end_header") {
      have_end = true;
      break;
    }
    if (tok[0] == "obj_info") {
      return InvalidAt(kFmt, at, "'obj_info' header lines are not supported");
    }
    if (!have_format && tok[0] != "format") {
      // OpenMesh takes the first three header tokens as the format line.
      return InvalidAt(kFmt, at, "expected the 'format' line first");
    }
    if (tok[0] == "format") {
      double version = 0;
      if (have_format || tok.size() != 3 || !ParseDouble(tok[2], &version)) {
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
      if (tok.size() != 3 || !ParseInt(tok[2], &element.count) ||
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
        // OpenMesh's reader accepts only these list count types.
        if (tok[2] != "uchar" && tok[2] != "uint8" && tok[2] != "uint16" &&
            tok[2] != "int") {
          return InvalidAt(kFmt, at,
                           absl::StrCat("list count type ", Quote(tok[2]),
                                        " is not supported (uchar, uint8, "
                                        "uint16 or int)"));
        }
        bool f = false, s = false;
        PlyType(tok[2], &p.count_size, &f, &s);
        p.type = absl::StrCat("list ", tok[2], " ", tok[3]);
        if (!PlyType(tok[3], &p.size, &p.is_float, &p.is_signed) ||
            p.is_float) {
          return InvalidAt(kFmt, at,
                           absl::StrCat("list entry type ", Quote(tok[3]),
                                        " is not an integer type"));
        }
        if (element.name != "face" ||
            (p.name != "vertex_indices" && p.name != "vertex_index")) {
          return InvalidAt(kFmt, at,
                           absl::StrCat("list property ", Quote(p.name),
                                        " of element ", Quote(element.name),
                                        " is not supported"));
        }
        if (!element.properties.empty()) {
          // OpenMesh discards face properties declared before the indices.
          return InvalidAt(kFmt, at,
                           "the face's vertex index list must be its first "
                           "property");
        }
        p.role_indices = true;
      } else if (tok.size() == 3) {
        p.name = std::string(tok[2]);
        p.type = std::string(tok[1]);
        if (!PlyType(tok[1], &p.size, &p.is_float, &p.is_signed)) {
          return InvalidAt(kFmt, at,
                           absl::StrCat("unknown property type ",
                                        Quote(tok[1])));
        }
        p.role_coordinate = element.name == "vertex" &&
                            (p.name == "x" || p.name == "y" || p.name == "z");
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
    int coords = 0;
    for (const auto& p : elements[vertex_element].properties) {
      coords += p.role_coordinate;
    }
    if (coords != 3) return Invalid(kFmt, "vertex needs x, y and z properties");
    const auto& fp = elements[face_element].properties;
    if (fp.empty() || !fp[0].role_indices) {
      return Invalid(kFmt, "face needs a 'vertex_indices' list property");
    }
  }
  // Only elements up to the faces are read (OpenMesh stops there).
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
      return InvalidAt(kFmt, element.line,
                       absl::StrCat("header declares ", element.count, " ",
                                    Quote(element.name), " elements, but ",
                                    body.size(), " bytes of data cannot hold "
                                    "them (truncated file or wrong count)"));
    }
  }
  for (const auto& element : elements) {
    if (element.count > std::numeric_limits<uint32_t>::max()) {
      return InvalidAt(kFmt, element.line,
                       absl::StrCat("element count ", element.count,
                                    " exceeds the reader's 32-bit range"));
    }
  }
  if (nv > options.max_vertices) return TooManyVertices(nv, options);
  if (nf > options.max_faces) return TooManyFaces(nf, options);

  Scan scan;
  scan.vertices = nv;
  scan.faces = nf;
  // OpenMesh's header parser is token-based and finds binary data by byte
  // arithmetic around "end_header" (a comment just before it, or trailing
  // blanks, misalign the body), so it gets a canonical header.
  {
    std::string& out = scan.canonical;
    out.reserve(body.size() + 512);
    absl::StrAppend(&out, "ply\nformat ",
                    encoding == PlyEncoding::kAscii    ? "ascii"
                    : encoding == PlyEncoding::kLittle ? "binary_little_endian"
                                                       : "binary_big_endian",
                    " 1.0\n");
    for (const auto& element : elements) {
      absl::StrAppend(&out, "element ", element.name, " ", element.count, "\n");
      for (const auto& p : element.properties) {
        absl::StrAppend(&out, "property ", p.type, " ", p.name, "\n");
      }
    }
    absl::StrAppend(&out, "end_header\n", body);
  }
  int64_t triangles = 0;
  if (encoding == PlyEncoding::kAscii) {
    // Token walk with line numbers, the way OpenMesh's `>>` reads.
    LineReader body_reader(body);
    const int64_t first_body_line = reader.number();
    std::vector<string_view> line_tokens;
    size_t next_token = 0;
    int64_t token_line = first_body_line;
    auto next = [&](string_view* token) -> absl::Status {
      while (next_token >= line_tokens.size()) {
        string_view l;
        if (!body_reader.Next(&l)) return absl::OutOfRangeError("eof");
        token_line = first_body_line + body_reader.number();
        if (HasBinaryBytes(l)) {
          return InvalidAt(kFmt, token_line, "binary data in an ASCII body");
        }
        SplitTokens(l, &line_tokens);
        next_token = 0;
      }
      *token = line_tokens[next_token++];
      return absl::OkStatus();
    };
    for (const auto& element : elements) {
      const bool is_face = &element == &elements[face_element];
      for (int64_t i = 0; i < element.count; ++i) {
        for (const auto& p : element.properties) {
          string_view token;
          absl::Status s = next(&token);
          auto truncated = [&]() {
            return Invalid(kFmt, absl::StrCat("truncated in ", element.name,
                                              " ", i, " of ", element.count));
          };
          if (absl::IsOutOfRange(s)) return truncated();
          TPR_RETURN_IF_ERROR(s);
          if (p.role_coordinate) {
            TPR_RETURN_IF_ERROR(CheckCoordinate(kFmt, token_line, i, token));
            continue;
          }
          int64_t n = 0;
          double d = 0;
          if (!p.is_list) {
            // OpenMesh reads these with `>>` into float or int, which fails
            // (and poisons the stream) on non-finite or out-of-range text.
            const bool ok =
                p.is_float
                    ? ParseDouble(token, &d) && std::fabs(d) <= kMaxFloat
                    : ParseInt(token, &n) &&
                          n <= std::numeric_limits<int32_t>::max() &&
                          n >= std::numeric_limits<int32_t>::min();
            if (!ok) {
              return InvalidAt(kFmt, token_line,
                               absl::StrCat(element.name, " ", i, ": property ",
                                            Quote(p.name), ": expected a finite ",
                                            p.is_float ? "float" : "32-bit integer",
                                            ", got ",
                                            Quote(token)));
            }
            continue;
          }
          if (!ParseInt(token, &n) || n < 3 || n > 1'000'000) {
            return InvalidAt(kFmt, token_line,
                             absl::StrCat("face ", i, " has vertex count ",
                                          Quote(token), "; at least 3 are needed"));
          }
          triangles += n - 2;
          if (triangles > options.max_faces) return TooManyFaces(triangles, options);
          for (int64_t k = 0; k < n; ++k) {
            s = next(&token);
            if (absl::IsOutOfRange(s)) return truncated();
            TPR_RETURN_IF_ERROR(s);
            int64_t index = 0;
            if (!ParseInt(token, &index)) {
              return InvalidAt(kFmt, token_line,
                               absl::StrCat("face ", i, ": expected a vertex index, got ",
                                            Quote(token)));
            }
            if (index < 0 || index >= nv) {
              return InvalidAt(kFmt, token_line,
                               absl::StrCat("face ", i, " references vertex ", index,
                                            "; the file has ", nv, " vertices"));
            }
          }
        }
        (void)is_face;
      }
    }
    return scan;
  }

  const bool big = encoding == PlyEncoding::kBig;
  size_t pos = 0;
  for (const auto& element : elements) {
    for (int64_t i = 0; i < element.count; ++i) {
      for (const auto& p : element.properties) {
        auto truncated = [&]() {
          return Invalid(kFmt, absl::StrCat("truncated in ", element.name, " ",
                                            i, " of ", element.count));
        };
        if (!p.is_list) {
          if (body.size() - pos < static_cast<size_t>(p.size)) return truncated();
          if (p.role_coordinate) {
            const double value = ReadPlyScalar(body.data() + pos, p.size,
                                               p.is_float, p.is_signed, big);
            if (!std::isfinite(value)) {
              return Invalid(kFmt, absl::StrCat("vertex ", i,
                                                " has a non-finite coordinate"));
            }
            if (std::fabs(value) > kMaxFloat) {
              return Invalid(kFmt, absl::StrCat("vertex ", i,
                                                ": coordinate exceeds the float range"));
            }
          }
          pos += p.size;
          continue;
        }
        if (body.size() - pos < static_cast<size_t>(p.count_size)) {
          return truncated();
        }
        const double count = ReadPlyScalar(body.data() + pos, p.count_size,
                                           false, p.count_size == 4, big);
        pos += p.count_size;
        if (count < 3) {
          return Invalid(kFmt, absl::StrCat("face ", i, " has ", count,
                                            " vertices; at least 3 are needed"));
        }
        const uint64_t n = static_cast<uint64_t>(count);
        if (n > (body.size() - pos) / p.size) return truncated();
        triangles += static_cast<int64_t>(n) - 2;
        if (triangles > options.max_faces) return TooManyFaces(triangles, options);
        for (uint64_t k = 0; k < n; ++k) {
          const double index = ReadPlyScalar(body.data() + pos, p.size, false,
                                             p.is_signed, big);
          pos += p.size;
          if (index < 0 || index >= static_cast<double>(nv)) {
            return Invalid(kFmt, absl::StrCat("face ", i, " references vertex ",
                                              static_cast<int64_t>(index),
                                              "; the file has ", nv, " vertices"));
          }
        }
      }
    }
  }
  if (pos == body.size() && !elements.empty()) {
    // OpenMesh's binary reader reports failure when its stream reaches EOF
    // while reading the last element, which a read of exactly the remaining
    // bytes does not do; nothing to adjust, but keep the invariant visible.
  }
  return scan;
}

// ---------------------------------------------------------------------------
// Running OpenMesh.

// OpenMesh's reader modules are process-wide singletons that keep per-read
// state in members (the PLY header, the OFF options), so reads are
// serialized. Parsing is a small part of extraction, so this costs little.
std::mutex& OpenMeshMutex() {
  static std::mutex* mutex = new std::mutex;
  return *mutex;
}

// Deletes a temporary file on scope exit.
class TempFile {
 public:
  TempFile() = default;
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;
  ~TempFile() {
    if (!path_.empty()) ::unlink(path_.c_str());
  }
  // Creates a private (0600, O_EXCL) file ending in `suffix` holding `bytes`.
  absl::Status Create(string_view bytes, const std::string& suffix) {
    std::error_code ec;
    std::filesystem::path dir = std::filesystem::temp_directory_path(ec);
    if (ec) dir = "/tmp";
    std::string pattern = (dir / ("tpr_intake_XXXXXX" + suffix)).string();
    std::vector<char> buffer(pattern.begin(), pattern.end());
    buffer.push_back('\0');
    const int fd = ::mkstemps(buffer.data(), static_cast<int>(suffix.size()));
    if (fd < 0) {
      return absl::InternalError(
          absl::StrCat("cannot create a temporary file: ", std::strerror(errno)));
    }
    path_ = buffer.data();
    size_t written = 0;
    while (written < bytes.size()) {
      const ssize_t n =
          ::write(fd, bytes.data() + written, bytes.size() - written);
      if (n <= 0) {
        ::close(fd);
        return absl::InternalError("cannot write a temporary file");
      }
      written += static_cast<size_t>(n);
    }
    ::close(fd);
    return absl::OkStatus();
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

absl::Status RunOpenMesh(MeshFormat format, string_view bytes, const Scan& scan,
                         RecordingImporter* importer) {
  std::lock_guard<std::mutex> lock(OpenMeshMutex());
  // The readers write progress and complaints to omerr/omlog; our statuses
  // carry the facts, so keep stderr quiet while they run.
  const bool err_on = omerr().is_enabled(), log_on = omlog().is_enabled();
  omerr().disable();
  omlog().disable();
  OpenMesh::IO::Options opt;
  bool ok = false;
  switch (format) {
    case MeshFormat::kOff: {
      // The OFF reader's stream entry point reuses header options that only
      // its file entry point (can_u_read(filename)) sets; from a stream it
      // would parse with whatever the previous file left behind. So OFF goes
      // through a private temporary file.
      TempFile file;
      absl::Status s = file.Create(scan.canonical, ".off");
      if (s.ok()) ok = OpenMesh::IO::IOManager().read(file.path(), *importer, opt);
      if (!s.ok()) {
        if (err_on) omerr().enable();
        if (log_on) omlog().enable();
        return s;
      }
      break;
    }
    case MeshFormat::kObj: {
      std::istringstream in(scan.canonical);
      ok = OpenMesh::IO::IOManager().read(in, "obj", *importer, opt);
      break;
    }
    case MeshFormat::kPly: {
      std::istringstream in(scan.canonical, std::ios::in | std::ios::binary);
      ok = OpenMesh::IO::IOManager().read(in, "ply", *importer, opt);
      break;
    }
    case MeshFormat::kStl: {
      std::istringstream in(std::string(bytes), std::ios::in | std::ios::binary);
      if (scan.stl_binary) opt += OpenMesh::IO::Options::Binary;
      ok = OpenMesh::IO::IOManager().read(in, "stl", *importer, opt);
      break;
    }
    case MeshFormat::kUnknown:
      break;
  }
  if (err_on) omerr().enable();
  if (log_on) omlog().enable();
  if (!ok) {
    return absl::InvalidArgumentError(absl::StrCat(
        MeshFormatName(format), ": OpenMesh's reader rejected the file"));
  }
  return absl::OkStatus();
}

MeshFormat GuessFormat(string_view bytes, string_view file_name) {
  const std::string lower = absl::AsciiStrToLower(file_name);
  if (absl::EndsWith(lower, ".off")) return MeshFormat::kOff;
  if (absl::EndsWith(lower, ".obj")) return MeshFormat::kObj;
  if (absl::EndsWith(lower, ".ply")) return MeshFormat::kPly;
  if (absl::EndsWith(lower, ".stl")) return MeshFormat::kStl;
  if (absl::StartsWith(bytes, "ply\n") || absl::StartsWith(bytes, "ply\r")) {
    return MeshFormat::kPly;
  }
  // Skip blanks and '#' comment lines (OFF and OBJ allow them).
  size_t i = 0;
  while (i < bytes.size()) {
    if (IsSpace(bytes[i])) {
      ++i;
    } else if (bytes[i] == '#') {
      const size_t end = bytes.find('\n', i);
      i = end == string_view::npos ? bytes.size() : end + 1;
    } else {
      break;
    }
  }
  string_view rest = bytes.substr(i);
  if (absl::StartsWith(rest, "OFF")) return MeshFormat::kOff;
  if (absl::StartsWith(rest, "solid")) return MeshFormat::kStl;
  if (bytes.size() >= 84 &&
      84 + 50 * static_cast<uint64_t>(LoadLe32(bytes.data() + 80)) ==
          bytes.size()) {
    return MeshFormat::kStl;
  }
  if (absl::StartsWith(rest, "v ") || absl::StrContains(bytes, "\nv ")) {
    return MeshFormat::kObj;
  }
  return MeshFormat::kUnknown;
}

// ---------------------------------------------------------------------------
// Validation and cleaning, shared by files and BuildMesh.

struct HalfEdge {
  uint64_t key;  // (min << 32) | max
  int64_t face;
  bool forward;  // traversed min -> max
  bool operator<(const HalfEdge& o) const {
    return key != o.key ? key < o.key : face < o.face;
  }
};

std::string EdgeName(uint64_t key) {
  return absl::StrCat("(", key >> 32, ", ", key & 0xffffffffu, ")");
}

absl::StatusOr<LoadedMesh> ValidateAndClean(
    std::vector<Eigen::Vector3d> positions,
    std::vector<std::vector<int32_t>> polygons, const IntakeOptions& options,
    int64_t reader_dropped_degenerate, std::vector<std::string> warnings) {
  const int64_t nv = static_cast<int64_t>(positions.size());
  if (nv > options.max_vertices) return TooManyVertices(nv, options);
  if (nv == 0) return absl::InvalidArgumentError("mesh has no vertices");
  if (polygons.empty()) return absl::InvalidArgumentError("mesh has no faces");
  for (int64_t v = 0; v < nv; ++v) {
    if (!positions[v].allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("vertex ", v, " has a non-finite coordinate"));
    }
  }
  int64_t triangle_count = 0;
  for (size_t f = 0; f < polygons.size(); ++f) {
    const auto& polygon = polygons[f];
    if (polygon.size() < 3) {
      return absl::InvalidArgumentError(
          absl::StrCat("face ", f, " has ", polygon.size(),
                       " vertices; at least 3 are needed"));
    }
    for (int32_t v : polygon) {
      if (v < 0 || v >= nv) {
        return absl::InvalidArgumentError(absl::StrCat(
            "face ", f, " references vertex ", v, "; the mesh has ", nv,
            " vertices"));
      }
    }
    triangle_count += static_cast<int64_t>(polygon.size()) - 2;
  }
  if (triangle_count > options.max_faces) {
    return TooManyFaces(triangle_count, options);
  }

  // Fan triangulation from each polygon's first corner, dropping degenerate
  // triangles on the way.
  std::vector<std::array<int32_t, 3>> triangles;
  triangles.reserve(triangle_count);
  int64_t degenerate = reader_dropped_degenerate;
  for (const auto& polygon : polygons) {
    for (size_t k = 1; k + 1 < polygon.size(); ++k) {
      const std::array<int32_t, 3> t{polygon[0], polygon[k], polygon[k + 1]};
      if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
        ++degenerate;
        continue;
      }
      const Eigen::Vector3d e0 = positions[t[1]] - positions[t[0]];
      const Eigen::Vector3d e1 = positions[t[2]] - positions[t[0]];
      const Eigen::Vector3d e2 = positions[t[2]] - positions[t[1]];
      const double longest = std::max(
          {e0.squaredNorm(), e1.squaredNorm(), e2.squaredNorm()});
      if (e0.cross(e1).norm() <= kDegenerateRatio * longest) {
        ++degenerate;
        continue;
      }
      triangles.push_back(t);
    }
  }
  polygons.clear();
  polygons.shrink_to_fit();

  // Duplicates: same vertex set in any order; the first occurrence stays.
  int64_t duplicates = 0;
  {
    std::vector<std::pair<std::array<int32_t, 3>, int64_t>> keys;
    keys.reserve(triangles.size());
    for (size_t f = 0; f < triangles.size(); ++f) {
      std::array<int32_t, 3> k = triangles[f];
      std::sort(k.begin(), k.end());
      keys.emplace_back(k, static_cast<int64_t>(f));
    }
    std::sort(keys.begin(), keys.end());
    std::vector<char> drop(triangles.size(), 0);
    for (size_t i = 1; i < keys.size(); ++i) {
      if (keys[i].first == keys[i - 1].first) {
        drop[keys[i].second] = 1;
        ++duplicates;
      }
    }
    if (duplicates > 0) {
      size_t out = 0;
      for (size_t f = 0; f < triangles.size(); ++f) {
        if (!drop[f]) triangles[out++] = triangles[f];
      }
      triangles.resize(out);
    }
  }
  if (degenerate > 0) {
    warnings.push_back(absl::StrCat("dropped ", degenerate,
                                    " degenerate (zero-area) triangles"));
  }
  if (duplicates > 0) {
    warnings.push_back(
        absl::StrCat("dropped ", duplicates, " duplicate triangles"));
  }
  if (triangles.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "mesh has no faces left after dropping ", degenerate,
        " degenerate and ", duplicates, " duplicate triangles"));
  }

  // Edges: sorted half-edges group each undirected edge's faces.
  const int64_t nf = static_cast<int64_t>(triangles.size());
  std::vector<HalfEdge> halfedges;
  halfedges.reserve(3 * nf);
  for (int64_t f = 0; f < nf; ++f) {
    for (int k = 0; k < 3; ++k) {
      const uint32_t a = static_cast<uint32_t>(triangles[f][k]);
      const uint32_t b = static_cast<uint32_t>(triangles[f][(k + 1) % 3]);
      const uint64_t key = a < b ? (static_cast<uint64_t>(a) << 32) | b
                                 : (static_cast<uint64_t>(b) << 32) | a;
      halfedges.push_back({key, f, a < b});
    }
  }
  std::sort(halfedges.begin(), halfedges.end());
  // Non-manifold edges first: the sorted order names the smallest such edge.
  for (size_t i = 0; i < halfedges.size();) {
    size_t j = i + 1;
    while (j < halfedges.size() && halfedges[j].key == halfedges[i].key) ++j;
    if (j - i > 2) {
      return absl::InvalidArgumentError(absl::StrCat(
          "non-manifold edge ", EdgeName(halfedges[i].key), ": shared by ",
          j - i, " triangles (at most 2 allowed)"));
    }
    i = j;
  }

  // Non-manifold vertices: corners (f, k) of triangles meeting at a vertex
  // are linked across each interior edge they share; a manifold vertex's
  // corners then form one set (its single fan), a pinch vertex several.
  DisjointSets corners(3 * nf);
  auto corner_of = [&](int64_t f, uint32_t v) -> int64_t {
    for (int k = 0; k < 3; ++k) {
      if (static_cast<uint32_t>(triangles[f][k]) == v) return 3 * f + k;
    }
    return -1;
  };
  struct Link {
    int64_t f, g;
    bool flip;  // g must be flipped relative to f
    uint64_t key;
  };
  std::vector<Link> links;
  links.reserve(halfedges.size() / 2);
  for (size_t i = 0; i + 1 < halfedges.size(); ++i) {
    if (halfedges[i].key != halfedges[i + 1].key) continue;
    const HalfEdge& h0 = halfedges[i];
    const HalfEdge& h1 = halfedges[i + 1];
    const uint32_t a = static_cast<uint32_t>(h0.key >> 32);
    const uint32_t b = static_cast<uint32_t>(h0.key & 0xffffffffu);
    corners.Union(corner_of(h0.face, a), corner_of(h1.face, a));
    corners.Union(corner_of(h0.face, b), corner_of(h1.face, b));
    // Consistently oriented neighbours traverse their shared edge in
    // opposite directions.
    links.push_back({h0.face, h1.face, h0.forward == h1.forward, h0.key});
    ++i;
  }
  {
    std::vector<int64_t> fan(nv, -1);
    int64_t worst = -1;
    for (int64_t c = 0; c < 3 * nf; ++c) {
      const int32_t v = triangles[c / 3][c % 3];
      const int64_t root = corners.Find(c);
      if (fan[v] < 0) {
        fan[v] = root;
      } else if (fan[v] != root && (worst < 0 || v < worst)) {
        worst = v;
      }
    }
    if (worst >= 0) {
      std::vector<int64_t> roots;
      for (int64_t c = 0; c < 3 * nf; ++c) {
        if (triangles[c / 3][c % 3] == worst) roots.push_back(corners.Find(c));
      }
      std::sort(roots.begin(), roots.end());
      roots.erase(std::unique(roots.begin(), roots.end()), roots.end());
      return absl::InvalidArgumentError(absl::StrCat(
          "non-manifold vertex ", worst, ": its triangles form ", roots.size(),
          " separate fans (one disk or half-disk allowed)"));
    }
  }

  // Orientation: breadth-first over faces, flipping to agree with the first
  // face; then per component keep the majority's orientation, and for a
  // closed component make the signed volume positive (outward normals).
  {
    std::vector<int64_t> offsets(nf + 1, 0);
    for (const Link& l : links) {
      ++offsets[l.f + 1];
      ++offsets[l.g + 1];
    }
    for (int64_t f = 0; f < nf; ++f) offsets[f + 1] += offsets[f];
    std::vector<std::pair<int64_t, size_t>> adjacency(offsets[nf]);
    {
      std::vector<int64_t> fill(offsets.begin(), offsets.end() - 1);
      for (size_t i = 0; i < links.size(); ++i) {
        adjacency[fill[links[i].f]++] = {links[i].g, i};
        adjacency[fill[links[i].g]++] = {links[i].f, i};
      }
    }
    std::vector<int8_t> flip(nf, -1);
    std::vector<int64_t> queue;
    std::vector<int64_t> component;
    int64_t reoriented = 0;
    for (int64_t seed = 0; seed < nf; ++seed) {
      if (flip[seed] >= 0) continue;
      flip[seed] = 0;
      queue.assign(1, seed);
      component.clear();
      for (size_t q = 0; q < queue.size(); ++q) {
        const int64_t f = queue[q];
        component.push_back(f);
        for (int64_t a = offsets[f]; a < offsets[f + 1]; ++a) {
          const auto [g, link] = adjacency[a];
          const int8_t want = flip[f] ^ (links[link].flip ? 1 : 0);
          if (flip[g] < 0) {
            flip[g] = want;
            queue.push_back(g);
          } else if (flip[g] != want) {
            return absl::InvalidArgumentError(absl::StrCat(
                "non-orientable surface: triangles around edge ",
                EdgeName(links[link].key),
                " cannot be oriented consistently"));
          }
        }
      }
      int64_t flipped = 0;
      for (int64_t f : component) flipped += flip[f];
      bool invert = 2 * flipped > static_cast<int64_t>(component.size());
      // A closed component
      // (every triangle has three neighbours) decides by signed volume.
      bool closed = true;
      for (int64_t f : component) {
        if (offsets[f + 1] - offsets[f] != 3) {
          closed = false;
          break;
        }
      }
      if (closed) {
        double volume = 0.0;
        for (int64_t f : component) {
          const auto& t = triangles[f];
          double v6 = positions[t[0]].dot(positions[t[1]].cross(positions[t[2]]));
          volume += flip[f] ? -v6 : v6;
        }
        invert = volume < 0;
      }
      for (int64_t f : component) {
        if ((flip[f] != 0) != invert) {
          std::swap(triangles[f][1], triangles[f][2]);
          ++reoriented;
        }
      }
    }
    if (reoriented > 0) {
      warnings.push_back(absl::StrCat(
          "reoriented ", reoriented, " triangles for a consistent orientation"));
    }
  }

  // Compact away unreferenced vertices.
  std::vector<int32_t> remap(nv, -1);
  int32_t used = 0;
  for (const auto& t : triangles) {
    for (int32_t v : t) {
      if (remap[v] < 0) remap[v] = 0;
    }
  }
  LoadedMesh loaded;
  loaded.mesh.positions.reserve(nv);
  for (int64_t v = 0; v < nv; ++v) {
    if (remap[v] == 0) {
      remap[v] = used++;
      loaded.mesh.positions.push_back(positions[v]);
    }
  }
  const int64_t unreferenced = nv - used;
  if (unreferenced > 0) {
    warnings.push_back(absl::StrCat("removed ", unreferenced,
                                    " vertices no triangle references"));
  }
  for (auto& t : triangles) {
    for (int32_t& v : t) v = remap[v];
  }
  loaded.mesh.triangles = std::move(triangles);
  loaded.stats = ComputeMeshStats(loaded.mesh);
  loaded.stats.dropped_degenerate_faces = degenerate;
  loaded.stats.dropped_duplicate_faces = duplicates;
  loaded.stats.unreferenced_vertices = unreferenced;
  loaded.warnings = std::move(warnings);
  return loaded;
}

}  // namespace

const char* MeshFormatName(MeshFormat format) {
  switch (format) {
    case MeshFormat::kOff:
      return "OFF";
    case MeshFormat::kObj:
      return "OBJ";
    case MeshFormat::kPly:
      return "PLY";
    case MeshFormat::kStl:
      return "STL";
    case MeshFormat::kUnknown:
      break;
  }
  return "unknown";
}

absl::StatusOr<LoadedMesh> BuildMesh(
    std::vector<Eigen::Vector3d> positions,
    std::vector<std::vector<int32_t>> polygons, const IntakeOptions& options) {
  return ValidateAndClean(std::move(positions), std::move(polygons), options,
                          0, {});
}

absl::StatusOr<LoadedMesh> LoadMeshFromBuffer(absl::string_view bytes,
                                              MeshFormat format,
                                              absl::string_view file_name,
                                              const IntakeOptions& options) {
  if (format == MeshFormat::kUnknown) format = GuessFormat(bytes, file_name);
  if (bytes.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(MeshFormatName(format), ": the file is empty"));
  }
  absl::StatusOr<Scan> scan;
  switch (format) {
    case MeshFormat::kOff:
      scan = ScanOff(bytes, options);
      break;
    case MeshFormat::kObj:
      scan = ScanObj(bytes, options);
      break;
    case MeshFormat::kPly:
      scan = ScanPly(bytes, options);
      break;
    case MeshFormat::kStl:
      scan = LooksLikeAsciiStl(bytes) ? ScanStlAscii(bytes, options)
                                      : ScanStlBinary(bytes, options);
      break;
    case MeshFormat::kUnknown:
      return absl::InvalidArgumentError(
          "cannot tell the mesh format from the name or the bytes (expected "
          "OFF, OBJ, PLY or STL)");
  }
  if (!scan.ok()) return scan.status();

  RecordingImporter importer;
  TPR_RETURN_IF_ERROR(RunOpenMesh(format, bytes, *scan, &importer));

  // The reader must agree with the scan; STL welds vertices and, like OBJ,
  // may drop a face whose corners coincide, which we count as degenerate.
  const char* name = MeshFormatName(format);
  const int64_t got_v = static_cast<int64_t>(importer.positions.size());
  const int64_t got_f = static_cast<int64_t>(importer.polygons.size());
  int64_t reader_dropped = 0;
  if (format == MeshFormat::kStl || format == MeshFormat::kObj) {
    if (got_f > scan->faces ||
        (format == MeshFormat::kObj && got_v != scan->vertices)) {
      return absl::InternalError(absl::StrCat(
          name, ": OpenMesh's reader returned ", got_v, " vertices and ",
          got_f, " faces, the scan found ", scan->vertices, " and ",
          scan->faces));
    }
    reader_dropped = scan->faces - got_f;
  } else if (got_v != scan->vertices || got_f != scan->faces) {
    return absl::InternalError(absl::StrCat(
        name, ": OpenMesh's reader returned ", got_v, " vertices and ", got_f,
        " faces, the header declares ", scan->vertices, " and ", scan->faces));
  }
  std::vector<std::string> warnings;
  if (format == MeshFormat::kStl) {
    warnings.push_back(absl::StrCat("welded ", scan->vertices,
                                    " STL corners into ", got_v, " vertices"));
  }
  return ValidateAndClean(std::move(importer.positions),
                          std::move(importer.polygons), options,
                          reader_dropped, std::move(warnings));
}

absl::StatusOr<LoadedMesh> LoadMeshFromFile(const std::string& path,
                                            const IntakeOptions& options) {
  std::ifstream in(path, std::ios::in | std::ios::binary);
  if (!in) {
    return absl::NotFoundError(
        absl::StrCat("cannot open mesh file '", path, "'"));
  }
  std::string bytes((std::istreambuf_iterator<char>(in)),
                    std::istreambuf_iterator<char>());
  if (in.bad()) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot read mesh file '", path, "'"));
  }
  return LoadMeshFromBuffer(bytes, MeshFormat::kUnknown, path, options);
}

}  // namespace tpr::extract
