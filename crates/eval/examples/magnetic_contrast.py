#!/usr/bin/env python3
"""How much a magnetic-field fingerprint could tell places apart on a floor: a map of the
field (magnitude, vertical and horizontal components of the tilt-compensated field, the tilt
from the accelerometer's low-passed gravity) averaged per CELL_M cell over the survey walks,
and each test walk's field against the map at its true cell and at cells 3-8 m away. Each test
walk's mean residual is taken off first (a per-session bias, as an online estimate would).
What a second emission would be worth (docs/accuracy.md).

Usage: magnetic_contrast.py FLOOR_DIR...   (split of the data's README: index % 5 == 4 is a test walk)
"""
import bisect, collections, math, os, sys

CELL_M = 2.0  # map cell, m
BIN_MS = 500  # samples averaged per 0.5 s (the field is sampled at ~50 Hz)
GRAVITY_ALPHA = 0.02  # low-pass of the accelerometer at 50 Hz: ~1 s time constant


def read(path):
    waypoints, mag, acc = [], [], []
    for line in open(path, errors="replace"):
        if line.startswith("#"):
            continue
        p = line.rstrip("\n").split("\t")
        if len(p) < 4:
            continue
        if p[1] == "TYPE_WAYPOINT":
            waypoints.append((int(p[0]), float(p[2]), float(p[3])))
        elif p[1] == "TYPE_MAGNETIC_FIELD":
            mag.append((int(p[0]), float(p[2]), float(p[3]), float(p[4])))
        elif p[1] == "TYPE_ACCELEROMETER":
            acc.append((int(p[0]), float(p[2]), float(p[3]), float(p[4])))
    waypoints.sort(); mag.sort(); acc.sort()
    times = [w[0] for w in waypoints]
    gravity, k, out, bins = [0.0, 0.0, 9.8], 0, [], collections.defaultdict(list)
    for t, mx, my, mz in mag:
        while k < len(acc) and acc[k][0] <= t:
            gravity = [(1 - GRAVITY_ALPHA) * g + GRAVITY_ALPHA * a for g, a in zip(gravity, acc[k][1:])]
            k += 1
        i = bisect.bisect_left(times, t)
        if not 0 < i < len(times):
            continue
        (t0, x0, y0), (t1, x1, y1) = waypoints[i - 1], waypoints[i]
        f = (t - t0) / max(1, t1 - t0)
        norm = math.sqrt(sum(g * g for g in gravity)) or 1.0
        vertical = (mx * gravity[0] + my * gravity[1] + mz * gravity[2]) / norm
        magnitude = math.sqrt(mx * mx + my * my + mz * mz)
        horizontal = math.sqrt(max(0.0, magnitude ** 2 - vertical ** 2))
        bins[t // BIN_MS].append((x0 + f * (x1 - x0), y0 + f * (y1 - y0), magnitude, vertical, horizontal))
    return [tuple(sum(c) / len(v) for c in zip(*v)) for _, v in sorted(bins.items())]


def cell(x, y):
    return int(x // CELL_M), int(y // CELL_M)


for floor in sys.argv[1:]:
    files = sorted(os.listdir(os.path.join(floor, "path_data_files")))
    walks = [read(os.path.join(floor, "path_data_files", f)) for f in files]
    cells = collections.defaultdict(list)
    for i, walk in enumerate(walks):
        if i % 5 != 4:
            for x, y, *field in walk:
                cells[cell(x, y)].append(field)
    field_map = {c: [sum(v) / len(v) for v in zip(*fs)] for c, fs in cells.items()}
    away = [(dx, dy) for dx in range(-8, 9) for dy in range(-8, 9) if 3 <= math.hypot(dx, dy) <= 8]
    name = os.path.basename(floor.rstrip("/"))
    for component, label in enumerate(("magnitude", "vertical", "horizontal")):
        at_truth, elsewhere = [], []
        for i, walk in enumerate(walks):
            if i % 5 != 4:
                continue
            mapped = [(x, y, f[component]) for x, y, *f in walk if cell(x, y) in field_map]
            if not mapped:
                continue
            bias = sum(v - field_map[cell(x, y)][component] for x, y, v in mapped) / len(mapped)
            for x, y, v in mapped:
                at_truth.append(v - bias - field_map[cell(x, y)][component])
                for dx, dy in away:
                    other = field_map.get(cell(x + dx, y + dy))
                    if other is not None and cell(x + dx, y + dy) != cell(x, y):
                        elsewhere.append(v - bias - other[component])
        rms = lambda a: math.sqrt(sum(z * z for z in a) / len(a))
        print(f"{name} {label:10}: rms against the map at the truth {rms(at_truth):.2f} µT, "
              f"3-8 m away {rms(elsewhere):.2f} µT ({len(at_truth)} samples)")
