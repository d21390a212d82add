#!/usr/bin/env python3
"""Whether a fingerprint should depend on the way the walker faces (research/tuning-history.md#where-the-error-is):
each test walk's WiFi readings against the mean of 3 survey readings of the same access point
within 3 m taken walking the same way (within 45 degrees), 3 taken walking the opposite way, and
all 6 together, where a reading has both (positions and directions from the waypoints, segments
under 1 m left out). Prints the rms residual of each, dB.

Usage: direction_residuals.py FLOOR_DIR...   (the data README's split: index % 5 == 4 is a test walk)
Standard library only.
"""
import collections, math, os, statistics, sys

from rssi_offset import read

CELL_M = 3.0  # neighbourhood radius, m
EACH = 3  # survey readings each way


def angle(a, b):
    d = abs(a - b) % (2 * math.pi)
    return min(d, 2 * math.pi - d)


def rms(xs):
    return math.sqrt(sum(x * x for x in xs) / len(xs))


for floor in sys.argv[1:]:
    files = sorted(os.listdir(os.path.join(floor, "path_data_files")))
    walks = [read(os.path.join(floor, "path_data_files", f)) for f in files]
    index = collections.defaultdict(list)
    for i, walk in enumerate(walks):
        if i % 5 != 4:
            for x, y, h, b, v in walk:
                if h is not None:
                    index[(b, int(x // CELL_M), int(y // CELL_M))].append((x, y, h, v))
    same, opposite, both = [], [], []
    for walk in walks[4::5]:
        for x, y, h, b, v in walk:
            if h is None:
                continue
            cx, cy = int(x // CELL_M), int(y // CELL_M)
            near = [(hh, vv) for i in (-1, 0, 1) for j in (-1, 0, 1)
                    for (xx, yy, hh, vv) in index.get((b, cx + i, cy + j), ())
                    if (xx - x) ** 2 + (yy - y) ** 2 < CELL_M ** 2]
            s = [vv for hh, vv in near if angle(hh, h) < math.pi / 4][:EACH]
            o = [vv for hh, vv in near if angle(hh, h) > 3 * math.pi / 4][:EACH]
            if len(s) == EACH and len(o) == EACH:
                same.append(v - statistics.mean(s))
                opposite.append(v - statistics.mean(o))
                both.append(v - statistics.mean(s + o))
    name = os.path.basename(floor.rstrip("/"))
    if not same:
        print(f"{name}: no test reading has {EACH} survey readings each way")
        continue
    print(f"{name}: {len(same)} readings, rms residual same way {rms(same):.2f}, opposite way "
          f"{rms(opposite):.2f}, both {rms(both):.2f} dB")
