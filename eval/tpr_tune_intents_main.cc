// tpr-tune-intents: chooses the intents' weightings (indexer/lib/intent.h:
// d_w = w.emd EMD + w.spectral S + w.heat H) and the two spectral
// embeddings S and H share (indexer/lib/spectral.h) by cross-validation over
// every dev set together, from the files `tpr-eval-local --save-matrices`
// wrote once per set (names, classes, spectra, the EMD of Eq. 7 and D2): no
// EMD is recomputed, S and H are computed here from the stored spectra with
// the index's own embedding functions.
//
//   tpr-tune-intents identity:shrec11=/tmp/m/shrec11.mat
//       identity:scape=/tmp/m/scape.mat kind:shrec07=/tmp/m/shrec07.mat
//       --out docs/results/intents_cv.md
//
// Each set is tagged by the question its classes answer: `identity` (a class
// is one model or body in many poses) or `kind` (a class holds different
// models of one kind). IDENTITY is chosen over the identity sets, KIND over
// the kind sets, BALANCED over all of them.
//
// Candidates: an S embedding (phi in {by_index, log} x n in {20, 30, 50}),
// an H embedding (16 times over [t_min, t_max] in {[0.01, 1], [0.05, 5],
// [0.2, 20]} x n in {20, 50}; the extractor stores 50) and weights w.emd in {0,
// 1}, w.spectral and w.heat each 0 or one of 7 values on a 1-2-5 grid from 0.1
// to 10 times the ratio of the EMD's to the term's median over every pair of
// every set (rounded to two digits, so each weight is a plain constant).
// Objective of a candidate on a set: mean(NN, FT, ST, DCG) of leave-one-out
// retrieval; over several sets, the sum, each set weighted 1 / (the number of
// sets of its tag), whatever its size: IDENTITY and KIND average their sets,
// and BALANCED gives the identity sets and the kind sets equal shares (a
// compromise between the two questions, not a vote of the more numerous
// sets).
// Figures per intent:
//   * leave-one-set-out: for each of the intent's sets, the candidate best
//     summed over the intent's OTHER sets, scored on the held-out set;
//   * K-fold (the models of each class dealt to the K folds in turn): for
//     each fold, the candidate best summed over the other folds of the
//     intent's sets, scored on that fold of each (retrieval within the fold);
//   * the default. The embeddings are one pair for the whole index (every
//     intent reads the same prepared signatures): S is the one of
//     IDENTITY's best candidate (the intent the spectrum answers), H the
//     one whose best weights then give the largest sum over the three
//     intents; each intent takes its best weights for that pair. Its figures on
//     the sets are in-sample; the two estimates above are the honest ones.
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
#include "indexer/lib/intent.h"
#include "indexer/lib/spectral.h"

namespace tpr::eval {
namespace {

using index::HeatTraceOptions;
using index::Intent;
using index::SpectralOptions;
using index::SpectralTransform;
using index::TermWeights;

std::vector<SpectralOptions> SpectralConfigs() {
  std::vector<SpectralOptions> out;
  for (SpectralTransform t :
       {SpectralTransform::kByIndex, SpectralTransform::kLog}) {
    for (int n : {20, 30, 50}) {
      SpectralOptions o;
      o.transform = t;
      o.eigenvalues = n;
      out.push_back(o);
    }
  }
  return out;
}

std::vector<HeatTraceOptions> HeatConfigs() {
  std::vector<HeatTraceOptions> out;
  for (auto [lo, hi] : {std::pair{0.01, 1.0}, {0.05, 5.0}, {0.2, 20.0}}) {
    for (int n : {20, 50}) {
      HeatTraceOptions o;
      o.scales = 16;
      o.t_min = lo;
      o.t_max = hi;
      o.eigenvalues = n;
      out.push_back(o);
    }
  }
  return out;
}

std::string SpectralName(const SpectralOptions& o) {
  return absl::StrFormat(
      "S(%s, n=%d)", index::SpectralTransformName(o.transform), o.eigenvalues);
}
std::string HeatName(const HeatTraceOptions& o) {
  return absl::StrFormat("H(t=%g..%g, n=%d)", o.t_min, o.t_max, o.eigenvalues);
}

// Candidate: embeddings (indices into the config lists) and weights.
struct Candidate {
  int s = 0, h = 0;
  TermWeights w;
};

std::string CandidateName(const Candidate& c) {
  std::string out;
  auto add = [&out](const std::string& term) {
    absl::StrAppend(&out, out.empty() ? "" : " + ", term);
  };
  if (c.w.emd > 0) add(absl::StrFormat("%g EMD", c.w.emd));
  if (c.w.spectral > 0)
    add(absl::StrFormat("%g %s", c.w.spectral,
                        SpectralName(SpectralConfigs()[c.s])));
  if (c.w.heat > 0)
    add(absl::StrFormat("%g %s", c.w.heat, HeatName(HeatConfigs()[c.h])));
  return out;
}

// Set: one dev set with its per-term matrices.
struct Set {
  std::string name;
  bool identity = false;  // tag: identity set (else kind)
  bool select = true;     // false: --report only
  SavedSet data;
  std::vector<DistanceMatrix> s, h;  // per config, at weight 1
  std::vector<std::vector<size_t>> folds;
};

// Four PSB figures of one retrieval experiment.
struct Four {
  double nn = 0, ft = 0, st = 0, dcg = 0;
  double Objective() const { return (nn + ft + st + dcg) / 4; }
};

// Score returns leave-one-out NN / FT / ST / DCG among `members` of `set`
// under `dist(i, j)`, with metrics.h's tie rule (each position of a group
// of equal distances gains the group's fraction of relevant models).
template <typename Dist>
Four Score(const Set& set, const std::vector<size_t>& members, Dist dist) {
  const size_t m = members.size();
  Four sum;
  int queries = 0;
  std::vector<std::pair<double, bool>> row;
  std::vector<double> discount(m);
  for (size_t r = 0; r < m; ++r)
    discount[r] = r == 0 ? 1.0 : 1.0 / std::log2(static_cast<double>(r + 1));
  for (size_t a = 0; a < m; ++a) {
    const std::string& label = set.data.labels[members[a]];
    row.clear();
    size_t relevant = 0;
    for (size_t b = 0; b < m; ++b) {
      if (b == a) continue;
      const bool rel = set.data.labels[members[b]] == label;
      relevant += rel;
      row.emplace_back(dist(members[a], members[b]), rel);
    }
    if (relevant == 0) continue;
    ++queries;
    std::sort(row.begin(), row.end(),
              [](const auto& x, const auto& y) { return x.first < y.first; });
    Four q;
    double ideal = 0;
    for (size_t r = 0; r < relevant; ++r) ideal += discount[r];
    for (size_t g = 0; g < row.size();) {
      size_t e = g, rel = 0;
      while (e < row.size() && row[e].first == row[g].first)
        rel += row[e++].second;
      const double gain = static_cast<double>(rel) / static_cast<double>(e - g);
      for (size_t r = g; r < e; ++r) {
        if (r == 0) q.nn = gain;
        if (r < relevant) q.ft += gain;
        if (r < 2 * relevant) q.st += gain;
        q.dcg += gain * discount[r];
      }
      g = e;
    }
    sum.nn += q.nn;
    sum.ft += q.ft / relevant;
    sum.st += q.st / relevant;
    sum.dcg += q.dcg / ideal;
  }
  if (queries > 0) {
    sum.nn /= queries;
    sum.ft /= queries;
    sum.st /= queries;
    sum.dcg /= queries;
  }
  return sum;
}

Four ScoreCandidate(const Set& set, const Candidate& c,
                    const std::vector<size_t>& members) {
  const DistanceMatrix& s = set.s[c.s];
  const DistanceMatrix& h = set.h[c.h];
  return Score(set, members, [&](size_t i, size_t j) {
    return c.w.emd * set.data.emd(i, j) + c.w.spectral * s(i, j) +
           c.w.heat * h(i, j);
  });
}

std::vector<size_t> All(const Set& set) {
  std::vector<size_t> all(set.data.names.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = i;
  return all;
}

double Median(const DistanceMatrix& d, std::vector<double>* pool) {
  std::vector<double> v;
  for (size_t i = 0; i < d.size(); ++i)
    for (size_t j = i + 1; j < d.size(); ++j) v.push_back(d(i, j));
  pool->insert(pool->end(), v.begin(), v.end());
  if (v.empty()) return 1.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

double PoolMedian(std::vector<double> v) {
  if (v.empty()) return 1.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// Round2 keeps two significant digits.
double Round2(double x) {
  if (x <= 0) return 0;
  const double p = std::pow(10.0, std::floor(std::log10(x)) - 1);
  return std::round(x / p) * p;
}

bool LoadSet(const std::string& arg, bool select, int folds, int threads,
             Set* out) {
  const size_t eq = arg.find('=');
  const size_t colon = arg.find(':');
  if (eq == std::string::npos ||
      (select && (colon == std::string::npos || colon > eq))) {
    std::fprintf(stderr, "tpr-tune-intents: expected %sNAME=FILE, got '%s'\n",
                 select ? "identity:|kind:" : "", arg.c_str());
    return false;
  }
  std::string tag = select ? arg.substr(0, colon) : "kind";
  if (tag != "identity" && tag != "kind") {
    std::fprintf(stderr, "tpr-tune-intents: tag '%s' is not identity or kind\n",
                 tag.c_str());
    return false;
  }
  out->identity = tag == "identity";
  out->select = select;
  out->name = arg.substr(select ? colon + 1 : 0, eq - (select ? colon + 1 : 0));
  absl::StatusOr<SavedSet> data = tpr::eval::LoadSet(arg.substr(eq + 1));
  if (!data.ok()) {
    std::fprintf(stderr, "tpr-tune-intents: %s\n",
                 data.status().ToString().c_str());
    return false;
  }
  out->data = std::move(*data);
  const size_t n = out->data.names.size();
  auto matrix = [&](auto embed) {
    std::vector<std::vector<double>> e(n);
    for (size_t i = 0; i < n; ++i) e[i] = embed(out->data.spectra[i]);
    return PairwiseDistances(n, threads, [&] {
      return [&](size_t a, size_t b) {
        return index::SpectralDistance(e[a].data(), e[b].data(), e[a].size());
      };
    });
  };
  for (const SpectralOptions& o : SpectralConfigs())
    out->s.push_back(matrix([&](const std::vector<double>& x) {
      return index::SpectralEmbedding(x, o);
    }));
  for (const HeatTraceOptions& o : HeatConfigs())
    out->h.push_back(matrix([&](const std::vector<double>& x) {
      return index::HeatTraceEmbedding(x, o);
    }));
  std::map<std::string, int> seen;
  out->folds.assign(static_cast<size_t>(folds), {});
  for (size_t i = 0; i < n; ++i)
    out->folds[seen[out->data.labels[i]]++ % folds].push_back(i);
  std::fprintf(stderr, "%s (%s): %zu models\n", out->name.c_str(), tag.c_str(),
               n);
  return true;
}

// Candidates returns every candidate: the paper first, then the weight grid
// (see the file comment) over every embedding pair, a term's embedding
// fixed to config 0 when its weight is 0 (so no candidate is repeated).
std::vector<Candidate> Candidates(const std::vector<Set>& sets,
                                  std::string* grid_note) {
  const std::vector<SpectralOptions> sc = SpectralConfigs();
  const std::vector<HeatTraceOptions> hc = HeatConfigs();
  std::vector<double> pool;
  for (const Set& s : sets)
    if (s.select) Median(s.data.emd, &pool);
  const double emd_median = PoolMedian(pool);
  auto grid = [&](const std::vector<DistanceMatrix> Set::*term, size_t k) {
    std::vector<double> p;
    for (const Set& s : sets)
      if (s.select) Median((s.*term)[k], &p);
    const double ratio = emd_median / std::max(PoolMedian(p), 1e-300);
    std::vector<double> g = {0.0};
    for (double m : {0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0})
      g.push_back(Round2(m * ratio));
    return g;
  };
  std::vector<std::vector<double>> sgrid, hgrid;
  absl::StrAppendFormat(grid_note,
                        "Median EMD over every pair of every "
                        "selection set: %.4g. Weight grids (0 and 0.1 to 10 "
                        "times the EMD's median over the term's):\n\n",
                        emd_median);
  for (size_t k = 0; k < sc.size(); ++k) {
    sgrid.push_back(grid(&Set::s, k));
    absl::StrAppendFormat(grid_note, "- %s: %g to %g\n", SpectralName(sc[k]),
                          sgrid.back()[1], sgrid.back().back());
  }
  for (size_t k = 0; k < hc.size(); ++k) {
    hgrid.push_back(grid(&Set::h, k));
    absl::StrAppendFormat(grid_note, "- %s: %g to %g\n", HeatName(hc[k]),
                          hgrid.back()[1], hgrid.back().back());
  }
  std::vector<Candidate> out;
  out.push_back(Candidate{0, 0, {1.0, 0.0, 0.0}});
  for (int si = 0; si < static_cast<int>(sc.size()); ++si) {
    for (int hi = 0; hi < static_cast<int>(hc.size()); ++hi) {
      for (double we : {0.0, 1.0}) {
        for (size_t a = 0; a < sgrid[si].size(); ++a) {
          for (size_t b = 0; b < hgrid[hi].size(); ++b) {
            const double ws = sgrid[si][a], wh = hgrid[hi][b];
            if (ws == 0 && wh == 0) continue;  // the paper, or nothing
            if ((ws == 0 && si != 0) || (wh == 0 && hi != 0)) continue;
            // Without the EMD only the ratio counts: keep one scale.
            if (we == 0 && ws > 0 && a != 4) continue;
            if (we == 0 && ws == 0 && b != 4) continue;
            out.push_back(Candidate{si, hi, {we, ws, wh}});
          }
        }
      }
    }
  }
  return out;
}

const char* IntentTitle(Intent i) {
  switch (i) {
    case Intent::kIdentity:
      return "IDENTITY";
    case Intent::kKind:
      return "KIND";
    case Intent::kBalanced:
      return "BALANCED";
  }
  return "?";
}

bool InIntent(const Set& s, Intent i) {
  if (!s.select) return false;
  return i == Intent::kBalanced || s.identity == (i == Intent::kIdentity);
}

std::string Row(const Four& f) {
  return absl::StrFormat("%.3f | %.3f | %.3f | %.3f", f.nn, f.ft, f.st, f.dcg);
}

// Table of every candidate's figures: full[c][s], fold[c][s][f].
struct Table {
  std::vector<std::vector<Four>> full;
  std::vector<std::vector<std::vector<Four>>> fold;
};

Table ScoreAll(const std::vector<Set>& sets, const std::vector<Candidate>& cs,
               int folds, int threads) {
  Table t;
  t.full.assign(cs.size(), std::vector<Four>(sets.size()));
  t.fold.assign(cs.size(), std::vector<std::vector<Four>>(
                               sets.size(), std::vector<Four>(folds)));
  std::vector<std::vector<size_t>> all;
  for (const Set& s : sets) all.push_back(All(s));
  common::ParallelFor(cs.size(), threads, [&](size_t c) {
    for (size_t s = 0; s < sets.size(); ++s) {
      t.full[c][s] = ScoreCandidate(sets[s], cs[c], all[s]);
      for (int f = 0; f < folds; ++f)
        t.fold[c][s][f] = ScoreCandidate(sets[s], cs[c], sets[s].folds[f]);
    }
  });
  return t;
}

// Best returns the candidate maximizing score(c) among those `allowed`
// admits; the first (simplest) on ties.
template <typename Allowed, typename ScoreFn>
size_t Best(size_t count, Allowed allowed, ScoreFn score) {
  size_t best = count;
  double best_score = -1;
  for (size_t c = 0; c < count; ++c) {
    if (!allowed(c)) continue;
    const double v = score(c);
    if (best == count || v > best_score + 1e-12) best = c, best_score = v;
  }
  return best;
}

std::string Header4(const char* prefix) {
  return absl::StrFormat("%sNN | FT | ST | DCG", prefix);
}

int Run(int argc, char** argv) {
  CLI::App app{
      "Cross-validates the intents' weightings and the spectral embeddings "
      "over every dev set together"};
  std::vector<std::string> select_args, report_args;
  int folds = 2;
  int threads =
      static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::string out, dump;
  app.add_option("sets", select_args,
                 "identity:NAME=FILE or kind:NAME=FILE (tpr-eval-local "
                 "--save-matrices), used to choose")
      ->required();
  app.add_option("--report", report_args,
                 "NAME=FILE scored with the choice, never used to choose");
  app.add_option("--folds", folds, "K of the K-fold cross-validation")
      ->check(CLI::Range(2, 10));
  app.add_option("--threads", threads, "worker threads");
  app.add_option("--out", out, "also write the Markdown report to this file");
  app.add_option("--dump", dump,
                 "write every candidate's NN, FT, ST and DCG on every set "
                 "(tab-separated) to this file");
  CLI11_PARSE(app, argc, argv);

  std::vector<Set> sets;
  for (const auto& [args, select] :
       {std::pair{&select_args, true}, {&report_args, false}}) {
    for (const std::string& a : *args) {
      Set s;
      if (!LoadSet(a, select, folds, threads, &s)) return 2;
      sets.push_back(std::move(s));
    }
  }
  std::string md =
      "## Intents: cross-validation over every dev set together\n\n";
  std::string grid_note;
  const std::vector<Candidate> cs = Candidates(sets, &grid_note);
  std::fprintf(stderr, "%zu candidates x %zu sets x (1 + %d folds)\n",
               cs.size(), sets.size(), folds);
  const Table t = ScoreAll(sets, cs, folds, threads);

  const Intent intents[] = {Intent::kIdentity, Intent::kKind,
                            Intent::kBalanced};
  std::vector<double> share(sets.size(), 0.0);
  {
    int tagged[2] = {0, 0};
    for (const Set& s : sets)
      if (s.select) ++tagged[s.identity];
    for (size_t s = 0; s < sets.size(); ++s)
      if (sets[s].select) share[s] = 1.0 / tagged[sets[s].identity];
  }
  auto sum_full = [&](size_t c, Intent i, int skip) {
    double v = 0;
    for (size_t s = 0; s < sets.size(); ++s)
      if (InIntent(sets[s], i) && static_cast<int>(s) != skip)
        v += share[s] * t.full[c][s].Objective();
    return v;
  };
  auto sum_folds = [&](size_t c, Intent i, int skip_fold) {
    double v = 0;
    for (size_t s = 0; s < sets.size(); ++s)
      for (int f = 0; f < folds; ++f)
        if (InIntent(sets[s], i) && f != skip_fold)
          v += share[s] * t.fold[c][s][f].Objective();
    return v;
  };
  auto any = [](size_t) { return true; };

  // The embedding pair. S is IDENTITY's: the intent that the spectrum
  // answers (its best candidate over every embedding); H then gives the
  // largest sum over the intents of each intent's best in-sample sum. A
  // candidate whose weight of a term is 0 fits every embedding of that term.
  auto fits = [&](size_t c, int si, int hi) {
    return (cs[c].w.spectral == 0 || cs[c].s == si) &&
           (cs[c].w.heat == 0 || cs[c].h == hi);
  };
  const int ns = static_cast<int>(SpectralConfigs().size());
  const int nh = static_cast<int>(HeatConfigs().size());
  int best_s = cs[Best(cs.size(), any, [&](size_t c) {
                 return sum_full(c, Intent::kIdentity, -1);
               })].s;
  int best_h = 0;
  double best_pair = -1;
  for (int si = best_s; si <= best_s && si < ns; ++si) {
    for (int hi = 0; hi < nh; ++hi) {
      double v = 0;
      for (Intent i : intents) {
        const size_t b = Best(
            cs.size(), [&](size_t c) { return fits(c, si, hi); },
            [&](size_t c) { return sum_full(c, i, -1); });
        v += sum_full(b, i, -1);
      }
      if (v > best_pair + 1e-12) best_pair = v, best_s = si, best_h = hi;
    }
  }
  size_t chosen[3];
  for (int k = 0; k < 3; ++k) {
    chosen[k] = Best(
        cs.size(), [&](size_t c) { return fits(c, best_s, best_h); },
        [&](size_t c) { return sum_full(c, intents[k], -1); });
  }

  md += "Sets: ";
  for (size_t s = 0; s < sets.size(); ++s)
    absl::StrAppendFormat(&md, "%s%s (%s, %zu models)", s ? ", " : "",
                          sets[s].name,
                          !sets[s].select    ? "report only"
                          : sets[s].identity ? "identity"
                                             : "kind",
                          sets[s].data.names.size());
  absl::StrAppendFormat(
      &md,
      ". %zu candidates; objective mean(NN, FT, ST, DCG) summed over the "
      "intent's sets, each weighted 1 / (sets of its tag); %d folds.\n\n%s\n",
      cs.size(), folds, grid_note);
  absl::StrAppendFormat(&md, "**Embeddings: %s, %s.**\n\n",
                        SpectralName(SpectralConfigs()[best_s]),
                        HeatName(HeatConfigs()[best_h]));
  for (int k = 0; k < 3; ++k)
    absl::StrAppendFormat(&md, "- **%s**: %s (emd %g, spectral %g, heat %g)\n",
                          IntentTitle(intents[k]), CandidateName(cs[chosen[k]]),
                          cs[chosen[k]].w.emd, cs[chosen[k]].w.spectral,
                          cs[chosen[k]].w.heat);

  for (Intent i : intents) {
    absl::StrAppendFormat(
        &md,
        "\n### %s: leave-one-set-out (chosen on the intent's other sets, "
        "scored on the held-out set)\n\n| held-out set | chosen on the others "
        "| %s |\n|---|---|---:|---:|---:|---:|\n",
        IntentTitle(i), Header4(""));
    for (size_t s = 0; s < sets.size(); ++s) {
      if (!InIntent(sets[s], i)) continue;
      const size_t c = Best(cs.size(), any, [&](size_t x) {
        return sum_full(x, i, static_cast<int>(s));
      });
      absl::StrAppendFormat(&md, "| %s | %s | %s |\n", sets[s].name,
                            CandidateName(cs[c]), Row(t.full[c][s]));
    }
    absl::StrAppendFormat(
        &md,
        "\n### %s: %d-fold (chosen on the other folds of the intent's sets, "
        "scored on the held-out fold of each)\n\n| fold | chosen | set | %s "
        "|\n|---:|---|---|---:|---:|---:|---:|\n",
        IntentTitle(i), folds, Header4(""));
    for (int f = 0; f < folds; ++f) {
      const size_t c =
          Best(cs.size(), any, [&](size_t x) { return sum_folds(x, i, f); });
      for (size_t s = 0; s < sets.size(); ++s) {
        if (!InIntent(sets[s], i)) continue;
        absl::StrAppendFormat(&md, "| %d | %s | %s | %s |\n", f,
                              CandidateName(cs[c]), sets[s].name,
                              Row(t.fold[c][s][f]));
      }
    }
  }

  // Every set in full under each default, beside the paper, ShapeDNA-50
  // (by_index n = 50 alone: area-scaled eigenvalues weighted 1/i, L2) and D2.
  Candidate dna{0, 0, {0.0, 1.0, 0.0}};
  for (int k = 0; k < ns; ++k) {
    const SpectralOptions& o = SpectralConfigs()[k];
    if (o.transform == SpectralTransform::kByIndex && o.eigenvalues == 50)
      dna.s = k;
  }
  md +=
      "\n### Every set in full (in-sample for the selection sets)\n\n| set | "
      "paper EMD | ShapeDNA-50 | D2 | IDENTITY | KIND | BALANCED |\n"
      "|---|---|---|---|---|---|---|\n";
  auto cell = [](const Four& f) {
    return absl::StrFormat("%.3f / %.3f / %.3f / %.3f", f.nn, f.ft, f.st,
                           f.dcg);
  };
  for (size_t s = 0; s < sets.size(); ++s) {
    const std::vector<size_t> all = All(sets[s]);
    const Four d2 = Score(sets[s], all, [&](size_t i, size_t j) {
      return sets[s].data.d2(i, j);
    });
    absl::StrAppendFormat(
        &md, "| %s | %s | %s | %s | %s | %s | %s |\n", sets[s].name,
        cell(t.full[0][s]), cell(ScoreCandidate(sets[s], dna, all)), cell(d2),
        cell(t.full[chosen[0]][s]), cell(t.full[chosen[1]][s]),
        cell(t.full[chosen[2]][s]));
  }
  // Self-check of the fast scorer against metrics.h's Evaluate.
  {
    const Set& s = sets[0];
    DistanceMatrix d(s.data.names.size());
    const Candidate& c = cs[chosen[2]];
    for (size_t i = 0; i < d.size(); ++i)
      for (size_t j = i + 1; j < d.size(); ++j)
        d.Set(i, j,
              c.w.emd * s.data.emd(i, j) + c.w.spectral * s.s[c.s](i, j) +
                  c.w.heat * s.h[c.h](i, j));
    const Metrics m = Evaluate(s.data.labels, LeaveOneOutQueries(d)).overall;
    const Four f = t.full[chosen[2]][0];
    if (std::abs(m.nn - f.nn) + std::abs(m.ft - f.ft) + std::abs(m.st - f.st) +
            std::abs(m.dcg - f.dcg) >
        1e-9) {
      std::fprintf(stderr,
                   "tpr-tune-intents: scorer disagrees with Evaluate\n");
      return 1;
    }
  }
  if (!dump.empty()) {
    std::string tsv = "candidate\temd\tspectral\theat";
    for (const Set& s : sets)
      absl::StrAppend(&tsv, "\t", s.name, ".nn\t", s.name, ".ft\t", s.name,
                      ".st\t", s.name, ".dcg");
    tsv += "\n";
    for (size_t c = 0; c < cs.size(); ++c) {
      absl::StrAppendFormat(&tsv, "%s\t%g\t%g\t%g", CandidateName(cs[c]),
                            cs[c].w.emd, cs[c].w.spectral, cs[c].w.heat);
      for (size_t s = 0; s < sets.size(); ++s) {
        const Four& f = t.full[c][s];
        absl::StrAppendFormat(&tsv, "\t%.4f\t%.4f\t%.4f\t%.4f", f.nn, f.ft,
                              f.st, f.dcg);
      }
      tsv += "\n";
    }
    if (absl::Status st = WriteTextFile(dump, tsv); !st.ok()) {
      std::fprintf(stderr, "tpr-tune-intents: %s\n", st.ToString().c_str());
      return 1;
    }
  }
  std::printf("%s", md.c_str());
  if (!out.empty()) {
    if (absl::Status st = WriteTextFile(out, md); !st.ok()) {
      std::fprintf(stderr, "tpr-tune-intents: %s\n", st.ToString().c_str());
      return 1;
    }
  }
  return 0;
}

}  // namespace
}  // namespace tpr::eval

int main(int argc, char** argv) { return tpr::eval::Run(argc, argv); }
