#include "web/console_files.h"

#include <zlib.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"

namespace tpr::web {
namespace {

constexpr uintmax_t kMaxTotalBytes = uintmax_t{64} << 20;

std::string ContentType(const std::string& path) {
  const std::string ext = std::filesystem::path(path).extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs")
    return "application/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json") return "application/json; charset=utf-8";
  if (ext == ".svg") return "image/svg+xml; charset=utf-8";
  if (ext == ".png") return "image/png";
  if (ext == ".ico") return "image/x-icon";
  if (ext == ".woff2") return "font/woff2";
  return "application/octet-stream";
}

// Gzip returns `bytes` gzip-compressed (zlib level 6), or "" when that
// fails or does not save space.
std::string Gzip(const std::string& bytes) {
  z_stream z{};
  // 15 window bits + 16: a gzip header rather than zlib's.
  if (deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    return "";
  std::string out(deflateBound(&z, bytes.size()) + 32, '\0');
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(bytes.data()));
  z.avail_in = static_cast<uInt>(bytes.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  const int result = deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  if (result != Z_STREAM_END || out.size() >= bytes.size()) return "";
  return out;
}

}  // namespace

absl::StatusOr<ConsoleFiles> ConsoleFiles::Load(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_regular_file(fs::path(dir) / "index.html", ec)) {
    return absl::NotFoundError("the console directory has no index.html");
  }
  ConsoleFiles files;
  uintmax_t total = 0;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end;
       it.increment(ec)) {
    if (!it->is_regular_file(ec)) continue;
    total += it->file_size(ec);
    if (total > kMaxTotalBytes) {
      return absl::ResourceExhaustedError(
          "the console directory holds more than 64 MiB");
    }
    std::ifstream in(it->path(), std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    const std::string relative =
        "/" + fs::relative(it->path(), dir, ec).generic_string();
    File file;
    file.bytes = text.str();
    file.content_type = ContentType(relative);
    if (!absl::StartsWith(file.content_type, "image/png") &&
        !absl::StartsWith(file.content_type, "font/"))
      file.gzip = Gzip(file.bytes);
    file.cache_control = absl::StartsWith(relative, "/assets/")
                             ? "public, max-age=31536000, immutable"
                             : "no-cache";
    files.files_.emplace(relative, std::move(file));
  }
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat("cannot read the console directory: ", ec.message()));
  }
  return files;
}

const ConsoleFiles::File* ConsoleFiles::Find(absl::string_view path) const {
  if (path == "/" || path.empty()) path = "/index.html";
  auto it = files_.find(path);
  return it == files_.end() ? nullptr : &it->second;
}

}  // namespace tpr::web
