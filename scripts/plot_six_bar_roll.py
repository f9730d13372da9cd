#!/usr/bin/python3
"""The six-bar robot's roll step, ours against MuJoCo's (docs/validation.md, "Six-bar rolling robot").

usage: plot_six_bar_roll.py PATHS.csv OUT.png

PATHS.csv is tensegrity_bench work-precision config/scenes/six_bar.yaml ... --paths PATHS.csv: per run and output
step the bodies' mass centre. Drawn: its x (along the roll) and z against time for the reference, our runs at
dt = 1 ms and MuJoCo's three integrators at their coarsest and finest steps.
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(paths, out):
    runs = {}
    with open(paths) as f:
        for row in csv.DictReader(f):
            key = (row["scheme"], float(row["dt"]))
            runs.setdefault(key, []).append((float(row["t"]), float(row["x"]), float(row["z"])))
    if not runs:
        sys.exit("plot_six_bar_roll.py: %s has no rows" % paths)
    mujoco_dts = sorted({dt for (name, dt) in runs if name.startswith("mujoco_")})
    shown = [(k, v) for k, v in runs.items()
             if k[0] == "reference" or (not k[0].startswith("mujoco_") and not k[0].startswith("adaptive")
                                        and k[1] == 1e-3)
             or (k[0].startswith("mujoco_") and mujoco_dts and k[1] in (mujoco_dts[0], mujoco_dts[-1]))]
    fig, (ax_x, ax_z) = plt.subplots(2, 1, figsize=(7.5, 6.5), sharex=True)
    for (name, dt), rows in sorted(shown):
        t = [r[0] for r in rows]
        style = dict(lw=2.2, color="black") if name == "reference" else dict(lw=1.1)
        if name.startswith("mujoco_"):
            style["ls"] = "--"
        label = "%s, dt %g s" % (name, dt)
        ax_x.plot(t, [r[1] for r in rows], label=label, **style)
        ax_z.plot(t, [r[2] for r in rows], **style)
    ax_x.set_ylabel("mass centre x (m)")
    ax_z.set_ylabel("mass centre z (m)")
    ax_z.set_xlabel("t (s)")
    ax_x.set_title("six_bar.yaml: C14 pulled in by 0.4 m from 0.5 s, let out from 3.5 s")
    ax_x.legend(fontsize=7, loc="upper left")
    for ax in (ax_x, ax_z):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
