// tpr-counts: how stable TPR analysis (sections 4.3-4.6) is within a class.
// Extracts every mesh of a dataset in process and prints, per class, the
// number of topological points and rings: min, max, spread (max - min), mean
// and standard deviation. A class of one model in many poses should give one
// count; the spread measures how far it is from that.
//
//   tpr-counts --dataset ../shared/data/scape/MANIFEST.txt
//   tpr-counts --dataset ../shared/data/scape-identity/MANIFEST.txt
//       --tpr-method paper --features /tmp/features.txt
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "common/parallel.h"
#include "eval/lib/dataset.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"

namespace tpr::eval {
namespace {

// Counted is what one mesh contributes.
struct Counted {
  bool ok = false;
  std::string error;
  int points = 0, rings = 0;
  extract::Explanation explanation;
};

Counted Count(const Item& item, const extract::Options& options) {
  Counted out;
  absl::StatusOr<extract::LoadedMesh> loaded =
      extract::LoadMeshFromFile(item.path, extract::IntakeOptions{});
  if (!loaded.ok()) {
    out.error = std::string(loaded.status().message());
    return out;
  }
  absl::StatusOr<extract::ExtractResult> result =
      extract::ExtractSignature(loaded->mesh, loaded->stats, options);
  if (!result.ok()) {
    out.error = std::string(result.status().message());
    return out;
  }
  for (const extract::Feature& f : result->signature.features) {
    (f.kind == extract::FeatureKind::kPoint ? out.points : out.rings) += 1;
  }
  if (result->explanation) out.explanation = std::move(*result->explanation);
  out.ok = true;
  return out;
}

// Spread is the summary of one count over a class.
struct Spread {
  int min = 0, max = 0;
  double mean = 0.0, std = 0.0;
};

Spread Summarize(const std::vector<int>& v) {
  Spread s;
  if (v.empty()) return s;
  s.min = *std::min_element(v.begin(), v.end());
  s.max = *std::max_element(v.begin(), v.end());
  for (int x : v) s.mean += x;
  s.mean /= v.size();
  for (int x : v) s.std += (x - s.mean) * (x - s.mean);
  s.std = std::sqrt(s.std / v.size());
  return s;
}

void PrintRow(const std::string& name, size_t models, const Spread& p,
              const Spread& r) {
  std::printf(
      "%-14s %6zu | %3d %3d %3d %6.2f %5.2f | %3d %3d %3d %6.2f %5.2f\n",
      name.c_str(), models, p.min, p.max, p.max - p.min, p.mean, p.std, r.min,
      r.max, r.max - r.min, r.mean, r.std);
}

// WriteFeatures writes one line per mesh: id, class, counts, each point's
// vertex, then each ring's vertices (count first).
void WriteFeatures(const std::string& file, const std::vector<Item>& items,
                   const std::vector<Counted>& counted) {
  std::ofstream out(file);
  for (size_t i = 0; i < items.size(); ++i) {
    const Counted& c = counted[i];
    if (!c.ok) continue;
    out << items[i].id << " " << items[i].label << " " << c.points << " "
        << c.rings << " P";
    const auto& fv = c.explanation.feature_vertices;
    for (int k = 0; k < c.points && k < static_cast<int>(fv.size()); ++k)
      out << " " << fv[k].front();
    for (size_t k = c.points; k < fv.size(); ++k) {
      out << " R " << fv[k].size();
      for (int32_t v : fv[k]) out << " " << v;
    }
    out << "\n";
  }
  if (!out) std::fprintf(stderr, "warning: cannot write %s\n", file.c_str());
}

int Main(int argc, char** argv) {
  CLI::App app{"TPR point and ring counts per class (pose stability)"};
  std::string dataset, features;
  int threads =
      static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  extract::Options options;
  options.spectrum_eigenvalues = 0;  // not counted; saves the eigensolve
  app.add_option("--dataset", dataset,
                 "MANIFEST.txt ('<relative path> <class>' lines) or a folder "
                 "of class folders")
      ->required();
  app.add_option("--threads", threads, "meshes extracted at once");
  app.add_option("--ring-threshold", options.ring_length_threshold,
                 "paper: ring length threshold / MAX g_o (4.6.2)");
  app.add_option("--ring-min-length", options.ring_min_length,
                 "persistence: ring length threshold / sqrt(area)");
  app.add_option("--topology", options.topology,
                 "critical point filter: persistence (default) or paper "
                 "(4.3's cycle filter)")
      ->transform(CLI::CheckedTransformer(
          std::map<std::string, extract::TopologyMethod>{
              {"persistence", extract::TopologyMethod::kPersistence},
              {"paper", extract::TopologyMethod::kPaper}},
          CLI::ignore_case));
  app.add_option("--point-prominence", options.point_min_prominence,
                 "persistence: smallest protrusion holding a topological "
                 "point, / sqrt(area)");
  app.add_option("--cut-handles", options.cut_handles,
                 "cut handles before describing (1, default) or not (0)");
  app.add_option("--features", features,
                 "write each mesh's point vertices and ring vertices here");
  CLI11_PARSE(app, argc, argv);
  options.explain = !features.empty();

  absl::StatusOr<std::vector<Item>> items = ReadDataset(dataset);
  if (!items.ok()) {
    std::fprintf(stderr, "error: %s\n",
                 std::string(items.status().message()).c_str());
    return 1;
  }
  std::vector<Counted> counted(items->size());
  std::atomic<int> done{0};
  common::ParallelFor(items->size(), threads, [&](size_t i) {
    counted[i] = Count((*items)[i], options);
    const int n = ++done;
    if (n % 50 == 0) std::fprintf(stderr, "  %d/%zu\n", n, items->size());
  });

  std::map<std::string, std::pair<std::vector<int>, std::vector<int>>> by_class;
  std::vector<int> all_points, all_rings;
  int failed = 0;
  for (size_t i = 0; i < items->size(); ++i) {
    const Counted& c = counted[i];
    if (!c.ok) {
      std::fprintf(stderr, "FAILED %s: %s\n", (*items)[i].id.c_str(),
                   c.error.c_str());
      ++failed;
      continue;
    }
    by_class[(*items)[i].label].first.push_back(c.points);
    by_class[(*items)[i].label].second.push_back(c.rings);
    all_points.push_back(c.points);
    all_rings.push_back(c.rings);
  }
  std::printf("%-14s %6s | %-27s | %-27s\n", "", "",
              "points min max spread mean std",
              "rings min max spread mean std");
  double point_spread = 0.0, ring_spread = 0.0;
  for (const auto& [label, counts] : by_class) {
    const Spread p = Summarize(counts.first), r = Summarize(counts.second);
    PrintRow(label, counts.first.size(), p, r);
    point_spread += p.max - p.min;
    ring_spread += r.max - r.min;
  }
  PrintRow("ALL", all_points.size(), Summarize(all_points),
           Summarize(all_rings));
  std::printf(
      "mean spread within a class: points %.2f rings %.2f (%zu classes)\n",
      point_spread / by_class.size(), ring_spread / by_class.size(),
      by_class.size());
  if (!features.empty()) WriteFeatures(features, *items, counted);
  return failed > 0 ? 1 : 0;
}

}  // namespace
}  // namespace tpr::eval

int main(int argc, char** argv) { return tpr::eval::Main(argc, argv); }
