// OBJ reader (mesh_io_readers.h): "v" and "f" statements only.
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"
#include "common/status_macros.h"
#include "extractor/lib/mesh_io_readers.h"
#include "extractor/lib/mesh_io_text.h"

namespace tpr::extract {

using absl::string_view;
using mesh_io::Invalid;
using mesh_io::InvalidAt;
using mesh_io::Quote;

absl::StatusOr<PolygonSoup> ReadObj(string_view bytes,
                                    const IntakeOptions& options) {
  constexpr string_view kFmt = "OBJ";
  constexpr int32_t kTooLarge = std::numeric_limits<int32_t>::max();
  mesh_io::LineReader reader(bytes);
  string_view line;
  std::vector<string_view> tok;
  PolygonSoup soup;
  std::vector<int64_t> face_lines;  // for errors found after the last 'v'
  int64_t first_too_large = 0;      // the value behind the first kTooLarge
  int64_t triangles = 0;
  while (reader.Next(&line)) {
    if (mesh_io::HasBinaryBytes(line)) {
      return InvalidAt(kFmt, reader.number(), "binary data in a text file");
    }
    line = mesh_io::StripComment(line);
    mesh_io::TokenCursor cursor(line);
    string_view keyword;
    if (!cursor.Next(&keyword)) continue;
    if (keyword == "v") {
      const int64_t v = static_cast<int64_t>(soup.positions.size());
      mesh_io::SplitTokens(line, &tok, 4);
      if (tok.size() < 4) {
        return InvalidAt(kFmt, reader.number(),
                         absl::StrCat("vertex ", v, " has ", tok.size() - 1,
                                      " values; 3 are needed"));
      }
      Eigen::Vector3d p;
      for (int k = 0; k < 3; ++k) {
        TPR_RETURN_IF_ERROR(mesh_io::ParseCoordinate(kFmt, reader.number(), v,
                                                     tok[k + 1], &p[k]));
      }
      if (v + 1 > options.max_vertices) {
        return mesh_io::TooManyVertices(v + 1, options);
      }
      soup.positions.push_back(p);
    } else if (keyword == "f") {
      const int64_t face = static_cast<int64_t>(face_lines.size());
      // Count first: a line may list millions of corners, and the limit
      // must refuse before any of them is stored.
      int64_t n = 0;
      string_view ref;
      for (mesh_io::TokenCursor count = cursor; count.Next(&ref);) ++n;
      if (n < 3) {
        return InvalidAt(kFmt, reader.number(),
                         absl::StrCat("face ", face, " has ", n,
                                      " vertices; at least 3 are needed"));
      }
      if (triangles + n - 2 > options.max_faces) {
        return mesh_io::TooManyFaces(triangles + n - 2, options);
      }
      while (cursor.Next(&ref)) {
        const string_view vertex = ref.substr(0, ref.find('/'));
        int64_t index = 0;
        if (!mesh_io::ParseInt(vertex, &index) || index == 0) {
          return InvalidAt(
              kFmt, reader.number(),
              absl::StrCat("face ", face,
                           ": expected a vertex index (1-based), got ",
                           Quote(ref)));
        }
        // Negative indices count back from the latest vertex (OBJ spec).
        if (index < 0) {
          index += static_cast<int64_t>(soup.positions.size()) + 1;
        }
        if (index < 1) {
          return InvalidAt(
              kFmt, reader.number(),
              absl::StrCat("face ", face, " references relative vertex ",
                           vertex, " before vertex 1"));
        }
        if (index >= kTooLarge) {
          if (first_too_large == 0) first_too_large = index;
          index = kTooLarge;
        }
        soup.corners.push_back(static_cast<int32_t>(index));  // 1-based
      }
      soup.offsets.push_back(static_cast<int64_t>(soup.corners.size()));
      face_lines.push_back(reader.number());
      triangles += n - 2;
    }
  }
  // Ranges are known only now: a face may name a vertex defined after it.
  const int64_t nv = static_cast<int64_t>(soup.positions.size());
  for (int64_t f = 0; f < soup.num_polygons(); ++f) {
    for (int64_t k = soup.offsets[f]; k < soup.offsets[f + 1]; ++k) {
      if (soup.corners[k] > nv) {
        const int64_t index =
            soup.corners[k] == kTooLarge ? first_too_large : soup.corners[k];
        return InvalidAt(
            kFmt, face_lines[f],
            absl::StrCat("face ", f, " references vertex ", index,
                         " (1-based); the file has ", nv, " vertices"));
      }
    }
  }
  if (nv == 0) return Invalid(kFmt, "no vertices ('v' lines) found");
  if (soup.num_polygons() == 0)
    return Invalid(kFmt, "no faces ('f' lines) found");
  face_lines = {};
  // 0-based ids; a face's repeated ids are removed (first kept) and a face
  // left with fewer than three is dropped as degenerate.
  std::vector<int64_t> seen(nv, -1);
  int64_t out = 0;
  int64_t out_polygons = 0;
  const int64_t num_polygons = soup.num_polygons();
  int64_t begin_in = 0;
  for (int64_t f = 0; f < num_polygons; ++f) {
    const int64_t begin = out;
    const int64_t end_in = soup.offsets[f + 1];  // read before rewritten
    for (int64_t k = begin_in; k < end_in; ++k) {
      const int32_t v = soup.corners[k] - 1;
      if (seen[v] == f) continue;
      seen[v] = f;
      soup.corners[out++] = v;
    }
    begin_in = end_in;
    if (out - begin < 3) {
      out = begin;
      ++soup.reader_dropped_degenerate;
      continue;
    }
    soup.offsets[++out_polygons] = out;
  }
  soup.corners.resize(out);
  soup.offsets.resize(out_polygons + 1);
  return soup;
}

}  // namespace tpr::extract
