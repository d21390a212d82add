#!/usr/bin/env python3
"""Whether a floor classifier from the survey alone could pick a test scan's floor better than
the engine does (docs/accuracy.md). Two classifiers, each trained on the survey walks kept at
each survey fraction (the rule of `waymark eval --survey-fraction`):

- home floor: each transmitter's floor is where the survey heard it strongest; a scan's floor
  is the majority of its K strongest known readings' floors;
- presence: naive Bayes over which transmitters a scan hears, p(heard | floor) the share of the
  floor's survey scans that heard it (add-one-half smoothed), summed over the walk so far
  (a test walk keeps to one floor, so this is the most evidence a walk can give).

Prints the share of test scans on the right floor, pooled and per floor.

Usage: floor_vote.py FRACTION... -- FLOOR_DIR...   (split of the data's README: index % 5 == 4
is a test walk)
"""
import collections, math, os, sys

TOP_K = (1, 3, 5, 10)


def subset(n, fraction):
    """Indices of the survey walks kept at FRACTION, as `survey_subset` in the survey crate."""
    kept_before = lambda i: math.ceil(i * fraction - 1e-9)
    return [i for i in range(n) if kept_before(i + 1) > kept_before(i)]


def scans(path):
    """The WiFi scans of a walk, in order: lists of (transmitter, rssi)."""
    by_time = collections.OrderedDict()
    for line in open(path, errors="replace"):
        p = line.rstrip("\n").split("\t")
        if len(p) >= 5 and p[1] == "TYPE_WIFI":
            by_time.setdefault(p[0], []).append((p[3], float(p[4])))
    return list(by_time.values())


def main():
    args = sys.argv[1:]
    split = args.index("--")
    fractions = [float(a) for a in args[:split]]
    dirs = args[split + 1 :]
    names = [os.path.basename(d.rstrip("/")) for d in dirs]
    walks = {}
    for name, d in zip(names, dirs):
        files = sorted(os.listdir(os.path.join(d, "path_data_files")))
        paths = [os.path.join(d, "path_data_files", f) for f in files]
        survey = [scans(p) for i, p in enumerate(paths) if i % 5 != 4]
        test = [scans(p) for i, p in enumerate(paths) if i % 5 == 4]
        walks[name] = (survey, test)

    def report(label, right):
        pooled = sum(sum(r) for r in right.values()) / sum(len(r) for r in right.values())
        floors = " ".join(f"{n}:{sum(right[n]) / len(right[n]):.3f}" for n in names)
        print(f"{label}: {pooled:.4f} of test scans | {floors}")

    for fraction in fractions:
        kept = {n: [walks[n][0][i] for i in subset(len(walks[n][0]), fraction)] for n in names}
        strongest = collections.defaultdict(dict)
        heard = {n: collections.Counter() for n in names}
        scan_count = collections.Counter()
        for n in names:
            for walk in kept[n]:
                for scan in walk:
                    scan_count[n] += 1
                    for tx, rssi in scan:
                        heard[n][tx] += 1
                        strongest[tx][n] = max(rssi, strongest[tx].get(n, -200.0))
        home = {tx: max(by.items(), key=lambda kv: kv[1])[0] for tx, by in strongest.items()}

        for k in TOP_K:
            right = {n: [] for n in names}
            for n in names:
                for walk in walks[n][1]:
                    for scan in walk:
                        known = sorted(((r, tx) for tx, r in scan if tx in home), reverse=True)[:k]
                        if known:
                            votes = collections.Counter(home[tx] for _, tx in known)
                            right[n].append(votes.most_common(1)[0][0] == n)
            report(f"F = {fraction} home floor, top {k}", right)

        right = {n: [] for n in names}
        for n in names:
            for walk in walks[n][1]:
                total = collections.Counter()
                for scan in walk:
                    for g in names:
                        for tx, _ in scan:
                            if tx in home:
                                total[g] += math.log((heard[g][tx] + 0.5) / (scan_count[g] + 1))
                    right[n].append(max(names, key=lambda g: total[g]) == n)
        report(f"F = {fraction} presence, walk so far", right)


if __name__ == "__main__":
    main()
