// Signature cache: a line-oriented text format with round-trip decimals
// (%.17g), chosen over a binary one so that entries can be inspected by eye
// when diagnosing features.
#include "eval/lib/signature_cache.h"

#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace tpr::eval {
namespace {

// Format v1 (no vertex and face counts) is not read: its entries were all
// written under feature-code versions older than any key built today, so
// they could only ever miss.
constexpr char kMagicV2[] = "tpr-eval-cache-v2";  // v2: vertex and face counts
constexpr char kMagic[] = "tpr-eval-cache-v3";    // v2 plus the spectrum

void WriteVector(std::ostream& out, const std::vector<double>& v) {
  out << v.size();
  char buf[32];
  for (double x : v) {
    std::snprintf(buf, sizeof(buf), " %.17g", x);
    out << buf;
  }
  out << "\n";
}

bool ReadVector(std::istream& in, std::vector<double>* v) {
  size_t n = 0;
  if (!(in >> n) || n > (1u << 20)) return false;
  v->resize(n);
  for (double& x : *v) {
    if (!(in >> x)) return false;
  }
  return true;
}

}  // namespace

std::string CacheFileName(const std::string& key) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : key) {
    h ^= c;
    h *= 1099511628211ull;
  }
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%016" PRIx64 ".sig", h);
  return buf;
}

bool LoadCached(const std::string& dir, const std::string& key,
                CachedDescription* out) {
  std::ifstream in(std::filesystem::path(dir) / CacheFileName(key));
  if (!in) return false;
  std::string magic, stored_key;
  if (!std::getline(in, magic) || (magic != kMagic && magic != kMagicV2)) {
    return false;
  }
  if (!std::getline(in, stored_key) || stored_key != key) return false;
  CachedDescription d;
  size_t stages = 0, features = 0;
  if (!(in >> d.points >> d.rings >> d.extract_ms >> stages >> d.vertices >>
        d.faces)) {
    return false;
  }
  for (size_t i = 0; i < stages; ++i) {
    std::string name;
    double ms = 0.0;
    if (!(in >> name >> ms)) return false;
    d.stage_ms[name] = ms;
  }
  if (!ReadVector(in, &d.d2) || !(in >> features) || features > 100000)
    return false;
  d.signature.features.resize(features);
  for (index::Feature& f : d.signature.features) {
    if (!(in >> f.weight >> f.integral_geodesic)) return false;
    for (std::vector<double>* band : index::BandVectors(f)) {
      if (!ReadVector(in, band)) return false;
    }
  }
  if (magic == kMagic && !ReadVector(in, &d.signature.spectrum)) return false;
  std::string end;
  if (!(in >> end) || end != "end") return false;
  *out = std::move(d);
  return true;
}

bool StoreCached(const std::string& dir, const std::string& key,
                 const CachedDescription& d) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  const std::filesystem::path final_path =
      std::filesystem::path(dir) / CacheFileName(key);
  std::ostringstream tmp_name;
  tmp_name << final_path.string() << ".tmp" << std::hash<std::string>{}(key);
  {
    std::ofstream out(tmp_name.str());
    if (!out) return false;
    out << kMagic << "\n" << key << "\n";
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%d %d %.17g %zu %" PRId64 " %" PRId64 "\n",
                  d.points, d.rings, d.extract_ms, d.stage_ms.size(),
                  d.vertices, d.faces);
    out << buf;
    for (const auto& [name, ms] : d.stage_ms) {
      std::snprintf(buf, sizeof(buf), " %.17g\n", ms);
      out << name << buf;
    }
    WriteVector(out, d.d2);
    out << d.signature.features.size() << "\n";
    for (const index::Feature& f : d.signature.features) {
      std::snprintf(buf, sizeof(buf), "%.17g %.17g\n", f.weight,
                    f.integral_geodesic);
      out << buf;
      for (const std::vector<double>* band : index::BandVectors(f))
        WriteVector(out, *band);
    }
    WriteVector(out, d.signature.spectrum);
    out << "end\n";
    if (!out) return false;
  }
  std::filesystem::rename(tmp_name.str(), final_path, ec);
  return !ec;
}

}  // namespace tpr::eval
