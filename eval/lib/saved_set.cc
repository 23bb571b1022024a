#include "eval/lib/saved_set.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "eval/lib/report.h"

namespace tpr::eval {
namespace {

constexpr char kMagic[] = "tpr-eval-matrices v1";

void AppendMatrix(const DistanceMatrix& d, std::string* out) {
  for (size_t i = 0; i + 1 < d.size(); ++i) {
    for (size_t j = i + 1; j < d.size(); ++j) {
      absl::StrAppend(out, j == i + 1 ? "" : " ",
                      absl::StrFormat("%.17g", d(i, j)));
    }
    out->push_back('\n');
  }
}

bool Clean(const std::string& s) {
  return s.find_first_of("\t\n\r") == std::string::npos;
}

// Reader keeps the line number for error messages.
class Reader {
 public:
  Reader(std::istream& in, std::string path)
      : in_(in), path_(std::move(path)) {}
  bool Next(std::string* line) {
    ++line_;
    return static_cast<bool>(std::getline(in_, *line));
  }
  absl::Status Error(absl::string_view what) const {
    return absl::InvalidArgumentError(
        absl::StrCat(path_, ":", line_, ": ", what));
  }
  // Reads one line of exactly `count` finite numbers (count < 0: the first
  // number on the line is the count of those after it).
  absl::Status Numbers(int64_t count, std::vector<double>* out) {
    std::string line;
    if (!Next(&line)) return Error("unexpected end of file");
    std::istringstream s(line);
    if (count < 0) {
      if (!(s >> count) || count < 0) return Error("expected a count");
    }
    out->resize(static_cast<size_t>(count));
    for (double& x : *out) {
      if (!(s >> x) || !std::isfinite(x))
        return Error("expected a finite number");
    }
    std::string rest;
    if (s >> rest) return Error("more numbers than expected");
    return absl::OkStatus();
  }

 private:
  std::istream& in_;
  std::string path_;
  int64_t line_ = 0;
};

absl::Status ReadMatrix(Reader& r, size_t n, DistanceMatrix* d) {
  *d = DistanceMatrix(n);
  std::vector<double> row;
  for (size_t i = 0; i + 1 < n; ++i) {
    if (absl::Status st = r.Numbers(static_cast<int64_t>(n - i - 1), &row);
        !st.ok())
      return st;
    for (size_t j = i + 1; j < n; ++j) d->Set(i, j, row[j - i - 1]);
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status SaveSet(const std::string& path, const SavedSet& set) {
  const size_t n = set.names.size();
  if (set.labels.size() != n || set.spectra.size() != n ||
      set.emd.size() != n || set.d2.size() != n) {
    return absl::InvalidArgumentError(
        "SaveSet: names, labels, spectra and matrices differ in size");
  }
  std::string out = absl::StrCat(kMagic, "\n", n, "\n");
  for (size_t i = 0; i < n; ++i) {
    if (!Clean(set.names[i]) || !Clean(set.labels[i])) {
      return absl::InvalidArgumentError(absl::StrCat(
          "SaveSet: model ", i, " has a tab or newline in its name or label"));
    }
    absl::StrAppend(&out, set.names[i], "\t", set.labels[i], "\n");
  }
  for (const std::vector<double>& s : set.spectra) {
    absl::StrAppend(&out, s.size());
    for (double x : s) absl::StrAppend(&out, " ", absl::StrFormat("%.17g", x));
    out.push_back('\n');
  }
  AppendMatrix(set.emd, &out);
  AppendMatrix(set.d2, &out);
  return WriteTextFile(path, out);
}

absl::StatusOr<SavedSet> LoadSet(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open ", path));
  Reader r(in, path);
  std::string line;
  if (!r.Next(&line) || line != kMagic)
    return r.Error(absl::StrCat("expected '", kMagic, "'"));
  std::vector<double> count;
  if (absl::Status st = r.Numbers(1, &count); !st.ok()) return st;
  if (count[0] < 0 || count[0] > 1e6 || count[0] != std::floor(count[0])) {
    return r.Error("expected a model count");
  }
  const size_t n = static_cast<size_t>(count[0]);
  SavedSet set;
  for (size_t i = 0; i < n; ++i) {
    if (!r.Next(&line)) return r.Error("unexpected end of file");
    const size_t tab = line.find('\t');
    if (tab == std::string::npos) return r.Error("expected 'name<TAB>label'");
    set.names.push_back(line.substr(0, tab));
    set.labels.push_back(line.substr(tab + 1));
  }
  set.spectra.resize(n);
  for (size_t i = 0; i < n; ++i) {
    if (absl::Status st = r.Numbers(-1, &set.spectra[i]); !st.ok()) return st;
  }
  if (absl::Status st = ReadMatrix(r, n, &set.emd); !st.ok()) return st;
  if (absl::Status st = ReadMatrix(r, n, &set.d2); !st.ok()) return st;
  return set;
}

}  // namespace tpr::eval
