"""Turns `waymark sim-export`'s walk.json into the line format test.c reads:
E <t_ns> <truth_x> <truth_y> <n_acc> <n_gyro> <n_mag> <n_wifi>, then the rows."""
import json
import sys

walk = json.load(open(sys.argv[1]))
with open(sys.argv[2], "w") as out:
    for e in walk["epochs"]:
        streams = [e["accelerometer"], e["gyroscope"], e["magnetometer"]]
        out.write("E %d %r %r %d %d %d %d\n" % (e["timestamp_ns"], e["truth"][0], e["truth"][1],
                                                *[len(s) for s in streams], len(e["wifi"])))
        for s in streams:
            for t, x, y, z in s:
                out.write("%d %r %r %r\n" % (int(t), x, y, z))
        for w in e["wifi"]:
            out.write("%s %r\n" % (w["bssid"], w["rssi_dbm"]))
