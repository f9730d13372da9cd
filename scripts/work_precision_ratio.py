#!/usr/bin/env python3
"""Run-time ratio at equal error, from a `tensegrity_bench work-precision ... --mujoco-dts ...` CSV.

    work_precision_ratio.py FILE.csv [METRIC]   (default metric: position_error)

For every converged MuJoCo run (scheme mujoco_*), the wall time each of our schemes needs for the same
error, interpolated linearly in log(wall time) against log(error) between the two neighbouring runs of
that scheme's ladder (not extrapolated: "-" outside its range), and the ratio ours / MuJoCo."""
import csv
import math
import sys


def time_at(points, err):
    """wall time at `err` on a ladder of (error, wall) points, log-log interpolation, or None"""
    pts = sorted(points)
    for (e0, w0), (e1, w1) in zip(pts, pts[1:]):
        if e0 <= err <= e1 and e0 > 0 and e1 > e0:
            f = (math.log(err) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(w0) + f * (math.log(w1) - math.log(w0)))
    return None


def main(argv):
    if len(argv) < 2:
        sys.exit(__doc__)
    metric = argv[2] if len(argv) > 2 else "position_error"
    with open(argv[1]) as f:
        rows = [r for r in csv.DictReader(f) if r["status"] == "converged"]
    ours = {}
    for r in rows:
        if not r["scheme"].startswith("mujoco_"):
            ours.setdefault(r["scheme"], []).append((float(r[metric]), float(r["wall_time"])))
    print("| MuJoCo run | %s | wall (s) | %s |" % (metric, " | ".join("%s: wall, ratio" % s for s in ours)))
    print("|---|---|---|%s" % ("---|" * len(ours)))
    for r in rows:
        if not r["scheme"].startswith("mujoco_"):
            continue
        err, wall = float(r[metric]), float(r["wall_time"])
        cells = []
        for pts in ours.values():
            t = time_at(pts, err)
            cells.append("-" if t is None else "%.3g s, %.2g" % (t, t / wall))
        print("| %s dt %s | %.3g | %.3g | %s |" % (r["scheme"], r["dt"], err, wall, " | ".join(cells)))


if __name__ == "__main__":
    main(sys.argv)
