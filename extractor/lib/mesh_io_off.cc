// OFF reader (mesh_io_readers.h): plain ASCII OFF only.
#include <cstdint>
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

using absl::string_view;
using mesh_io::Invalid;
using mesh_io::InvalidAt;
using mesh_io::Quote;

absl::StatusOr<PolygonSoup> ReadOff(string_view bytes,
                                    const IntakeOptions& options) {
  constexpr string_view kFmt = "OFF";
  mesh_io::LineReader reader(bytes);
  string_view line;
  std::vector<string_view> tok;
  // Moves to the next line holding a token (comments stripped) and sets
  // `line` to it.
  auto next_content = [&]() -> absl::StatusOr<bool> {
    while (reader.Next(&line)) {
      if (mesh_io::HasBinaryBytes(line)) {
        return InvalidAt(kFmt, reader.number(), "binary data in a text file");
      }
      line = mesh_io::StripComment(line);
      string_view first;
      if (mesh_io::TokenCursor(line).Next(&first)) return true;
    }
    return false;
  };
  if (bytes.empty()) return Invalid(kFmt, "the file is empty");
  TPR_ASSIGN_OR_RETURN(bool have, next_content());
  if (!have) return Invalid(kFmt, "the file is empty");
  mesh_io::SplitTokens(line, &tok, 4);
  if (tok[0] != "OFF") {
    if (absl::EndsWith(tok[0], "OFF")) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("header variant ", Quote(tok[0]),
                                    " is not supported (plain OFF only)"));
    }
    return InvalidAt(
        kFmt, reader.number(),
        absl::StrCat("expected the 'OFF' header, got ", Quote(tok[0])));
  }
  if (tok.size() > 1 && tok[1] == "BINARY") {
    return InvalidAt(kFmt, reader.number(), "binary OFF is not supported");
  }
  std::vector<string_view> counts(tok.begin() + 1, tok.end());
  if (counts.empty()) {
    TPR_ASSIGN_OR_RETURN(have, next_content());
    if (!have) return Invalid(kFmt, "truncated: no vertex and face counts");
    mesh_io::SplitTokens(line, &counts, 3);
  }
  int64_t nv = 0, nf = 0;
  if (counts.size() < 2 || !mesh_io::ParseInt(counts[0], &nv) ||
      !mesh_io::ParseInt(counts[1], &nf) || nv < 0 || nf < 0) {
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
  if (nv > options.max_vertices) return mesh_io::TooManyVertices(nv, options);
  if (nf > options.max_faces) return mesh_io::TooManyFaces(nf, options);

  PolygonSoup soup;
  soup.positions.resize(nv);
  for (int64_t v = 0; v < nv; ++v) {
    TPR_ASSIGN_OR_RETURN(have, next_content());
    if (!have) {
      return Invalid(kFmt, absl::StrCat("truncated: header declares ", nv,
                                        " vertices, the file ends after ", v));
    }
    mesh_io::SplitTokens(line, &tok, 3);
    if (tok.size() < 3) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("vertex ", v, " has ", tok.size(),
                                    " values; 3 are needed"));
    }
    for (int k = 0; k < 3; ++k) {
      TPR_RETURN_IF_ERROR(mesh_io::ParseCoordinate(
          kFmt, reader.number(), v, tok[k], &soup.positions[v][k]));
    }
  }
  soup.offsets.reserve(nf + 1);
  int64_t triangles = 0;
  for (int64_t f = 0; f < nf; ++f) {
    TPR_ASSIGN_OR_RETURN(have, next_content());
    if (!have) {
      return Invalid(kFmt, absl::StrCat("truncated: header declares ", nf,
                                        " faces, the file ends after ", f));
    }
    mesh_io::TokenCursor cursor(line);
    string_view token;
    cursor.Next(&token);
    int64_t n = 0;
    if (!mesh_io::ParseInt(token, &n)) {
      return InvalidAt(
          kFmt, reader.number(),
          absl::StrCat("face ", f, ": expected a vertex count, got ",
                       Quote(token)));
    }
    if (n < 3) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("face ", f, " has ", n,
                                    " vertices; at least 3 are needed"));
    }
    // Count the listed indices without storing them: a line may hold
    // millions, and the limit must refuse before anything is allocated.
    int64_t listed = 0;
    for (mesh_io::TokenCursor count(line); count.Next(&token);) ++listed;
    if (listed - 1 < n) {
      return InvalidAt(kFmt, reader.number(),
                       absl::StrCat("face ", f, " declares ", n,
                                    " vertices but lists ", listed - 1));
    }
    triangles += n - 2;
    if (triangles > options.max_faces) {
      return mesh_io::TooManyFaces(triangles, options);
    }
    for (int64_t k = 0; k < n; ++k) {
      cursor.Next(&token);
      int64_t index = 0;
      if (!mesh_io::ParseInt(token, &index)) {
        return InvalidAt(
            kFmt, reader.number(),
            absl::StrCat("face ", f, ": expected a vertex index, got ",
                         Quote(token)));
      }
      if (index < 0 || index >= nv) {
        return InvalidAt(kFmt, reader.number(),
                         absl::StrCat("face ", f, " references vertex ", index,
                                      "; the file has ", nv, " vertices"));
      }
      soup.corners.push_back(static_cast<int32_t>(index));
    }
    soup.offsets.push_back(static_cast<int64_t>(soup.corners.size()));
  }
  return soup;
}

}  // namespace tpr::extract
