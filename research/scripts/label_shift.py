"""How well each walk's labels agree with the survey's radio: for every walk of the given floors
(Indoor Location Competition 2.0 directories, the data README's split) and each third of it, the
RMS residual of its WiFi readings (last seen at most 2 s before their scan, placed at their
last-seen time) against the mean of the survey walks' readings of the same access point within
3 m of the labelled position, the walk itself left out. The same with the walk's labels shifted
in time by -20 to +20 s, every 2 s: a third whose residual falls far at a shift of many seconds
was heard where its labels put it that many seconds later or earlier (research/tuning-history.md
#where-the-error-is).

    python3 research/scripts/label_shift.py target/ilc/site1/{B1,F1,F2,F3,F4} > shifts.txt

One line per walk: floor, `test` or `survey`, the walk's name, then per third the residual
unshifted, the least residual, and the shift that gives it in seconds (`nan nan 0` for a third
with under 30 readings to compare). Standard library only.
"""

import collections
import math
import os
import sys
from bisect import bisect_right

SHIFTS_S = range(-20, 21, 2)
MAX_AGE_MS = 2000
NEAR_M = 3.0
MIN_READINGS = 30


def load(path):
    """Waypoints (t ms, x, y) in time order and WiFi readings (last seen ms, BSSID, RSSI)."""
    waypoints, wifi = [], []
    for line in open(path):
        f = line.rstrip("\n").split("\t")
        if len(f) > 3 and f[1] == "TYPE_WAYPOINT":
            waypoints.append((int(f[0]), float(f[2]), float(f[3])))
        elif len(f) >= 7 and f[1] == "TYPE_WIFI" and int(f[0]) - int(f[6]) <= MAX_AGE_MS:
            wifi.append((int(f[6]), f[3], int(f[4])))
    waypoints.sort()
    return waypoints, wifi


def position(waypoints, times, t):
    """The labelled position at t ms, linear between waypoints; None outside them."""
    if t < times[0] or t > times[-1]:
        return None
    k = min(max(1, bisect_right(times, t)), len(times) - 1)
    (ta, xa, ya), (tb, xb, yb) = waypoints[k - 1], waypoints[k]
    f = (t - ta) / max(tb - ta, 1)
    return xa + f * (xb - xa), ya + f * (yb - ya)


def floor_lines(directory, name):
    files = sorted(os.listdir(directory))
    walks = {}
    # (BSSID, 3 m cell) -> survey readings (x, y, RSSI, walk)
    survey = collections.defaultdict(list)
    for i, file in enumerate(files):
        waypoints, wifi = load(os.path.join(directory, file))
        if len(waypoints) < 2:
            continue
        times = [w[0] for w in waypoints]
        test = i % 5 == 4
        walks[file] = (test, waypoints, times, wifi)
        if test:
            continue
        for t, bssid, rssi in wifi:
            p = position(waypoints, times, t)
            if p:
                survey[(bssid, int(p[0] // NEAR_M), int(p[1] // NEAR_M))].append((p[0], p[1], rssi, file))

    def residual(file, waypoints, times, wifi, lo, hi, shift_ms):
        total, n = 0.0, 0
        for t, bssid, rssi in wifi:
            if not lo <= t < hi:
                continue
            p = position(waypoints, times, t + shift_ms)
            if not p:
                continue
            gx, gy = int(p[0] // NEAR_M), int(p[1] // NEAR_M)
            near = [
                r
                for dx in (-1, 0, 1)
                for dy in (-1, 0, 1)
                for x, y, r, w in survey.get((bssid, gx + dx, gy + dy), ())
                if w != file and (x - p[0]) ** 2 + (y - p[1]) ** 2 <= NEAR_M**2
            ]
            if len(near) >= 2:
                total += (rssi - sum(near) / len(near)) ** 2
                n += 1
        return math.sqrt(total / n) if n >= MIN_READINGS else None

    for file, (test, waypoints, times, wifi) in walks.items():
        t0, t1 = times[0], times[-1]
        thirds = []
        for k in range(3):
            lo, hi = t0 + (t1 - t0) * k / 3, t0 + (t1 - t0) * (k + 1) / 3
            curve = {s: residual(file, waypoints, times, wifi, lo, hi, s * 1000) for s in SHIFTS_S}
            curve = {s: r for s, r in curve.items() if r is not None}
            if 0 in curve:
                best = min(curve, key=curve.get)
                thirds.append(f"{curve[0]:.2f} {curve[best]:.2f} {best:+d}")
            else:
                thirds.append("nan nan 0")
        stem = os.path.splitext(file)[0]
        print(name, "test" if test else "survey", stem, " | ".join(thirds), flush=True)


if __name__ == "__main__":
    for directory in sys.argv[1:]:
        floor_lines(os.path.join(directory, "path_data_files"), os.path.basename(directory.rstrip("/")))
