// Mesh intake: pick the reader (mesh_io_readers.h), then clean
// (mesh_clean.h). Each file is parsed once, by its reader.
#include "extractor/lib/mesh_io.h"

#include <cstdint>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "common/status_macros.h"
#include "extractor/lib/mesh_clean.h"
#include "extractor/lib/mesh_io_readers.h"
#include "extractor/lib/mesh_io_text.h"

namespace tpr::extract {
namespace {

using absl::string_view;

// The readers, one row per format. A new format is a reader
// (mesh_io_<format>.cc, declared in mesh_io_readers.h), its MeshFormat
// value (mesh_io.h) and a row here; recognising its bytes without a file
// name (GuessFormat below) is optional.
struct Reader {
  MeshFormat format;
  const char* name;       // in messages and MeshFormatName
  const char* extension;  // lower case, with the dot
  absl::StatusOr<PolygonSoup> (*read)(string_view bytes,
                                      const IntakeOptions& options);
};
constexpr Reader kReaders[] = {
    {MeshFormat::kOff, "OFF", ".off", ReadOff},
    {MeshFormat::kObj, "OBJ", ".obj", ReadObj},
    {MeshFormat::kPly, "PLY", ".ply", ReadPly},
    {MeshFormat::kStl, "STL", ".stl", ReadStl},
};

const Reader* FindReader(MeshFormat format) {
  for (const Reader& r : kReaders) {
    if (r.format == format) return &r;
  }
  return nullptr;
}

// "OFF, OBJ, PLY or STL".
std::string ReaderNames() {
  std::string out;
  const size_t n = std::size(kReaders);
  for (size_t i = 0; i < n; ++i) {
    absl::StrAppend(&out,
                    i == 0       ? ""
                    : i + 1 == n ? " or "
                                 : ", ",
                    kReaders[i].name);
  }
  return out;
}

MeshFormat GuessFormat(string_view bytes, string_view file_name) {
  const std::string lower = absl::AsciiStrToLower(file_name);
  for (const Reader& r : kReaders) {
    if (absl::EndsWith(lower, r.extension)) return r.format;
  }
  if (absl::StartsWith(bytes, "ply\n") || absl::StartsWith(bytes, "ply\r")) {
    return MeshFormat::kPly;
  }
  // Skip blanks and '#' comment lines (OFF and OBJ allow them).
  size_t i = 0;
  while (i < bytes.size()) {
    if (mesh_io::IsSpace(bytes[i])) {
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
      84 + 50 * static_cast<uint64_t>(mesh_io::LoadLe32(bytes.data() + 80)) ==
          bytes.size()) {
    return MeshFormat::kStl;
  }
  if (absl::StartsWith(rest, "v ") || absl::StrContains(bytes, "\nv ")) {
    return MeshFormat::kObj;
  }
  return MeshFormat::kUnknown;
}

}  // namespace

const char* MeshFormatName(MeshFormat format) {
  const Reader* reader = FindReader(format);
  return reader != nullptr ? reader->name : "unknown";
}

absl::StatusOr<LoadedMesh> BuildMesh(std::vector<Eigen::Vector3d> positions,
                                     std::vector<std::vector<int32_t>> polygons,
                                     const IntakeOptions& options) {
  PolygonSoup soup;
  soup.positions = std::move(positions);
  soup.offsets.reserve(polygons.size() + 1);
  for (const auto& polygon : polygons) soup.AddPolygon(polygon);
  polygons = {};
  return CleanPolygonSoup(std::move(soup), options);
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
  const Reader* reader = FindReader(format);
  if (reader == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat(
        "cannot tell the mesh format from the name or the bytes (expected ",
        ReaderNames(), ")"));
  }
  absl::StatusOr<PolygonSoup> soup = reader->read(bytes, options);
  if (!soup.ok()) return soup.status();
  return CleanPolygonSoup(*std::move(soup), options);
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
