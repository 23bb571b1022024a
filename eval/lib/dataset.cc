#include "eval/lib/dataset.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <system_error>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"

namespace tpr::eval {

namespace fs = std::filesystem;

bool IsMeshFile(const std::string& path) {
  const std::string ext =
      absl::AsciiStrToLower(fs::path(path).extension().string());
  return ext == ".off" || ext == ".obj" || ext == ".ply" || ext == ".stl";
}

absl::StatusOr<std::vector<ManifestEntry>> ReadManifestEntries(
    const std::string& file) {
  std::ifstream in(file);
  if (!in) {
    return absl::NotFoundError(absl::StrCat("cannot open manifest ", file));
  }
  std::vector<ManifestEntry> entries;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    absl::string_view l = absl::StripAsciiWhitespace(line);
    if (l.empty() || l[0] == '#') continue;
    std::vector<std::string> fields =
        absl::StrSplit(l, absl::ByAnyChar(" \t"), absl::SkipEmpty());
    if (fields.size() < 2) {
      return absl::InvalidArgumentError(absl::StrCat(
          file, ":", number, ": expected 'PATH LABEL', got '", l, "'"));
    }
    entries.push_back({fields[0], fields[1], number});
  }
  return entries;
}

absl::StatusOr<std::map<std::string, std::string>> ReadManifest(
    const std::string& file) {
  absl::StatusOr<std::vector<ManifestEntry>> entries =
      ReadManifestEntries(file);
  if (!entries.ok()) return entries.status();
  std::map<std::string, std::string> labels;
  for (ManifestEntry& e : *entries) labels[e.path] = std::move(e.label);
  return labels;
}

absl::StatusOr<std::vector<Item>> CollectItems(
    const std::vector<std::string>& paths) {
  std::vector<Item> items;
  for (const std::string& arg : paths) {
    std::error_code ec;
    const fs::path root(arg);
    if (fs::is_directory(root, ec)) {
      std::vector<fs::path> files;
      for (auto it = fs::recursive_directory_iterator(root, ec);
           !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
        if (it->is_regular_file() && IsMeshFile(it->path().string())) {
          files.push_back(it->path());
        }
      }
      if (ec) {
        return absl::NotFoundError(
            absl::StrCat("cannot walk ", arg, ": ", ec.message()));
      }
      std::sort(files.begin(), files.end());
      for (const fs::path& f : files) {
        Item item;
        item.path = f.string();
        item.id = f.lexically_relative(root).generic_string();
        item.label =
            f.parent_path() == root ? "" : f.parent_path().filename().string();
        items.push_back(std::move(item));
      }
    } else if (fs::is_regular_file(root, ec)) {
      Item item;
      item.path = arg;
      item.id = root.lexically_normal().generic_string();
      item.label = root.parent_path().filename().string();
      items.push_back(std::move(item));
    } else {
      return absl::NotFoundError(absl::StrCat("no such file or folder: ", arg));
    }
  }
  return items;
}

absl::StatusOr<std::vector<Item>> ReadDataset(const std::string& dataset) {
  std::error_code ec;
  std::vector<Item> items;
  if (fs::is_directory(dataset, ec)) {
    absl::StatusOr<std::vector<Item>> found = CollectItems({dataset});
    if (!found.ok()) return found.status();
    for (Item& item : *found) {
      // A mesh beside the class folders has no class to be relevant to.
      if (item.label.empty()) {
        return absl::InvalidArgumentError(
            absl::StrCat(item.path,
                         " is not in a class folder (DATASET holds one "
                         "folder per class)"));
      }
    }
    items = std::move(*found);
  } else if (fs::is_regular_file(dataset, ec)) {
    absl::StatusOr<std::vector<ManifestEntry>> entries =
        ReadManifestEntries(dataset);
    if (!entries.ok()) return entries.status();
    const fs::path root = fs::path(dataset).parent_path();
    for (ManifestEntry& e : *entries) {
      Item item;
      item.path = (root / e.path).string();
      item.id = fs::path(e.path).lexically_normal().generic_string();
      item.label = std::move(e.label);
      if (!fs::is_regular_file(item.path, ec)) {
        return absl::NotFoundError(absl::StrCat(dataset, ":", e.line,
                                                ": no such mesh file: ", e.path,
                                                " (", item.path, ")"));
      }
      items.push_back(std::move(item));
    }
  } else {
    return absl::NotFoundError(
        absl::StrCat("no such folder or manifest: ", dataset));
  }
  if (items.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(dataset, " holds no mesh file"));
  }
  std::set<std::string> ids;
  for (const Item& item : items) {
    if (!ids.insert(item.id).second) {
      return absl::InvalidArgumentError(
          absl::StrCat(dataset, ": ", item.id, " is listed twice"));
    }
  }
  return items;
}

}  // namespace tpr::eval
