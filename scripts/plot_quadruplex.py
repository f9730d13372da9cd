#!/usr/bin/python3
"""Plot quadruplex runs of tensegrity_run: resultant actuation force against actuation value.

usage: plot_quadruplex.py OUT.png CSV[=LABEL]... [--zoom VMAX] [--zoom-force FMAX] [--linear]
                          [--title TEXT] [--vmax VMAX]

Each CSV is one run (columns of tensegrity_run). The first point where min_gap < 0 (two struts
overlap: without contact they would have collided, with contact they touch) is marked on each
curve. With --zoom, a second panel shows v in [0, VMAX] (and forces up to FMAX with --zoom-force).
The first panel has a symlog force axis unless --linear, and shows v up to VMAX with --vmax.
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"plot_quadruplex: {path} has no rows")
    v = [float(r["actuation"]) for r in rows]
    force = [float(r["actuation_force"]) for r in rows]
    gap = [float(r["min_gap"]) for r in rows]
    first = next((i for i, g in enumerate(gap) if g < 0.0), None)
    return v, force, first


def option(argv, name, convert):
    if name not in argv:
        return None
    i = argv.index(name)
    value = convert(argv[i + 1])
    del argv[i : i + 2]
    return value


def main(argv):
    zoom = option(argv, "--zoom", float)
    zoom_force = option(argv, "--zoom-force", float)
    title = option(argv, "--title", str)
    vmax_all = option(argv, "--vmax", float)
    linear = "--linear" in argv
    if linear:
        argv.remove("--linear")
    if len(argv) < 2:
        sys.exit(__doc__)
    out, runs = argv[0], argv[1:]
    panels = 2 if zoom else 1
    fig, axes = plt.subplots(1, panels, figsize=(6.5 * panels, 4.5), squeeze=False)
    for spec in runs:
        path, _, label = spec.partition("=")
        v, force, first = read(path)
        for k, ax in enumerate(axes[0]):
            vmax = zoom if k == 1 else vmax_all
            idx = [i for i, x in enumerate(v) if vmax is None or x <= vmax]
            (line,) = ax.plot([v[i] for i in idx], [force[i] for i in idx], label=label or path)
            if first is not None and (vmax is None or v[first] <= vmax):
                ax.plot(v[first], force[first], "o", color=line.get_color(), markersize=5)
    for k, ax in enumerate(axes[0]):
        ax.set_xlabel("actuation value v (m)")
        ax.set_ylabel("resultant actuation force (N)")
        ax.grid(True, alpha=0.3)
        if k == 0:
            if linear:
                ax.set_title(title or "resultant actuation force; dots: first contact/overlap")
            else:
                ax.set_yscale("symlog", linthresh=300.0)
                ax.set_title(title or "full path (symlog: linear within ±300 N); dots: first overlap")
        else:
            ax.set_title(f"zoom, v <= {zoom} m")
            if zoom_force is not None:
                ax.set_ylim(top=zoom_force)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"plot_quadruplex: wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
