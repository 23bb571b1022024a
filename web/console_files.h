// ConsoleFiles: the built console (index.html, assets/) held in memory and
// served by tpr-web, each file also gzip-compressed once at load.
//
// Why not httplib's own mount point: it compresses every text response per
// request, with brotli at quality 11 when the browser accepts it, which
// takes over 2 s for the 600 KB bundle on this kind of machine; a file
// compressed once at start costs nothing per request.
//
//   absl::StatusOr<ConsoleFiles> files =
//   ConsoleFiles::Load("build/web/console"); const ConsoleFiles::File* f =
//   files->Find("/assets/index-abc.js");
#ifndef TPR_WEB_CONSOLE_FILES_H_
#define TPR_WEB_CONSOLE_FILES_H_

#include <map>
#include <string>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace tpr::web {

// ConsoleFiles: path ("/index.html") -> file. Immutable after Load, hence
// thread-safe.
class ConsoleFiles {
 public:
  struct File {
    std::string bytes;
    // gzip of bytes; empty when compression would not make it smaller.
    std::string gzip;
    // Content type with a charset for text, so that the HTTP layer's own
    // compressor leaves it alone.
    std::string content_type;
    // Cache-Control: assets/ names carry a content hash (vite), so they
    // never change; index.html is revalidated.
    std::string cache_control;
  };

  // Load reads every regular file under `dir` (at most 64 MiB in all).
  // NOT_FOUND when dir has no index.html, RESOURCE_EXHAUSTED beyond the
  // bound. Cost: one read and one gzip pass of each file.
  static absl::StatusOr<ConsoleFiles> Load(const std::string& dir);

  // Find returns the file at `path` ("/" is "/index.html"), or nullptr.
  const File* Find(absl::string_view path) const;

 private:
  std::map<std::string, File, std::less<>> files_;
};

}  // namespace tpr::web

#endif  // TPR_WEB_CONSOLE_FILES_H_
