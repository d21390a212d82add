"""Two rules for the museum rows' 68% radius, fitted on the held-out rows of `radius_diag`
and scored on its test rows (research/radius-museum.md, "Rules 1 and 2 measured").

    ROW=ipin2023-t3/both-phones cargo run --release -p waymark-eval --example radius_diag \
        > target/runs/rd-both-phones.csv   # and A520F-surveys, G930F-surveys
    python3 research/scripts/radius_rules.py target/runs

Rule 1: a factor per tercile of one density column (held-out terciles, bins under 30 epochs
fall back to the global factor). Rule 2: does the engine's end-of-walk device offset predict
the factor a walk needs?
"""
import collections
import csv
import sys

import numpy as np

ROWS = ["A520F-surveys", "G930F-surveys", "both-phones"]
DENSITY = ["walks_r", "scans_r", "walks_4m", "states_8m", "fit", "k"]


def ratio(r):
    """The factor that would just hold this epoch: radio part of the error over the radius."""
    e, b, r68 = float(r["error_m"]), float(r["beyond_radio_m"]), float(r["r68"])
    return (e - b) / max(r68 - b, 1e-9)


def by_density(held, test):
    hr = np.array([ratio(r) for r in held])
    tr = np.array([ratio(r) for r in test])
    f = np.quantile(hr, 0.68)
    print("  global factor %.2f, test hold %.3f" % (f, (tr <= f).mean()))
    for col in DENSITY:
        hv = np.array([float(r[col]) for r in held])
        tv = np.array([float(r[col]) for r in test])
        edges = np.unique(np.quantile(hv, [0, 1 / 3, 2 / 3, 1]))
        hb = np.clip(np.searchsorted(edges[1:-1], hv, side="right"), 0, len(edges) - 2)
        tb = np.clip(np.searchsorted(edges[1:-1], tv, side="right"), 0, len(edges) - 2)
        fs = np.array([np.quantile(hr[hb == k], 0.68) if (hb == k).sum() > 30 else f
                       for k in range(len(edges) - 1)])
        print("  by %-9s factors %-20s test hold %.3f" % (col, fs.round(2), (tr <= fs[tb]).mean()))


def by_offset(rows, which):
    walks = collections.defaultdict(list)
    for r in rows:
        if r["set"] == which:
            walks[r["walk"]].append(r)
    per = np.array([(abs(float(v[0]["offset_db"])), np.quantile([ratio(r) for r in v], 0.68))
                    for v in walks.values()])
    print("  %s: %d walks, median |offset| %.1f dB, corr(|offset|, walk factor) %.2f"
          % (which, len(per), np.median(per[:, 0]), np.corrcoef(per[:, 0], per[:, 1])[0, 1]))


def main(folder):
    for row in ROWS:
        rows = [r for r in csv.DictReader(open(f"{folder}/rd-{row}.csv")) if r["throttled"] == "0"]
        print(row)
        by_density([r for r in rows if r["set"] == "held"], [r for r in rows if r["set"] == "test"])
        for which in ["held", "test"]:
            by_offset(rows, which)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "target/runs")
