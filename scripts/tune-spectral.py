#!/usr/bin/env python3
"""Chooses the spectral term's defaults (phi, w_s) across every dev set.

Reads the results.json that `tpr-eval-local --tune-spectral` wrote for each
set (every (phi, w_s) scored on each half of every class, objective =
mean(NN, FT, ST, DCG)) and:
  * for each half, picks the candidate whose objective SUMMED OVER ALL SETS
    is best on that half, and reports it on the other half, per set (the
    honest, held-out estimate);
  * picks the default: the candidate best summed over both halves and all
    sets. Never tuned to one set.

  scripts/tune-spectral.py NAME=docs/results/shrec11/results.json ... > table.md
"""
import json
import sys


def main(argv):
    sets = []
    for arg in argv[1:]:
        name, path = arg.split("=", 1)
        with open(path) as f:
            sets.append((name, json.load(f)["spectral_tuning"]))
    if not sets:
        print(__doc__)
        return 2
    # score[set][(phi, w)][fold] = (objective, metrics)
    score = []
    for _, rows in sets:
        s = {}
        for r in rows:
            s.setdefault((r["phi"], str(r["w"])), {})[r["fold"]] = (r["objective"], r["metrics"])
        score.append(s)
    candidates = [c for c in score[0] if c[1] != "alone" and all(c in s for s in score)]

    def total(c, folds):
        return sum(s[c][f][0] for s in score for f in folds)

    out = []
    out.append("| chosen on half | phi | w_s | set | held-out NN | FT | ST | DCG | objective |")
    out.append("|---|---|---:|---|---:|---:|---:|---:|---:|")
    for f in (0, 1):
        best = max(candidates, key=lambda c: total(c, [f]))
        for (name, _), s in zip(sets, score):
            m = s[best][1 - f][1]
            out.append("| %d | %s | %s | %s | %.3f | %.3f | %.3f | %.3f | %.3f |" % (
                f, best[0], best[1], name, m["nn"], m["ft"], m["st"], m["dcg"], s[best][1 - f][0]))
    default = max(candidates, key=lambda c: total(c, [0, 1]))
    out.append("")
    out.append("Default (best summed over both halves of every set): phi = %s, w_s = %s." % default)
    out.append("")
    out.append("| phi | w_s | " + " | ".join("%s half 0 / 1" % n for n, _ in sets) + " | sum |")
    out.append("|---|---:|" + "---:|" * (len(sets) + 1))
    for c in sorted(candidates + [k for k in score[0] if k[1] == "alone"],
                    key=lambda c: (c[0], float(c[1]) if c[1] != "alone" else 1e9)):
        if not all(c in s for s in score):
            continue
        cells = ["%.3f / %.3f" % (s[c][0][0], s[c][1][0]) for s in score]
        out.append("| %s | %s | %s | %.3f |" % (c[0], c[1], " | ".join(cells), total(c, [0, 1])))
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
