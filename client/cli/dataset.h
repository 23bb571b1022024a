// Which mesh files a `tpr` command works on, with their ids and labels: from
// folders (walked recursively; label = parent folder) or from a manifest of
// "<relative path> <label>" lines.
//
//   absl::StatusOr<std::vector<Item>> items = CollectItems({"shapes/"});
//   absl::StatusOr<std::vector<Item>> set = ItemsFromDataset("shrec/MANIFEST.txt");
//   for (const Item& item : *set) Upload(item.path, item.id, item.label);
#ifndef TPR_CLIENT_CLI_DATASET_H_
#define TPR_CLIENT_CLI_DATASET_H_

#include <map>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace tpr::cli {

// Item is one mesh file to work on.
struct Item {
  std::string path;   // on disk
  std::string id;     // relative path (generic separators)
  std::string label;  // class; "" when none is known
};

// IsMeshFile returns whether `path` has a mesh extension (.off, .obj, .ply,
// .stl; any case).
bool IsMeshFile(const std::string& path);

// ReadManifest returns relative path -> label from `file`: one
// "relative/path label" pair per line, tab or spaces between, '#' comments
// and blank lines ignored (a later line for the same path wins).
// Errors: NOT_FOUND when the file cannot be opened; INVALID_ARGUMENT naming
// file and line for a line without a label. O(file size).
absl::StatusOr<std::map<std::string, std::string>> ReadManifest(const std::string& file);

// CollectItems returns the mesh files under `paths`, each folder walked
// recursively in sorted order (id = path under that folder, label = name of
// the file's parent folder, "" for files directly in it); a file argument
// is taken as given (id = its normalized path, label = its parent folder).
// Errors: NOT_FOUND for an argument that is neither, or a folder that cannot
// be walked. O(files log files).
absl::StatusOr<std::vector<Item>> CollectItems(const std::vector<std::string>& paths);

// ItemsFromDataset returns the labelled models of an evaluation set:
// `dataset` is a folder of class subfolders (as CollectItems; meshes
// directly in the folder have no class and are refused) or a manifest file
// (ReadManifest; paths relative to the manifest's folder; id = that path).
// Sorted by id. Errors: NOT_FOUND for a missing dataset or a manifest entry
// whose file is missing; INVALID_ARGUMENT for meshes outside a class folder,
// a malformed manifest line, or a set without any mesh. O(files log files).
absl::StatusOr<std::vector<Item>> ItemsFromDataset(const std::string& dataset);

}  // namespace tpr::cli

#endif  // TPR_CLIENT_CLI_DATASET_H_
