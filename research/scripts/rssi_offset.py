#!/usr/bin/env python3
"""Per-walk RSSI offsets of a floor's walks: each walk's WiFi readings against the survey walks'
readings of the same access point within 3 m (positions interpolated between waypoints), the
walk itself left out. What a per-session RSSI offset would have to correct (docs/accuracy.md).

Usage: rssi_offset.py FLOOR_DIR...   (the split of the data's README: index % 5 == 4 is a test walk)
"""
import bisect, collections, math, os, statistics, sys

CELL_M = 3.0  # neighbourhood radius, m


def read(path):
    """A walk's fresh WiFi readings as (x, y, heading, bssid, rssi): position interpolated
    between the waypoints either side of the scan, heading (rad) that segment's direction, or
    None when the segment is under 1 m long."""
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
            f = (t - t0) / max(1, t1 - t0)
            h = math.atan2(y1 - y0, x1 - x0) if math.hypot(x1 - x0, y1 - y0) >= 1.0 else None
            out.extend((x0 + f * (x1 - x0), y0 + f * (y1 - y0), h, b, v) for b, v in readings)
    return out


def offsets(floor):
    files = sorted(os.listdir(os.path.join(floor, "path_data_files")))
    walks = [read(os.path.join(floor, "path_data_files", f)) for f in files]
    survey = [w for i, w in enumerate(walks) if i % 5 != 4]
    index = collections.defaultdict(list)
    for k, walk in enumerate(survey):
        for x, y, _, b, v in walk:
            index[(b, int(x // CELL_M), int(y // CELL_M))].append((x, y, v, k))

    def offset(walk, own):
        d = []
        for x, y, _, b, v in walk:
            cx, cy = int(x // CELL_M), int(y // CELL_M)
            near = [vv for i in (-1, 0, 1) for j in (-1, 0, 1)
                    for (xx, yy, vv, k) in index.get((b, cx + i, cy + j), ())
                    if k != own and (xx - x) ** 2 + (yy - y) ** 2 < CELL_M ** 2]
            if near:
                d.append(v - sum(near) / len(near))
        return statistics.mean(d) if len(d) >= 30 else None

    tests = [offset(w, None) for i, w in enumerate(walks) if i % 5 == 4]
    held = [offset(w, k) for k, w in enumerate(survey)]
    return [o for o in held if o is not None], [o for o in tests if o is not None]


def summary(xs):
    xs = sorted(xs)
    return (f"median {statistics.median(xs):+.2f}, sd {statistics.pstdev(xs):.2f}, "
            f"range {xs[0]:+.2f} to {xs[-1]:+.2f} dB ({len(xs)} walks)")


if __name__ == "__main__":
    for floor in sys.argv[1:]:
        held, tests = offsets(floor)
        name = os.path.basename(floor.rstrip("/"))
        print(f"{name}: survey walks held out: {summary(held)}")
        print(f"{name}: test walks:            {summary(tests)}")
