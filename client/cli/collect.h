// Which files `tpr add` indexes, under which ids and labels, and which it
// skips and why.
//
// Naming: a folder F given on the command line is walked recursively. A
// mesh directly in F gets the id "<name of F>/<file>" and the label
// "<name of F>"; a mesh in a subfolder gets its path under F as id and the
// name of its own folder as label. So `tpr add library` and, later,
// `tpr add library/dog1` give library/dog1/T305.obj the same id,
// "dog1/T305.obj", and the same label, "dog1". A mesh file given on the
// command line is named as if its folder had been given. --label replaces
// every label, --id-prefix is put before every id.
//
//   absl::StatusOr<Collected> c = CollectAddFiles({"library"}, naming);
//   for (const AddFile& f : c->files) Add(f.path, f.id, f.label);
#ifndef TPR_CLIENT_CLI_COLLECT_H_
#define TPR_CLIENT_CLI_COLLECT_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace tpr::cli {

// Naming: what the user chose instead of the default ids and labels.
struct Naming {
  // Label of every file; empty: the folder rule above.
  std::string label;
  // Put before every id, e.g. "shop/" gives "shop/dog1/T305.obj". Default
  // none.
  std::string id_prefix;
};

// AddFile is one mesh to index.
struct AddFile {
  std::string path;      // on disk, as found
  std::string id;        // see the naming rule
  std::string label;     // never empty unless --label "" would be given
  std::string relative;  // path under the folder given (a --manifest key)
};

// SkippedFile is a file that was found but will not be indexed.
struct SkippedFile {
  std::string path;
  std::string reason;
};

// Collected is the outcome of CollectAddFiles.
struct Collected {
  std::vector<AddFile> files;  // sorted by folder argument, then path
  std::vector<SkippedFile> skipped;
};

// CollectAddFiles returns the meshes under `paths` (folders walked in
// sorted order, files taken as given) named as above, and every other file
// met with the reason it is skipped (not a mesh format, not a regular
// file). Errors: NOT_FOUND for an argument that does not exist or a folder
// that cannot be walked; INVALID_ARGUMENT when two files would get one id,
// naming both (the user resolves it with separate runs and --id-prefix).
// O(files log files).
absl::StatusOr<Collected> CollectAddFiles(const std::vector<std::string>& paths,
                                          const Naming& naming);

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_COLLECT_H_
