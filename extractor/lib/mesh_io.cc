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
  absl::StatusOr<PolygonSoup> soup;
  switch (format) {
    case MeshFormat::kOff:
      soup = ReadOff(bytes, options);
      break;
    case MeshFormat::kObj:
      soup = ReadObj(bytes, options);
      break;
    case MeshFormat::kPly:
      soup = ReadPly(bytes, options);
      break;
    case MeshFormat::kStl:
      soup = ReadStl(bytes, options);
      break;
    case MeshFormat::kUnknown:
      return absl::InvalidArgumentError(
          "cannot tell the mesh format from the name or the bytes (expected "
          "OFF, OBJ, PLY or STL)");
  }
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
