#!/usr/bin/env python3
"""A venue's map refitted from walks without labels on a Dask cluster (docs/evidence.md#at-scale).

Map: one task per walk runs `waymark evidence collect --site SITE0` (the labelled survey's site).
Reduce: a tree of `waymark evidence merge`, FAN_IN files per task; merging is exact and in any
order the same bytes, so the tree's shape does not change the result. Then one
`waymark survey FLOORS --evidence MERGED` refits the labelled survey with it.

    python3 pipeline.py --waymark target/release/waymark --floors F1 --site0 site0.json \
        --work WORK --out site.json WALK...

Without --scheduler it starts a LocalCluster of --workers processes, one thread each; with it,
it joins that scheduler (every worker must see the same paths, a shared file system).
"""

import argparse
import subprocess
import sys
import time
from pathlib import Path

from dask.distributed import Client, LocalCluster


def run(args):
    """Runs a waymark command; its standard output, or an error with its standard error."""
    done = subprocess.run(args, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, args))} failed: {done.stderr.strip()}")
    return done.stdout


def collect(waymark, site0, walk, out):
    """Map: one walk's evidence on the labelled site."""
    run([waymark, "evidence", "collect", "--site", site0, "--out", out, walk])
    return out


def merge(waymark, out, *inputs):
    """Reduce: evidence files merged into one."""
    run([waymark, "evidence", "merge", "--out", out, *inputs])
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--waymark", required=True, help="the waymark binary (every worker runs it)")
    parser.add_argument("--floors", nargs="+", required=True, help="the labelled survey's floor folders")
    parser.add_argument("--site0", required=True, help="the labelled survey's site (waymark survey FLOORS)")
    parser.add_argument("--work", required=True, help="a folder for the evidence files")
    parser.add_argument("--out", required=True, help="where to write the refitted site")
    parser.add_argument("--fan-in", type=int, default=4, help="evidence files per merge task (2 or more)")
    parser.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes")
    parser.add_argument("--scheduler", help="a running scheduler's address instead of a LocalCluster")
    parser.add_argument("walks", nargs="+", help="walk files without labels")
    args = parser.parse_args()
    if args.fan_in < 2:
        parser.error("--fan-in must be 2 or more")
    waymark = str(Path(args.waymark).resolve())
    site0 = str(Path(args.site0).resolve())
    work = Path(args.work).resolve()
    work.mkdir(parents=True, exist_ok=True)

    cluster = None if args.scheduler else LocalCluster(
        n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=None)
    with Client(args.scheduler or cluster) as client:
        started = time.monotonic()
        # One task per walk; the file names are the walks' indices, so that two walks of the
        # same name cannot overwrite each other.
        level = [
            client.submit(collect, waymark, site0, str(Path(walk).resolve()), str(work / f"walk{k}.wmev"),
                          key=f"collect-{k}", pure=False)
            for k, walk in enumerate(args.walks)
        ]
        depth = 0
        while len(level) > 1:
            depth += 1
            level = [
                client.submit(merge, waymark, str(work / f"merge{depth}-{k}.wmev"), *level[i:i + args.fan_in],
                              key=f"merge-{depth}-{k}", pure=False)
                for k, i in enumerate(range(0, len(level), args.fan_in))
            ]
        merged = level[0].result()
        mapped = time.monotonic() - started
    if cluster is not None:
        cluster.close()
    print(f"{len(args.walks)} walks collected and merged in {depth} levels ({mapped:.1f} s): {merged}")
    survey = [waymark, "survey", *args.floors, "--evidence", merged, "--out", args.out]
    print(next(line for line in run(survey).splitlines() if line.startswith("map evidence")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
