"""How much of each walk another survey walk passed near: for every walk of the given floors
(Indoor Location Competition 2.0 directories, the data README's split), the share of its
waypoints within 3 m of the path of a survey walk other than itself (paths drawn straight
between waypoints), pooled by the walk's index modulo 5 in the sorted file list (4: the test
walks). A survey walk held out by the calibration is scored against the other survey walks,
a test walk against all of them; walks recorded one after another often cover the same
stretch, so the split's rule decides what a held-out walk has left to be compared with
(research/tuning-history.md#radius-factors).

    python3 research/scripts/walk_coverage.py target/ilc/site1/{B1,F1,F2,F3,F4}

Standard library only.
"""

import math
import os
import sys

NEAR_M = 3.0


def waypoints(path):
    """The walk's waypoints (x, y) in file order."""
    with open(path, encoding="utf-8") as f:
        return [
            (float(p[2]), float(p[3]))
            for p in (line.rstrip("\n").split("\t") for line in f)
            if len(p) >= 4 and p[1] == "TYPE_WAYPOINT"
        ]


def densified(points):
    """Points every metre or less along the straight legs between waypoints."""
    out = []
    for a, b in zip(points, points[1:]):
        n = max(1, int(math.dist(a, b)))
        out.extend((a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n) for k in range(n))
    out.extend(points[-1:])
    return out


def main():
    by_index = [[0, 0] for _ in range(5)]
    for floor in sys.argv[1:]:
        folder = os.path.join(floor, "path_data_files")
        names = sorted(n for n in os.listdir(folder) if n.endswith(".txt"))
        walks = [waypoints(os.path.join(folder, n)) for n in names]
        paths = [densified(w) for w in walks]
        survey = [i for i in range(len(names)) if i % 5 != 4]
        # Path points by 3 m cell, with their walk.
        cells = {}
        for i in survey:
            for x, y in paths[i]:
                cells.setdefault((int(x // NEAR_M), int(y // NEAR_M)), []).append((x, y, i))
        for i, points in enumerate(walks):
            for x, y in points:
                cx, cy = int(x // NEAR_M), int(y // NEAR_M)
                near = any(
                    j != i and math.hypot(px - x, py - y) <= NEAR_M
                    for dx in (-1, 0, 1)
                    for dy in (-1, 0, 1)
                    for px, py, j in cells.get((cx + dx, cy + dy), ())
                )
                by_index[i % 5][0] += near
                by_index[i % 5][1] += 1
    for k, (near, total) in enumerate(by_index):
        role = "test" if k == 4 else "survey"
        print(f"index % 5 = {k} ({role}): {near / max(total, 1):.3f} of {total} waypoints within {NEAR_M:g} m")


if __name__ == "__main__":
    main()
