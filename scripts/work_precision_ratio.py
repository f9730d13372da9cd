#!/usr/bin/env python3
"""Run-time ratio at equal error, from a `tensegrity_bench work-precision ... --mujoco-dts ...` CSV.

    work_precision_ratio.py FILE.csv [METRIC] [--front]   (default metric: position_error)

For every converged MuJoCo run (scheme mujoco_*), the wall time each of our schemes needs for the same
error, interpolated linearly in log(wall time) against log(error) between the two neighbouring runs of
that scheme's ladder (not extrapolated: "-" outside its range), and the ratio ours / MuJoCo.

--front: only MuJoCo's best runs, those no other MuJoCo run (any integrator, any step) beats in both error
and wall time, each against the fastest of our schemes at its error; the last line gives the largest of
these ratios ("worst ratio"), or says that none of our schemes reaches a front run's error range."""
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


def front(runs):
    """the runs (error, wall, ...) no other run matches or beats in both error and wall time"""
    return [r for r in runs if not any(o[0] <= r[0] and o[1] <= r[1] and (o[0], o[1]) != (r[0], r[1]) for o in runs)]


def print_front(rows, ours, metric):
    mujoco = [(float(r[metric]), float(r["wall_time"]), "%s dt %s" % (r["scheme"], r["dt"]))
              for r in rows if r["scheme"].startswith("mujoco_")]
    best = sorted(front(mujoco), key=lambda m: m[1])
    print("| MuJoCo's front | %s | wall (s) | our fastest at that error | wall (s) | ratio ours / MuJoCo |" % metric)
    print("|---|---|---|---|---|---|")
    worst = None
    for err, wall, name in best:
        times = [(t, s) for s, pts in ours.items() for t in [time_at(pts, err)] if t is not None]
        if not times:
            print("| %s | %.3g | %.3g | - | - | - |" % (name, err, wall))
            continue
        t, scheme = min(times)
        print("| %s | %.3g | %.3g | %s | %.3g | %.2f |" % (name, err, wall, scheme, t, t / wall))
        if worst is None or t / wall > worst[0]:
            worst = (t / wall, name)
    if worst is None:
        print("worst ratio: none (no scheme of ours reaches the error range of MuJoCo's front)")
    else:
        print("worst ratio: %.2f (%s)" % worst)


def main(argv):
    args = [a for a in argv[1:] if a != "--front"]
    if not args or len(args) > 2 or any(a.startswith("-") for a in args):
        sys.exit(__doc__)
    metric = args[1] if len(args) > 1 else "position_error"
    with open(args[0]) as f:
        rows = [r for r in csv.DictReader(f) if r["status"] == "converged"]
    if rows and metric not in rows[0]:
        sys.exit("work_precision_ratio.py: no column '%s' in %s" % (metric, args[0]))
    ours = {}
    for r in rows:
        if not r["scheme"].startswith("mujoco_"):
            ours.setdefault(r["scheme"], []).append((float(r[metric]), float(r["wall_time"])))
    if "--front" in argv[1:]:
        print_front(rows, ours, metric)
        return
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
