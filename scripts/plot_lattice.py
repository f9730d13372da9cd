#!/usr/bin/env python3
"""Time per step against the number of struts, from `tensegrity_bench lattice ... --csv FILE`.

    plot_lattice.py OUT.png [TITLE=]FILE.csv [[TITLE=]FILE.csv ...]

Left: us per step against struts, log-log, one line per CSV (e.g. --pairs near and --pairs all), with a
linear reference (slope 1 through each line's first point, dashed) and the fitted exponent in the
legend. Right: the breakdown of the time per step (forces, contact, constraints, factorization, solve)
of the first CSV, log-log. Rows whose run did not converge are drawn as crosses and left out
of the fit."""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PARTS = ["forces_us", "contact_us", "constraints_us", "factorization_us", "solve_us"]


def parse(arg):
    if "=" in arg:
        title, path = arg.split("=", 1)
    else:
        title, path = os.path.splitext(os.path.basename(arg))[0], arg
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return title, rows


def slope(xs, ys):
    if len(xs) < 2:
        return float("nan")
    lx, ly = [math.log(x) for x in xs], [math.log(y) for y in ys]
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    sxx = sum((a - mx) ** 2 for a in lx)
    return sum((a - mx) * (b - my) for a, b in zip(lx, ly)) / sxx if sxx > 0 else float("nan")


def main(argv):
    if len(argv) < 3:
        sys.exit(__doc__)
    out, runs = argv[1], [parse(a) for a in argv[2:]]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.4))
    for title, rows in runs:
        ok = [r for r in rows if r["status"] == "converged"]
        bad = [r for r in rows if r["status"] != "converged"]
        xs = [float(r["struts"]) for r in ok]
        ys = [float(r["us_per_step"]) for r in ok]
        if xs:
            line, = ax.loglog(xs, ys, "o-", label="%s (exponent %.2f)" % (title, slope(xs, ys)))
            ax.loglog([xs[0], xs[-1]], [ys[0], ys[0] * xs[-1] / xs[0]], "--", color=line.get_color(), alpha=0.5,
                      label="%s: linear from the first point" % title)
        if bad:
            ax.loglog([float(r["struts"]) for r in bad], [float(r["us_per_step"]) for r in bad], "x", color="red",
                      label="%s: did not converge" % title)
    ax.set_xlabel("struts")
    ax.set_ylabel("wall time per step (us)")
    ax.set_title("quadruplex lattice: time per step", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)

    title, rows = runs[0]
    ok = [r for r in rows if r["status"] == "converged"]
    for part in PARTS:
        pts = [(float(r["struts"]), float(r[part])) for r in ok if float(r[part]) > 0]
        if pts:
            bx.loglog([p[0] for p in pts], [p[1] for p in pts], "o-", ms=3, label=part.replace("_us", ""))
    if ok:
        bx.loglog([float(r["struts"]) for r in ok], [float(r["us_per_step"]) for r in ok], "k.--", label="whole step")
    bx.set_xscale("log")
    bx.set_yscale("log")
    bx.set_xlabel("struts")
    bx.set_ylabel("us per step")
    bx.set_title("where the time goes: %s" % title, fontsize=9)
    bx.grid(True, which="both", alpha=0.3)
    bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print("wrote " + out)


if __name__ == "__main__":
    main(sys.argv)
