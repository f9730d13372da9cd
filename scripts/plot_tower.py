#!/usr/bin/python3
"""Figures and findings of the tower study (scripts/tower_study; paper Sec. 6.2, Fig. 14-27).

usage: plot_tower.py RESULTS_DIR FIGURES_DIR
       plot_tower.py --demo DYNAMIC.csv STATIC.csv OUT.png   (one run: layer heights and contact force)

RESULTS_DIR holds the folders of the two study files of scripts/tower_study: quasi_static/ with
static_contact_true.csv and static_contact_false.csv, dynamic/ with, per speed V, dynamic_vV.csv, dynamic_vV.yaml
and dynamic_vV_contacts.csv, as tensegrity_run writes them. Writes
  tower_quasi_static.png   heights against actuation, with and without contact (Fig. 14)
  tower_dynamic_heights.png layer heights against time per speed, quasi-static curve dashed (Fig. 15-19)
  tower_contact_forces.png  largest normal contact force per stage against time per speed (Fig. 21-25)
  tower_peaks.png           largest normal and tangential force, bending stress, cable stress per speed
                            (Fig. 26-27)
and prints the findings as Markdown tables.
"""
import csv
import os
import sys

import matplotlib
import yaml

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SPEEDS = ["5", "2", "0.5", "0.05", "0.005"]
LAYERS = ["height_layer1", "height_layer2", "height_layer3", "height_layer4"]


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) if k not in ("strut_a", "strut_b") else r[k] for r in rows] for k in rows[0]} if rows else {}


def read_summary(path):
    """A tensegrity_run summary (YAML)."""
    with open(path) as f:
        return yaml.safe_load(f)


def crossing(xs, ys, level, below=True):
    """First x where y goes below (or above) level, interpolated."""
    for i in range(1, len(xs)):
        a, b = ys[i - 1], ys[i]
        if (below and a >= level > b) or (not below and a <= level < b):
            return xs[i - 1] + (xs[i] - xs[i - 1]) * (a - level) / (a - b)
    return None


def stage_of(strut):
    return int(strut[1])  # S<stage><k>


def demo(dynamic_csv, static_csv, out_png):
    d, s = read_csv(dynamic_csv), read_csv(static_csv)
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for k, col in enumerate(LAYERS):
        ax[0].plot(d["t"], d[col], color=f"C{k}", label=f"layer {k + 1}")
        # quasi-static height at the same actuation
        qs = []
        for a in d["actuation"]:
            i = min(range(len(s["actuation"])), key=lambda j: abs(s["actuation"][j] - a))
            qs.append(s[col][i])
        ax[0].plot(d["t"], qs, "--", color=f"C{k}", lw=0.7)
    ax[0].set_ylabel("height, m (dashed: quasi-static)")
    ax[0].legend(fontsize=8, ncol=4)
    ax[0].grid(alpha=0.3)
    ax[1].plot(d["t"], d["max_normal_force"], label="largest normal contact force")
    ax[1].plot(d["t"], d["max_friction_force"], label="largest friction force")
    ax[1].set_yscale("symlog", linthresh=10.0)
    ax[1].set_xlabel("t, s")
    ax[1].set_ylabel("N")
    ax[1].legend(fontsize=8)
    ax[1].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=100)


def main():
    if len(sys.argv) == 5 and sys.argv[1] == "--demo":
        demo(*sys.argv[2:])
        return
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    res, figs = sys.argv[1], sys.argv[2]
    sc = read_csv(os.path.join(res, "quasi_static", "static_contact_true.csv"))
    sn = read_csv(os.path.join(res, "quasi_static", "static_contact_false.csv"))
    res = os.path.join(res, "dynamic")

    # quasi-static findings
    onset = crossing(sn["actuation"], sn["min_gap"], 0.0)
    onset_height = None
    if onset is not None:
        i = next(i for i, v in enumerate(sn["actuation"]) if v >= onset)
        a0, a1 = sn["actuation"][i - 1], sn["actuation"][i]
        h0, h1 = sn["height"][i - 1], sn["height"][i]
        onset_height = h0 + (h1 - h0) * (onset - a0) / (a1 - a0)
    first_contact = next((v for v, n in zip(sc["actuation"], sc["active_contacts"]) if n > 0), None)
    below_half = crossing(sc["actuation"], sc["height"], 0.5)
    collapse = crossing(sn["actuation"], sn["height"], 0.01)

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    ax[0].plot(sc["actuation"], sc["height"], label="with contact")
    ax[0].plot(sn["actuation"], sn["height"], "--", label="without contact")
    if onset is not None:
        ax[0].plot([onset], [onset_height], "ko", label=f"contact onset {onset:.3f} m, height {onset_height:.3f} m")
    if below_half is not None:
        ax[0].plot([below_half], [0.5], "rs", label=f"height 0.5 m at {below_half:.3f} m")
    ax[0].set_xlabel("actuation (travel of B1-B4), m")
    ax[0].set_ylabel("height of the tower, m")
    ax[0].set_title("quasi-static folding (paper Fig. 14)")
    ax[0].legend(fontsize=8)
    ax[0].grid(alpha=0.3)
    for k, col in enumerate(LAYERS):
        ax[1].plot(sc["actuation"], sc[col], color=f"C{k}", label=f"layer {k + 1}, contact")
        ax[1].plot(sn["actuation"], sn[col], "--", color=f"C{k}", lw=0.8)
    ax[1].set_xlabel("actuation, m")
    ax[1].set_ylabel("height of the top of each stage, m (dashed: no contact)")
    ax[1].legend(fontsize=8)
    ax[1].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(figs, "tower_quasi_static.png"), dpi=110)

    # dynamic runs present
    speeds = [v for v in SPEEDS if os.path.exists(os.path.join(res, f"dynamic_v{v}.yaml"))]
    dyn = {v: read_csv(os.path.join(res, f"dynamic_v{v}.csv")) for v in speeds}
    summ = {v: read_summary(os.path.join(res, f"dynamic_v{v}.yaml")) for v in speeds}

    def quasi_static_at(actuation, col):
        xs, ys = sc["actuation"], sc[col]
        out = []
        for a in actuation:
            a = min(max(a, xs[0]), xs[-1])
            i = max(1, next((i for i, x in enumerate(xs) if x >= a), len(xs) - 1))
            w = (a - xs[i - 1]) / (xs[i] - xs[i - 1]) if xs[i] > xs[i - 1] else 0.0
            out.append(ys[i - 1] + w * (ys[i] - ys[i - 1]))
        return out

    fig, axes = plt.subplots(len(speeds), 1, figsize=(10, 2.6 * len(speeds)), squeeze=False)
    deviation = {}
    for ax, v in zip(axes[:, 0], speeds):
        d = dyn[v]
        dev = 0.0
        for k, col in enumerate(LAYERS):
            qs = quasi_static_at(d["actuation"], col)
            ax.plot(d["t"], d[col], color=f"C{k}", lw=0.9, label=f"layer {k + 1}")
            ax.plot(d["t"], qs, "--", color=f"C{k}", lw=0.7)
            dev = max(dev, max(abs(a - b) for a, b in zip(d[col], qs)))
        deviation[v] = dev
        ax.set_title(f"V = {v} m/s (dashed: quasi-static at the same actuation)", fontsize=9)
        ax.set_ylabel("height, m")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=4)
    axes[-1, 0].set_xlabel("t, s")
    fig.tight_layout()
    fig.savefig(os.path.join(figs, "tower_dynamic_heights.png"), dpi=100)

    fig, axes = plt.subplots(len(speeds), 1, figsize=(10, 2.6 * len(speeds)), squeeze=False)
    stage_peak = {}
    for ax, v in zip(axes[:, 0], speeds):
        path = os.path.join(res, f"dynamic_v{v}_contacts.csv")
        by_stage = {s: {} for s in range(1, 5)}
        if os.path.exists(path) and os.path.getsize(path) > 0:
            c = read_csv(path)
            for t, a, fn in zip(c.get("t", []), c.get("strut_a", []), c.get("normal_force", [])):
                st = by_stage[stage_of(a)]
                st[t] = max(st.get(t, 0.0), fn)
        times = dyn[v]["t"]
        stage_peak[v] = {}
        for s in range(1, 5):
            ys = [by_stage[s].get(t, 0.0) for t in times]
            stage_peak[v][s] = max(ys) if ys else 0.0
            ax.plot(times, ys, lw=0.8, label=f"stage {s}")
        ax.set_title(f"V = {v} m/s: largest normal contact force in each stage (output steps)", fontsize=9)
        ax.set_ylabel("F_N, N")
        ax.set_yscale("symlog", linthresh=10.0)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=4)
    axes[-1, 0].set_xlabel("t, s")
    fig.tight_layout()
    fig.savefig(os.path.join(figs, "tower_contact_forces.png"), dpi=100)

    fig, ax = plt.subplots(1, 3, figsize=(13, 4))
    x = range(len(speeds))
    peak = {v: summ[v].get("peaks", {}) for v in speeds}
    get = lambda v, k: peak[v].get(k, {}).get("value", 0.0)  # noqa: E731
    ax[0].bar([i - 0.2 for i in x], [get(v, "max_normal_force") for v in speeds], 0.4, label="normal")
    ax[0].bar([i + 0.2 for i in x], [get(v, "max_friction_force") for v in speeds], 0.4, label="tangential")
    ax[0].set_yscale("log")
    ax[0].set_ylabel("largest contact force, N")
    ax[0].legend()
    ax[1].bar(list(x), [get(v, "max_strut_bending_stress") / 1e6 for v in speeds])
    ax[1].axhline(235.0, color="r", ls="--", label="steel yield, 235 MPa (S235)")
    ax[1].set_yscale("log")
    ax[1].set_ylabel("largest strut bending stress (core), MPa")
    ax[1].legend(fontsize=8)
    ax[2].bar(list(x), [get(v, "max_cable_stress") / 1e6 for v in speeds])
    ax[2].set_ylabel("largest cable stress, MPa")
    for a in ax:
        a.set_xticks(list(x))
        a.set_xticklabels([f"{v} m/s" for v in speeds])
        a.grid(alpha=0.3, axis="y")
    fig.suptitle("peaks over every time step (paper Fig. 26-27)")
    fig.tight_layout()
    fig.savefig(os.path.join(figs, "tower_peaks.png"), dpi=110)

    # findings
    print("## quasi-static (1 mm load steps)")
    print("| finding | ours | paper |")
    print("|---|---|---|")
    if onset is not None:
        print(f"| contact onset (no-contact run's first overlap) | actuation {onset:.4f} m, height {onset_height:.4f} m "
              f"| 0.638 m, 0.799 m |")
    if first_contact is not None:
        print(f"| first load step with contact (contact run) | {first_contact:.3f} m | |")
    if collapse is not None:
        print(f"| without contact: height below 1 cm | actuation {collapse:.3f} m | collapses soon after onset |")
    if below_half is not None:
        print(f"| with contact: height below 0.5 m | actuation {below_half:.4f} m | 1.448 m |")
    print(f"| with contact at 1.5 m: height, largest normal force | {sc['height'][-1]:.4f} m, "
          f"{sc['max_normal_force'][-1]:.1f} N | |")
    print()
    print("## dynamic runs")
    print("| V (m/s) | simulated (s) | steps | Newton it. | wall (s) | real-time factor | max F_N (N) | max F_T (N) "
          "| max bending stress (MPa) | max cable stress (MPa) | stage with largest F_N | max height gap to quasi-static (m) "
          "| final height (m) | status |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for v in speeds:
        s = summ[v]
        sp = stage_peak.get(v, {})
        hardest = max(sp, key=sp.get) if sp and max(sp.values()) > 0 else "-"
        print(f"| {v} | {s['final']['t']:g} | {int(float(s['solver_steps']))} | {int(float(s['newton_iterations']))} "
              f"| {float(s['wall_time']):.1f} | {float(s.get('real_time_factor', 0)):.3f} "
              f"| {get(v, 'max_normal_force'):.1f} | {get(v, 'max_friction_force'):.1f} "
              f"| {get(v, 'max_strut_bending_stress') / 1e6:.1f} | {get(v, 'max_cable_stress') / 1e6:.1f} "
              f"| {hardest} | {deviation[v]:.3f} | {s['final']['height']:.4f} | {s['status']} |")


if __name__ == "__main__":
    main()
