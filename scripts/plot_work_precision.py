#!/usr/bin/env python3
"""Work-precision figure from `tensegrity_bench work-precision ... --csv FILE` (docs/benchmarks.md).

    plot_work_precision.py OUT.png TITLE=FILE.csv [TITLE=FILE.csv ...]

One row of panels per CSV: position error and actuation-force error against wall time, log-log, one
line per integrator (points: the step ladder, labelled with the step)."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

METRICS = [("position_error", "largest body-position error (m)"),
           ("force_error", "largest actuation-force error / largest force")]


def main(argv):
    if len(argv) < 3 or any("=" not in a for a in argv[2:]):
        sys.exit(__doc__)
    out, runs = argv[1], [a.rsplit("=", 1) for a in argv[2:]]
    fig, axes = plt.subplots(len(runs), len(METRICS), figsize=(11, 4.2 * len(runs)), squeeze=False)
    for row, (title, path) in enumerate(runs):
        with open(path) as f:
            rows = [r for r in csv.DictReader(f) if r["status"] == "converged"]
        schemes = []
        for r in rows:
            if r["scheme"] not in schemes:
                schemes.append(r["scheme"])
        for col, (key, label) in enumerate(METRICS):
            ax = axes[row][col]
            for s in schemes:
                pts = [(float(r["wall_time"]), float(r[key]), r["dt"]) for r in rows if r["scheme"] == s]
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
