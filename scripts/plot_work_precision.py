#!/usr/bin/env python3
"""Work-precision figure from `tensegrity_bench work-precision ... --csv FILE` (docs/benchmarks.md).

    plot_work_precision.py OUT.png TITLE=FILE.csv[:METRIC,METRIC..] [...]

One row of panels per CSV, one panel per metric (CSV column; default position_error,force_error):
the error against wall time, log-log, one line per integrator (points: the step ladder labelled
with the step, or for adaptive schemes the tolerance ladder labelled "tol ...")."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

LABELS = {"position_error": "largest body-position error (m)",
          "height_error": "largest layer-height error (m)",
          "force_error": "largest actuation-force error / largest force",
          "peak_force_error": "peak contact force: relative error",
          "peak_time_error": "time of the peak contact force: error (s)",
          "impulse_error": "contact impulse: relative error"}
DEFAULT = ["position_error", "force_error"]


def parse(arg):
    title, rest = arg.rsplit("=", 1)
    path, _, metrics = rest.partition(":")
    return title, path, metrics.split(",") if metrics else DEFAULT


def tag(r):
    tol = float(r.get("tolerance") or 0)
    return "tol %g" % tol if tol > 0 else r["dt"]


def main(argv):
    if len(argv) < 3 or any("=" not in a for a in argv[2:]):
        sys.exit(__doc__)
    out, runs = argv[1], [parse(a) for a in argv[2:]]
    cols = max(len(r[2]) for r in runs)
    fig, axes = plt.subplots(len(runs), cols, figsize=(5.5 * cols, 4.2 * len(runs)), squeeze=False)
    for row, (title, path, metrics) in enumerate(runs):
        with open(path) as f:
            rows = [r for r in csv.DictReader(f) if r["status"] == "converged"]
        schemes = []
        for r in rows:
            if r["scheme"] not in schemes:
                schemes.append(r["scheme"])
        for col in range(len(metrics), cols):
            axes[row][col].axis("off")
        for col, key in enumerate(metrics):
            label = LABELS.get(key, key)
            ax = axes[row][col]
            for s in schemes:
                pts = [(float(r["wall_time"]), float(r[key]), tag(r)) for r in rows if r["scheme"] == s]
                pts = [p for p in pts if p[1] > 0]
                if not pts:
                    continue
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", label=s.replace("_", " "))
                for x, y, dt in pts:
                    ax.annotate(dt, (x, y), fontsize=6, xytext=(2, 2), textcoords="offset points")
            ax.set_xlabel("wall time (s)")
            ax.set_ylabel(label)
            ax.set_title(title, fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print("wrote " + out)


if __name__ == "__main__":
    main(sys.argv)
