// tpr-eval-local: in-process retrieval evaluation for research and tuning.
// Links the pure libraries directly (no services), extracts every model once,
// computes the full leave-one-out distance matrix for each descriptor (TPR
// under the EMD, and the D2 baseline) and prints PSB/SHREC metrics, per class
// and overall, with SVG pictures. `tpr eval` does the same through the
// services.
//
//   tpr-eval-local --out results/ --invariance
//       --manifest ../shared/data/shrec07-watertight/MANIFEST.txt
//   tpr-eval-local --synthetic 8x10 --out /tmp/eval
//   tpr-eval-local --synthetic identity:10x10   # bodies x poses, synth.h
//       [--identity-surface skinned|repolygonized]
#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/parallel.h"
#include "eval/lib/d2.h"
#include "eval/lib/dataset.h"
#include "eval/lib/distance_matrix.h"
#include "eval/lib/metrics.h"
#include "eval/lib/plots.h"
#include "eval/lib/report.h"
#include "eval/lib/saved_set.h"
#include "eval/lib/signature_cache.h"
#include "eval/local/models.h"
#include "extractor/lib/extract.h"
#include "extractor/lib/mesh_io.h"
#include "extractor/synth/synth.h"
#include "indexer/lib/emd.h"
#include "indexer/lib/ground_distance.h"
#include "indexer/lib/metric.h"
#include "indexer/lib/signature_index.h"

namespace tpr::eval {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

using local::Config;
using local::DescribeAll;
using local::Described;
using local::ManifestModels;
using local::MillisecondsSince;
using local::Model;
using local::SyntheticModels;

// Everything the command line sets.
struct Flags {
  std::string manifest, synthetic, out_dir, dump, save_matrices;
  bool invariance = false, tune = false, index_timing = false;
  std::string spectral_transform;  // "" keeps the default
  int threads =
      static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  Config config;
};

void DeclareFlags(CLI::App* app, Flags* f) {
  Config& c = f->config;
  app->add_option("--manifest", f->manifest,
                  "MANIFEST.txt: '<relative path> <class>' per line");
  app->add_option(
      "--synthetic", f->synthetic,
      "generate CLASSESxPOSES synthetic models instead, or "
      "identity:BODIESxPOSES (bodies of one skeleton, class = body)");
  app->add_option("--identity-surface", c.identity_surface,
                  "identity mode's surfaces: skinned (one rest mesh per body, "
                  "skinned to each pose; default) or repolygonized (each "
                  "pose polygonized afresh, the older sets)")
      ->transform(CLI::CheckedTransformer(
          std::map<std::string, synth::IdentitySurface>{
              {"skinned", synth::IdentitySurface::kSkinned},
              {"repolygonized", synth::IdentitySurface::kRepolygonized}},
          CLI::ignore_case));
  app->add_option("--synthetic-vertices", c.synthetic_vertices,
                  "vertices per synthetic model");
  app->add_option("--out", f->out_dir,
                  "folder for results.json, tables.md and SVG pictures");
  app->add_flag("--invariance", f->invariance,
                "add rotated, scaled and rotated+scaled copies (the paper's 4x "
                "database)");
  app->add_flag(
      "--tune", f->tune,
      "cross-validate W1..W4 on half of each class, report on the other half");
  app->add_option("--threads", f->threads, "worker threads");
  app->add_flag(
      "--index-timing", f->index_timing,
      "also time k-NN queries through the VP-tree index (paper Table 7)");
  app->add_option("--bands", c.extract.bands, "geodesic bands (5.3)");
  app->add_option("--band-extent", c.extract.bands_per_feature_extent,
                  "bands span each feature's own extent (1) or the mesh's "
                  "geodesic diameter (0)");
  app->add_option("--ring-threshold", c.extract.ring_length_threshold,
                  "ring length threshold (4.6.2)");
  app->add_option("--cut-handles", c.extract.cut_handles,
                  "cut a closed mesh of genus > 0 to genus 0 before describing "
                  "it (1, default) or describe it as it is (0, the paper)");
  app->add_option("--topology", c.extract.topology,
                  "critical point filter before the vote of 4.4: persistence "
                  "(default) or paper (4.3's cycle filter)")
      ->transform(CLI::CheckedTransformer(
          std::map<std::string, extract::TopologyMethod>{
              {"persistence", extract::TopologyMethod::kPersistence},
              {"paper", extract::TopologyMethod::kPaper}},
          CLI::ignore_case));
  app->add_option("--point-prominence", c.extract.point_min_prominence,
                  "persistence filter: smallest protrusion holding a "
                  "topological point, / sqrt(area)");
  app->add_option(
      "--spectral-weight", c.spectral_weight,
      "w_s: weight of the spectral term (0: the paper's TPR distance)");
  app->add_option("--spectral-transform", f->spectral_transform,
                  "phi of the spectral term: raw, by_index or log");
  app->add_option("--spectral-eigenvalues", c.ground.spectral.eigenvalues,
                  "eigenvalues the spectral term compares");
  app->add_option(
      "--extract-eigenvalues", c.extract.spectrum_eigenvalues,
      "Laplace-Beltrami eigenvalues each signature stores (extraction; "
      "the spectral term compares the first --spectral-eigenvalues)");
  app->add_option("--w1", c.ground.w1, "Eq. 7 weight of G'");
  app->add_option("--w2", c.ground.w2, "Eq. 7 weight of curvature");
  app->add_option("--w3", c.ground.w3, "Eq. 7 weight of area");
  app->add_option("--w4", c.ground.w4, "Eq. 7 weight of thickness");
  app->add_option("--seed", c.seed, "seed for copies, D2 and synthetic shapes");
  app->add_option(
      "--cache", c.cache_dir,
      "folder caching extracted signatures (keyed by mesh, copy and options)");
  app->add_option("--k-scale", c.ground.k_scale,
                  "Eq. 7 L2norm scale of curvature");
  app->add_option("--a-scale", c.ground.a_scale, "Eq. 7 L2norm scale of area");
  app->add_option("--h-scale", c.ground.h_scale,
                  "Eq. 7 L2norm scale of thickness");
  app->add_option(
      "--save-matrices", f->save_matrices,
      "write names, classes, spectra and the EMD and D2 matrices to this file "
      "(saved_set.h), for tpr-tune-intents");
  app->add_option("--dump", f->dump,
                  "write every model's features (text) to this file");
}

// The evaluation set: the manifest's or generated models, followed (with
// --invariance) by the three copies of each, in the same order.
absl::StatusOr<std::vector<Model>> LoadModels(const Flags& flags,
                                              size_t* base_size) {
  absl::StatusOr<std::vector<Model>> base =
      flags.manifest.empty() ? SyntheticModels(flags.synthetic)
                             : ManifestModels(flags.manifest);
  if (!base.ok()) return base.status();
  *base_size = base->size();
  std::vector<Model> models = *base;
  if (flags.invariance) {
    for (int copy = 1; copy <= 3; ++copy) {
      for (Model m : *base) {
        m.copy = copy;
        m.name += "#" + std::to_string(copy);
        models.push_back(m);
      }
    }
  }
  return models;
}

// What the models that could be described add up to.
struct Summary {
  std::vector<int> kept;  // indices into the models, described without error
  std::vector<std::string> labels;  // parallel to kept
  ClassSizes models_per_class;
  std::map<std::string, std::pair<int, int>>
      features_per_class;  // points, rings
  double extract_ms = 0.0;
  int64_t sum_vertices = 0, sum_faces = 0;
  std::map<std::string, double> stage_ms;
};

// Failed models are reported and left out (they cannot be ranked).
Summary Summarize(const std::vector<Model>& models,
                  const std::vector<Described>& described) {
  Summary s;
  for (size_t i = 0; i < models.size(); ++i) {
    const Described& d = described[i];
    if (!d.ok) {
      std::fprintf(stderr, "FAILED %s: %s\n", models[i].name.c_str(),
                   d.error.c_str());
      continue;
    }
    s.kept.push_back(static_cast<int>(i));
    s.labels.push_back(models[i].label);
    auto& fc = s.features_per_class[models[i].label];
    fc.first += d.points;
    fc.second += d.rings;
    s.models_per_class[models[i].label] += 1;
    s.extract_ms += d.extract_ms;
    s.sum_vertices += d.vertices;
    s.sum_faces += d.faces;
    for (const auto& [stage, ms] : d.stage_ms) s.stage_ms[stage] += ms;
  }
  return s;
}

void PrintSummary(const Summary& s, size_t total) {
  std::printf("models %zu described, %zu failed; mean extraction %.1f ms\n",
              s.kept.size(), total - s.kept.size(),
              s.extract_ms / s.kept.size());
  for (const auto& [stage, ms] : s.stage_ms) {
    std::printf("  stage %-18s %8.2f ms\n", stage.c_str(), ms / s.kept.size());
  }
  std::printf("%-18s %8s %8s\n", "class", "points", "rings");
  for (const auto& [cls, pr] : s.features_per_class) {
    const double n = s.models_per_class.at(cls);
    std::printf("%-18s %8.2f %8.2f\n", cls.c_str(), pr.first / n,
                pr.second / n);
  }
}

// Balance of the Eq. 7 terms: the mean unweighted, scaled contribution of
// each block over feature pairs of random model pairs (weighted by the
// features' masses, as the EMD sees them).
void PrintTermBalance(const std::vector<Described>& described,
                      const std::vector<int>& kept, const Config& config) {
  auto l2 = [](const std::vector<double>& x, const std::vector<double>& y) {
    double s = 0.0;
    for (size_t b = 0; b < x.size() && b < y.size(); ++b)
      s += (x[b] - y[b]) * (x[b] - y[b]);
    return std::sqrt(s);
  };
  double sum[4] = {0, 0, 0, 0}, mass = 0.0;
  std::mt19937_64 rng(config.seed);
  std::uniform_int_distribution<size_t> pick(0, kept.size() - 1);
  for (int trial = 0; trial < 4000; ++trial) {
    const index::Signature& a = described[kept[pick(rng)]].raw;
    const index::Signature& b = described[kept[pick(rng)]].raw;
    for (const index::Feature& fa : a.features) {
      for (const index::Feature& fb : b.features) {
        const double w = fa.weight * fb.weight;
        sum[0] += w * std::abs(fa.integral_geodesic - fb.integral_geodesic);
        sum[1] += w * config.ground.k_scale * l2(fa.curvature, fb.curvature);
        sum[2] += w * config.ground.a_scale * l2(fa.area, fb.area);
        sum[3] += w * config.ground.h_scale * l2(fa.distance, fb.distance);
        mass += w;
      }
    }
  }
  std::printf(
      "mean scaled Eq. 7 terms over feature pairs: G %.4f  K %.4f  A %.4f  H "
      "%.4f\n",
      sum[0] / mass, sum[1] / mass, sum[2] / mass, sum[3] / mass);
}

void DumpFeatures(const std::string& file, const std::vector<Model>& models,
                  const std::vector<Described>& described,
                  const std::vector<int>& kept) {
  std::ofstream out(file);
  for (int i : kept) {
    const Described& d = described[i];
    out << "model " << models[i].name << " " << models[i].label << " points "
        << d.points << " rings " << d.rings << "\n";
    for (size_t f = 0; f < d.raw.features.size(); ++f) {
      const index::Feature& x = d.raw.features[f];
      out << (static_cast<int>(f) < d.points ? "P" : "R") << " w " << x.weight
          << " g " << x.integral_geodesic;
      out << "\n  K";
      for (double v : x.curvature) out << " " << v;
      out << "\n  A";
      for (double v : x.area) out << " " << v;
      out << "\n  H";
      for (double v : x.distance) out << " " << v;
      out << "\n";
    }
  }
  if (!out) std::fprintf(stderr, "warning: cannot write %s\n", file.c_str());
}

// The leave-one-out matrices over the kept models (position a is model
// kept[a]), with the workers' busy time: per-pair costs that do not depend
// on the thread count.
// tpr is the distance searched with (metric.h): emd + w_s * spectral, where
// emd is the paper's TPR distance (w_s = 0) and spectral the spectral term
// at weight 1, which alone is the ShapeDNA baseline.
struct Matching {
  DistanceMatrix tpr, emd, spectral, d2;
  double tpr_thread_ms = 0.0, d2_thread_ms = 0.0, wall_ms = 0.0;
  double pairs = 0.0;
  double EmdMicroseconds() const { return 1000 * tpr_thread_ms / pairs; }
  double D2Microseconds() const { return 1000 * d2_thread_ms / pairs; }
};

// SpectralMatrix returns the spectral term of metric.h at weight 1 with
// transform `t` between every pair of kept models. O(n^2 eigenvalues).
DistanceMatrix SpectralMatrix(const std::vector<Described>& described,
                              const std::vector<int>& kept,
                              index::SpectralOptions options,
                              index::SpectralTransform t, int threads) {
  options.transform = t;
  std::vector<std::vector<double>> e(kept.size());
  for (size_t a = 0; a < kept.size(); ++a) {
    e[a] = index::SpectralEmbedding(described[kept[a]].raw.spectrum, options);
  }
  return PairwiseDistances(kept.size(), threads, [&] {
    return [&](size_t a, size_t b) {
      return index::SpectralDistance(e[a].data(), e[b].data(), e[a].size());
    };
  });
}

// Sum returns a + w b.
DistanceMatrix Sum(const DistanceMatrix& a, double w, const DistanceMatrix& b) {
  DistanceMatrix out(a.size());
  for (size_t i = 0; i < a.size(); ++i) {
    for (size_t j = i + 1; j < a.size(); ++j)
      out.Set(i, j, a(i, j) + w * b(i, j));
  }
  return out;
}

Matching MatchAll(const std::vector<Described>& described,
                  const std::vector<int>& kept, const Config& config,
                  int threads) {
  Matching m;
  const Clock::time_point start = Clock::now();
  // One EMD per pair: the spectral term is added afterwards, which equals
  // index::Distance (metric.h) to rounding.
  m.emd = PairwiseDistances(
      kept.size(), threads,
      [&] {
        return [&, solver = index::EmdSolver()](size_t a, size_t b) mutable {
          return solver.Distance(described[kept[a]].tpr,
                                 described[kept[b]].tpr);
        };
      },
      &m.tpr_thread_ms);
  m.spectral = SpectralMatrix(described, kept, config.ground.spectral,
                              config.ground.spectral.transform, threads);
  m.tpr = Sum(m.emd, config.spectral_weight, m.spectral);
  m.d2 = PairwiseDistances(
      kept.size(), threads,
      [&] {
        return [&](size_t a, size_t b) {
          return D2Distance(described[kept[a]].d2, described[kept[b]].d2);
        };
      },
      &m.d2_thread_ms);
  m.wall_ms = MillisecondsSince(start);
  m.pairs = kept.size() * (kept.size() - 1) / 2.0;
  std::printf(
      "matching: %.0f pairs in %.1f ms wall on %d threads; %.2f us per EMD, "
      "%.3f us "
      "per D2 (thread time)\n",
      m.pairs, m.wall_ms, threads, m.EmdMicroseconds(), m.D2Microseconds());
  return m;
}

// How far each copy lies from its original, against the typical distance
// between two models of one class. Models [0, base_size) are the originals;
// model i >= base_size is a copy of i % base_size.
std::string InvarianceNote(const std::vector<Model>& models,
                           const std::vector<int>& kept,
                           const DistanceMatrix& tpr, size_t base_size) {
  std::vector<int> position(models.size(), -1);
  for (size_t a = 0; a < kept.size(); ++a)
    position[kept[a]] = static_cast<int>(a);
  std::vector<double> copy_d, class_d;
  for (size_t a = 0; a < kept.size(); ++a) {
    const size_t i = kept[a];
    if (i >= base_size) {
      const int orig = position[i % base_size];
      if (orig >= 0) copy_d.push_back(tpr(a, orig));
      continue;
    }
    for (size_t b = 0; b < kept.size(); ++b) {
      const size_t j = kept[b];
      if (j < base_size && j != i && models[j].label == models[i].label) {
        class_d.push_back(tpr(a, b));
      }
    }
  }
  auto median = [](std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  const double copy_max =
      copy_d.empty() ? 0.0 : *std::max_element(copy_d.begin(), copy_d.end());
  const double class_median = median(class_d);
  int far_copies = 0;
  for (double d : copy_d) far_copies += d > 0.1 * class_median;
  return absl::StrFormat(
      "TPR EMD from a rotated/scaled copy to its original: median %.4g, max "
      "%.4g, %d of %zu "
      "copies beyond a tenth of the median EMD between two models of one class "
      "(%.4g)",
      median(copy_d), copy_max, far_copies, copy_d.size(), class_median);
}

// Paper Table 7: k-nearest-neighbour search through the VP-tree index
// (6.2), every model as a query, one thread.
struct KnnRow {
  size_t k;
  double emds_per_query, ms_per_query;
};
struct IndexTiming {
  double build_ms = 0.0;
  std::vector<KnnRow> rows;
};

absl::StatusOr<IndexTiming> TimeIndex(const std::vector<Described>& described,
                                      const std::vector<int>& kept,
                                      const Config& config) {
  index::IndexOptions io;
  io.ground = config.ground;
  io.background_rebuild = false;
  index::SignatureIndex vp(io);
  std::vector<std::pair<std::string, index::Signature>> entries;
  for (int i : kept) entries.push_back({std::to_string(i), described[i].raw});
  IndexTiming timing;
  const Clock::time_point b0 = Clock::now();
  if (absl::Status st = vp.UpsertBatch(entries); !st.ok()) return st;
  vp.Rebuild();
  timing.build_ms = MillisecondsSince(b0);
  for (size_t k : {size_t{1}, size_t{5}, size_t{10}, size_t{25}, kept.size()}) {
    int64_t emds = 0;
    const Clock::time_point q0 = Clock::now();
    for (int i : kept) {
      index::SearchStats st;
      vp.Knn(described[i].raw, k, &st);
      emds += st.emd_computations;
    }
    timing.rows.push_back({k, static_cast<double>(emds) / kept.size(),
                           MillisecondsSince(q0) / kept.size()});
  }
  std::printf("VP-tree: built in %.1f ms\n", timing.build_ms);
  for (const KnnRow& r : timing.rows) {
    std::printf("  k = %4zu: %8.1f EMDs, %8.2f ms per query\n", r.k,
                r.emds_per_query, r.ms_per_query);
  }
  return timing;
}

// Two folds: models alternate between folds within each class. W1..W4 are
// chosen on one fold by a grid over the simplex (step 0.1) that maximizes
// mean(NN, FT, ST, DCG); the chosen W is reported on the other fold. No
// per-query or per-class tuning. Returns the JSON array of the folds.
std::string Tune(const std::vector<Model>& models,
                 const std::vector<Described>& described,
                 const std::vector<int>& kept, const Config& config,
                 int threads) {
  std::map<std::string, int> seen;
  std::vector<int> fold[2];
  for (int i : kept) fold[seen[models[i].label]++ % 2].push_back(i);
  auto fold_scores = [&](const std::vector<int>& members,
                         const index::GroundDistanceOptions& w) {
    std::vector<index::PreparedSignature> prep(members.size());
    for (size_t a = 0; a < members.size(); ++a) {
      prep[a] = *index::Prepare(described[members[a]].raw, w);
    }
    const DistanceMatrix d = PairwiseDistances(members.size(), threads, [&] {
      return [&, solver = index::EmdSolver()](size_t a, size_t b) mutable {
        return solver.Distance(prep[a], prep[b]);
      };
    });
    std::vector<std::string> fold_labels;
    for (int i : members) fold_labels.push_back(models[i].label);
    return Evaluate(fold_labels, LeaveOneOutQueries(d));
  };
  // Every W of the grid is scored on both halves once; each half's best W is
  // reported on the other half (the honest estimate), and the W that is best
  // summed over both halves is the one to make the default.
  std::vector<index::GroundDistanceOptions> grid;
  for (int a = 0; a <= 10; ++a) {
    for (int b = 0; a + b <= 10; ++b) {
      for (int c = 0; a + b + c <= 10; ++c) {
        index::GroundDistanceOptions w = config.ground;
        w.w1 = a / 10.0;
        w.w2 = b / 10.0;
        w.w3 = c / 10.0;
        w.w4 = (10 - a - b - c) / 10.0;
        grid.push_back(w);
      }
    }
  }
  std::vector<Metrics> on_half[2];
  for (int f = 0; f < 2; ++f) {
    for (const auto& w : grid)
      on_half[f].push_back(fold_scores(fold[f], w).overall);
  }
  std::string json = "[";
  for (int f = 0; f < 2; ++f) {
    size_t best = 0;
    for (size_t g = 0; g < grid.size(); ++g) {
      if (Objective(on_half[f][g]) > Objective(on_half[f][best])) best = g;
    }
    const index::GroundDistanceOptions& best_w = grid[best];
    const Metrics& held_out = on_half[1 - f][best];
    const Scores held_out_default = fold_scores(fold[1 - f], config.ground);
    std::printf(
        "\ntune fold %d: W = (%.1f, %.1f, %.1f, %.1f), objective %.3f on the "
        "tuning "
        "half\n  held-out half: %s\n  held-out half with the given W: %s\n",
        f, best_w.w1, best_w.w2, best_w.w3, best_w.w4,
        Objective(on_half[f][best]), MetricsSummary(held_out).c_str(),
        MetricsSummary(held_out_default.overall).c_str());
    absl::StrAppend(&json, f ? "," : "", "{\"w\":[", JsonNumber(best_w.w1), ",",
                    JsonNumber(best_w.w2), ",", JsonNumber(best_w.w3), ",",
                    JsonNumber(best_w.w4),
                    "],\"held_out\":", MetricsJson(held_out), "}");
  }
  size_t both = 0;
  for (size_t g = 0; g < grid.size(); ++g) {
    if (Objective(on_half[0][g]) + Objective(on_half[1][g]) >
        Objective(on_half[0][both]) + Objective(on_half[1][both])) {
      both = g;
    }
  }
  std::printf(
      "\ntune: best W over both halves (the default to choose): "
      "(%.1f, %.1f, %.1f, %.1f), objectives %.3f / %.3f\n",
      grid[both].w1, grid[both].w2, grid[both].w3, grid[both].w4,
      Objective(on_half[0][both]), Objective(on_half[1][both]));
  return json + "]";
}

// WithinBetween returns "mean distance within classes W, between B, ratio
// W / B" (distance_matrix.h Separation: lower separates better).
std::string WithinBetween(const std::vector<std::string>& labels,
                          const DistanceMatrix& d) {
  const ClassSeparation s = Separation(labels, d);
  return absl::StrFormat(
      "mean distance within classes %.4g, between %.4g, ratio %.4f", s.within,
      s.between, s.Ratio());
}

std::string TprTitle(const Config& c) {
  return absl::StrFormat(
      "TPR + spectrum (EMD of Eq. 7 + %g x ||phi(spec)||, phi = %s, %d "
      "eigenvalues)",
      c.spectral_weight,
      index::SpectralTransformName(c.ground.spectral.transform),
      c.ground.spectral.eigenvalues);
}

std::string ShapeDnaTitle(const Config& c) {
  return absl::StrFormat(
      "ShapeDNA (spectrum alone, phi = %s, %d eigenvalues, L2)",
      index::SpectralTransformName(c.ground.spectral.transform),
      c.ground.spectral.eigenvalues);
}

// Everything a run measured, for the files of --out.
struct Results {
  Scores tpr, paper, shapedna, d2;
  Config config;
  Summary summary;
  Matching matching;
  IndexTiming index_timing;
  std::string copy_note;
  std::string tune_json;  // "" without --tune
};

// The paper's Tables 5-7 in this run's figures, plus the metric tables.
std::string TablesMarkdown(const Results& r,
                           const std::vector<Described>& described) {
  const Summary& s = r.summary;
  const double nk = static_cast<double>(s.kept.size());
  double features = 0.0;
  for (int i : s.kept) features += described[i].points + described[i].rings;
  std::string md =
      ScoresMarkdown(TprTitle(r.config), r.tpr, s.models_per_class) +
      ScoresMarkdown("Paper TPR (EMD of Eq. 7, w_s = 0)", r.paper,
                     s.models_per_class) +
      ScoresMarkdown(ShapeDnaTitle(r.config), r.shapedna, s.models_per_class) +
      ScoresMarkdown("D2 (Osada et al. 2001, L1)", r.d2, s.models_per_class);
  md +=
      "#### Features per model (mean)\n\n| class | points | rings "
      "|\n|---|---:|---:|\n";
  for (const auto& [cls, pr] : s.features_per_class) {
    const double c = s.models_per_class.at(cls);
    absl::StrAppendFormat(&md, "| %s | %.2f | %.2f |\n", cls, pr.first / c,
                          pr.second / c);
  }
  absl::StrAppendFormat(&md,
                        "\n#### Feature extraction (paper Table 5 form)\n\n| | "
                        "TPR |\n|---|---:|\n"
                        "| average vertices / faces per model | %.0f / %.0f |\n"
                        "| average topological features per model | %.1f |\n"
                        "| average extraction time per model | %.1f ms |\n",
                        s.sum_vertices / nk, s.sum_faces / nk, features / nk,
                        s.extract_ms / nk);
  for (const auto& [stage, ms] : s.stage_ms) {
    absl::StrAppendFormat(&md, "| &nbsp;&nbsp;stage %s | %.1f ms |\n", stage,
                          ms / nk);
  }
  const Matching& m = r.matching;
  absl::StrAppendFormat(
      &md,
      "\n#### Matching (paper Table 6 form)\n\n| | TPR | D2 "
      "|\n|---|---:|---:|\n"
      "| average time for matching one model | %.1f us | %.2f us |\n"
      "| average time for one query (all %zu others) | %.2f ms | %.3f ms |\n"
      "| all %zu models as queries (thread time) | %.2f s | %.3f s |\n",
      m.EmdMicroseconds(), m.D2Microseconds(), s.kept.size() - 1,
      m.EmdMicroseconds() * (nk - 1) / 1000,
      m.d2_thread_ms / m.pairs * (nk - 1), s.kept.size(),
      2 * m.tpr_thread_ms / 1000, 2 * m.d2_thread_ms / 1000);
  if (!r.index_timing.rows.empty()) {
    absl::StrAppendFormat(
        &md,
        "\n#### k-NN through the VP-tree (paper Table 7 form, one thread)\n\n"
        "Index build: %.1f ms for %zu models.\n\n| k | EMDs per query | time "
        "per "
        "query |\n|---:|---:|---:|\n",
        r.index_timing.build_ms, s.kept.size());
    for (const KnnRow& row : r.index_timing.rows) {
      absl::StrAppendFormat(&md, "| %zu | %.1f | %.2f ms |\n", row.k,
                            row.emds_per_query, row.ms_per_query);
    }
  }
  if (!r.copy_note.empty()) md += "\n" + r.copy_note + ".\n";
  return md;
}

// Writes results.json, tables.md and the pictures into `out_dir`.
absl::Status WriteOutputs(const std::string& out_dir, const Results& r,
                          const std::vector<Described>& described) {
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) {
    return absl::PermissionDeniedError(
        absl::StrCat("cannot create ", out_dir, ": ", ec.message()));
  }
  const Summary& s = r.summary;
  const std::string json = absl::StrCat(
      "{\"models\":", s.kept.size(), ",\"classes\":", r.tpr.per_class.size(),
      ",\"tpr\":{\"overall\":", MetricsJson(r.tpr.overall),
      ",\"per_class\":", PerClassJson(r.tpr, s.models_per_class),
      "},\"d2\":{\"overall\":", MetricsJson(r.d2.overall), "}",
      ",\"paper\":{\"overall\":", MetricsJson(r.paper.overall),
      ",\"per_class\":", PerClassJson(r.paper, s.models_per_class),
      "},\"shapedna\":{\"overall\":", MetricsJson(r.shapedna.overall),
      ",\"per_class\":", PerClassJson(r.shapedna, s.models_per_class), "}",
      r.tune_json.empty() ? "" : ",\"tuning\":" + r.tune_json, "}\n");
  const fs::path out(out_dir);
  const std::vector<std::pair<std::string, std::string>> files = {
      {"results.json", json},
      {"tables.md", TablesMarkdown(r, described)},
      {"precision_recall.svg",
       PrecisionRecallSvg({{"TPR", r.tpr.overall.pr}, {"D2", r.d2.overall.pr}},
                          "Precision-recall")},
      {"similarity_tpr.svg",
       SimilaritySvg(
           MeanSimilarity(s.labels, LeaveOneOutQueries(r.matching.tpr)),
           "TPR mean class similarity")},
      {"similarity_d2.svg",
       SimilaritySvg(
           MeanSimilarity(s.labels, LeaveOneOutQueries(r.matching.d2)),
           "D2 mean class similarity")},
  };
  for (const auto& [name, text] : files) {
    if (absl::Status st = WriteTextFile((out / name).string(), text); !st.ok())
      return st;
  }
  std::printf(
      "\nwrote "
      "%s/{results.json,tables.md,precision_recall.svg,similarity_tpr.svg,"
      "similarity_d2.svg}\n",
      out_dir.c_str());
  return absl::OkStatus();
}

int Run(int argc, char** argv) {
  CLI::App app{"In-process TPR retrieval evaluation (PSB/SHREC metrics)"};
  Flags flags;
  DeclareFlags(&app, &flags);
  CLI11_PARSE(app, argc, argv);
  if (flags.manifest.empty() == flags.synthetic.empty()) {
    std::fprintf(stderr, "give exactly one of --manifest or --synthetic\n");
    return 2;
  }
  Config& config = flags.config;
  config.d2.seed = config.seed;
  if (!flags.spectral_transform.empty()) {
    absl::StatusOr<index::SpectralTransform> t =
        index::ParseSpectralTransform(flags.spectral_transform);
    if (!t.ok()) {
      std::fprintf(stderr, "tpr-eval-local: %s\n",
                   t.status().ToString().c_str());
      return 2;
    }
    config.ground.spectral.transform = *t;
  }
  if (absl::Status st = index::ValidateOptions(config.ground); !st.ok()) {
    std::fprintf(stderr, "tpr-eval-local: %s\n", st.ToString().c_str());
    return 2;
  }

  size_t base_size = 0;
  absl::StatusOr<std::vector<Model>> models = LoadModels(flags, &base_size);
  if (!models.ok()) {
    std::fprintf(stderr, "tpr-eval-local: %s\n",
                 models.status().ToString().c_str());
    return 2;
  }
  const std::vector<Described> described =
      DescribeAll(*models, config, flags.threads);
  Results r;
  r.config = config;
  r.summary = Summarize(*models, described);
  const std::vector<int>& kept = r.summary.kept;
  if (kept.size() < 2) {
    std::fprintf(stderr,
                 "fewer than two models described; nothing to evaluate\n");
    return 1;
  }
  PrintSummary(r.summary, models->size());
  PrintTermBalance(described, kept, config);
  if (!flags.dump.empty()) DumpFeatures(flags.dump, *models, described, kept);

  // Full matrices over all kept models, so that timing is honest.
  r.matching = MatchAll(described, kept, config, flags.threads);
  if (!flags.save_matrices.empty()) {
    SavedSet saved;
    for (int i : kept) {
      saved.names.push_back((*models)[i].name);
      saved.labels.push_back((*models)[i].label);
      saved.spectra.push_back(described[i].raw.spectrum);
    }
    saved.emd = r.matching.emd;
    saved.d2 = r.matching.d2;
    if (absl::Status st = SaveSet(flags.save_matrices, saved); !st.ok()) {
      std::fprintf(stderr, "tpr-eval-local: %s\n", st.ToString().c_str());
      return 1;
    }
  }
  if (flags.invariance) {
    r.copy_note = InvarianceNote(*models, kept, r.matching.tpr, base_size);
    std::printf("%s\n", r.copy_note.c_str());
  }
  if (flags.index_timing) {
    absl::StatusOr<IndexTiming> timing = TimeIndex(described, kept, config);
    if (!timing.ok()) {
      std::fprintf(stderr, "index: %s\n", timing.status().ToString().c_str());
      return 1;
    }
    r.index_timing = std::move(*timing);
  }

  r.tpr = Evaluate(r.summary.labels, LeaveOneOutQueries(r.matching.tpr));
  r.paper = Evaluate(r.summary.labels, LeaveOneOutQueries(r.matching.emd));
  r.shapedna =
      Evaluate(r.summary.labels, LeaveOneOutQueries(r.matching.spectral));
  r.d2 = Evaluate(r.summary.labels, LeaveOneOutQueries(r.matching.d2));
  std::printf("\n%s\n%s", TprTitle(config).c_str(),
              ScoresTable(r.tpr, r.summary.models_per_class).c_str());
  std::printf("%s\n", WithinBetween(r.summary.labels, r.matching.tpr).c_str());
  std::printf("\nPaper TPR (EMD of Eq. 7, w_s = 0)\n%s",
              ScoresTable(r.paper, r.summary.models_per_class).c_str());
  std::printf("\n%s\n%s", ShapeDnaTitle(config).c_str(),
              ScoresTable(r.shapedna, r.summary.models_per_class).c_str());
  std::printf("\nD2 (Osada et al. 2001, L1)\n%s",
              ScoresTable(r.d2, r.summary.models_per_class).c_str());
  if (flags.tune)
    r.tune_json = Tune(*models, described, kept, config, flags.threads);

  if (!flags.out_dir.empty()) {
    if (absl::Status st = WriteOutputs(flags.out_dir, r, described); !st.ok()) {
      std::fprintf(stderr, "tpr-eval-local: %s\n", st.ToString().c_str());
      return 1;
    }
  }
  return 0;
}

}  // namespace
}  // namespace tpr::eval

int main(int argc, char** argv) { return tpr::eval::Run(argc, argv); }
