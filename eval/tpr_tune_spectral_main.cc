// tpr-tune-spectral: chooses the spectral term's defaults (metric.h: phi,
// the number of eigenvalues n and the weight w_s) by cross-validation over
// EVERY dev set together, never on one set (issue 9, item 4), from the
// matrices `tpr-eval-local --save-matrices` wrote once per set: no EMD is
// recomputed, every candidate is EMD + w_s * S combined offline.
//
//   tpr-tune-spectral shrec07=/tmp/m/shrec07.mat shrec11=/tmp/m/shrec11.mat
//       identity=/tmp/m/identity.mat --report articulated11=/tmp/m/art11.mat
//       --out docs/results/spectral_cv.md
//
// Candidates: phi in {raw, by_index, log} x n in {10, 20, 30, 50} x w_s on
// a 1-2-5 grid from 0.001 to 1000, plus w_s = 0 (the paper) and the
// spectrum alone (ShapeDNA). Objective of a candidate on a set: mean(NN,
// FT, ST, DCG) of leave-one-out retrieval; over several sets, the sum (each
// set counts once, whatever its size). Three figures per candidate:
//   * leave-one-set-out: for each selection set, the candidate best summed
//     over the OTHER selection sets, scored on the held-out set;
//   * K-fold (models of each class dealt to the K folds in turn): for each
//     fold, the candidate best summed over the other folds of every set,
//     scored on that fold of each set (retrieval within the fold);
//   * the default: the candidate best summed over every selection set in
//     full. Its figures on those sets are in-sample; the two estimates
//     above are the honest ones.
// Sets given with --report are scored but never used to choose (the
// articulated 11 are a subset of SHREC'07's 20 classes).
// Also printed, for comparison only: each term divided by its median over
// the set being searched ("naive sum" of the issue), which depends on the
// data and so is no fixed metric.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "common/parallel.h"
#include "eval/lib/distance_matrix.h"
#include "eval/lib/metrics.h"
#include "eval/lib/report.h"
#include "eval/lib/saved_set.h"
#include "indexer/lib/spectral.h"

namespace tpr::eval {
namespace {

using index::SpectralTransform;

// Candidate: one way to combine the two terms.
struct Candidate {
  SpectralTransform phi = SpectralTransform::kLog;
  int n = 50;
  double w = 0.0;       // weight of the spectral term
  bool alone = false;   // the spectrum alone (ShapeDNA)
  bool median = false;  // both terms divided by their median over the set
  std::string Name() const {
    if (!alone && w == 0.0) return "paper TPR (w_s = 0)";
    return absl::StrFormat(
        "%s%s n=%d %s", median ? "median-normalised " : "",
        index::SpectralTransformName(phi), n,
        alone ? "alone (ShapeDNA)" : absl::StrFormat("w_s=%g", w));
  }
};

const std::vector<int>& EigenvalueCounts() {
  static const std::vector<int> counts = {10, 20, 30, 50};
  return counts;
}

std::vector<double> WeightGrid() {
  std::vector<double> w;
  for (double decade = 1e-3; decade < 2e3; decade *= 10) {
    for (double m : {1.0, 2.0, 5.0}) {
      if (decade * m <= 1000.0 + 1e-9) w.push_back(decade * m);
    }
  }
  return w;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 1.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// One dev set with its spectral matrices per (phi, n), at weight 1.
struct Set {
  std::string name;
  SavedSet data;
  std::map<std::pair<int, int>, DistanceMatrix> spectral;  // (phi, n)
  std::map<std::pair<int, int>, double> spectral_median;
  double emd_median = 1.0;
  std::vector<std::vector<size_t>> folds;
};

bool LoadAll(const std::vector<std::string>& args, int folds, int threads,
             std::vector<Set>* sets) {
  for (const std::string& arg : args) {
    const size_t eq = arg.find('=');
    if (eq == std::string::npos) {
      std::fprintf(stderr, "tpr-tune-spectral: expected NAME=FILE, got '%s'\n",
                   arg.c_str());
      return false;
    }
    Set s;
    s.name = arg.substr(0, eq);
    absl::StatusOr<SavedSet> data = LoadSet(arg.substr(eq + 1));
    if (!data.ok()) {
      std::fprintf(stderr, "tpr-tune-spectral: %s\n",
                   data.status().ToString().c_str());
      return false;
    }
    s.data = std::move(*data);
    const size_t n = s.data.names.size();
    auto upper = [n](const DistanceMatrix& d) {
      std::vector<double> v;
      for (size_t i = 0; i < n; ++i)
        for (size_t j = i + 1; j < n; ++j) v.push_back(d(i, j));
      return v;
    };
    s.emd_median = Median(upper(s.data.emd));
    for (SpectralTransform t :
         {SpectralTransform::kRaw, SpectralTransform::kByIndex,
          SpectralTransform::kLog}) {
      for (int count : EigenvalueCounts()) {
        index::SpectralOptions o;
        o.transform = t;
        o.eigenvalues = count;
        std::vector<std::vector<double>> e(n);
        for (size_t i = 0; i < n; ++i)
          e[i] = index::SpectralEmbedding(s.data.spectra[i], o);
        const std::pair<int, int> key(static_cast<int>(t), count);
        s.spectral[key] = PairwiseDistances(n, threads, [&] {
          return [&](size_t a, size_t b) {
            return index::SpectralDistance(e[a].data(), e[b].data(),
                                           e[a].size());
          };
        });
        s.spectral_median[key] = Median(upper(s.spectral[key]));
      }
    }
    std::map<std::string, int> seen;
    s.folds.assign(static_cast<size_t>(folds), {});
    for (size_t i = 0; i < n; ++i)
      s.folds[seen[s.data.labels[i]]++ % folds].push_back(i);
    std::fprintf(stderr, "%s: %zu models, median EMD %.4g\n", s.name.c_str(), n,
                 s.emd_median);
    sets->push_back(std::move(s));
  }
  return true;
}

// Combined returns the candidate's distance over `members` of set `s`.
DistanceMatrix Combined(const Set& s, const Candidate& c,
                        const std::vector<size_t>& members) {
  const std::pair<int, int> key(static_cast<int>(c.phi), c.n);
  const DistanceMatrix& sp = s.spectral.at(key);
  const double e_scale = c.median ? 1.0 / std::max(s.emd_median, 1e-300) : 1.0;
  const double s_scale =
      c.median ? 1.0 / std::max(s.spectral_median.at(key), 1e-300) : 1.0;
  DistanceMatrix d(members.size());
  for (size_t a = 0; a < members.size(); ++a) {
    for (size_t b = a + 1; b < members.size(); ++b) {
      const size_t i = members[a], j = members[b];
      const double spec = s_scale * sp(i, j);
      d.Set(a, b, c.alone ? spec : e_scale * s.data.emd(i, j) + c.w * spec);
    }
  }
  return d;
}

Scores Score(const Set& s, const DistanceMatrix& d,
             const std::vector<size_t>& members) {
  std::vector<std::string> labels;
  for (size_t i : members) labels.push_back(s.data.labels[i]);
  return Evaluate(labels, LeaveOneOutQueries(d));
}

double WithinBetween(const Set& s, const DistanceMatrix& d) {
  return Separation(s.data.labels, d).Ratio();
}

std::string Row4(const Metrics& m) {
  return absl::StrFormat("%.3f | %.3f | %.3f | %.3f", m.nn, m.ft, m.st, m.dcg);
}

int Run(int argc, char** argv) {
  CLI::App app{
      "Cross-validates the spectral term's defaults over every dev set "
      "together"};
  std::vector<std::string> select_args, report_args;
  int folds = 2;
  int threads =
      static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::string out;
  app.add_option("sets", select_args,
                 "NAME=FILE (tpr-eval-local --save-matrices) used to choose")
      ->required();
  app.add_option("--report", report_args,
                 "NAME=FILE scored with the choice, never used to choose");
  app.add_option(
         "--folds", folds,
         "K of the K-fold cross-validation (models of a class dealt in turn)")
      ->check(CLI::Range(2, 10));
  app.add_option("--threads", threads, "worker threads");
  app.add_option("--out", out, "also write the Markdown report to this file");
  CLI11_PARSE(app, argc, argv);

  std::vector<Set> sets;
  if (!LoadAll(select_args, folds, threads, &sets)) return 2;
  const size_t selecting = sets.size();
  if (!LoadAll(report_args, folds, threads, &sets)) return 2;

  std::vector<Candidate> candidates;
  candidates.push_back(Candidate{});  // the paper, w_s = 0
  for (bool median : {false, true}) {
    for (SpectralTransform t :
         {SpectralTransform::kRaw, SpectralTransform::kByIndex,
          SpectralTransform::kLog}) {
      for (int n : EigenvalueCounts()) {
        if (!median) candidates.push_back(Candidate{t, n, 0.0, true, false});
        for (double w : median ? std::vector<double>{0.1, 0.2, 0.5, 1, 2, 5, 10}
                               : WeightGrid()) {
          candidates.push_back(Candidate{t, n, w, false, median});
        }
      }
    }
  }
  std::fprintf(stderr, "%zu candidates x %zu sets x (1 + %d folds)\n",
               candidates.size(), sets.size(), folds);

  // full[c][s], fold[c][s][f]: overall metrics.
  std::vector<std::vector<Metrics>> full(candidates.size(),
                                         std::vector<Metrics>(sets.size()));
  std::vector<std::vector<std::vector<Metrics>>> on_fold(
      candidates.size(), std::vector<std::vector<Metrics>>(
                             sets.size(), std::vector<Metrics>(folds)));
  common::ParallelFor(candidates.size(), threads, [&](size_t c) {
    for (size_t s = 0; s < sets.size(); ++s) {
      std::vector<size_t> all(sets[s].data.names.size());
      for (size_t i = 0; i < all.size(); ++i) all[i] = i;
      full[c][s] =
          Score(sets[s], Combined(sets[s], candidates[c], all), all).overall;
      for (int f = 0; f < folds; ++f) {
        const std::vector<size_t>& m = sets[s].folds[f];
        on_fold[c][s][f] =
            Score(sets[s], Combined(sets[s], candidates[c], m), m).overall;
      }
    }
  });

  // argmax over the fixed-metric combinations (not ShapeDNA alone, not the
  // median-normalised diagnostics) of `score(c)`.
  auto best = [&](auto score) {
    size_t b = 0;
    for (size_t c = 0; c < candidates.size(); ++c) {
      if (candidates[c].alone || candidates[c].median) continue;
      if (score(c) > score(b) + 1e-12) b = c;
    }
    return b;
  };
  auto best_median = [&](auto score) {
    size_t b = 0;
    for (size_t c = 0; c < candidates.size(); ++c) {
      if (!candidates[c].median) continue;
      if (!candidates[b].median || score(c) > score(b) + 1e-12) b = c;
    }
    return b;
  };
  auto sum_full = [&](size_t c, int skip) {
    double t = 0;
    for (size_t s = 0; s < selecting; ++s)
      if (static_cast<int>(s) != skip) t += Objective(full[c][s]);
    return t;
  };
  auto sum_folds = [&](size_t c, int skip_fold) {
    double t = 0;
    for (size_t s = 0; s < selecting; ++s)
      for (int f = 0; f < folds; ++f)
        if (f != skip_fold) t += Objective(on_fold[c][s][f]);
    return t;
  };
  auto find = [&](const Candidate& like, bool alone) {
    for (size_t c = 0; c < candidates.size(); ++c) {
      const Candidate& x = candidates[c];
      if (x.alone == alone && !x.median && x.phi == like.phi && x.n == like.n)
        return c;
    }
    return size_t{0};
  };

  const size_t chosen = best([&](size_t c) { return sum_full(c, -1); });
  const Candidate& def = candidates[chosen];
  const size_t dna = find(def, true);
  const size_t dna_raw50 =
      find(Candidate{SpectralTransform::kRaw, 50, 0, true, false}, true);
  std::string md;
  absl::StrAppendFormat(
      &md,
      "## Spectral term: cross-validation over every dev set together\n\n"
      "Selection sets: ");
  for (size_t s = 0; s < selecting; ++s)
    absl::StrAppendFormat(&md, "%s%s (%zu models)", s ? ", " : "", sets[s].name,
                          sets[s].data.names.size());
  absl::StrAppendFormat(
      &md,
      ". %zu candidates, objective mean(NN, FT, ST, DCG) summed over sets, "
      "%d folds.\n\n",
      candidates.size(), folds);
  absl::StrAppendFormat(
      &md, "**Default (best summed over every selection set): %s.**\n\n",
      def.Name());

  md +=
      "### Leave-one-set-out (chosen on the other sets, scored on the held-out "
      "set)\n\n"
      "| held-out set | chosen on the others | NN | FT | ST | DCG | paper NN | "
      "FT | ST | DCG |\n"
      "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (size_t s = 0; s < selecting && selecting > 1; ++s) {
    const size_t c =
        best([&](size_t x) { return sum_full(x, static_cast<int>(s)); });
    absl::StrAppendFormat(&md, "| %s | %s | %s | %s |\n", sets[s].name,
                          candidates[c].Name(), Row4(full[c][s]),
                          Row4(full[0][s]));
  }
  absl::StrAppendFormat(
      &md,
      "\n### %d-fold (chosen on the other folds of every set, scored on the "
      "held-out fold of each)\n\n"
      "| fold | chosen | set | NN | FT | ST | DCG | paper NN | FT | ST | DCG | "
      "ShapeDNA NN | FT | ST | DCG |\n"
      "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---"
      ":|\n",
      folds);
  for (int f = 0; f < folds; ++f) {
    const size_t c = best([&](size_t x) { return sum_folds(x, f); });
    const size_t alone = find(candidates[c], true);
    for (size_t s = 0; s < sets.size(); ++s) {
      absl::StrAppendFormat(&md, "| %d | %s | %s | %s | %s | %s |\n", f,
                            candidates[c].Name(), sets[s].name,
                            Row4(on_fold[c][s][f]), Row4(on_fold[0][s][f]),
                            Row4(on_fold[alone][s][f]));
    }
  }

  md +=
      "\n### Every set with the default, in full (selection sets: "
      "in-sample)\n\n"
      "| set | method | NN | FT | ST | DCG | within / between |\n"
      "|---|---|---:|---:|---:|---:|---:|\n";
  for (size_t s = 0; s < sets.size(); ++s) {
    std::vector<size_t> all(sets[s].data.names.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = i;
    const std::vector<std::pair<std::string, size_t>> rows = {
        {"paper TPR (w_s = 0)", 0},
        {"default: " + def.Name(), chosen},
        {"ShapeDNA, " + candidates[dna].Name(), dna},
        {"ShapeDNA, " + candidates[dna_raw50].Name(), dna_raw50}};
    for (const auto& [title, c] : rows) {
      absl::StrAppendFormat(
          &md, "| %s | %s | %s | %.3f |\n", sets[s].name, title,
          Row4(full[c][s]),
          WithinBetween(sets[s], Combined(sets[s], candidates[c], all)));
    }
    // The strongest ShapeDNA: per metric, the best of every (phi, n).
    Metrics strongest;
    for (size_t c = 0; c < candidates.size(); ++c) {
      if (!candidates[c].alone) continue;
      strongest.nn = std::max(strongest.nn, full[c][s].nn);
      strongest.ft = std::max(strongest.ft, full[c][s].ft);
      strongest.st = std::max(strongest.st, full[c][s].st);
      strongest.dcg = std::max(strongest.dcg, full[c][s].dcg);
    }
    absl::StrAppendFormat(
        &md, "| %s | ShapeDNA, best (phi, n) per metric | %s | |\n",
        sets[s].name, Row4(strongest));
    const DistanceMatrix& d2 = sets[s].data.d2;
    absl::StrAppendFormat(&md, "| %s | D2 | %s | %.3f |\n", sets[s].name,
                          Row4(Score(sets[s], d2, all).overall),
                          WithinBetween(sets[s], d2));
  }

  // Per class, side by side.
  for (size_t s = 0; s < sets.size(); ++s) {
    std::vector<size_t> all(sets[s].data.names.size());
    for (size_t i = 0; i < all.size(); ++i) all[i] = i;
    const Scores paper =
        Score(sets[s], Combined(sets[s], candidates[0], all), all);
    const Scores now = Score(sets[s], Combined(sets[s], def, all), all);
    const Scores alone =
        Score(sets[s], Combined(sets[s], candidates[dna], all), all);
    const Scores d2s = Score(sets[s], sets[s].data.d2, all);
    absl::StrAppendFormat(
        &md,
        "\n#### %s per class (NN / FT / ST / DCG)\n\n"
        "| class | paper TPR | default | ShapeDNA (%s n=%d) | D2 |\n"
        "|---|---|---|---|---|\n",
        sets[s].name, index::SpectralTransformName(def.phi), def.n);
    auto cell = [](const Metrics& m) {
      return absl::StrFormat("%.2f / %.2f / %.2f / %.2f", m.nn, m.ft, m.st,
                             m.dcg);
    };
    for (const auto& [cls, m] : paper.per_class) {
      absl::StrAppendFormat(&md, "| %s | %s | %s | %s | %s |\n", cls, cell(m),
                            cell(now.per_class.at(cls)),
                            cell(alone.per_class.at(cls)),
                            cell(d2s.per_class.at(cls)));
    }
    absl::StrAppendFormat(&md, "| **all** | %s | %s | %s | %s |\n",
                          cell(paper.overall), cell(now.overall),
                          cell(alone.overall), cell(d2s.overall));
  }

  // Objective of every fixed-metric candidate, for the record.
  md +=
      "\n### Objective per candidate (mean of NN, FT, ST, DCG on each full "
      "set)\n\n| candidate |";
  for (const Set& s : sets) absl::StrAppend(&md, " ", s.name, " |");
  md += " sum over selection sets |\n|---|";
  for (size_t s = 0; s < sets.size(); ++s) md += "---:|";
  md += "---:|\n";
  for (size_t c = 0; c < candidates.size(); ++c) {
    absl::StrAppend(&md, "| ", candidates[c].Name(),
                    c == chosen ? " **(default)**" : "", " |");
    for (size_t s = 0; s < sets.size(); ++s)
      absl::StrAppendFormat(&md, " %.4f |", Objective(full[c][s]));
    absl::StrAppendFormat(&md, " %.4f |\n", sum_full(c, -1));
  }
  const size_t med = best_median([&](size_t c) { return sum_full(c, -1); });
  absl::StrAppendFormat(
      &md,
      "\nBest median-normalised sum (data-dependent, not a fixed metric; "
      "comparison only): %s, sum %.4f against the default's %.4f.\n",
      candidates[med].Name(), sum_full(med, -1), sum_full(chosen, -1));

  std::printf("%s", md.c_str());
  if (!out.empty()) {
    if (absl::Status st = WriteTextFile(out, md); !st.ok()) {
      std::fprintf(stderr, "tpr-tune-spectral: %s\n", st.ToString().c_str());
      return 1;
    }
  }
  return 0;
}

}  // namespace
}  // namespace tpr::eval

int main(int argc, char** argv) { return tpr::eval::Run(argc, argv); }
