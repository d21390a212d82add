#!/usr/bin/env python3
"""Analysis of examples/pdr_diag.rs's TSV (standard library only; not part of the
product). Every section prints the figure quoted in the diagnosis of the PDR distance error.

    cargo run --release -p waymark-eval --example pdr_diag -- .../site1/{B1,F1,F2,F3,F4}/path_data_files > /tmp/diag.tsv
    python3 research/scripts/pdr_diag.py /tmp/diag.tsv

Model choices are made on SURVEY walks only; TEST walks are only scored.
"""
import csv
import math
import random
import statistics as st
import sys

path = sys.argv[1] if len(sys.argv) > 1 else "/tmp/diag.tsv"
rows = list(csv.DictReader(open(path), delimiter="\t"))
K = None
walks, segs, firsts = [], {}, []
for r in rows:
    if r["kind"] == "walk":
        w = {k: (float(v) if k not in ("kind", "floor", "name", "test") else v) for k, v in r.items()}
        w["test"] = r["test"] == "1"
        walks.append(w)
    elif r["kind"] == "seg":
        segs.setdefault((r["test"] == "1", r["name"]), []).append(
            dict(len=float(r["L"]), i=int(r["nwp"]), dur=float(r["T"]), n=int(r["N"]), est=float(r["est"]),
                 W=float(r["W"]), gap=float(r["pause"]), turn=float(r["turn_wp"]),
                 wig=float(r["turn_steps"]), net=float(r["minseg"])))
    elif r["kind"] == "first":
        firsts.append([float(r[c]) for c in list(r)[4:13]])
for w in walks:
    w["err"] = (w["est"] - w["L"]) / w["L"]
K = sum(s["est"] for v in segs.values() for s in v) / sum(s["W"] for v in segs.values() for s in v)
T = [w for w in walks if w["test"]]
S = [w for w in walks if not w["test"]]


def mean_abs(ws):
    return st.mean(abs(w["err"]) for w in ws)


def corr(x, y):
    mx, my = st.mean(x), st.mean(y)
    return sum((a - mx) * (b - my) for a, b in zip(x, y)) / math.sqrt(
        sum((a - mx) ** 2 for a in x) * sum((b - my) ** 2 for b in y))


print(f"k = {K:.4f}; test walks {len(T)}, mean |e| {100 * mean_abs(T):.1f} %")
print("\n== 1. test error by walk length / waypoints / pauses (share = part of Σ|e|) ==")
tot = sum(abs(w["err"]) for w in T)


def bucket(name, ws):
    if ws:
        print(f"  {name:22s} n={len(ws):3d} mean|e| {100 * mean_abs(ws):5.1f} % median {100 * st.median(abs(w['err']) for w in ws):5.1f} % "
              f"signed {100 * st.mean(w['err'] for w in ws):+5.1f} % share {100 * sum(abs(w['err']) for w in ws) / tot:4.1f} %")


for lo, hi in [(0, 10), (10, 20), (20, 35), (35, 70), (70, 1e9)]:
    bucket(f"L [{lo},{hi}) m", [w for w in T if lo <= w["L"] < hi])
for lo, hi in [(2, 3), (3, 5), (5, 8), (8, 100)]:
    bucket(f"waypoints [{lo},{hi})", [w for w in T if lo <= w["nwp"] < hi])
bucket("with a pause > 1.5 s", [w for w in T if w["npause"] > 0])
bucket("without", [w for w in T if w["npause"] == 0])

print("\n== 2. selection: mean log(est/L) by L, by est, by duration (SURVEY, N >= 3) ==")
R = [w for w in S if w["N"] >= 3]
for key in ("L", "est", "T"):
    out = []
    for lo, hi in [(0, 10), (10, 20), (20, 35), (35, 70), (70, 1e9)]:
        b = [math.log(w["est"] / w["L"]) for w in R if lo <= w[key] < hi]
        out.append(f"{100 * st.mean(b):+5.1f}")
    print(f"  by {key:3s}: " + " ".join(out) + "  (buckets <10, 10-20, 20-35, 35-70, 70+)")

print("\n== 3. start and end of the recordings ==")
print(f"  first accelerometer sample after the first waypoint: median {st.median(w['acc_first'] for w in walks):.2f} s; "
      f"last sample after the last waypoint: median {st.median(w['acc_last'] for w in walks):.2f} s")
rel = [w["lead"] / w["period"] for w in walks if w["N"] > 0]
print(f"  first step after the first waypoint / step period, deciles: {[round(x, 2) for x in st.quantiles(rel, n=10)]}")
print(f"  walks with a step in the first 0.14 s: {100 * sum(w['lead'] < 0.14 for w in walks) / len(walks):.0f} % "
      f"(uniform phase: {100 * st.mean(min(1, 0.14 / w['period']) for w in walks if w['N'] > 0):.0f} %)")
print(f"  last step before the last waypoint: median {st.median(w['trail'] for w in walks if w['N'] > 0):.2f} s")
if firsts:
    m = [st.mean(f[i] for f in firsts) for i in range(9)]
    print(f"  Weinberg term of steps 1-4 / walk mean: {m[0]:.3f} {m[1]:.3f} {m[2]:.3f} {m[3]:.3f}; last step {m[4]:.3f}")
multi = [v for (t, _), v in segs.items() if not t and len(v) >= 3]
for name, ss in [("first", [v[0] for v in multi]), ("interior", [s for v in multi for s in v[1:-1]]), ("last", [v[-1] for v in multi])]:
    print(f"  SURVEY {name:8s} segments: Σ length / Σ Weinberg = {sum(s['len'] for s in ss) / sum(s['W'] for s in ss):.3f} "
          f"(m per step {sum(s['len'] for s in ss) / sum(s['n'] for s in ss):.3f})")

speeds = [w["L"] / w["T"] for w in walks if w["T"] > 0]
print(f"  walking speed, waypoint path / span over {len(speeds)} walks: median {st.median(speeds):.2f} m/s, "
      f"quartiles {' '.join(f'{q:.2f}' for q in st.quantiles(speeds, n=4))} (HIPE's assumed speed: 1 m/s)")

print("\n== 4. per-walk models by leave-one-walk-out on SURVEY walks (>= 10 m, >= 5 steps, Hampel), scored on TEST ==")
U = [w for w in S if w["N"] >= 5 and w["L"] >= 10]
rat = [w["L"] / w["N"] for w in U]
c = st.median(rat)
mad = max(1.4826 * st.median(abs(x - c) for x in rat), 0.01 * c)
U = [w for w in U if abs(w["L"] / w["N"] - c) <= 3 * mad]


def wls(X, y, wt):
    p = len(X[0])
    M = [[sum(q * x[i] * x[j] for x, q in zip(X, wt)) for j in range(p)] + [sum(q * x[i] * b for x, b, q in zip(X, y, wt))] for i in range(p)]
    for i in range(p):
        piv = M[i][i]
        M[i] = [v / piv for v in M[i]]
        for k in range(p):
            if k != i:
                f = M[k][i]
                M[k] = [a - f * b for a, b in zip(M[k], M[i])]
    return [M[i][p] for i in range(p)]


for name, f in [("k·W (current)", lambda w: [w["W"]]), ("k·W + c", lambda w: [w["W"], 1.0]),
                ("k·W + c·bouts", lambda w: [w["W"], 1.0 + w["npause"]]), ("l·N", lambda w: [w["N"]])]:
    X, y, wt = [f(w) for w in U], [w["L"] for w in U], [1 / w["N"] for w in U]
    beta = wls(X, y, wt)
    cv = [abs(sum(a * x for a, x in zip(wls(X[:i] + X[i + 1:], y[:i] + y[i + 1:], wt[:i] + wt[i + 1:]), X[i])) - y[i]) / y[i] for i in range(len(U))]
    te = [abs(sum(a * x for a, x in zip(beta, f(w))) - w["L"]) / w["L"] for w in T]
    print(f"  {name:15s} β={[round(b, 3) for b in beta]} survey LOWO {100 * st.mean(cv):.2f} % | test mean {100 * st.mean(te):.2f} % median {100 * st.median(te):.2f} %")


def k_l1(ws):
    pts = sorted((w["L"] / w["W"], w["W"] / w["L"]) for w in ws)
    half, acc = sum(q for _, q in pts) / 2, 0
    for x, q in pts:
        acc += q
        if acc >= half:
            return x


cv = [abs(k_l1(U[:i] + U[i + 1:]) * U[i]["W"] - U[i]["L"]) / U[i]["L"] for i in range(len(U))]
k1 = k_l1(U)
print(f"  k minimising mean relative error (weighted median): k={k1:.4f} survey LOWO {100 * st.mean(cv):.2f} % | "
      f"test mean {100 * st.mean(abs(k1 * w['W'] - w['L']) / w['L'] for w in T):.2f} %")

# Weinberg's exponent 1/4 on the peak-to-peak, generalised to β/4 on the walk's mean term
# (β = 4/3 is about Kim et al.'s cube root): how much a steeper law would give.
for beta in (1.0, 1.5, 2.0):
    def fit_b(ws):
        return sum(w["L"] for w in ws) / sum(w["N"] * (w["W"] / w["N"]) ** beta for w in ws)
    cv = [abs(fit_b(U[:i] + U[i + 1:]) * U[i]["N"] * (U[i]["W"] / U[i]["N"]) ** beta - U[i]["L"]) / U[i]["L"] for i in range(len(U))]
    kb = fit_b(U)
    te = [abs(kb * w["N"] * (w["W"] / w["N"]) ** beta - w["L"]) / w["L"] for w in T]
    print(f"  k·N·mean(ptp^¼)^{beta}: survey LOWO {100 * st.mean(cv):.2f} % | test mean {100 * st.mean(te):.2f} %")

print("\n== 5. segments (SURVEY walks >= 10 m, >= 2 segments): residual length − k_walk · W ==")
res = []
for (t, _), v in segs.items():
    if t or len(v) < 2:
        continue
    L, Wt = sum(s["len"] for s in v), sum(s["W"] for s in v)
    if Wt <= 0 or L < 10 or not 0.25 < L / Wt < 0.5:
        continue
    for s in v:
        res.append(dict(s, r=s["len"] - L / Wt * s["W"]))
for lo, hi in [(0, 2), (2, 4), (4, 6), (6, 9), (9, 13), (13, 20)]:
    b = [s for s in res if lo <= s["len"] < hi]
    print(f"  length [{lo},{hi}) m: n={len(b):4d} rms {math.sqrt(st.mean(s['r'] ** 2 for s in b)):.2f} m, mean {st.mean(s['r'] for s in b):+.2f} m")
b = [s for s in res if s["gap"] < 0.3 and s["n"] >= 2]
print(f"  segments with no step gap: rms {math.sqrt(st.mean(s['r'] ** 2 for s in b)):.2f} m (n={len(b)})")
b = [s for s in res if s["wig"] >= 100 and s["n"] >= 2]
print(f"  segments with Σ|Δheading| >= 100°: mean {st.mean(s['r'] for s in b):+.2f} m (n={len(b)})")
R2 = [s for s in res if s["n"] >= 2]
print(f"  corr(residual, gap) {corr([s['gap'] for s in R2], [s['r'] for s in R2]):+.2f}, "
      f"corr(residual, Σ|Δheading|) {corr([s['wig'] for s in R2], [s['r'] for s in R2]):+.2f}")

# Adjacent-segment covariance with k from the walk's other segments: a label (position or
# time) error at a shared waypoint makes adjacent residuals anticorrelated (cov −σ²).
sq, adj, lag2 = [], [], []
for (t, _), v in segs.items():
    if t or len(v) < 4:
        continue
    for lag, out in ((1, adj), (2, lag2)):
        for i in range(len(v) - lag):
            rest = [s for j, s in enumerate(v) if j not in (i, i + lag)]
            L, Wt = sum(s["len"] for s in rest), sum(s["W"] for s in rest)
            if Wt <= 0 or L < 8 or not 0.25 < L / Wt < 0.55:
                continue
            a, b = (v[j]["len"] - L / Wt * v[j]["W"] for j in (i, i + lag))
            if abs(a) > 6 or abs(b) > 6:
                continue
            out.append(a * b)
            if lag == 1:
                sq += [a * a, b * b]
print(f"  leave-pair-out: var {st.mean(sq):.2f} m², cov adjacent {st.mean(adj):+.2f}, cov lag 2 {st.mean(lag2):+.2f} "
      f"(label error along track: σ² ≈ cov lag 2 − cov adjacent = {st.mean(lag2) - st.mean(adj):+.2f} m²)")

# The same segments against other distance measures, each scaled by its own walk.
meas = {"n": "steps × walk's constant length", "W": "Weinberg Σ × walk's k", "net": "net step displacement × walk's k",
        "dur": "segment duration × walk's speed", "walkt": "stepping time × walk's speed"}
rr = {c: [] for c in meas}
for (t, _), v in segs.items():
    if t or len(v) < 3:
        continue
    L = sum(s["len"] for s in v)
    for s in v:
        s["walkt"] = max(s["dur"] - max(s["gap"], 0.0), 0.0)
    tots = {c: sum(s[c] for s in v) for c in meas}
    if L < 10 or min(tots.values()) <= 0 or not 0.25 < L / tots["W"] < 0.5:
        continue
    for c in meas:
        rr[c] += [s["len"] - L / tots[c] * s[c] for s in v]
for c, name in meas.items():
    print(f"  {name:34s} per-segment rms {math.sqrt(st.mean(x * x for x in rr[c])):.2f} m")
print(f"  corr(Weinberg residual, stepping-time residual) {corr(rr['W'], rr['walkt']):.2f}; "
      f"rms of their difference {math.sqrt(st.mean((a - b) ** 2 for a, b in zip(rr['W'], rr['walkt']))):.2f} m")

print("\n== 6. variance components of log(segment length / (k·W)), SURVEY segments >= 5 m with >= 4 steps ==")
by = {}
for (t, name), v in segs.items():
    if not t:
        for s in v:
            if s["len"] >= 5 and s["n"] >= 4 and s["W"] > 0:
                by.setdefault(name, []).append(math.log(s["len"] / (K * s["W"])))
groups = [g for g in by.values() if len(g) >= 2]
within = sum(sum((y - st.mean(g)) ** 2 for y in g) for g in groups) / sum(len(g) - 1 for g in groups)
nbar = st.mean(len(g) for g in groups)
between = st.pvariance([st.mean(g) for g in groups]) - within / nbar
print(f"  within-walk sd {100 * math.sqrt(within):.1f} %, between-walk sd {100 * math.sqrt(max(between, 0)):.1f} % ({len(groups)} walks)")

print("\n== 7. what the TEST score would be (Monte Carlo on the test walks' segments) ==")
random.seed(1)
tw = [[s["len"] for s in v] for (t, _), v in segs.items() if t]


def sim(scale_sd, seg_sd, offset_m):
    return st.mean(st.mean(abs(scale_sd * random.gauss(0, 1) * sum(g) + sum(random.gauss(0, seg_sd) for _ in g) + offset_m) / sum(g)
                           for g in tw) for _ in range(20))


sb = math.sqrt(max(between, 0))
for a, b, c, what in [(sb, 1.0, 0.8, "as measured (scale, per-segment 1.0 m, start offset 0.8 m)"),
                      (sb, 1.0, 0.0, "no start offset"),
                      (0.0, 1.0, 0.0, "oracle per-walk step length, no offset"),
                      (0.0, 1.1, 0.0, "the same with the leave-pair-out per-segment sd 1.1 m"),
                      (sb, 0.0, 0.0, "no per-segment noise (only scale)"),
                      (0.0, 0.5, 0.0, "oracle scale, per-segment 0.5 m (the step-only part)")]:
    print(f"  {what:58s} → mean |e| {100 * sim(a, b, c):.1f} %")
