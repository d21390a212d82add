#!/usr/bin/env python3
"""Whether a fingerprint should depend on the way the walker faces (docs/tuning.md#where-the-error-is):
each test walk's WiFi readings against the mean of 3 survey readings of the same access point
within 3 m taken walking the same way (within 45 degrees), 3 taken walking the opposite way, and
all 6 together, where a reading has both (positions and directions from the waypoints, segments
under 1 m left out). Prints the rms residual of each, dB.

Usage: direction_residuals.py FLOOR_DIR...   (the data README's split: index % 5 == 4 is a test walk)
Standard library only.
"""
import bisect, collections, math, os, statistics, sys

CELL_M = 3.0  # neighbourhood radius, m
EACH = 3  # survey readings each way


def read(path):
    waypoints, scans = [], collections.defaultdict(list)
    for line in open(path, errors="replace"):
        if line.startswith("#"):
            continue
        p = line.rstrip("\n").split("\t")
        if len(p) < 3:
            continue
        if p[1] == "TYPE_WAYPOINT":
            waypoints.append((int(p[0]), float(p[2]), float(p[3])))
        elif p[1] == "TYPE_WIFI" and int(p[0]) - int(p[6]) <= 2000:  # fresh readings only
            scans[int(p[0])].append((p[3], int(p[4])))
    waypoints.sort()
    times = [w[0] for w in waypoints]
    out = []
    for t, readings in scans.items():
        i = bisect.bisect_left(times, t)
        if 0 < i < len(times):
            (t0, x0, y0), (t1, x1, y1) = waypoints[i - 1], waypoints[i]
            if math.hypot(x1 - x0, y1 - y0) < 1.0:
                continue
            f = (t - t0) / max(1, t1 - t0)
            h = math.atan2(y1 - y0, x1 - x0)
            out.extend((x0 + f * (x1 - x0), y0 + f * (y1 - y0), h, b, v) for b, v in readings)
    return out


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
                index[(b, int(x // CELL_M), int(y // CELL_M))].append((x, y, h, v))
    same, opposite, both = [], [], []
    for walk in walks[4::5]:
        for x, y, h, b, v in walk:
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
