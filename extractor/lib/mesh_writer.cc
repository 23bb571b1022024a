// Mesh output. Hand-written rather than OpenMesh's writers: those go through
// a PolyMesh with float points (losing the doubles we computed) and report
// failure as a bool; the formats are small enough to emit directly.
#include "extractor/lib/mesh_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace tpr::extract {
namespace {

// std::to_chars is locale-independent (snprintf's "%g" is not: a program
// that calls setlocale could write "1,5") and yields the same bytes for the
// same double, which byte-identical output relies on.
// With 17 digits the shortest text that reads back as the same double is
// written ("0.1", not "0.10000000000000001").
void AppendNumber(std::string* out, double value, int digits) {
  char buffer[64];
  const auto result =
      digits >= 17 ? std::to_chars(buffer, buffer + sizeof(buffer), value)
                   : std::to_chars(buffer, buffer + sizeof(buffer), value,
                                   std::chars_format::general, digits);
  out->append(buffer, result.ptr);
}

void AppendInt(std::string* out, int64_t value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out->append(buffer, result.ptr);
}

bool LittleEndianHost() {
  const uint16_t one = 1;
  uint8_t first;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

template <typename T>
void AppendLittleEndian(std::string* out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if (!LittleEndianHost()) {
    for (size_t i = 0; i < sizeof(T) / 2; ++i) {
      std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
    }
  }
  out->append(bytes, sizeof(T));
}

absl::Status Validate(const Mesh& mesh, const MeshWriteOptions& options) {
  if (options.digits < 6 || options.digits > 17) {
    return absl::InvalidArgumentError(
        absl::StrCat("digits ", options.digits, " is outside [6, 17]"));
  }
  if (!options.vertex_colors.empty() &&
      options.vertex_colors.size() != mesh.positions.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("vertex_colors has ", options.vertex_colors.size(),
                     " entries for ", mesh.positions.size(), " vertices"));
  }
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    if (!mesh.positions[v].allFinite()) {
      return absl::InvalidArgumentError(
          absl::StrCat("vertex ", v, " has a non-finite coordinate"));
    }
  }
  const int64_t n = static_cast<int64_t>(mesh.positions.size());
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    for (int32_t v : mesh.triangles[f]) {
      if (v < 0 || v >= n) {
        return absl::InvalidArgumentError(absl::StrCat(
            "triangle ", f, " has vertex index ", v, " outside [0, ", n, ")"));
      }
    }
  }
  return absl::OkStatus();
}

std::string PlyHeader(const Mesh& mesh, bool binary, bool colors, int digits) {
  std::string out = "ply\n";
  absl::StrAppend(&out, "format ", binary ? "binary_little_endian" : "ascii",
                  " 1.0\n");
  absl::StrAppend(&out, "comment written by TPR Search\n");
  absl::StrAppend(&out, "element vertex ", mesh.positions.size(), "\n");
  // Binary keeps the doubles exact; ASCII with more digits than a float
  // holds declares double so that readers keep them.
  const char* type = binary || digits > 9 ? "double" : "float";
  for (const char* axis : {"x", "y", "z"}) {
    absl::StrAppend(&out, "property ", type, " ", axis, "\n");
  }
  if (colors) {
    out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  }
  absl::StrAppend(&out, "element face ", mesh.triangles.size(), "\n");
  out += "property list uchar int vertex_indices\nend_header\n";
  return out;
}

// FileError maps an errno from writing `path` to a code a caller need not
// retry (the same call fails the same way until someone changes the file
// system): NOT_FOUND for a missing directory, PERMISSION_DENIED,
// RESOURCE_EXHAUSTED for a full disk or quota, FAILED_PRECONDITION for
// anything else about the path (a directory, a read-only file system).
absl::Status FileError(int error, const char* what, const std::string& path) {
  const std::string message =
      absl::StrCat(what, " '", path, "': ", std::strerror(error));
  switch (error) {
    case ENOENT:
    case ENOTDIR:
      return absl::NotFoundError(
          absl::StrCat(message, " (a directory on the path is missing)"));
    case EACCES:
    case EPERM:
      return absl::PermissionDeniedError(message);
    case ENOSPC:
    case EDQUOT:
    case EFBIG:
      return absl::ResourceExhaustedError(message);
    default:
      return absl::FailedPreconditionError(message);
  }
}

}  // namespace

absl::StatusOr<std::string> WriteMeshToString(const Mesh& mesh,
                                              const MeshWriteOptions& options) {
  absl::Status valid = Validate(mesh, options);
  if (!valid.ok()) return valid;
  const bool colors = !options.vertex_colors.empty();
  std::string out;
  out.reserve(mesh.positions.size() * (colors ? 72 : 60) +
              mesh.triangles.size() * 24 + 256);

  if (options.format == MeshWriteFormat::kPlyBinary) {
    out += PlyHeader(mesh, /*binary=*/true, colors, options.digits);
    for (size_t v = 0; v < mesh.positions.size(); ++v) {
      for (int a = 0; a < 3; ++a)
        AppendLittleEndian(&out, mesh.positions[v][a]);
      if (colors) {
        for (uint8_t c : options.vertex_colors[v])
          out.push_back(static_cast<char>(c));
      }
    }
    for (const auto& t : mesh.triangles) {
      out.push_back(3);
      for (int32_t v : t) AppendLittleEndian(&out, v);
    }
    return out;
  }

  const bool off = options.format == MeshWriteFormat::kOff;
  if (off) {
    // COFF carries colours as r g b a per vertex line (Geomview's layout).
    out += colors ? "COFF\n" : "OFF\n";
    absl::StrAppend(&out, mesh.positions.size(), " ", mesh.triangles.size(),
                    " 0\n");
  } else {
    out += PlyHeader(mesh, /*binary=*/false, colors, options.digits);
  }
  for (size_t v = 0; v < mesh.positions.size(); ++v) {
    for (int a = 0; a < 3; ++a) {
      if (a > 0) out.push_back(' ');
      AppendNumber(&out, mesh.positions[v][a], options.digits);
    }
    if (colors) {
      for (uint8_t c : options.vertex_colors[v]) {
        out.push_back(' ');
        AppendInt(&out, c);
      }
      if (off) out += " 255";
    }
    out.push_back('\n');
  }
  for (const auto& t : mesh.triangles) {
    out += "3";
    for (int32_t v : t) {
      out.push_back(' ');
      AppendInt(&out, v);
    }
    out.push_back('\n');
  }
  return out;
}

absl::Status WriteMeshToFile(const Mesh& mesh, const MeshWriteOptions& options,
                             const std::string& path) {
  absl::StatusOr<std::string> bytes = WriteMeshToString(mesh, options);
  if (!bytes.ok()) return bytes.status();
  const int fd =
      ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return FileError(errno, "cannot open", path);
  size_t written = 0;
  while (written < bytes->size()) {
    const ssize_t n =
        ::write(fd, bytes->data() + written, bytes->size() - written);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int error = n < 0 ? errno : EIO;
      ::close(fd);
      return FileError(error, "cannot write", path);
    }
    written += static_cast<size_t>(n);
  }
  if (::close(fd) != 0) return FileError(errno, "cannot write", path);
  return absl::OkStatus();
}

}  // namespace tpr::extract
