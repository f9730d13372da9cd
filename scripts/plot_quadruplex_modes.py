#!/usr/bin/python3
"""The quadruplex's lowest natural frequencies along its compression path, with and without strut contact.

usage: plot_quadruplex_modes.py TENSEGRITY_RUN SCENE.yaml OUT.png [--vmax VMAX] [--step DV]

Runs `TENSEGRITY_RUN SCENE --set analysis.type=modal --set analysis.max_actuation=v` for v from 0 to VMAX
(default 0.5 m) every DV (default 0.01 m, and every DV/4 around the contact onset), the static path followed
in load steps of 0.25 mm, once with contact off and once on, and plots the four frequencies against v
(log scale). The actuation value where the first pair touches (the summary's active_contacts) is marked.
"""
import csv
import io
import math
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

LOAD_STEP = 0.00025  # m per static load step (docs/validation.md: coarser steps can jump branches with contact)


def modal(binary, scene, v, contact):
    """Frequencies (Hz) of the modes about the equilibrium at v, and the contacts touching there."""
    steps = max(1, math.ceil(v / LOAD_STEP))
    args = [binary, scene, "--set", "analysis.type=modal", "--set", f"analysis.max_actuation={v}",
            "--set", f"analysis.steps={steps}", "--set", f"contact.enabled={'true' if contact else 'false'}"]
    run = subprocess.run(args, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"plot_quadruplex_modes: {' '.join(args)} exited {run.returncode}:\n{run.stderr}")
    freqs = [float(r["frequency_hz"]) for r in csv.DictReader(io.StringIO(run.stdout))]
    contacts = next(int(float(line.split(":")[1])) for line in run.stderr.splitlines()
                    if line.strip().startswith("active_contacts:"))
    return freqs, contacts


def option(argv, name, default):
    if name not in argv:
        return default
    i = argv.index(name)
    value = float(argv[i + 1])
    del argv[i : i + 2]
    return value


def main(argv):
    vmax = option(argv, "--vmax", 0.5)
    dv = option(argv, "--step", 0.01)
    if len(argv) != 3:
        sys.exit(__doc__)
    binary, scene, out = argv
    grid = [round(k * dv, 9) for k in range(int(round(vmax / dv)) + 1)]
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for contact, style in ((False, "--"), (True, "-")):
        values = list(grid)
        rows = [modal(binary, scene, v, contact) for v in values]
        onset = next((i for i, (_, c) in enumerate(rows) if c > 0), None)
        if onset is not None and onset > 0:
            # refine around the onset
            lo, hi = values[onset - 1], values[onset]
            fine = [round(lo + k * (hi - lo) / 8, 9) for k in range(1, 8)]
            values = values[:onset] + fine + values[onset:]
            rows = rows[:onset] + [modal(binary, scene, v, contact) for v in fine] + rows[onset:]
            onset = next(i for i, (_, c) in enumerate(rows) if c > 0)
        label = "contact" if contact else "no contact"
        for k in range(4):
            ax.plot(values, [r[0][k] for r in rows], style, color=f"C{k}",
                    label=f"mode {k + 1}, {label}")
        if contact and onset is not None:
            ax.axvline(values[onset], color="grey", lw=0.8)
            ax.text(values[onset], 0.3, f"first contact, v = {values[onset]:.4g} m  ", rotation=90,
                    va="bottom", ha="right", fontsize=8, color="grey", transform=ax.get_xaxis_transform())
            print(f"plot_quadruplex_modes: first contact at v = {values[onset]:.4g} m "
                  f"(last apart at {values[onset - 1]:.4g} m)")
        apart = rows[:onset] if onset else rows
        softest = min(range(len(apart)), key=lambda i: apart[i][0][0])
        print(f"plot_quadruplex_modes: {label}: lowest frequency {rows[0][0][0]:.4g} Hz at v = 0, "
              f"{apart[softest][0][0]:.4g} Hz at v = {values[softest]:.4g} m (least with no pair touching), "
              f"{rows[-1][0][0]:.4g} Hz at v = {values[-1]:.4g} m")
    ax.set_yscale("log")
    ax.set_xlabel("actuation value v (m)")
    ax.set_ylabel("natural frequency (Hz)")
    ax.set_title("quadruplex: the four natural frequencies about the static equilibrium at v\n"
                 "(modes 2 and 3 coincide: the fourfold symmetry)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="center right")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"plot_quadruplex_modes: wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
