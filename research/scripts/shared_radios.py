#!/usr/bin/env python3
"""How alike two transmitters' readings are, by kind of pair: the measurement behind the
survey's shared-radio rule (research/tuning-history.md#shared-radios).

    python3 research/scripts/shared_radios.py target/ilc/site1/{B1,F1,F2,F3,F4}

Survey walks only (the data README's split: the file at index i of a floor's sorted walks is a
test walk when i % 5 == 4), readings at most 2 s older than their scan. Per pair of BSSIDs heard
together in 20 scans or more: the standard deviation of their readings' difference, and the
share of the more often heard one's scans that hear both. Pairs are labelled by their MAC
addresses only to describe them (the survey's rule does not look at ids): "one radio" when the
addresses differ only in the first and fourth bytes and both are on one band, "two bands" when
they are on 2.4 and 5 GHz, "other" for a sample of pairs with unrelated addresses heard together somewhere.
"""
import collections, glob, itertools, os, random, sys


def percentiles(values):
    v = sorted(values)
    return " / ".join(f"{v[int(len(v) * q)]:.2f}" for q in (0.1, 0.5, 0.9)) if v else "-"


def main(floors):
    scans, band = [], {}
    for floor in floors:
        files = sorted(glob.glob(os.path.join(floor, "path_data_files", "*.txt")), key=os.path.basename)
        for i, path in enumerate(files):
            if i % 5 == 4:
                continue
            by_time = collections.defaultdict(dict)
            for line in open(path, encoding="utf-8", errors="replace"):
                p = line.rstrip("\n").split("\t")
                if len(p) > 6 and p[1] == "TYPE_WIFI" and int(p[0]) - int(p[6]) <= 2000:
                    by_time[int(p[0])][p[3]] = int(p[4])
                    band[p[3]] = int(p[5]) > 4000
            scans.extend(by_time.values())
    family = lambda m: tuple(m.split(":")[i] for i in (1, 2, 4, 5))
    heard = collections.Counter(m for s in scans for m in s)
    # Unrelated pairs: a sample of those heard together in some scan, followed in every scan.
    random.seed(1)
    others = set()
    for s in random.sample(scans, min(2000, len(scans))):
        ms = sorted(s)
        for _ in range(5):
            if len(ms) > 1:
                a, b = sorted(random.sample(ms, 2))
                if family(a) != family(b):
                    others.add((a, b))
    diffs = collections.defaultdict(list)
    for s in scans:
        ms = sorted(s)
        for a, b in itertools.combinations(ms, 2):
            if family(a) == family(b) or (a, b) in others:
                diffs[(a, b)].append(s[a] - s[b])
    kinds = collections.defaultdict(lambda: ([], []))
    for (a, b), d in diffs.items():
        if len(d) < 20:
            continue
        kind = "other" if family(a) != family(b) else ("one radio" if band[a] == band[b] else "two bands")
        n = len(d)
        mean = sum(d) / n
        kinds[kind][0].append((sum(x * x for x in d) / n - mean * mean) ** 0.5)
        kinds[kind][1].append(n / max(heard[a], heard[b]))
    print(f"{len(scans)} survey scans; 10th / 50th / 90th percentiles")
    for kind in ("one radio", "two bands", "other"):
        sd, share = kinds[kind]
        print(f"{kind:10} {len(sd):6} pairs  difference SD {percentiles(sd)} dB  heard together {percentiles(share)}")


if __name__ == "__main__":
    main(sys.argv[1:])
