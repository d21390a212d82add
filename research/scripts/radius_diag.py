"""Candidate rules for the radius factors, fitted on the held-out rows of `radius_diag` and
checked on its test rows (research/tuning-history.md#radius-factors).

    cargo run --release -p waymark-eval --example radius_diag -- target/ilc/site1/F3 > F3.csv
    python3 research/scripts/radius_diag.py F3.csv

Each rule fits (68%, 95%) factors as the calibration does, the 68th and 95th percentiles of
(error - beyond_radio_m) / radius over the held-out epochs it selects (the kept rule: the 68th
over those on the map, the 95th over every one), steady epochs with steps
and heading apart from the throttled ones by sparse band (bands under 200 epochs fall back to
the steady factor), and prints the share of test epochs whose radii then hold the truth,
steady | throttled. Then, at the on-map factor, the walk-bootstrap standard error of the
steady test share and the spread of that share over random sets of held-out walks as many as
the test walks. Standard library only.
"""

import csv
import math
import random
import statistics
import sys
from collections import defaultdict

MIN_EPOCHS = 200
FLOATS = ("error_m", "r68", "r95", "beyond_radio_m", "fit", "off_map_m", "lag_d", "jump", "floor_p")
INTS = ("throttled", "floor", "scenario", "band", "floor_ok", "states_8m", "k", "walks_r", "scans_r", "walks_4m")


def load(path):
    rows = list(csv.DictReader(open(path)))
    for r in rows:
        for k in FLOATS:
            r[k] = float(r[k])
        for k in INTS:
            r[k] = int(r.get(k, -1))
    return rows


def quantile(values, p):
    v = sorted(values)
    if not v:
        return float("nan")
    k = p * (len(v) - 1)
    i = int(k)
    return v[i] if i + 1 >= len(v) else v[i] * (1 - (k - i)) + v[i + 1] * (k - i)


def factors(rows):
    if len(rows) < MIN_EPOCHS:
        return None
    need = lambda key, p: quantile([(r["error_m"] - r["beyond_radio_m"]) / max(r[key], 1e-9) for r in rows], p)
    return [need("r68", 0.68), need("r95", 0.95)]


def holds(r, s):
    r68 = r["r68"] * s[0]
    r95 = max(r["r95"] * s[1], r68)
    return r["error_m"] <= r68 + r["beyond_radio_m"], r["error_m"] <= r95 + r["beyond_radio_m"]


def share(rows, scale):
    h = [holds(r, scale(r)) for r in rows]
    return sum(a for a, _ in h) / len(h), sum(b for _, b in h) / len(h)


def rule(held, select, key=None, bands=1):
    """Factors over the held-out epochs `select` keeps, by quantile band of `key` when given."""
    steady = [r for r in held if not r["throttled"] and r["scenario"] == 0 and select(r)]
    edges = []
    if key:
        values = sorted(key(r) for r in steady)
        edges = [quantile(values, (k + 1) / bands) for k in range(bands - 1)]
    band_of = lambda r: sum(key(r) >= e for e in edges) if key else 0
    by_band = [factors([r for r in steady if band_of(r) == k]) for k in range(len(edges) + 1)]
    base = factors(steady)
    sparse = [factors([r for r in held if r["throttled"] and r["band"] == k and select(r)]) for k in range(5)]

    def scale(r):
        if r["band"] >= 0 and sparse[r["band"]]:
            return sparse[r["band"]]
        return by_band[band_of(r)] or base

    return scale


def power_law(rows, key, p):
    """(A, b) of the radius A * r^b whose log is the p-th quantile regression of the log error
    on the log posterior radius (least pinball loss, b on a 0.01 grid over [-0.5, 1.5])."""
    pts = [(math.log(max(r[key], 0.1)), math.log(max(r["error_m"] - r["beyond_radio_m"], 0.05))) for r in rows]
    best = None
    for k in range(-50, 151):
        b = k / 100
        c = quantile([y - b * x for x, y in pts], p)
        loss = sum((p if y >= c + b * x else p - 1) * (y - c - b * x) for x, y in pts)
        if best is None or loss < best[0]:
            best = (loss, math.exp(c), b)
    return best[1:]


def power_rule(held, select):
    """A power law of the posterior radius in place of the steady factor (sparse bands as before)."""
    steady = [r for r in held if not r["throttled"] and r["scenario"] == 0 and select(r)]
    laws = [power_law(steady, "r68", 0.68), power_law(steady, "r95", 0.95)]
    sparse = [factors([r for r in held if r["throttled"] and r["band"] == k and select(r)]) for k in range(5)]

    def scale(r):
        if r["band"] >= 0 and sparse[r["band"]]:
            return sparse[r["band"]]
        return [a * max(r[key], 0.1) ** (b - 1) for (a, b), key in zip(laws, ("r68", "r95"))]

    return scale


def main(path):
    rows = load(path)
    held = [r for r in rows if r["set"] == "held"]
    test = {t: [r for r in rows if r["set"] == "test" and r["throttled"] == t] for t in (0, 1)}
    on = lambda r: r["off_map_m"] == 0
    fit = lambda r: r["fit"] if r["fit"] == r["fit"] else -99.0
    steady_held = [r for r in held if not r["throttled"]]
    print(f"{path}: held-out epochs on the map {sum(map(on, steady_held)) / len(steady_held):.2f}, "
          f"test {sum(map(on, test[0])) / len(test[0]):.2f}")
    if test[0][0]["walks_r"] >= 0:
        for key in ("walks_r", "scans_r", "walks_4m"):
            mean = lambda rs: sum(r[key] for r in rs) / max(len(rs), 1)
            print(f"  {key}: held-out on the map {mean([r for r in steady_held if on(r)]):.1f}, "
                  f"every held-out {mean(steady_held):.1f}, test {mean(test[0]):.1f}")
    rules = [
        ("on the map, both factors", rule(held, on)),
        ("within 2 m of it", rule(held, lambda r: r["off_map_m"] <= 2.0)),
        ("within 5 m of it", rule(held, lambda r: r["off_map_m"] <= 5.0)),
        ("every epoch", rule(held, lambda r: True)),
        ("on the map, radio fit quintiles", rule(held, on, fit, 5)),
        ("every epoch, radio fit quintiles", rule(held, lambda r: True, fit, 5)),
        ("every epoch, states within 8 m quintiles", rule(held, lambda r: True, lambda r: r["states_8m"], 5)),
        ("every epoch, posterior 68% radius quintiles", rule(held, lambda r: True, lambda r: r["r68"], 5)),
        ("on the map, power law of the posterior radius", power_rule(held, on)),
        ("on the map, fixed-lag disagreement quintiles", rule(held, on, lambda r: r["lag_d"] if r["lag_d"] == r["lag_d"] else -1.0, 5)),
    ]
    on_map = rule(held, on)
    rules += [
        (f"68% on the map, 95% {name}{kept}", lambda r, o=other: [on_map(r)[0], o(r)[1]])
        for name, other, kept in (
            ("within 2 m of it", rule(held, lambda r: r["off_map_m"] <= 2.0), ""),
            ("within 5 m of it", rule(held, lambda r: r["off_map_m"] <= 5.0), ""),
            ("every epoch", rule(held, lambda r: True), " (kept)"),
        )
    ]
    if test[0][0]["walks_r"] >= 0:
        rules += [
            (f"on the map, {key} {n}-tiles", rule(held, on, lambda r, key=key: r[key], n))
            for key in ("walks_r", "scans_r", "walks_4m")
            for n in (3, 5)
        ] + [
            (f"every epoch, {key} quintiles", rule(held, lambda r: True, lambda r, key=key: r[key], 5))
            for key in ("walks_r", "walks_4m")
        ]
    for name, scale in rules:
        (a, b), (c, d) = share(test[0], scale), share(test[1], scale)
        print(f"  {name:45} {a:.3f} / {b:.3f} | {c:.3f} / {d:.3f}")
    # Sampling spread at the on-map factor.
    s = factors([r for r in steady_held if r["scenario"] == 0 and on(r)])
    walks = lambda rs: [v for v in group(rs, s).values()]
    test_walks, held_walks = walks(test[0]), walks([r for r in steady_held if on(r)])
    rate = lambda ws: sum(sum(w) for w in ws) / sum(len(w) for w in ws)
    random.seed(1)
    boot = [rate([random.choice(test_walks) for _ in test_walks]) for _ in range(2000)]
    subsets = [rate(random.sample(held_walks, min(len(test_walks), len(held_walks)))) for _ in range(2000)]
    print(f"  test walks {len(test_walks)}: 68% share {rate(test_walks):.3f}, walk-bootstrap SE "
          f"{statistics.pstdev(boot):.3f}; held-out walks on the map, sets of {len(test_walks)}: "
          f"SD {statistics.pstdev(subsets):.3f}, in [0.63, 0.73] {sum(0.63 <= x <= 0.73 for x in subsets) / len(subsets):.2f}")


def group(rows, s):
    by_walk = defaultdict(list)
    for r in rows:
        by_walk[r["walk"]].append(holds(r, s)[0])
    return by_walk


if __name__ == "__main__":
    for p in sys.argv[1:]:
        main(p)
