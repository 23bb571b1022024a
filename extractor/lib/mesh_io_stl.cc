// STL reader (mesh_io_readers.h): ASCII and binary, corners welded by
// position.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/match.h"
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

bool LooksLikeAsciiStl(string_view bytes) {
  size_t i = 0;
  while (i < bytes.size() && mesh_io::IsSpace(bytes[i])) ++i;
  if (!absl::StartsWith(bytes.substr(i), "solid")) return false;
  // Control bytes early on mean binary data behind a "solid" header.
  if (mesh_io::HasBinaryBytes(bytes.substr(0, 4096))) return false;
  // Binary files often start their 80-byte header with "solid" too; a size
  // that matches the binary layout exactly decides for binary.
  if (bytes.size() >= 84) {
    const uint64_t n = mesh_io::LoadLe32(bytes.data() + 80);
    if (84 + 50 * n == bytes.size()) return false;
  }
  return true;
}

// Corners as float triples, three per facet, before welding.
using Corners = std::vector<std::array<float, 3>>;

// Weld gives corners at equal float positions one vertex id,
// numbered in order of first appearance, and makes the soup; a facet whose
// corners weld together is dropped and counted. Sorting rather than
// hashing: O(n log n), no hash table to size, and the order is
// deterministic by construction.
PolygonSoup Weld(const Corners& corners) {
  const int64_t n = static_cast<int64_t>(corners.size());
  std::vector<int32_t> order(n);
  for (int64_t c = 0; c < n; ++c) order[c] = static_cast<int32_t>(c);
  auto key = [&](int32_t c) {
    std::array<float, 3> k = corners[c];
    // -0 = +0, and subnormals are 0: positions closer than FLT_MIN weld,
    // as they always have (OpenMesh's reader compared within FLT_MIN).
    for (float& x : k) {
      if (std::fabs(x) < std::numeric_limits<float>::min()) x = 0.0f;
    }
    return k;
  };
  std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
    const auto ka = key(a), kb = key(b);
    return ka != kb ? ka < kb : a < b;
  });
  // first[c]: the earliest corner at c's position.
  std::vector<int32_t> first(n);
  for (int64_t i = 0; i < n; ++i) {
    first[order[i]] = i > 0 && key(order[i]) == key(order[i - 1])
                          ? first[order[i - 1]]
                          : order[i];
  }
  order = {};
  PolygonSoup soup;
  std::vector<int32_t> id(n);
  for (int64_t c = 0; c < n; ++c) {
    if (first[c] == c) {
      id[c] = static_cast<int32_t>(soup.positions.size());
      soup.positions.emplace_back(corners[c][0], corners[c][1], corners[c][2]);
    } else {
      id[c] = id[first[c]];
    }
  }
  soup.offsets.reserve(n / 3 + 1);
  soup.corners.reserve(n);
  for (int64_t f = 0; f < n / 3; ++f) {
    const int32_t a = id[3 * f], b = id[3 * f + 1], c = id[3 * f + 2];
    if (a == b || b == c || a == c) {
      ++soup.reader_dropped_degenerate;
      continue;
    }
    soup.AddPolygon({a, b, c});
  }
  soup.warnings.push_back(absl::StrCat("welded ", n, " STL corners into ",
                                       soup.positions.size(), " vertices"));
  return soup;
}

absl::StatusOr<PolygonSoup> ReadStlBinary(string_view bytes,
                                          const IntakeOptions& options) {
  constexpr string_view kFmt = "STL (binary)";
  if (bytes.size() < 84) {
    return Invalid(kFmt, absl::StrCat("truncated: ", bytes.size(),
                                      " bytes, the header alone is 84"));
  }
  const uint64_t n = mesh_io::LoadLe32(bytes.data() + 80);
  if (84 + 50 * n != bytes.size()) {
    return Invalid(kFmt, absl::StrCat("header declares ", n, " triangles (",
                                      84 + 50 * n, " bytes) but the file has ",
                                      bytes.size(), " bytes"));
  }
  if (static_cast<int64_t>(n) > options.max_faces) {
    return mesh_io::TooManyFaces(static_cast<int64_t>(n), options);
  }
  if (n == 0) return Invalid(kFmt, "the file holds no triangles");
  Corners corners(3 * n);
  for (uint64_t t = 0; t < n; ++t) {
    for (int corner = 0; corner < 3; ++corner) {
      for (int c = 0; c < 3; ++c) {
        const uint32_t raw = mesh_io::LoadLe32(bytes.data() + 84 + 50 * t + 12 +
                                               12 * corner + 4 * c);
        float value;
        std::memcpy(&value, &raw, sizeof(value));
        TPR_RETURN_IF_ERROR(mesh_io::CheckCoordinateValue(
            kFmt, absl::StrCat("triangle ", t, " corner ", corner), value));
        corners[3 * t + corner][c] = value;
      }
    }
  }
  return Weld(corners);
}

absl::StatusOr<PolygonSoup> ReadStlAscii(string_view bytes,
                                         const IntakeOptions& options) {
  constexpr string_view kFmt = "STL (ASCII)";
  mesh_io::LineReader reader(bytes);
  string_view line;
  std::vector<string_view> tok;
  enum class State { kOutside, kSolid, kFacet, kLoopDone, kFacetDone };
  State state = State::kOutside;
  Corners corners;
  int64_t faces = 0;
  while (reader.Next(&line)) {
    if (mesh_io::HasBinaryBytes(line)) {
      return InvalidAt(kFmt, reader.number(), "binary data in a text file");
    }
    mesh_io::SplitTokens(line, &tok, 6);
    if (tok.empty()) continue;
    const int64_t at = reader.number();
    if (tok[0] == "solid" && state == State::kOutside) {
      state = State::kSolid;
    } else if (tok[0] == "endsolid" && state == State::kSolid) {
      state = State::kOutside;
    } else if (tok[0] == "facet" && state == State::kSolid) {
      if (tok.size() != 5 || tok[1] != "normal") {
        return InvalidAt(kFmt, at, "expected 'facet normal nx ny nz'");
      }
      state = State::kFacet;
    } else if (tok.size() == 2 && tok[0] == "outer" && tok[1] == "loop" &&
               state == State::kFacet) {
      for (int corner = 0; corner < 3; ++corner) {
        if (!reader.Next(&line)) {
          return Invalid(kFmt,
                         absl::StrCat("truncated inside triangle ", faces));
        }
        mesh_io::SplitTokens(line, &tok, 5);
        if (tok.size() != 4 || tok[0] != "vertex") {
          return InvalidAt(
              kFmt, reader.number(),
              absl::StrCat("triangle ", faces, ": expected 'vertex x y z'"));
        }
        std::array<float, 3> p;
        for (int k = 0; k < 3; ++k) {
          double value = 0.0;
          TPR_RETURN_IF_ERROR(mesh_io::ParseCoordinate(
              kFmt, reader.number(), static_cast<int64_t>(corners.size()),
              tok[k + 1], &value));
          p[k] = static_cast<float>(value);  // exact: value has float precision
        }
        corners.push_back(p);
      }
      state = State::kLoopDone;
    } else if (tok[0] == "endloop" && state == State::kLoopDone) {
      state = State::kFacetDone;
    } else if (tok[0] == "endfacet" && state == State::kFacetDone) {
      state = State::kSolid;
      if (++faces > options.max_faces) {
        return mesh_io::TooManyFaces(faces, options);
      }
    } else {
      return InvalidAt(kFmt, at,
                       absl::StrCat("unexpected ", mesh_io::Quote(tok[0])));
    }
  }
  if (state != State::kOutside && state != State::kSolid) {
    return Invalid(kFmt, absl::StrCat("truncated inside triangle ", faces));
  }
  if (faces == 0) return Invalid(kFmt, "the file holds no triangles");
  return Weld(corners);
}

}  // namespace

absl::StatusOr<PolygonSoup> ReadStl(string_view bytes,
                                    const IntakeOptions& options) {
  return LooksLikeAsciiStl(bytes) ? ReadStlAscii(bytes, options)
                                  : ReadStlBinary(bytes, options);
}

}  // namespace tpr::extract
