// Which mesh files an evaluation or a `tpr` command works on, with their ids
// and classes: folders walked recursively (class = parent folder) or a
// manifest of "<relative path> <class>" lines. The one dataset reader of the
// repository: `tpr add`, `tpr eval` and tpr-eval-local all read through it.
//
//   absl::StatusOr<std::vector<Item>> items = CollectItems({"shapes/"});
//   absl::StatusOr<std::vector<Item>> set = ReadDataset("shrec/MANIFEST.txt");
//   for (const Item& item : *set) Upload(item.path, item.id, item.label);
#ifndef TPR_EVAL_LIB_DATASET_H_
#define TPR_EVAL_LIB_DATASET_H_

#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace tpr::eval {

// Item is one mesh file to work on.
struct Item {
  std::string path;   // on disk
  std::string id;     // relative path (generic separators)
  std::string label;  // class; "" when none is known
};

// IsMeshFile returns whether `path` has a mesh extension (.off, .obj, .ply,
// .stl; any case). Pure.
bool IsMeshFile(const std::string& path);

// ManifestEntry is one "<relative path> <label>" line of a manifest.
struct ManifestEntry {
  std::string path;  // as written, relative to the manifest's folder
  std::string label;
  int line = 0;  // 1-based, for messages
};

// ReadManifestEntries returns the entries of `file` in file order: one
// "relative/path label" pair per line, tab or spaces between, further
// fields ignored, '#' comments and blank lines skipped.
// Errors: NOT_FOUND when the file cannot be opened; INVALID_ARGUMENT naming
// file and line for a line without a label. O(file size).
absl::StatusOr<std::vector<ManifestEntry>> ReadManifestEntries(
    const std::string& file);

// ReadManifest returns relative path -> label from `file`
// (ReadManifestEntries; a later line for the same path wins). Errors as
// ReadManifestEntries.
absl::StatusOr<std::map<std::string, std::string>> ReadManifest(
    const std::string& file);

// CollectItems returns the mesh files under `paths`, each folder walked
// recursively in sorted order (id = path under that folder, label = name of
// the file's parent folder, "" for files directly in it); a file argument
// is taken as given (id = its normalized path, label = its parent folder).
// Errors: NOT_FOUND for an argument that is neither, or a folder that cannot
// be walked. O(files log files).
absl::StatusOr<std::vector<Item>> CollectItems(
    const std::vector<std::string>& paths);

// ReadDataset returns the labelled models of an evaluation set. `dataset`
// is a folder of class subfolders (as CollectItems, sorted by id; meshes
// directly in the folder have no class and are refused) or a manifest file
// (ReadManifestEntries, in file order; paths relative to the manifest's
// folder; id = that path, normalized). The order is kept because a caller
// may derive seeds from an item's position.
// Errors: NOT_FOUND for a missing dataset or a manifest entry whose file is
// missing (naming the line); INVALID_ARGUMENT for meshes outside a class
// folder, a malformed manifest line, an id listed twice, or a set without
// any mesh. O(files log files).
absl::StatusOr<std::vector<Item>> ReadDataset(const std::string& dataset);

}  // namespace tpr::eval

#endif  // TPR_EVAL_LIB_DATASET_H_
