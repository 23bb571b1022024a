#include "client/cli/collect.h"

#include <algorithm>
#include <filesystem>
#include <map>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "eval/lib/dataset.h"

namespace tpr::cli {
namespace {

namespace fs = std::filesystem;

constexpr char kNotMesh[] =
    "not a mesh file (tpr add reads .off, .obj, .ply and .stl)";

// The name of folder `dir` as the user sees it: "library" for "library/",
// "./library" or "/data/library"; the working folder's name for ".".
std::string FolderName(const fs::path& dir) {
  std::error_code ec;
  fs::path absolute = fs::absolute(dir, ec).lexically_normal();
  if (ec) absolute = dir.lexically_normal();
  if (!absolute.empty() && absolute.filename().empty())
    absolute = absolute.parent_path();
  return absolute.filename().string();
}

AddFile Named(const fs::path& path, const std::string& relative,
              const std::string& folder, const Naming& naming) {
  AddFile file;
  file.path = path.string();
  file.relative = relative;
  const fs::path rel(relative);
  const bool direct = !rel.has_parent_path();
  file.id = direct ? absl::StrCat(folder, "/", relative) : relative;
  file.label = direct ? folder : rel.parent_path().filename().string();
  file.id = naming.id_prefix + file.id;
  if (!naming.label.empty()) file.label = naming.label;
  return file;
}

absl::Status Walk(const fs::path& dir, const Naming& naming, Collected* out) {
  const std::string folder = FolderName(dir);
  std::error_code ec;
  std::vector<fs::path> found;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end;
       it.increment(ec)) {
    if (!it->is_directory(ec)) found.push_back(it->path());
  }
  if (ec) {
    return absl::NotFoundError(
        absl::StrCat("cannot walk folder ", dir.string(), ": ", ec.message()));
  }
  std::sort(found.begin(), found.end());
  for (const fs::path& p : found) {
    if (!fs::is_regular_file(p, ec)) {
      out->skipped.push_back({p.string(), "not a regular file"});
    } else if (!eval::IsMeshFile(p.string())) {
      out->skipped.push_back({p.string(), kNotMesh});
    } else {
      out->files.push_back(
          Named(p, p.lexically_relative(dir).generic_string(), folder, naming));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<Collected> CollectAddFiles(const std::vector<std::string>& paths,
                                          const Naming& naming) {
  Collected out;
  for (const std::string& arg : paths) {
    const fs::path path(arg);
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
      if (absl::Status s = Walk(path, naming, &out); !s.ok()) return s;
    } else if (fs::exists(path, ec)) {
      if (!eval::IsMeshFile(arg)) {
        out.skipped.push_back({arg, kNotMesh});
        continue;
      }
      fs::path parent = path.parent_path();
      if (parent.empty()) parent = ".";
      out.files.push_back(
          Named(path, path.filename().string(), FolderName(parent), naming));
    } else {
      return absl::NotFoundError(
          absl::StrCat(arg, " is neither a file nor a folder"));
    }
  }
  std::map<std::string, const AddFile*> by_id;
  for (const AddFile& f : out.files) {
    auto [it, fresh] = by_id.emplace(f.id, &f);
    if (!fresh && it->second->path != f.path) {
      return absl::InvalidArgumentError(absl::StrCat(
          "files ", it->second->path, " and ", f.path,
          " would both get the id ", f.id,
          "; add them in separate runs with different --id-prefix"));
    }
  }
  // The same file named twice (`tpr add a a/x.off`) is indexed once.
  std::vector<AddFile> unique;
  std::map<std::string, bool> seen;
  for (AddFile& f : out.files) {
    if (!seen[f.id]) {
      seen[f.id] = true;
      unique.push_back(std::move(f));
    }
  }
  out.files = std::move(unique);
  return out;
}

}  // namespace tpr::cli
